"""The heap's big blocks (mixfw/heap.py) on the unix port: the step loop's arrays each
take one block, and build() takes them from a reserve held while the modules load; and
a G-code line takes nothing from the heap on its way to the planner."""
import json
import math

import pytest

from mixstep import paths

# Whether a call takes anything from the heap, even a frame it gives back at once, the
# scripts (upy/heap_*.py) ask upy/heap_probe.py.


def test_arrays_take_one_block_each_from_the_reserve_held_while_the_modules_load(mp):
    got = mp.script_json("heap_arrays")
    assert got["zeros"]
    # array('i', bytes(n)) holds the bytes too until they are collected
    assert got["one"] < 4 * 5000 + 256 < got["two"]
    assert got["held"] == [got["need"]] and got["left"] == 0
    assert got["arrays"] + 2048 <= got["need"]


def test_main_drops_the_code_that_built_the_printer(mp):
    """main.py on a board starts the printer, then drops assemble before serving: its
    code and tables go back to the heap, unless something built still refers to the
    module (a closure made in build would keep all of it)."""
    got = mp.script_json("heap_forget")
    assert got["gone"]
    # 5.8 kB on the 64-bit port, 3.7 kB on the 32-bit one; about 32 bytes were a
    # closure left in build (tried)
    assert got["freed"] >= 2048


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
    chips' small ints in nm, see filament.rebase),
    planned against a full queue: the parse of every line, and every G1 line that
    changes neither the feed rate nor has filament over an eighth of its path (those
    work out new float limits), from its bytes' arrival to its `ok`, take nothing from
    the heap. The first moves are left out: while the queue fills, SLOWDOWN works out
    slower speeds in floats."""
    lines = paths.EXAMPLE_GCODE.read_text().splitlines()[2999:3300]
    lines = [raw for raw in lines if raw[:4] not in ("M109", "M190", "M116")]
    (tmp_path / "part.gcode").write_text("\n".join(lines) + "\n")
    sent = numbered(lines) if way == "numbered" else lines
    got, errors, x_steps = mp.script_json(
        "heap_g1_line", stdin=json.dumps([way, str(tmp_path), sent]).encode())
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


def test_a_spiral_vase_line_takes_nothing_from_the_heap(mp, tmp_path):
    """A spiral vase (PrusaSlicer's, the emulator's print bench file) moves Z on every
    line at a speed past Z's own limits: Z's tiny share of the path binds nothing, and
    its numbered lines, from their bytes' arrival to their `ok`, take nothing from the
    heap (the first are left out while the queue fills). A new feed rate works out its
    floats, and how much of the path Z may take at it on the first line that moves Z a
    step."""
    vase = paths.ROOT / "testdata" / "vase_3mix_emu_excerpt.gcode"
    lines = [raw for raw in vase.read_text().splitlines()[1000:1300]
             if raw.split(";")[0].strip()]
    assert sum(1 for raw in lines if raw.startswith("G1 Z")) > 150
    got, errors, _ = mp.script_json(
        "heap_g1_line", stdin=json.dumps(["numbered", str(tmp_path), numbered(lines)]).encode())
    assert errors == 0
    z_steps_per_mm = paths.load_board("sim")["SETTINGS"]["steps_per_mm"][2]
    z_steps = None
    feed_new = True  # until a move has worked out its floats, and then Z's share
    moved = False
    allocating = []
    for i, (raw, (parsed, planned)) in enumerate(zip(lines, got)):
        if not raw.startswith("G1 "):
            continue
        words = {w[0]: float(w[1:]) for w in raw.split(";")[0].split()[1:]}
        z_was = z_steps
        z_steps = round(words.get("Z", (z_steps or 0) / z_steps_per_mm) * z_steps_per_mm)
        if "F" in words:
            feed_new = True
            moved = len(words) > 1
        elif feed_new and not moved:
            moved = True
        elif feed_new and z_steps != z_was:
            feed_new = False
        elif i >= FILLED and (parsed or planned):
            allocating.append(raw)
    assert allocating == []


def test_the_main_loops_background_takes_nothing_from_the_heap_between_control_periods(mp):
    """The background tasks run at every turn of the main loop and of every wait, and
    between lines at least every 10 ms: between two control periods they take
    nothing from the heap (the control period's own floats are left out)."""
    assert mp.script_json("heap_background") == [False] * 5


# The bytecode functions a G1 line runs on its way to the ring when it brings a new
# feed rate, when an axis's limits bind or when SLOWDOWN slows it: Planner._base_floats,
# _limited_floats and what they call. Their floats take a block each from the heap,
# found at once; a frame takes several, found only after a search through the heap's
# holes (on the emulated Pico's fragmented heap, hundreds of microseconds a call).
FEED_PATH = ("_base_floats", "_memo_load", "_work_base_floats", "_within", "_shares",
             "_min_bits", "_limited_floats", "_axis_limit", "_slowdown", "_set_floats", "_new_slot")

def test_a_new_feed_rate_takes_no_frame_from_the_heap(mp):
    """The planner's functions a line runs when it brings a new feed rate or where a
    limit binds keep their frames within the 11 words the VM takes from the C stack; a
    feed rate taken again (the memo's) takes nothing from the heap at all, a new one
    its floats."""
    frames, new, again = mp.script_json("heap_frames", *FEED_PATH)
    assert {name: words for name, words in frames.items() if words > 11} == {}
    assert new and not again
