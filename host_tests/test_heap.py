"""The heap's big blocks (mixfw/heap.py) on the unix port: the step loop's arrays each
take one block, and build() takes them from a reserve held while the modules load; and
a G-code line takes nothing from the heap on its way to the planner."""
import json
import math

import pytest

from mixstep import paths

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
from mixfw import assemble, planner
held = [len(r) for r in heap._reserves]
simmachine.attach_world(board.PINS, ["x", "y", "z"] + ["e%d" % i for i in range(6)])
printer = assemble.build(files_root=None)
print(json.dumps({"zeros": list(a) == [0] * words, "one": one, "two": two,
                  "held": held, "left": len(heap._reserves),
                  "need": planner.step_loop_bytes(printer.settings),
                  "arrays": 4 * (len(printer.mem) + len(printer.planner.lk))}))
"""


def test_arrays_take_one_block_each_from_the_reserve_held_while_the_modules_load(mp):
    got = mp.json(HEAP)
    assert got["zeros"]
    # array('i', bytes(n)) holds the bytes too until they are collected
    assert got["one"] < 4 * 5000 + 256 < got["two"]
    assert got["held"] == [got["need"]] and got["left"] == 0
    assert got["arrays"] + 2048 <= got["need"]


# Whether a call takes anything from the heap, even what it gives back at once: a
# bytecode function whose locals and stack pass 11 words gets its frame from the heap
# at every call, and frees it on return, so gc.mem_alloc() never shows it, and
# micropython.heap_lock() makes the VM take the frame from the C stack instead. With
# gc.threshold(1) any allocation collects first, and the garbage left before the call
# is then gone. On a chip's fragmented heap one such allocation costs up to hundreds
# of microseconds.
PROBE = """
import gc
def _garbage():
    bytearray(8000)
def allocates(fn, a, b):
    gc.collect()
    _garbage()
    before = gc.mem_alloc()
    gc.threshold(1)
    fn(a, b)
    gc.threshold(-1)
    return gc.mem_alloc() < before - 4000
def _small(a, b):
    return a
def _wide(a, b):  # a frame of more than 11 words
    c = d = e = f = g = h = i = j = k = l = a
    return c
for _ in range(3):  # the probe's own first calls
    allocates(_small, 7, 2)
assert not allocates(_small, 7, 2) and allocates(_wide, 7, 2)
"""

PLAN_LINES = PROBE + """
import json, sys
import simmachine
sys.modules["machine"] = simmachine
import board
from mixfw import assemble
from plan_only import retire_one
simmachine.attach_world(board.PINS, ["x", "y", "z"] + ["e%%d" %% i for i in range(6)])
printer = assemble.build(files_root=None)
printer.planner.idle = retire_one(printer.mem, printer.planner.queue)
parse = printer.parser.parse
for raw in (b"M302 P1", b"M83"):
    printer.run_line(parse(raw, len(raw)))
class Host:  # a console whose bytes are the line probed; the answers go nowhere
    def __init__(self):
        self.line = bytearray(257)
        self.n = self.at = self.errors = 0
    def readinto(self, mv, block=False):
        k = 0
        while self.at < self.n and k < len(mv):
            mv[k] = self.line[self.at]
            self.at += 1
            k += 1
        return k
    def write(self, text):
        if text.startswith("Error") or text.startswith("Resend"):
            self.errors += 1
host = Host()
printer.add_channel(host)
channel = printer.channels[0]
buf = bytearray(256)
def serve(a, b):  # one line, as Printer.serve takes it from a host
    printer.pump_all()
    printer.answer(channel, channel.next_line())
def run_job_line(a, b):  # one line, as Printer.serve takes it from the file printed
    printer.run_job_line()
way, root, lines = json.loads(%r)
if way == "long":
    # Past a metre of filament on every drive: positions in nm beyond small ints.
    for tool in (b"T0", b"T1", b"T2"):
        printer.run_line(parse(tool, 2))
        for _ in range(8):
            printer.run_line(parse(b"G1 E150 F6000", 13))
    for raw in (b"T0", b"G92 E0"):
        printer.run_line(parse(raw, len(raw)))
if way == "file":
    from mixfw.files import Files
    files = Files(root, printer)
    files.select("part.gcode")
    files.start()
    serve = run_job_line
out = []
for raw in lines:
    n = len(raw)
    buf[:n] = raw.encode()
    host.line[:n + 1] = buf[:n] + b"\\n"
    host.n = n + 1
    host.at = 0
    out.append([allocates(printer.parser.parse, buf, n), allocates(serve, 0, 0)])
x_steps = printer.planner.position_steps[0]
print(json.dumps([out, host.errors, x_steps]))
"""


FILLED = 64  # lines: more moves than the simulated board's queue holds


def numbered(lines):
    """The lines as a host prints a file: comments off, each with a line number and
    checksum, from N1 (a channel starts at N0)."""
    out = []
    for number, raw in enumerate(lines, 1):
        text = "N%d %s" % (number, raw.split(";")[0].strip())
        checksum = 0
        for c in text.encode():
            checksum ^= c
        out.append("%s*%d" % (text, checksum))
    return out


@pytest.mark.parametrize("way", ["host", "numbered", "file", "long"])
def test_a_g1_line_takes_nothing_from_the_heap_not_even_a_frame(mp, tmp_path, way):
    """The example's perimeter and infill moves, sent by a host or printed from a file,
    also after 1.2 m of filament on each of the three tools' drives (long: beyond the
    chips' small ints in nm, see Planner._rebase),
    planned against a full queue: the parse of every line, and every G1 line that
    changes neither the feed rate nor has filament over an eighth of its path (those
    work out new float limits), from its bytes' arrival to its `ok`, take nothing from
    the heap. The first moves are left out: while the queue fills, SLOWDOWN works out
    slower speeds in floats."""
    lines = paths.EXAMPLE_GCODE.read_text().splitlines()[2999:3300]
    lines = [raw for raw in lines if raw[:4] not in ("M109", "M190", "M116")]
    (tmp_path / "part.gcode").write_text("\n".join(lines) + "\n")
    sent = numbered(lines) if way == "numbered" else lines
    got, errors, x_steps = mp.json(PLAN_LINES % json.dumps([way, str(tmp_path), sent]))
    # Every line was taken and planned: the last move's X is where the planner is.
    last_x = [w for raw in lines if raw.startswith("G1 ") for w in raw.split() if w[0] == "X"][-1]
    assert errors == 0 and x_steps == round(float(last_x[1:]) * 80)
    assert [raw for raw, (parsed, _) in zip(lines, got) if parsed] == []
    at = {"X": 0.0, "Y": 0.0}
    plain = []
    feed_before = True
    for number, (raw, (_, planned)) in enumerate(zip(lines, got)):
        words = {w[0]: float(w[1:]) for w in raw.split(";")[0].split()[1:]}
        if raw.startswith("G1 "):
            path = math.hypot(words.get("X", at["X"]) - at["X"],
                              words.get("Y", at["Y"]) - at["Y"])
            if (number >= FILLED and "F" not in words and not feed_before and "E" in words
                    and 8 * abs(words["E"]) <= path):
                plain.append((raw, planned))
            feed_before = "F" in words
            at.update({k: v for k, v in words.items() if k in at})
    assert len(plain) > 150
    assert [raw for raw, planned in plain if planned] == []


BACKGROUND = PROBE + """
import json, sys
import simmachine
sys.modules["machine"] = simmachine
import board
from mixfw import assemble
simmachine.attach_world(board.PINS, ["x", "y", "z"] + ["e%d" % i for i in range(6)])
printer = assemble.build(files_root=None)
def turn(a, b):
    printer._run_background()
turn(0, 0)  # the first control period
print(json.dumps([allocates(turn, 0, 0) for _ in range(5)]))
"""


def test_the_main_loops_background_takes_nothing_from_the_heap_between_control_periods(mp):
    """The background tasks run at every turn of the main loop and of every wait, and
    between lines at least every 10 ms: between two control periods they take
    nothing from the heap (the control period's own floats are left out)."""
    assert mp.json(BACKGROUND) == [False] * 5


# The bytecode functions a G1 line runs on its way to the ring when it brings a new
# feed rate, when an axis's limits bind or when SLOWDOWN slows it: Planner._base_floats,
# _limited_floats and what they call. Their floats take a block each from the heap,
# found at once; a frame takes several, found only after a search through the heap's
# holes (on the emulated Pico's fragmented heap, hundreds of microseconds a call).
FEED_PATH = ("_base_floats", "_memo_load", "_work_base_floats", "_within", "_min_bits",
             "_limited_floats", "_axis_limit", "_slowdown", "_set_floats", "_new_slot")

FRAMES = PROBE + """
import json, sys, uctypes
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
import board
from mixfw import assemble
from mixfw.planner import Planner
simmachine.attach_world(board.PINS, ["x", "y", "z"] + ["e%%d" %% i for i in range(6)])
printer = assemble.build(files_root=None)
planner = printer.planner
accel = planner.acceleration_mm_s2
def base(speed, accel):
    Planner._base_floats(planner, speed, accel)
frames = {name: frame_words(Planner.__dict__[name]) for name in %r}
new = allocates(base, 50.0, accel)
print(json.dumps([frames, new, allocates(base, 50.0, accel)]))
"""


def test_a_new_feed_rate_takes_no_frame_from_the_heap(mp):
    """The planner's functions a line runs when it brings a new feed rate or where a
    limit binds keep their frames within the 11 words the VM takes from the C stack; a
    feed rate taken again (the memo's) takes nothing from the heap at all, a new one
    its floats."""
    frames, new, again = mp.json(FRAMES % (FEED_PATH,))
    assert {name: words for name, words in frames.items() if words > 11} == {}
    assert new and not again
