"""Any byte a host sends is answered, and the console log keeps it as it came: the
served printer runs on for every host."""
import socket

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
