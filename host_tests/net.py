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
