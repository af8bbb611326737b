"""The heap's big blocks (mixfw/heap.py) on the unix port: the step loop's arrays each
take one block, and build() takes them from a reserve held while the modules load."""

HEAP = """
import gc, json, sys
import simmachine
sys.modules["machine"] = simmachine
import board
from array import array
from mixfw import heap
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
from mixfw import assemble
held = [len(r) for r in heap._reserves]
simmachine.attach_world(board.PINS, ["x", "y", "z"] + ["e%d" % i for i in range(6)])
printer = assemble.build(files_root=None)
print(json.dumps({"zeros": list(a) == [0] * words, "one": one, "two": two,
                  "held": held, "left": len(heap._reserves),
                  "need": heap.step_loop_bytes(printer.settings),
                  "arrays": 4 * (len(printer.mem) + len(printer.planner.lk))}))
"""


def test_arrays_take_one_block_each_from_the_reserve_held_while_the_modules_load(mp):
    got = mp.json(HEAP)
    assert got["zeros"]
    # array('i', bytes(n)) holds the bytes too until they are collected
    assert got["one"] < 4 * 5000 + 256 < got["two"]
    assert got["held"] == [got["need"]] and got["left"] == 0
    assert got["arrays"] + 2048 <= got["need"]
