# Each line on stdin (JSON) through the parser: its letter, number and words (None for
# a word without a value), or "Error:" and why it was refused.
import json
import sys

from mixfw.gcode import GcodeError, Parser

p = Parser()
out = []
for s in json.loads(sys.stdin.read()):
    b = s.encode()
    try:
        line = p.parse(b, len(b))
        words = {}
        for i in range(26):
            ch = chr(65 + i)
            if line.has(ch):
                words[ch] = line.float(ch) if line.has_value(ch) else None
        out.append([line.letter, line.number, words])
    except GcodeError as e:
        out.append("Error:" + str(e))
print(json.dumps(out))
