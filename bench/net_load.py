"""A print streamed over the firmware's network console while others misbehave on the
network, and while the web page is open: the time the print takes in the simulation,
and on this machine's clock, against the same print with the network quiet. The
misbehaving: connections opened and dropped as fast as this machine can (a flood),
wrong passwords, and a logged-in sender of a byte a second. The page: a browser's
polls, the status every second and the console every half second.

    python bench/net_load.py [FILE] [--realtime FACTOR]

The firmware runs on the unix port under `mixstep serve --tcp` (the simulated
printer), paced at FACTOR times real time, and a host streams the file as printcore
does, a line after each `ok`. The print's time is read from the console log's
simulated time stamps, from the first line sent to the last `ok`. Prints JSON. The
emulated Pico has no network (the rp2040js emulator models no Wi-Fi chip), so these
figures come from the simulation alone."""
import argparse
import http.client
import json
import re
import socket
import sys
import tempfile
import threading
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "host_tests"))
from chip_print import host_lines  # noqa: E402
from mixstep import paths, serve  # noqa: E402
from net import free_port  # noqa: E402

PASSWORD = "bench-password"
FILE = paths.ROOT / "testdata" / "short_3tool_m117_prusaslicer.gcode"


def _connect(port):
    deadline = time.time() + 20
    while True:
        try:
            return socket.create_connection(("127.0.0.1", port), timeout=60)
        except OSError:
            if time.time() > deadline:
                raise
            time.sleep(0.05)


def _log_in(port):
    s = _connect(port)
    f = s.makefile("rb")
    assert f.readline() == b"password:\n"
    s.sendall(PASSWORD.encode() + b"\n")
    assert f.readline() == b"start\n"
    return s, f


def _misbehave(port, stop, counts):
    def flood():
        while not stop.is_set():
            try:
                s = socket.create_connection(("127.0.0.1", port), timeout=5)
                s.recv(100)
                if counts["floods"] % 7 == 0:
                    s.sendall(b"guess-%d\n" % counts["floods"])
                    s.recv(100)
                s.close()
                counts["floods"] += 1
            except OSError:
                pass

    # Logged in before the flood's guesses make every login wait.
    slow_sock, _f = _log_in(port)

    def slow():
        try:
            while not stop.is_set():
                slow_sock.sendall(b"M")
                counts["slow_bytes"] += 1
                time.sleep(1)
        except OSError:
            pass  # closed by the printer: no whole line for net_idle_timeout_s

    threads = [threading.Thread(target=flood) for _ in range(3)] + [
        threading.Thread(target=slow)]
    for t in threads:
        t.start()
    return threads


def _poll_page(port, stop, counts):
    def get(path, cookie=None, body=None):
        c = http.client.HTTPConnection("127.0.0.1", port, timeout=30)
        c.request("POST" if body else "GET", path, body=body,
                  headers={"Cookie": cookie} if cookie else {})
        r = c.getresponse()
        r.read()
        c.close()
        return r

    cookie = get("/api/login", body=PASSWORD).getheader("Set-Cookie").split(";")[0]

    def poll():
        k = 0
        while not stop.is_set():
            get("/api/console", cookie)
            if k % 2 == 0:
                get("/api/status", cookie)
            counts["polls"] += 1
            k += 1
            time.sleep(0.5)

    t = threading.Thread(target=poll)
    t.start()
    return [t]


def print_once(path, realtime, load):
    port = free_port()
    http_port = free_port()
    with tempfile.TemporaryDirectory() as tmp:
        log = Path(tmp) / "console.log"
        proc = serve.serve_tcp("127.0.0.1:%d" % port, realtime=realtime,
                               announce=lambda s: None, console_log=log,
                               config=Path(tmp) / "c.cfg", files=Path(tmp),
                               http="127.0.0.1:%d" % http_port,
                               settings={"net_password": PASSWORD,
                                         "net_idle_timeout_s": 600})
        stop = threading.Event()
        counts = {"floods": 0, "slow_bytes": 0, "polls": 0}
        threads = []
        try:
            s, f = _log_in(port)
            if load == "flood":
                threads = _misbehave(port, stop, counts)
            elif load == "page":
                threads = _poll_page(http_port, stop, counts)
            t0 = time.time()
            lines = host_lines(path) + ["M400"]
            for line in lines:
                s.sendall(line.encode("latin-1") + b"\n")
                while True:
                    reply = f.readline()
                    assert reply, "the printer closed the connection"
                    if reply.startswith(b"ok"):
                        break
            wall_s = time.time() - t0
        finally:
            stop.set()
            for t in threads:
                t.join()
            serve.stop(proc)
        stamps = [int(m.group(1)) for m in re.finditer(r"^(\d+) ", log.read_text(), re.M)]
    # The first line sent (M110) to the last ok (M400's), in simulated us.
    return {"print_s": (stamps[-1] - stamps[0]) / 1e6, "wall_s": wall_s,
            "lines": len(lines), **counts}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("file", nargs="?", default=str(FILE))
    ap.add_argument("--realtime", type=float, default=4.0)
    args = ap.parse_args(argv)
    runs = {load: print_once(Path(args.file), args.realtime, load)
            for load in ("quiet", "flood", "page")}
    for load in ("flood", "page"):
        runs[load]["print_time_ratio"] = runs[load]["print_s"] / runs["quiet"]["print_s"]
        runs[load]["wall_time_ratio"] = runs[load]["wall_s"] / runs["quiet"]["wall_s"]
    print(json.dumps({"file": Path(args.file).name, "realtime": args.realtime, **runs},
                     indent=1))


if __name__ == "__main__":
    main()
