# The heap's big blocks: what heap.zeros and an array from bytes take, the reserve
# heap.py holds while the modules load, and what build() needs and makes of it.
import gc
import json
import sys

import simmachine

sys.modules["machine"] = simmachine
import board  # noqa: E402
from array import array  # noqa: E402
from mixfw import heap  # noqa: E402

words = 5000
gc.collect()
gc.disable()
before = gc.mem_alloc()
a = heap.zeros(words)
one = gc.mem_alloc() - before
gc.collect()
gc.disable()
before = gc.mem_alloc()
b = array("i", bytes(4 * words))
two = gc.mem_alloc() - before
gc.enable()
from mixfw import assemble, planner  # noqa: E402

held = [len(r) for r in heap._reserves]
simmachine.attach_world(board.PINS, ["x", "y", "z"] + ["e%d" % i for i in range(6)])
printer = assemble.build(files_root=None)
print(json.dumps({"zeros": list(a) == [0] * words, "one": one, "two": two,
                  "held": held, "left": len(heap._reserves),
                  "need": planner.step_loop_bytes(printer.settings),
                  "arrays": 4 * (len(printer.mem) + len(printer.planner.lk))}))
