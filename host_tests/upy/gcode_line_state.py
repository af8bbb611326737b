# Each line on stdin (JSON) through one parser that takes M23's text: its command, N
# word, text arguments and words present.
import json
import sys

from mixfw.gcode import Parser

p = Parser((("M", 23),))
out = []
for s in json.loads(sys.stdin.read()):
    b = s.encode()
    line = p.parse(b, len(b))
    out.append([line.letter, line.number, line.has_line_number, line.line_number,
                line.args_text, line.present])
print(json.dumps(out))
