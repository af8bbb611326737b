# A hundred parses of a G1 line with the heap locked: "done" if none allocated.
import micropython

from mixfw.gcode import Parser

p = Parser()
b = bytearray(b"G1 X76.923 Y79.437 Z0.2 E.06669 F1800 ; comment")
n = len(b)
i = 0
micropython.heap_lock()
while i < 100:
    p.parse(b, n)
    i += 1
micropython.heap_unlock()
print("done")
