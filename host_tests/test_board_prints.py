"""The example print (real PrusaSlicer 3-tool output) through every real board's pin
map and settings, on a simulated chip of the board's kind (its GPIOs, its register
layout or PIO), with the heap locked around every step-loop call. `mixstep trace
check` then holds each board's trace to the G-code: step counts per axis and drive,
move order, mix windows, pulse widths, DIR setup and step rates."""
import pytest

from mixstep import cli, paths, sim

BOARDS = ["pico", "pico2", "esp32_devkit", "skr_pico", "fysetc_e4"]


@pytest.mark.parametrize("board", BOARDS)
def test_example_print_on_each_board(tmp_path, board):
    vcd = tmp_path / "trace.vcd"
    report = sim.run(paths.EXAMPLE_GCODE, trace_path=vcd, heap_lock=True, board=board)
    assert report["errors"] == [] and report["heap_locked_step_loop"]
    assert report["steps"] == report["firmware_steps"]
    drives = paths.load_board(board)["SETTINGS"]["drives"]
    assert all(report["steps"]["e%d" % d] > 0 for d in range(min(drives, 3)))
    assert cli.main(["trace", "check", str(vcd), "--gcode", str(paths.EXAMPLE_GCODE),
                     "--board", board, "--json", str(tmp_path / "check.json")]) == 0
