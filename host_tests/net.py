"""Loopback helpers the host tests share."""
import socket
import time


def free_port():
    """A TCP port on 127.0.0.1 that nothing listens on just now."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def wait_for_port(address, timeout_s=20):
    host, port = address.rsplit(":", 1)
    deadline = time.time() + timeout_s
    while True:
        try:
            socket.create_connection((host, int(port)), timeout=1).close()
            return
        except OSError:
            assert time.time() < deadline, "simulated printer did not listen on " + address
            time.sleep(0.1)


def traced_drive_steps(tmp_path, tcp, lines, password, monkeypatch):
    """The step capture pulled over the TCP console at tcp ("host:port", with the
    password), held by trace check to the G-code lines that made it: e0's and e1's
    steps, once every check passed."""
    from mixstep import tracecheck, tracepull
    monkeypatch.setenv("MIXSTEP_NET_PASSWORD", password)
    pulled = tmp_path / "pulled.vcd"
    assert tracepull.pull(pulled, tcp=tcp)["overrun"] == 0
    sent = tmp_path / "sent.gcode"
    sent.write_text("\n".join(lines) + "\n")
    checks = {c["name"]: c for c in tracecheck.check(pulled, sent)["checks"]}
    assert [c["name"] for c in checks.values() if c["ok"] is False] == []
    return checks["steps_e0"]["measured"], checks["steps_e1"]["measured"]
