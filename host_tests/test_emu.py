"""The firmware on an emulated Pico (`mixstep emu print`): a real slicer excerpt with a
tool change, booted from the emulated flash and streamed over the emulated USB
console; its trace must do what the G-code asks. Also the two counters the emulator's
report reads from the firmware (M122), on the unix port."""
import json

import pytest

from mixstep import emu, paths, tracecheck

EXCERPT = paths.ROOT / "testdata" / "part_3tool_emu_excerpt.gcode"

UNDERRUNS = """
import sys
import simmachine
sys.modules["machine"] = simmachine
import board
from mixfw import assemble
from mixfw import stepper as st

simmachine.attach_world(board.PINS, ["x", "y", "z"] + ["e%d" % i for i in range(6)])
printer = assemble.build(files_root=None)
pl = printer.planner
mem = printer.mem
said = []

class Console:
    def write(self, text):
        said.append(text)

printer.current = printer.add_channel(Console())

def run(text):
    printer.run_line(printer.parser.parse(text, len(text)))

def step_loop_runs_dry():
    mem[st.S_TAIL] = mem[st.S_HEAD]
    mem[st.S_ACTIVE] = 0

run(b"G1 X10 F3000")
run(b"G1 X20")           # queued behind the first: no underrun
step_loop_runs_dry()
run(b"G1 X30")           # the queue ran dry between two moves: one
counts = [pl.underruns]
pl.idle = step_loop_runs_dry  # waits end at once
run(b"G4 P10")           # a dwell is a wait: the queue may run dry before and after it
run(b"G1 X40")
run(b"M400")
run(b"G1 X50")
counts.append(pl.underruns)
run(b"M122")
print(json.dumps({"counts": counts, "said": said}))
"""


def test_underruns_counted_between_moves_and_reported_by_m122(mp):
    out = mp.json("import json\n" + UNDERRUNS)
    assert out["counts"] == [1, 1]
    line = "".join(out["said"]).strip()
    assert line.startswith("echo:underruns:1 mem_free:")
    words = dict(w.split(":") for w in line[len("echo:"):].split())
    assert int(words["mem_free_collected"]) >= int(words["mem_free"]) > 0


def _emulator_or_skip():
    try:
        emu.check_setup()
        emu.image_files()
    except emu.EmuError as e:
        pytest.skip("no emulator: %s" % e)


@pytest.mark.slow
def test_excerpt_prints_on_the_emulated_pico(tmp_path):
    _emulator_or_skip()
    vcd = tmp_path / "emu.vcd"
    report = emu.run(EXCERPT, "pico", vcd, tmp_path / "emu.json", max_emu_s=60,
                     max_wall_s=900)
    assert report["stopped"] is None, report["stopped"]
    assert report["errors"] == []
    assert report["lines"] == sum(1 for _ in open(EXCERPT))
    assert report["underruns"] == 0
    assert 0 < report["cpu_step_fraction"] < 1
    # About 45.5 kB: every kB of code the firmware adds comes from here (a .mpy
    # module's code loads into the heap), so a drop past the margin asks whether it is
    # worth its place.
    assert report["mem_free_min_bytes"] > 44000
    assert report["mem_free_samples"] >= 2
    assert 2 < report["emulated_seconds"] < 20
    # Every drive the excerpt uses moved: T0 prints with e0, T2 with e2.
    assert report["steps"]["e0"] and report["steps"]["e2"]
    check = tracecheck.check(vcd, EXCERPT, board="pico")
    assert check["timescale_us"] == 0.001
    assert check["ok"], json.dumps([c for c in check["checks"] if not c["ok"]], indent=1)
