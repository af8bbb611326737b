"""The network console's safety, on the firmware's own TCP console (netconsole.py)
running on the unix port under `mixstep serve --tcp`: nothing runs before the
password, a wrong one closes the connection and slows the next try, and floods,
slow senders, oversize lines, half-open connections and too many clients are turned
away while a logged-in host goes on printing."""
import socket
import subprocess
import sys
import threading
import time

import pytest

from mixstep import paths, serve
from net import free_port

PASSWORD = "mixing-is-fun"


class Client:
    def __init__(self, port, password=PASSWORD, timeout_s=20):
        self.sock = socket.create_connection(("127.0.0.1", port), timeout=timeout_s)
        self.f = self.sock.makefile("rb")
        if password is not None:
            assert self.readline() == "password:"
            self.send(password)
            assert self.readline() == "start"

    def send(self, line):
        self.sock.sendall(line.encode() + b"\n")

    def readline(self):
        """A line, or None once the printer has closed the connection."""
        raw = self.f.readline()
        return raw.decode("ascii", "replace").rstrip("\r\n") if raw else None

    def rest(self):
        """Every line until the printer closes the connection."""
        lines = []
        while True:
            line = self.readline()
            if line is None:
                return lines
            lines.append(line)

    def ask(self, line):
        self.send(line)
        got = []
        while not got or not got[-1].startswith("ok"):
            got.append(self.readline())
            assert got[-1] is not None, got
        return got

    def close(self):
        self.sock.close()


def start(settings, address=None):
    port = free_port()
    proc = serve.serve_tcp(address or "127.0.0.1:%d" % port, realtime=0,
                           announce=lambda s: None, settings=settings)
    deadline = time.time() + 20
    while True:  # connected and let go at once: no login tried, none counted
        try:
            socket.create_connection(("127.0.0.1", port), timeout=1).close()
            return proc, port
        except OSError:
            assert time.time() < deadline
            time.sleep(0.05)


@pytest.fixture
def printer():
    proc, port = start({"net_password": PASSWORD, "net_idle_timeout_s": 3,
                        "tcp_max_clients": 2})
    yield port
    serve.stop(proc)


def test_an_address_beyond_this_machine_needs_a_password(tmp_path):
    port = free_port()
    cmd = [sys.executable, "-m", "mixstep.cli", "serve", "--tcp", "0.0.0.0:%d" % port,
           "--config", str(tmp_path / "c.cfg"), "--files", str(tmp_path), "--realtime", "0"]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=60, cwd=paths.ROOT)
    assert proc.returncode != 0
    assert ("mixstep: the network console on 0.0.0.0 needs a password first: set "
            "net_password (M926 Inet_password V<8 to 64 characters>, then M500)") \
        in proc.stdout + proc.stderr


def test_loopback_without_a_password_is_open():
    proc, port = start({})
    try:
        c = Client(port, password=None)
        assert c.readline() == "start"
        assert c.ask("M105")[-1].startswith("ok T:")
    finally:
        serve.stop(proc)


def test_g_code_before_the_password_runs_nothing(printer):
    c = Client(printer, password=None)
    assert c.readline() == "password:"
    c.send("M104 S250")
    c.send("G28")
    assert c.rest() == ["Error:wrong password"]
    time.sleep(1.1)  # the wait after a wrong password
    ok = Client(printer)
    assert ok.ask("M105")[-1].startswith("ok T:22.0 /0.0 ")  # no target set
    assert ok.ask("M114")[0].startswith("X:0.00 Y:0.00 Z:0.00")


def _try(port, password):
    """What the printer answers a connection that sends this password, then closes."""
    c = Client(port, password=None)
    c.readline()
    c.send(password)
    return c.rest()


def test_a_wrong_password_closes_and_the_next_try_waits(printer):
    assert _try(printer, PASSWORD[:-1] + "X") == ["Error:wrong password"]
    # Right away, even the right password is not looked at: a guesser gains nothing
    # from a new connection per guess.
    assert _try(printer, PASSWORD) == ["Error:too many wrong passwords: try again in 1 s"]
    time.sleep(1.1)
    assert _try(printer, "wrong-again") == ["Error:wrong password"]
    assert _try(printer, PASSWORD) == ["Error:too many wrong passwords: try again in 2 s"]
    time.sleep(2.1)
    Client(printer).close()  # and right, once the wait is over


def test_the_password_is_never_shown(printer):
    c = Client(printer)
    shown = c.ask("M503") + c.ask("M925 Inet_password") + c.ask("M122")
    assert not [line for line in shown if PASSWORD in line]
    assert "echo:; M926 Inet_password V... ; " in "\n".join(shown)
    assert [line for line in shown if line.startswith("echo:; M926 Inet_password")
            and line.endswith("(set, not shown)")]


def test_an_oversize_password_line_and_a_silent_login_are_turned_away(printer):
    c = Client(printer, password=None)
    c.readline()
    c.sock.sendall(b"x" * 200)
    assert c.rest() == ["Error:password line too long"]
    t0 = time.time()
    c = Client(printer, password=None)
    c.readline()
    c.sock.sendall(b"mix")  # and never more: a half-open login
    assert c.rest() == ["Error:no password within 10 s"]
    assert 9.5 < time.time() - t0 < 15


def test_a_slow_sender_and_a_silent_host_are_closed_and_free_their_place(printer):
    slow = Client(printer)
    quiet = Client(printer)
    assert Client(printer, password=None).rest() == [
        "Error:too many connections (tcp_max_clients)"]
    t0 = time.time()
    for ch in "G1 X10":  # a byte a second, never a whole line
        slow.sock.sendall(ch.encode())
        time.sleep(0.6)
    assert slow.rest() == ["Error:closed: no whole line for 3 s (net_idle_timeout_s)"]
    assert quiet.rest() == ["Error:closed: no whole line for 3 s (net_idle_timeout_s)"]
    assert time.time() - t0 < 8
    # Their places are free again, and the half line ran nothing.
    c = Client(printer)
    assert c.ask("M114")[0].startswith("X:0.00 ")


def test_an_oversize_g_code_line_is_refused_and_the_connection_goes_on(printer):
    c = Client(printer)
    c.sock.sendall(b"M117 " + b"x" * 5000 + b"\nG1 X" + b"1" * 5000 + b"\n")
    got = [c.readline(), c.readline(), c.readline()]
    assert got[-1] == "ok" and got[1] == "Error:line longer than 96 bytes", got
    assert c.ask("M105")[-1].startswith("ok T:")


def test_a_connection_flood_leaves_a_logged_in_host_printing(printer):
    c = Client(printer)
    c.ask("G28")
    c.ask("G91")
    stop = threading.Event()
    turned = []

    def flood():
        while not stop.is_set():
            try:
                s = socket.create_connection(("127.0.0.1", printer), timeout=5)
                turned.append(s.recv(200))
                s.close()
            except OSError:
                pass

    floods = [threading.Thread(target=flood) for _ in range(4)]
    for t in floods:
        t.start()
    try:
        for _ in range(200):
            assert c.ask("G1 X0.5 F6000") == ["ok"]
        c.ask("M400")
        assert c.ask("M114")[0].startswith("X:100.00 ")
    finally:
        stop.set()
        for t in floods:
            t.join()
    reasons = {r.split(b"\n")[0] for r in turned}
    assert len(turned) > 20
    assert reasons <= {b"password:", b"Error:too many connections (tcp_max_clients)",
                       b"Error:too many connections logging in; try again", b""}, reasons


def test_the_password_set_over_an_open_loopback_is_kept_by_m500(tmp_path):
    cfg = tmp_path / "printer.cfg"
    port = free_port()
    proc = serve.serve_tcp("127.0.0.1:%d" % port, realtime=0, announce=lambda s: None,
                           config=cfg, files=tmp_path)
    try:
        c = _wait_for(lambda: Client(port, password=None))
        assert c.readline() == "start"
        assert c.ask("M926 Inet_password Vshort")[0] == (
            "Error:net_password: must be empty or 8 to 64 characters without spaces")
        assert c.ask("M926 Inet_password V" + PASSWORD) == ["ok"]
        assert c.ask("M500") == ["ok"]
        assert PASSWORD in cfg.read_text()  # the flash keeps it; no console shows it
    finally:
        serve.stop(proc)
    proc = serve.serve_tcp("127.0.0.1:%d" % port, realtime=0, announce=lambda s: None,
                           config=cfg, files=tmp_path)
    try:
        c = _wait_for(lambda: Client(port, password=None))
        assert c.readline() == "password:"
        c.send(PASSWORD)
        assert c.readline() == "start"
    finally:
        serve.stop(proc)


def _wait_for(connect):
    deadline = time.time() + 20
    while True:
        try:
            return connect()
        except OSError:
            assert time.time() < deadline
            time.sleep(0.05)


def test_a_board_listens_once_on_wi_fi_with_a_password(mp):
    """webserver.board_listeners, as assemble calls it on a board whose `network`
    imports (a double of the chip's here): nothing off Wi-Fi, nothing and a warning
    without a password, then the console and the page sharing one wait after wrong
    passwords; a port of 0 turns its listener off."""
    got = mp.json("""
import json, sys
sys.path.append(%r)
import network
from mixfw.webserver import board_listeners
class Printer:
    settings = {"tcp_port": %d, "web_page_port": %d, "net_password": "",
                "tcp_max_clients": 4, "net_idle_timeout_s": 600}
def listeners():
    warnings = []
    made = board_listeners(Printer, "/web", warnings)
    names = [type(l).__name__ for l in made]
    shared = len(made) == 2 and made[0].gate is made[1].gate
    for l in made:
        l.sock.close()
    return [names, warnings, shared]
out = [listeners()]
network.CONNECTED[0] = True
out.append(listeners())
Printer.settings["net_password"] = %r
out.append(listeners())
Printer.settings["web_page_port"] = 0
out.append(listeners())
print(json.dumps(out))
""" % (str(paths.ROOT / "host_tests" / "upy" / "wifi"), free_port(), free_port(), PASSWORD))
    assert got == [
        [[], [], False],
        [[], ["//network console and web page off: no password set "
              "(M926 Inet_password V<8 to 64 characters>, M500, restart)"], False],
        [["TcpListener", "HttpListener"], [], True],
        [["TcpListener"], [], False]]
