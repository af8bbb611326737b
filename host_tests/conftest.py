"""Shared fixtures. Firmware behaviour is tested on the real MicroPython unix port.

The MicroPython code the tests run lives in host_tests/upy/, a script per purpose named
after the test module that runs it (upy/planner_plans.py for test_planner.py), and the
modules those scripts share; `mp.script(name, *args)` runs one. Snippets of a line or
two are passed inline to `mp.run`."""
import json
import os
import subprocess
import textwrap
from pathlib import Path

import pytest

from mixstep import paths
from mixstep.simprinter import SimPrinter

UPY = Path(__file__).resolve().parent / "upy"


class MicroPython:
    """Runs code on the unix port with the firmware and the simulated board on its path,
    and host_tests/upy/ after them (its modules for the inline snippets; a script's own
    folder comes first on its path anyway). binary: another build than
    paths.micropython(), e.g. the 32-bit one."""

    def __init__(self, binary=None):
        self.binary = binary

    def using(self, binary):
        """The same runner on another MicroPython build."""
        return MicroPython(binary)

    def run(self, code, stdin=b"", heap="8M", env=None):
        """Run code (dedented) with -c; return its output. env: in place of the
        simulated board's (paths.micropython_env)."""
        return self._run(["-c", textwrap.dedent(code)], stdin, heap, env)

    def script(self, name, *args, stdin=b"", heap="8M", env=None):
        """Run host_tests/upy/<name>.py with args (as text in sys.argv[1:]); return its
        output."""
        path = UPY / (name + ".py")
        if not path.is_file():
            raise FileNotFoundError(path)
        return self._run([str(path)] + [str(a) for a in args], stdin, heap, env)

    def json(self, code, **kw):
        """Run code whose last output line is JSON; return it decoded."""
        return _last_json(self.run(code, **kw))

    def script_json(self, name, *args, **kw):
        """Run a script whose last output line is JSON; return it decoded."""
        return _last_json(self.script(name, *args, **kw))

    def _run(self, argv, stdin, heap, env):
        if env is None:
            env = paths.micropython_env("sim")
        env = dict(env, MICROPYPATH=os.pathsep.join([env["MICROPYPATH"], str(UPY)]))
        proc = subprocess.run(
            [self.binary or paths.micropython(), "-X", "heapsize=" + heap] + argv,
            input=stdin, capture_output=True, env=env, timeout=600)
        if proc.returncode != 0:
            raise AssertionError("micropython failed (status %d):\n%s%s" % (
                proc.returncode, proc.stdout.decode(), proc.stderr.decode()))
        return proc.stdout.decode()


def _last_json(out):
    return json.loads(out.strip().splitlines()[-1])


@pytest.fixture(scope="session")
def mp():
    return MicroPython()


@pytest.fixture(scope="session")
def board():
    return paths.load_board("sim")


@pytest.fixture
def sim_printer():
    """Start simulated printers: sim_printer(cold_extrusion=False, **options) is a
    SimPrinter (mixstep/simprinter.py: board, config_path, edges_path, settings, ...);
    cold_extrusion=True sends M302 P1 first, for tests about motion and mixing rather
    than heating. Each is stopped after the test unless the test finished it."""
    started = []

    def start(cold_extrusion=False, **options):
        p = SimPrinter(**options)
        started.append(p)
        if cold_extrusion:
            assert p.send("M302 P1") == ["ok"]
        return p

    yield start
    for p in started:
        if p.proc.poll() is None:
            p.proc.kill()
            p.proc.wait()


@pytest.fixture
def printer(sim_printer):
    """A simulated printer on the simulated board, cold extrusion allowed (M302 P1)."""
    return sim_printer(cold_extrusion=True)
