"""The firmware on an emulated Pico (`mixstep emu print`): a real slicer excerpt with a
tool change, booted from the emulated flash and streamed over the emulated USB
console; its trace must do what the G-code asks. Also the two counters the emulator's
report reads from the firmware (M122), on the unix port."""
import json

import pytest

from mixstep import emu, paths, tracecheck

EXCERPT = paths.ROOT / "testdata" / "part_3tool_emu_excerpt.gcode"


def test_underruns_counted_between_moves_and_reported_by_m122(mp):
    out = mp.script_json("emu_underruns")
    assert out["counts"] == [1, 1]
    assert out["said"][0] == "start\n"  # what a console hears first
    line = "".join(out["said"][1:]).strip()
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
    # About 27 kB (after a 48-block queue, G2/G3 and the job commands): every kB of
    # code the firmware adds comes from here (a .mpy module's code loads into the
    # heap), so a drop past the margin asks whether it is worth its place.
    assert report["mem_free_min_bytes"] > 25000
    assert report["mem_free_samples"] >= 2
    assert 2 < report["emulated_seconds"] < 20
    # Every drive the excerpt uses moved: T0 prints with e0, T2 with e2.
    assert report["steps"]["e0"] and report["steps"]["e2"]
    check = tracecheck.check(vcd, EXCERPT, board="pico")
    assert check["timescale_us"] == 0.001
    assert check["ok"], json.dumps([c for c in check["checks"] if not c["ok"]], indent=1)
