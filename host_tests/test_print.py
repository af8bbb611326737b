"""End to end: real PrusaSlicer 3-tool prints streamed through the firmware on the
unix port, line by line as a host does, with the heap locked around every
step-loop call. The GPIO trace must say what the G-code says. make test prints the
short part; make test-all the whole example part as well."""
import subprocess

import numpy as np
import pytest

from mixstep import paths, sim, trace
from gcode_model import expected_steps
from sigrok import need_sigrok

SAMPLES = paths.ROOT / "testdata"


@pytest.fixture(scope="module", params=[
    "short_3tool_m117_prusaslicer.gcode",
    pytest.param("part_3tool_prusaslicer_rel.gcode", marks=pytest.mark.slow)])
def printed(request, tmp_path_factory):
    """The print's report, its output folder and its G-code file."""
    out = tmp_path_factory.mktemp("print")
    gcode = SAMPLES / request.param
    report = sim.run(gcode, trace_path=out / "trace.vcd", report_path=out / "report.json",
                     heap_lock=True, edges_path=out / "run.edges")
    return report, out, gcode


def test_whole_print_runs_with_heap_locked_and_no_errors(printed):
    report, _, gcode = printed
    assert report["heap_locked_step_loop"] is True
    assert report["errors"] == []
    assert report["lines"] == sum(1 for _ in open(gcode))


# The firmware's data heap during a print with the default queue, as bench/run.py
# reports it (heap_peak_bytes): measured on the 64-bit unix port, where every object is
# twice its size on the chips, so an ESP32 without PSRAM has room to spare.
HEAP_TARGET_BYTES = 64 * 1024


def test_firmware_data_heap_during_the_print_fits_the_target(printed):
    """What building the printer and printing allocate (the firmware's code is not in
    it: frozen into flash on a board)."""
    report, _, _ = printed
    assert 0 < report["heap_data_at_rest_bytes"] <= report["heap_data_peak_bytes"]
    assert report["heap_data_peak_bytes"] <= HEAP_TARGET_BYTES


def test_each_drive_gets_the_e_of_its_tool_and_xyz_end_where_commanded(printed, board):
    report, _, gcode = printed
    want = expected_steps(gcode, board["SETTINGS"]["steps_per_mm"])
    assert report["steps"] == want
    assert report["firmware_steps"] == want  # the step loop's own counters agree
    assert want["e0"] > 0 and want["e1"] != 0 and want["e2"] > 0  # every tool was used


@pytest.mark.slow
def test_absolute_e_file_gives_the_same_drive_totals(board, tmp_path):
    gcode = SAMPLES / "part_3tool_prusaslicer_abs.gcode"
    report = sim.run(gcode)
    assert report["errors"] == []
    assert report["steps"] == expected_steps(gcode, board["SETTINGS"]["steps_per_mm"])


def _edges_by_pin(out):
    times, gpios, levels = trace.read_edges(out / "run.edges")
    keep = times > 0
    return times[keep], gpios[keep], levels[keep]


def test_trace_pulse_width_and_dir_setup(printed, board):
    _, out, _ = printed
    s = board["SETTINGS"]
    times, gpios, levels = _edges_by_pin(out)
    pins = board["PINS"]
    for axis in ["x", "y", "z"] + ["e%d" % i for i in range(6)]:
        st = pins[axis + "_step"]
        rise = times[(gpios == st) & (levels == 1)]
        fall = times[(gpios == st) & (levels == 0)]
        if len(rise) == 0:
            continue
        assert len(fall) == len(rise)
        high = fall - rise
        assert high.min() >= s["step_pulse_us"], axis
        low = rise[1:] - fall[:-1]
        assert low.min() >= s["step_pulse_us"], axis
        dir_times = times[gpios == pins[axis + "_dir"]]
        last = np.searchsorted(dir_times, rise, side="right") - 1
        setup = rise[last >= 0] - dir_times[last[last >= 0]]
        assert setup.min() >= s["dir_setup_us"], axis


def test_no_axis_steps_faster_than_its_max_feed_rate(printed, board):
    """Over any run of 20 steps, the average rate stays within the axis's limit. The
    slack is one tick per end, since steps fall on ticks."""
    _, out, _ = printed
    s = board["SETTINGS"]
    times, gpios, levels = _edges_by_pin(out)
    k = 20
    for i, axis in enumerate(["x", "y", "z"] + ["e%d" % d for d in range(6)]):
        limit = min(i, 3)
        max_rate = s["max_feed_mm_s"][limit] * s["steps_per_mm"][limit]
        rise = times[(gpios == board["PINS"][axis + "_step"]) & (levels == 1)]
        if len(rise) <= k:
            continue
        span = (rise[k:] - rise[:-k]).astype(float)
        fastest = k / ((span.min() + 2 * s["tick_us"]) * 1e-6)
        assert fastest <= max_rate, (axis, fastest, max_rate)


def test_sigrok_decodes_the_trace(printed, board):
    """sigrok's stepper_motor decoder labels each step interval with the position
    at its start, so its last label is one step short of the final position."""
    need_sigrok()
    report, out, _ = printed
    proc = subprocess.run(["sigrok-cli", "-I", "vcd", "-i", str(out / "trace.vcd"),
                           "-P", "stepper_motor:step=e1_step:dir=e1_dir", "-A", "stepper_motor"],
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr
    positions = [int(l.split()[1]) for l in proc.stdout.splitlines() if l.endswith(" steps")]
    assert positions, proc.stdout[:500]
    times, gpios, levels = _edges_by_pin(out)
    pins = board["PINS"]
    last_rise = times[(gpios == pins["e1_step"]) & (levels == 1)][-1]
    dir_sel = (gpios == pins["e1_dir"]) & (times <= last_rise)
    last_dir = levels[dir_sel][-1] if dir_sel.any() else 0
    final = report["steps"]["e1"]
    assert positions[-1] == final - (1 if last_dir else -1)
    assert len(positions) == int(np.sum((gpios == pins["e1_step"]) & (levels == 1))) - 1
