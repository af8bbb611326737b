"""The example print (real PrusaSlicer 3-tool output) through every real board's pin
map and settings, on a simulated chip of the board's kind (its GPIOs, its register
layout or PIO), with the heap locked around every step-loop call. `mixstep trace
check` then holds each board's trace to the G-code: step counts per axis and drive,
move order, mix windows, pulse widths, DIR setup and step rates."""
import pytest

from mixstep import boards, cli, detool, paths, sim

# make test-all only (whole prints on every board).
pytestmark = pytest.mark.slow

# Every board in boards/, so a new one prints without being listed here.
BOARDS = [n for n in boards.board_names() if n != "sim"]


def print_and_check(tmp_path, gcode, board):
    """Simulate gcode on the board and trace-check it; returns the sim report."""
    vcd = tmp_path / "trace.vcd"
    report = sim.run(gcode, trace_path=vcd, heap_lock=True, board=board)
    assert report["heap_locked_step_loop"]
    assert report["steps"] == report["firmware_steps"]
    assert cli.main(["trace", "check", str(vcd), "--gcode", str(gcode),
                     "--board", board, "--json", str(tmp_path / "check.json")]) == 0
    return report


def fan_errors(gcode, board):
    """What the firmware must answer to the file on the board: a board without a
    part fan refuses each M106 (and only those), every other line is run."""
    if "part_fan" in paths.load_board(board)["PINS"]:
        return []
    with open(gcode) as f:
        return ["line %d: Error:this board has no part fan" % n
                for n, line in enumerate(f, 1) if line.startswith("M106")]


@pytest.mark.parametrize("board", BOARDS)
def test_example_print_on_each_board(tmp_path, board):
    report = print_and_check(tmp_path, paths.EXAMPLE_GCODE, board)
    assert report["errors"] == fan_errors(paths.EXAMPLE_GCODE, board)
    drives = paths.load_board(board)["SETTINGS"]["drives"]
    assert all(report["steps"]["e%d" % d] > 0 for d in range(min(drives, 3)))


def test_the_sixth_drive_prints_on_pico_6drives(tmp_path):
    """The example's three tools moved onto e3, e4 and e5 (e5 on the old part-fan pin
    and GPIO 28): every one of them prints, and the trace holds to the G-code."""
    gcode = tmp_path / "last_drives.gcode"
    detool.detool(paths.EXAMPLE_GCODE, gcode, detool.parse_matrix(
        "0,0,0,1,0,0;0,0,0,0,1,0;0,0,0,0,0,1"))
    assert fan_errors(gcode, "pico_6drives")  # the slicer's M106 lines are refused
    report = print_and_check(tmp_path, gcode, "pico_6drives")
    assert report["errors"] == fan_errors(gcode, "pico_6drives")
    steps = report["steps"]
    assert all(steps["e%d" % d] > 0 for d in (3, 4, 5))
    assert all(steps["e%d" % d] == 0 for d in (0, 1, 2))
