"""Any byte a host sends is answered, and the console log keeps it as it came: the
served printer runs on for every host."""
import socket
from pathlib import Path

from mixstep import serve
from net import free_port, wait_for_port


def _ask(console, data):
    console.write(data + b"\n")
    console.flush()
    replies = []
    while True:
        line = console.readline()
        assert line, "the printer closed the connection"
        text = line.decode("latin-1").rstrip("\r\n")
        replies.append(text)
        if text.startswith("ok"):
            return replies


def test_bytes_that_are_not_utf8_get_an_answer_and_the_log_keeps_them(tmp_path):
    address = "127.0.0.1:%d" % free_port()
    log = tmp_path / "console.log"
    proc = serve.serve_tcp(address, realtime=0, announce=lambda s: None, console_log=log,
                           config=tmp_path / "mixstep.cfg", files=tmp_path / "files")
    try:
        wait_for_port(address)
        host, port = address.rsplit(":", 1)
        with socket.create_connection((host, int(port)), timeout=60) as c, \
                c.makefile("rwb") as console:
            for data in (b"\xff", b"M117 caf\xe9", b"M118 E1 \xc2\xb0C"):
                _ask(console, data)
            assert _ask(console, b"M115")[-1] == "ok"  # still serving
        assert proc.poll() is None
    finally:
        serve.stop(proc)
    logged = log.read_bytes()
    for data in (b"< \xff\n", b"< M117 caf\xe9\n", b"< M118 E1 \xc2\xb0C\n"):
        assert data in logged


def test_m997_ends_serve_with_a_line_for_its_user(tmp_path):
    """M997 ends the served firmware (a board restarts into its REPL): the terminal of
    `mixstep serve` gets one line saying so, not the simulation's report."""
    import subprocess
    import sys
    address = "127.0.0.1:%d" % free_port()
    proc = subprocess.Popen([sys.executable, "-m", "mixstep.cli", "serve", "--tcp", address,
                             "--config", str(tmp_path / "mixstep.cfg"),
                             "--files", str(tmp_path / "files")],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        wait_for_port(address)
        host, port = address.rsplit(":", 1)
        with socket.create_connection((host, int(port)), timeout=60) as c:
            c.sendall(b"M997\n")
            out, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert "//sim" not in out and "Traceback" not in err
    assert "the firmware stopped on M997" in out.splitlines()[-1]


def test_utf8_text_is_shown_and_a_long_message_is_cut_not_refused():
    """Slicers write UTF-8 messages (object names, M117 Druck läuft): they are text;
    a message longer than the line buffer is cut at a whole character, as Marlin cuts
    it. Bytes above 127 in words, or text that is not UTF-8, get one clear error."""
    from mixstep.simprinter import SimPrinter
    p = SimPrinter()
    try:
        assert p.send("M117 Druck läuft") == ["ok"]
        assert p.send("M118 E1 Düse 215 °C ✓") == ["echo:Düse 215 °C ✓", "ok"]
        # 5 bytes of "M118 " and 2 of each "ä": 45 fit in 96 bytes, the 46th would not.
        assert p.send("M118 " + "ä" * 60) == ["ä" * 45, "ok"]
        assert p.send("M117 " + "x" * 200) == ["ok"]
        # A numbered line is never cut: its checksum would no longer hold.
        assert p.send("N1 M118 " + "ä" * 60)[0] == "Error:line longer than 96 bytes"
        assert p.send(b"M118 caf\xe9") == ["Error:text is not UTF-8", "ok"]
        assert p.send("G1 X1 ä") == ["Error:unexpected byte 0xc3", "ok"]
        assert p.send(b"M118 ok\x07") == ["Error:byte 0x07 is a control character", "ok"]
        assert p.send("M118 still here") == ["still here", "ok"]
    finally:
        p.finish()


def test_sim_reads_a_file_as_its_bytes(tmp_path):
    """mixstep sim sends a file's bytes as a host would: UTF-8 text prints, a Latin-1
    message is an error in the report, named by its line."""
    from mixstep import sim
    source = (Path(__file__).parent.parent / "testdata" / "part_3tool_prusaslicer_rel.gcode")
    head = source.read_bytes().splitlines(keepends=True)[:40]
    gcode = tmp_path / "messages.gcode"
    gcode.write_bytes(b"".join(head) + "M117 Druck läuft\n".encode() + b"M117 caf\xe9\n")
    report = sim.run(gcode, report_path=tmp_path / "report.json")
    assert report["errors"] == ["line %d: Error:text is not UTF-8" % (len(head) + 2)]
