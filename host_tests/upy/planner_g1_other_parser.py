# G1 lines run by the printer's own parser and by another Parser's lines given to
# Motion.g1: the position (nm) after each.
import json

import simbuild
from mixfw.gcode import Parser

printer = simbuild.printer()
out = []
for text in (b"G1 X10 Y5 F3000", b"G1 X12"):
    printer.run_line(printer.parser.parse(text, len(text)))
    out.append(list(printer.motion.pos_nm))
other = Parser()
for text in (b"G1 X20 Y7", b"G1 Y9"):
    printer.motion.g1(other.parse(text, len(text)))
    out.append(list(printer.motion.pos_nm))
text = b"G1 X3"
printer.run_line(printer.parser.parse(text, len(text)))
out.append(list(printer.motion.pos_nm))
print(json.dumps(out))
