# main.py's way on a board: the printer started by assemble.start, then assemble's code
# dropped (assemble.drop) before serving. What that gives back to the heap, and
# that the printer still serves.
import gc
import json
import sys

import simmachine

sys.modules["machine"] = simmachine
import board  # noqa: E402
from mixfw import assemble  # noqa: E402

simmachine.attach_world(board.PINS, ["x", "y", "z"] + ["e%d" % i for i in range(6)])
printer = assemble.start(consoles=[], repl_flag=None)
gc.collect()
held = gc.mem_alloc()
assemble.drop()
del assemble
gc.collect()
freed = held - gc.mem_alloc()
from mixfw import safety  # noqa: E402

line = bytearray(b"M115")
printer.run_line(printer.parser.parse(line, len(line)))
safety.serve(printer)  # no console: everything off, and back
print(json.dumps({"freed": freed, "gone": "mixfw.assemble" not in sys.modules}))
