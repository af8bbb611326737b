# The frame size in words of each Planner function named in argv, and whether a new
# feed rate, then the same one again, takes anything from the heap in
# Planner._base_floats.
import json
import sys

import uctypes

from heap_probe import allocates
import simmachine

sys.modules["machine"] = simmachine
WORD = 8 if sys.maxsize > 2 ** 32 else 4


def frame_words(fn):
    # A bytecode function object's fourth word points at its bytecode, which opens with
    # its frame's size: the locals and stack (n_state) and the exception handlers' depth
    # (two words each), packed as py/bc.h's MP_BC_PRELUDE_SIG_DECODE unpacks them.
    code = int.from_bytes(uctypes.bytearray_at(id(fn) + 3 * WORD, WORD), "little")
    ip = uctypes.bytearray_at(code, 8)
    z = ip[0]
    state = (z >> 3) & 0xF
    handlers = (z >> 2) & 1
    n = 0
    while z & 0x80:
        n += 1
        z = ip[n]
        state |= (z & 0x30) << (2 * (n - 1))
        handlers |= (z & 2) << (n - 1)
    return state + 1 + 2 * handlers


def _eleven(a, b):  # 2 arguments, 7 locals, 2 words of stack
    c = d = e = f = g = h = i = a
    return c


def _twelve(a, b):
    c = d = e = f = g = h = i = j = a
    return c


# The reading agrees with the VM: 11 words on the C stack, 12 from the heap.
assert frame_words(_eleven) == 11 and not allocates(_eleven, 7, 2)
assert frame_words(_twelve) == 12 and allocates(_twelve, 7, 2)
import board  # noqa: E402
from mixfw import assemble  # noqa: E402
from mixfw.planner import Planner  # noqa: E402

simmachine.attach_world(board.PINS, ["x", "y", "z"] + ["e%d" % i for i in range(6)])
printer = assemble.build(files_root=None)
planner = printer.planner
accel = planner.acceleration_mm_s2


def base(speed, accel):
    Planner._base_floats(planner, speed, accel)


frames = {name: frame_words(Planner.__dict__[name]) for name in sys.argv[1:]}
new = allocates(base, 50.0, accel)
print(json.dumps([frames, new, allocates(base, 50.0, accel)]))
