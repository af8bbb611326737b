"""The web page's server (webserver.py) on the firmware running on the unix port under
`mixstep serve --http`: its password, its JSON API over the printer the consoles
see, uploads streamed to the simulated flash, and the limits that keep it from
holding up the printer. The page itself, in a browser: test_web_page.py."""
import http.client
import json
import re
import socket
import time

import pytest

from mixstep import paths, serve
from net import free_port, traced_drive_steps

PASSWORD = "mixing-is-fun"
# Real slicer output with progress (M73) in it.
PRINT = paths.ROOT / "testdata" / "tc_top_bambustudio_arcs.gcode"
# Real slicer output that heats up first (G28, M190, M109).
HEATED = paths.ROOT / "testdata" / "short_3tool_m117_prusaslicer.gcode"


class Page:
    """A browser's requests: one connection each, the session cookie kept."""

    def __init__(self, port):
        self.port = port
        self.cookie = None

    def call(self, method, path, body=None, headers=None):
        c = http.client.HTTPConnection("127.0.0.1", self.port, timeout=30)
        h = dict(headers or {})
        if self.cookie:
            h["Cookie"] = self.cookie
        c.request(method, path, body=body, headers=h)
        r = c.getresponse()
        data = r.read()
        cookie = r.getheader("Set-Cookie")
        if cookie:
            self.cookie = cookie.split(";")[0]
        c.close()
        kind = r.getheader("Content-Type") or ""
        return r.status, (json.loads(data) if kind == "application/json" else data), r

    def ok(self, method, path, body=None):
        status, got, _ = self.call(method, path, body)
        assert status in (200, 201), (status, got)
        return got

    def log_in(self):
        assert self.call("POST", "/api/login", PASSWORD)[:2] == (200, {"ok": True})

    def gcode(self, *lines, want=None):
        """Run lines on the page's channel; the printer's lines until `want` lines
        beginning with "ok" have come."""
        self.ok("POST", "/api/gcode", "\n".join(lines))
        want = len(lines) if want is None else want
        got = []
        deadline = time.time() + 60
        while sum(1 for g in got if g.startswith("ok")) < want:
            assert time.time() < deadline, got
            got += self.ok("GET", "/api/console")["lines"]
            time.sleep(0.05)
        return got


def start(tmp_path, settings=None, tcp=False, realtime=0):
    port = free_port()
    tcp_port = free_port() if tcp else None
    (tmp_path / "files").mkdir(exist_ok=True)
    proc = serve.serve_tcp("127.0.0.1:%d" % tcp_port if tcp else None, realtime=realtime,
                           announce=lambda s: None, http="127.0.0.1:%d" % port,
                           settings=dict({"net_password": PASSWORD}, **(settings or {})),
                           config=tmp_path / "printer.cfg", files=tmp_path / "files")
    deadline = time.time() + 20
    while True:
        try:
            socket.create_connection(("127.0.0.1", port), timeout=1).close()
            break
        except OSError:
            assert time.time() < deadline
            time.sleep(0.05)
    return proc, port, tcp_port


@pytest.fixture
def printer(tmp_path):
    proc, port, _ = start(tmp_path)
    yield port
    serve.stop(proc)


def test_nothing_but_the_page_and_the_session_before_the_password(printer):
    page = Page(printer)
    assert page.call("GET", "/api/session")[:2] == (
        200, {"login_needed": True, "logged_in": False})
    for method, path, body in (("GET", "/api/status", None), ("POST", "/api/gcode", "M104 S250"),
                               ("GET", "/api/files", None), ("PUT", "/api/files/x.gcode", "G1"),
                               ("DELETE", "/api/files/x.gcode", None)):
        assert page.call(method, path, body)[:2] == (401, {"error": "log in first"}), path
    assert page.call("POST", "/api/login", "wrong-password")[:2] == (
        403, {"error": "wrong password"})
    assert page.call("POST", "/api/login", PASSWORD)[:2] == (
        429, {"error": "too many wrong passwords: try again in 1 s"})
    time.sleep(1.1)
    page.log_in()
    assert page.ok("GET", "/api/session") == {"login_needed": True, "logged_in": True}
    status = page.ok("GET", "/api/status")
    assert status["heaters"][0]["target_c"] == 0  # the M104 before the login never ran
    assert status["position_mm"] == {"x": 0, "y": 0, "z": 0, "e": 0}
    # The page's files, gzipped as they lie on the flash.
    status, body, r = page.call("GET", "/")
    assert status == 200 and r.getheader("Content-Encoding") == "gzip"
    assert body[:2] == b"\x1f\x8b"
    assert page.call("GET", "/../printer.cfg")[0] == 404


def test_the_page_and_a_console_see_one_printer(tmp_path):
    proc, port, tcp_port = start(tmp_path, tcp=True)
    try:
        page = Page(port)
        page.log_in()
        host = socket.create_connection(("127.0.0.1", tcp_port), timeout=30)
        f = host.makefile("rb")
        assert f.readline() == b"password:\n"
        host.sendall(PASSWORD.encode() + b"\nM104 S205\nM117 from the console\n")
        assert [f.readline() for _ in range(3)] == [b"start\n", b"ok\n", b"ok\n"]
        status = page.ok("GET", "/api/status")
        assert status["heaters"][0]["target_c"] == 205
        assert status["message"] == "from the console"
        assert page.gcode("M140 S55", "T2") == ["start", "ok", "ok"]
        host.sendall(b"M105\n")
        assert re.match(rb"ok T:[\d.]+ /205.0 B:[\d.]+ /55.0 ", f.readline())
        assert page.ok("GET", "/api/status")["tool"] == 2
    finally:
        serve.stop(proc)


def test_a_mix_edited_on_the_page_is_the_next_extrusion_s(tmp_path, monkeypatch):
    """The mix the page saves (M567, M500) is what the next extrusion feeds: the step
    capture pulled from the board (`mixstep trace pull`, over the TCP console with
    its password) counts each drive's steps, and trace check holds them to the lines
    the page sent."""
    proc, port, tcp_port = start(tmp_path, {"trace_records": 60000}, tcp=True)
    try:
        page = Page(port)
        page.log_in()
        status = page.ok("GET", "/api/status")
        assert status["tools"][0] == {"mix": [1, 0, 0, 0, 0, 0], "rgb": status["drive_rgb"][0]}
        page.gcode("M926 Idrive_colour_rgb_0 V16711680", "M926 Idrive_colour_rgb_1 V255",
                   "M930")
        page.gcode("M302 P1", "M7300 S1")  # cold extrusion allowed; the capture on
        lines = ["M567 P0 E1:3:0:0:0:0", "M500", "T0", "G92 E0", "M167 R", "G1 E40 F600",
                 "M400", "M167"]
        got = page.gcode(*lines)
        status = page.ok("GET", "/api/status")
        # A quarter red, three quarters blue, each channel rounded.
        assert status["tools"][0] == {"mix": [1, 3, 0, 0, 0, 0], "rgb": "#4000bf"}
        fed = [float(v) for v in re.findall(r"e\d:(\S+)", got[-2])]
        assert fed[:2] == pytest.approx([10.0, 30.0], abs=0.01) and sum(fed[2:]) == 0, got
        spm = 415  # the simulated board's filament steps per mm
        assert traced_drive_steps(tmp_path, "127.0.0.1:%d" % tcp_port, lines, PASSWORD,
                                  monkeypatch) == (10 * spm, 30 * spm)
    finally:
        serve.stop(proc)


def test_an_upload_streams_to_flash_and_prints(tmp_path, printer):
    page = Page(printer)
    page.log_in()
    data = PRINT.read_bytes()
    assert page.call("PUT", "/api/files/part.gcode", data)[:2] == (
        201, {"name": "part.gcode", "bytes": len(data)})
    assert (tmp_path / "files" / "part.gcode").read_bytes() == data
    listing = page.ok("GET", "/api/files")
    assert listing["files"] == [{"name": "part.gcode", "bytes": len(data)}]
    # One upload at a time: a second, begun while the first's body comes, waits.
    slow = socket.create_connection(("127.0.0.1", printer), timeout=30)
    slow.sendall(b"PUT /api/files/a.gcode HTTP/1.1\r\nCookie: %s\r\n"
                 b"Content-Length: 100\r\n\r\nG1 X1\n" % page.cookie.encode())
    time.sleep(0.3)
    assert page.call("PUT", "/api/files/b.gcode", b"G1 X2\n")[:2] == (
        409, {"error": "a.gcode is being uploaded; try again after it"})
    slow.close()
    time.sleep(0.3)  # the cut upload dropped: the next one is taken
    assert page.call("PUT", "/api/files/b.gcode", b"G1 X2\n")[0] == 201
    assert "a.gcode" not in [f["name"] for f in page.ok("GET", "/api/files")["files"]]
    page.gcode("M23 part.gcode", "M24")
    deadline = time.time() + 120
    seen = set()
    while True:
        status = page.ok("GET", "/api/status")
        seen.add(status["job"]["state"])
        if status["progress_pct"]:
            break
        assert time.time() < deadline
        time.sleep(0.2)
    assert status["job"]["file"] == "part.gcode" and "printing" in seen
    # While it prints, no upload: a flash write would stop the steppers.
    got = page.call("PUT", "/api/files/other.gcode", b"G1 X1\n")
    assert got[:2] == (409, {"error": "cannot write other.gcode while part.gcode prints: "
                                      "pause it (M25) first"})
    assert page.gcode("M524")[-1] == "ok"
    assert page.ok("GET", "/api/status")["job"]["state"] == "idle"


def test_cancel_ends_the_print_during_its_heat_up(tmp_path):
    """M524 acts as its line arrives, as Marlin's emergency parser has it: a print
    waiting for its hot end (M109) stops at once, not once it is hot."""
    proc, port, _ = start(tmp_path, realtime=1)
    try:
        page = Page(port)
        page.log_in()
        page.ok("PUT", "/api/files/part.gcode", HEATED.read_bytes())
        page.gcode("M23 part.gcode", "M24")
        deadline = time.time() + 30
        while page.ok("GET", "/api/status")["heaters"][0]["target_c"] < 200:
            assert time.time() < deadline
            time.sleep(0.1)
        t0 = time.time()
        page.gcode("M524")
        status = page.ok("GET", "/api/status")
        assert status["job"]["state"] == "idle" and time.time() - t0 < 3
        assert status["heaters"][0]["c"] < 150  # far from hot: the wait had ended
    finally:
        serve.stop(proc)


def test_a_full_flash_is_an_error_and_the_old_file_survives(tmp_path, printer):
    page = Page(printer)
    page.log_in()
    old = b"G1 X1\n" * 100
    page.ok("PUT", "/api/files/part.gcode", old)
    page.gcode("M7103 C5000")  # the simulated flash takes 5 kB more
    data = PRINT.read_bytes()
    status, got, _ = page.call("PUT", "/api/files/part.gcode", data)
    assert (status, got) == (507, {"error": "could not write part.gcode: the flash is full"})
    assert sorted(p.name for p in (tmp_path / "files").iterdir()) == ["part.gcode"]
    assert (tmp_path / "files" / "part.gcode").read_bytes() == old


def test_limits_oversize_slow_and_too_many(printer):
    page = Page(printer)
    page.log_in()
    assert page.call("POST", "/api/gcode", "G1 X1\n" * 100)[:2] == (
        413, {"error": "request body over 512 bytes"})
    status, got, _ = page.call("GET", "/api/status", headers={"X-Big": "x" * 2000})
    assert (status, got) == (431, {"error": "request head over 1024 bytes"})
    # Four connections that never finish their request: a fifth is turned away, and
    # after 10 s they are answered and closed.
    t0 = time.time()
    slow = [socket.create_connection(("127.0.0.1", printer), timeout=30) for _ in range(4)]
    for s in slow:
        s.sendall(b"GET /api/status HTTP/1.1\r\nHost: x\r\n")
    time.sleep(0.5)
    assert page.call("GET", "/api/session")[0] == 503
    for s in slow:
        assert s.recv(200).startswith(b"HTTP/1.1 400 Bad Request")
    assert 9.5 < time.time() - t0 < 15
    assert page.ok("GET", "/api/session")["logged_in"]
