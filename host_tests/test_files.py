"""Printing from flash (M20-M32) and uploading (M28/M29), on the unix port."""

import pytest
from mixstep.simprinter import SimPrinter
from mixstep import paths
from gcode_model import expected_steps


def send_all(printer, lines):
    return [printer.send(l) for l in lines]


def test_upload_list_select_print_and_delete(tmp_path, board):
    files = tmp_path / "flash"
    files.mkdir()
    p = SimPrinter(files_dir=files)
    body = ["G28", "G1 X10 Y10 F3000 ; go", "M109 S200", "M83", "G1 E2 F600", "T1", "G1 X20 E1"]
    assert p.send("M28 job.gcode")[0] == "Writing to file: job.gcode"
    for text in body:
        assert p.send(text) == ["ok"]  # stored, not run
    assert p.send("M29") == ["Done saving file.", "ok"]
    # Stored as the firmware received it: comments are not kept.
    assert (files / "job.gcode").read_text().splitlines() == [l.split(";")[0].strip() for l in body]
    assert p.send("M114")[0].startswith("X:0.00 Y:0.00")  # nothing ran
    assert p.send("M20") == ["Begin file list", "job.gcode %d" % (files / "job.gcode").stat().st_size,
                             "End file list", "ok"]
    assert p.send("M32 job.gcode")[:2] == ["File opened: job.gcode Size: %d"
                                           % (files / "job.gcode").stat().st_size, "File selected"]
    # The console stays answered while the file prints.
    size = (files / "job.gcode").stat().st_size
    while True:
        status = [l for l in p.send("M27") if l.startswith("SD printing byte")]
        if status == ["SD printing byte %d/%d" % (size, size)]:
            break
    p.send("M400")
    position = [l for l in p.send("M114") if l.startswith("X:")]
    assert position[0].startswith("X:20.00 Y:10.00")
    assert p.send("M30 job.gcode") == ["File deleted:job.gcode", "ok"]
    assert not (files / "job.gcode").exists()
    assert p.send("M23 job.gcode")[0] == "Error:open failed, File: job.gcode."
    steps = p.finish()["steps"]
    assert (steps["x"], steps["y"], steps["e0"], steps["e1"]) == (1600, 800, 830, 415)


@pytest.mark.slow
def test_a_real_slicer_file_prints_from_flash_with_pause_and_resume(tmp_path, board):
    files = tmp_path / "flash"
    files.mkdir()
    gcode = paths.ROOT / "testdata" / "part_3tool_prusaslicer_rel.gcode"
    (files / "part.gcode").write_bytes(gcode.read_bytes())
    p = SimPrinter(files_dir=files)
    p.send("M23 part.gcode")
    p.send("M24")
    p.send("M25")
    paused_at = p.send("M27")[0]
    assert paused_at.startswith("SD printing byte")
    before = p.send("M114")
    p.send("M400")
    assert p.send("M27")[0] == paused_at  # paused: no more of the file is read
    assert p.send("M114") == before  # and the position is kept
    p.send("M24")
    while True:
        replies = p.send("M27")
        if any("Done printing file" in r for r in replies) or replies[0] == "Not SD printing":
            break
        assert not [r for r in replies if r.startswith("Error")], replies
    p.send("M400")
    steps = p.finish()["steps"]
    assert steps == expected_steps(gcode, board["SETTINGS"]["steps_per_mm"])


def test_bad_file_commands_get_errors(tmp_path):
    files = tmp_path / "flash"
    files.mkdir()
    p = SimPrinter(files_dir=files)
    assert p.send("M24")[0] == "Error:no file selected (M23 <name>)"
    assert p.send("M23 ../etc/passwd")[0].startswith("Error:bad file name")
    assert p.send("M29")[0].startswith("Error:not writing a file")
    assert p.send("M30 nothing.gcode")[0] == "Error:Deletion failed, File: nothing.gcode."
    p.finish()


def test_long_lines_from_flash_keep_their_words_or_are_refused(tmp_path):
    """Lines are read through a buffer of line_buffer_bytes (96, as Marlin's
    MAX_CMD_SIZE): a longer line whose part past it is comment prints, one whose words
    run past it is refused with an error naming the file and line, which pauses the
    print; M24 resumes after it. M26 rewinds exactly, and the byte count stays exact."""
    files = tmp_path / "flash"
    files.mkdir()
    lines = ["G28", "; " + "x" * 200, "G1 X10 F3000 ; " + "y" * 150,
             "M117 " + "z" * 120, "G1 X20", "G1 Y5"]
    data = ("\n".join(lines) + "\n").encode()
    (files / "long.gcode").write_bytes(data)
    p = SimPrinter(files_dir=files)
    p.send("M23 long.gcode")
    replies = p.send("M24")
    while not any(r.startswith("Error:") for r in replies):
        replies = p.send("M27")
    assert [r for r in replies if r.startswith("Error:")] == [
        "Error:line longer than 96 bytes (file long.gcode, line 4)"]
    p.send("M400")
    assert p.send("M114")[0].startswith("X:10.00 Y:0.00")
    done = len(data) - len(lines[4]) - len(lines[5]) - 2
    assert p.send("M27")[0] == "SD printing byte %d/%d" % (done, len(data))
    p.send("M24")
    while p.send("M27")[0] != "SD printing byte %d/%d" % (len(data), len(data)):
        pass
    p.send("M400")
    assert p.send("M114")[0].startswith("X:20.00 Y:5.00")
    # Rewound to the start of "G1 X20" (M26 S<byte>) and printed again from there.
    send_all(p, ["G1 X0 Y0", "M400", "M26 S%d" % done, "M24"])
    while p.send("M27")[0] != "SD printing byte %d/%d" % (len(data), len(data)):
        pass
    p.send("M400")
    assert p.send("M114")[0].startswith("X:20.00 Y:5.00")
    p.finish()
