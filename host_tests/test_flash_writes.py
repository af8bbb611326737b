"""No flash write while the step path has work. The rp2 port erases and programs flash
with every interrupt off (45 ms typical, 400 ms at worst), far longer than the step
path runs ahead of the pins, so M500, M164 P1, an upload (M28/M29) and M30 first wait
for the queued moves, as M400 does. The simulated flash holds every interrupt for
`M7103 F<us>` at each write (boards/sim/simfaults.py), and the traces show the axes
only ever standing still where a move ends, with the steps of every move as planned."""
import itertools

import numpy as np
import pytest

from mixstep import paths, trace
from mixstep.simprinter import SimPrinter
from gcode_model import expected_steps

BOARDS = {"pio_dma": "pico_6drives", "timer": "skr_pico"}
HOLDS_US = (45000, 400000)
SLICER = paths.ROOT / "testdata" / "part_3tool_prusaslicer_rel.gcode"
# What an upload sends: real slicer lines, as stored (no comments), over a flash
# sector's worth so that a chunk is written in the middle of the upload.
UPLOAD = [code for code in (l.split(";")[0].strip() for l in open(SLICER)) if code][:400]
assert len("\n".join(UPLOAD)) > 8192
CRUISE = "M7102 S300"  # the moves' cruise: the main loop waits 300 ms, the axes run


def x_rises(edges, board):
    pins = paths.load_board(board)["PINS"]
    t, g, v = trace.read_edges(edges)
    return t[(g == pins["x_step"]) & (v == 1)].astype(np.int64)


def move_steps(board):
    return int(paths.load_board(board)["SETTINGS"]["steps_per_mm"][0] * 100)


def intervals(edges, board, moves):
    """X's step intervals within the moves (each 100 mm, back and forth), and the
    intervals between them, where the axis stands still."""
    gaps = np.diff(x_rises(edges, board))
    n = move_steps(board)
    assert len(gaps) == moves * n - 1
    ends = [k * n - 1 for k in range(1, moves)]
    return np.delete(gaps, ends), gaps[ends]


def run(tmp_path, board, hold_us, commands):
    """Five moves of X 100 mm back and forth, each of commands[i] sent in the cruise
    of move i; every line must get its `ok` and no error. Returns the run's report,
    its trace and what each command answered."""
    flash = tmp_path / "flash"
    flash.mkdir()
    (flash / "old.gcode").write_text("G1 X1\n")
    edges = tmp_path / "x.edges"
    p = SimPrinter(edges_path=edges, board=board, config_path=tmp_path / "mixstep.cfg",
                   files_dir=flash)
    answers = []
    for line in ["G91", "M7103 F%d" % hold_us, "M926 Imax_feed_mm_s_z V12"]:
        assert p.send(line) == ["ok"]
    for i, lines in enumerate(commands + [["M400"]]):
        assert p.send("G1 X%d F3000" % (100 if i % 2 == 0 else -100)) == ["ok"]
        assert p.send(CRUISE) == ["ok"]
        said = [p.send(line) for line in lines]
        for reply in said:
            assert reply[-1] == "ok" and not [r for r in reply if "Error" in r], said
        answers.append(said)
    return p.finish(), edges, answers


FLASH_COMMANDS = [["M500"], ["M163 S0 P0.3", "M163 S1 P0.7", "M164 S1 P1",
                             "M925 Itool_mixes_1"],
                  ["M28 up.gcode"] + UPLOAD + ["M29"], ["M30 old.gcode"]]


@pytest.fixture(scope="module", params=sorted(BOARDS))
def planned(request, tmp_path_factory):
    """The same moves with M400 where the flash commands are: how they are planned."""
    board = BOARDS[request.param]
    _, edges, _ = run(tmp_path_factory.mktemp("planned"), board, 0,
                      [["M400"]] * len(FLASH_COMMANDS))
    return board, intervals(edges, board, len(FLASH_COMMANDS) + 1)


@pytest.mark.parametrize("hold_us", HOLDS_US)
def test_flash_writes_in_a_cruise_wait_for_the_moves_and_leave_them_as_planned(
        tmp_path, planned, hold_us):
    board, (planned_steps, planned_stills) = planned
    report, edges, answers = run(tmp_path, board, hold_us, FLASH_COMMANDS)
    steps, stills = intervals(edges, board, len(FLASH_COMMANDS) + 1)
    # Within every move the steps come as planned: no stall, no restart at full speed.
    assert np.array_equal(steps, planned_steps)
    # Each write stood between two moves: the axis stood still at least one hold there.
    assert planned_stills.max() < min(HOLDS_US) and (stills >= hold_us).all(), stills
    cfg = (tmp_path / "mixstep.cfg").read_text()
    assert "max_feed_mm_s_z = 12.0\n" in cfg
    mix = answers[1][3][0].split()[2][1:]  # echo:M926 Itool_mixes_1 V<mix> ; ...
    assert "tool_mixes_1 = %s\n" % mix in cfg and mix != "0:1000:0:0:0:0"
    assert answers[2][-1] == ["Done saving file.", "ok"]
    assert (tmp_path / "flash" / "up.gcode").read_text() == "\n".join(UPLOAD) + "\n"
    assert answers[3] == [["File deleted:old.gcode", "ok"]]
    assert not (tmp_path / "flash" / "old.gcode").exists()
    assert report["steps"]["x"] == move_steps(board)
    # The saved configuration loads.
    again = SimPrinter(board=board, config_path=tmp_path / "mixstep.cfg")
    assert again.send("M925 Itool_mixes_1")[0] == answers[1][3][0]
    assert again.send("M925 Imax_feed_mm_s_z")[0].startswith("echo:M926 Imax_feed_mm_s_z V12.0 ")
    again.finish()


@pytest.mark.parametrize("hold_us", HOLDS_US)
@pytest.mark.parametrize("backend", sorted(BOARDS))
def test_a_flash_write_in_a_cruise_would_stall_the_axes(tmp_path, backend, hold_us):
    """The converse, which shows the simulated flash stalls the chip: the same hold
    forced in the cruise (M7103 W1, no wait for the moves) stops the pins dead in the
    middle of the move, for the hold less what the step path had run ahead."""
    board = BOARDS[backend]
    _, edges, _ = run(tmp_path, board, hold_us, [["M7103 W1"]])
    steps, _ = intervals(edges, board, 2)
    assert steps.max() > hold_us - 5000


def test_an_upload_or_delete_is_refused_while_a_file_prints(tmp_path, board):
    """Writing while a file prints from flash would stop it at every chunk: M28, and
    M30 of the printing file, are refused by name; the print goes on to its end. Once
    paused (M25), the upload is taken."""
    flash = tmp_path / "flash"
    flash.mkdir()
    (flash / "part.gcode").write_text("".join(itertools.islice(open(SLICER), 300)))
    p = SimPrinter(files_dir=flash)

    def send(line):  # the print's own lines (temperatures while it heats) left out
        return [r for r in p.send(line) if not r.startswith(("T:", "echo:", "busy:"))]

    assert send("M32 part.gcode")[-1] == "ok"
    assert send("M28 new.gcode") == [
        "Error:cannot write new.gcode while part.gcode prints: pause it (M25) first; the "
        "lines up to M29 are not run", "ok"]
    # A host that sends the file anyway: its lines are taken, not run, and not saved.
    assert send("G28") == ["ok"]
    assert send("M29") == [
        "Error:new.gcode not saved: cannot write new.gcode while part.gcode prints: pause "
        "it (M25) first", "ok"]
    assert send("M30 part.gcode") == [
        "Error:cannot delete part.gcode while it prints: pause it (M25) first", "ok"]
    assert not (flash / "new.gcode.part").exists()
    assert send("M25") == ["ok"]
    assert send("M28 new.gcode") == ["Writing to file: new.gcode", "ok"]
    assert send("G1 X5") == ["ok"]  # stored, not run
    assert send("M29") == ["Done saving file.", "ok"]
    assert (flash / "new.gcode").read_text() == "G1 X5\n"
    assert send("M24") == ["ok"]
    while True:
        replies = p.send("M27")
        assert not [r for r in replies if r.startswith("Error")], replies
        if any("Done printing file" in r for r in replies) or replies[0] == "Not SD printing":
            break
    p.send("M400")
    assert p.finish()["steps"] == expected_steps(flash / "part.gcode",
                                                 board["SETTINGS"]["steps_per_mm"])
