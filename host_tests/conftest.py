"""Shared fixtures. Firmware behaviour is tested on the real MicroPython unix port."""
import json
import subprocess
import textwrap

import pytest

from mixstep import paths


class MicroPython:
    """Runs code on the unix port with the firmware and the simulated board on its path."""

    def run(self, code, stdin=b"", heap="8M"):
        proc = subprocess.run(
            [paths.micropython(), "-X", "heapsize=" + heap, "-c", textwrap.dedent(code)],
            input=stdin, capture_output=True, env=paths.micropython_env("sim"), timeout=600)
        if proc.returncode != 0:
            raise AssertionError("micropython failed (status %d):\n%s%s" % (
                proc.returncode, proc.stdout.decode(), proc.stderr.decode()))
        return proc.stdout.decode()

    def json(self, code, **kw):
        """Run code whose last output line is JSON; return it decoded."""
        out = self.run(code, **kw).strip().splitlines()
        return json.loads(out[-1])


@pytest.fixture(scope="session")
def mp():
    return MicroPython()


@pytest.fixture(scope="session")
def board():
    return paths.load_board("sim")
