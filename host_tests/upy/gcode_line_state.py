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
    number = p.line_number()
    out.append([line.letter, line.number, number is not None, number or 0,
                line.args_text, line.present])
print(json.dumps(out))
