"""Printing from flash (M20-M32) and uploading (M28/M29), on the unix port."""

import pytest
from mixstep import paths
from gcode_model import expected_steps


def send_all(printer, lines):
    return [printer.send(l) for l in lines]


def test_upload_list_select_print_and_delete(sim_printer, tmp_path, board):
    files = tmp_path / "flash"
    files.mkdir()
    p = sim_printer(files_dir=files)
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
def test_a_real_slicer_file_prints_from_flash_with_pause_and_resume(sim_printer, tmp_path, board):
    files = tmp_path / "flash"
    files.mkdir()
    gcode = paths.ROOT / "testdata" / "part_3tool_prusaslicer_rel.gcode"
    (files / "part.gcode").write_bytes(gcode.read_bytes())
    p = sim_printer(files_dir=files)
    p.send("M23 part.gcode")
    p.send("M24")
    p.send("M25")
    paused_at = p.send("M27")[0]
    assert paused_at.startswith("SD printing byte")
    # The moves queued before the pause run out: M114's Count is the step loop's, and
    # M25 may arrive while one is under way (the host's timing, not the firmware's).
    p.send("M400")
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


def test_an_upload_whose_write_fails_runs_none_of_its_lines(sim_printer, tmp_path):
    """An upload is written a flash sector (4 KB) at a time: when a write fails, the
    host hears why at that line, the rest of the upload is still taken as text and
    never run, and M29 says the file was not saved."""
    files = tmp_path / "flash"
    files.mkdir()
    (files / "up.gcode.part").mkdir()  # where the upload is written: no file can be
    gcode = paths.ROOT / "testdata" / "part_3tool_prusaslicer_rel.gcode"
    lines = [c for c in (l.split(";")[0].strip() for l in open(gcode)) if c][:400]
    p = sim_printer(files_dir=files)
    assert p.send("M28 up.gcode") == ["Writing to file: up.gcode", "ok"]
    said = [p.send(line) for line in lines]
    failed = [reply for reply in said if reply != ["ok"]]
    assert len(failed) == 1 and failed[0][0].startswith(
        "Error:could not write up.gcode: [Errno 21] EISDIR; M29 ends the upload")
    assert p.send("M29") == ["Error:up.gcode not saved: [Errno 21] EISDIR", "ok"]
    assert not (files / "up.gcode").exists()
    assert p.send("M114")[0].startswith("X:0.00 Y:0.00 Z:0.00 E:0.00")  # nothing ran
    p.finish()


def test_bad_file_commands_get_errors(sim_printer, tmp_path):
    files = tmp_path / "flash"
    files.mkdir()
    p = sim_printer(files_dir=files)
    assert p.send("M24")[0] == "Error:no file selected (M23 <name>)"
    assert p.send("M23 ../etc/passwd")[0].startswith("Error:bad file name")
    assert p.send("M29")[0].startswith("Error:not writing a file")
    assert p.send("M30 nothing.gcode")[0] == "Error:Deletion failed, File: nothing.gcode."
    p.finish()


def test_a_file_without_a_last_newline_prints_whole_and_m26_prints_it_again(sim_printer, tmp_path):
    """The file is read in chunks through the console's intake: a last line with no
    newline still runs, a line whose words pass the line buffer is refused by name
    and pauses the print, and M26 S0 rewinds for a second print."""
    files = tmp_path / "flash"
    files.mkdir()
    long_words = "G1 X1 " + " ".join("Y%d" % i for i in range(40))
    (files / "job.gcode").write_text("M83\nG91\n; a comment " + "x" * 300 + "\n"
                                     + long_words + "\nG1 X10 F3000\nG1 X5")
    p = sim_printer(files_dir=files)

    def print_it():
        p.send("M24")
        while True:
            replies = p.send("M27")
            if any("Done printing file" in r for r in replies) or replies[0] == "Not SD printing":
                return
            if any(r.startswith("Error:") for r in replies):
                return replies

    p.send("M23 job.gcode")
    errors = print_it()
    assert errors and "line longer than" in " ".join(errors) and "line 4" in " ".join(errors)
    assert print_it() is None  # M24 resumes after the refused line, to the file's end
    p.send("M400")
    assert p.send("M114")[0].startswith("X:15.00")
    assert p.send("M26 S0") == ["ok"]
    print_it()
    print_it()
    p.send("M400")
    assert p.send("M114")[0].startswith("X:30.00")
    p.finish()


def test_a_hosts_line_waits_at_most_four_lines_of_a_file_print(mp, tmp_path):
    """While a file prints, the main loop reads the hosts every few of its lines
    (printer._FILE_LINES_PER_READ), not before each one: a host's line that is
    waiting as the print starts runs after the file's fourth line. Every line of both
    runs once, in order. The real Printer and Job, with handlers that only record."""
    gcode = paths.ROOT / "testdata" / "part_3tool_prusaslicer_rel.gcode"
    (tmp_path / "part.gcode").write_bytes(b"".join(gcode.read_bytes().splitlines(True)[:60]))
    commands = [l.split(";")[0].split() for l in gcode.read_text().splitlines()[:60]]
    commands = [w[0] for w in commands if w]
    names = sorted(set(c if c[0] != "T" else "T" for c in commands))
    got = mp.script_json("files_host_during_print", tmp_path / "part.gcode",
                         *names, "G92")
    assert ["host", 4] in got
    file_lines = [(c, n) for c, n in got if c != "host"]
    assert [c for c, _ in file_lines] == commands
    numbers = [n for _, n in file_lines]
    assert numbers == sorted(set(numbers))
