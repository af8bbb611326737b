"""The host tools as a newcomer meets them: an output never overwrites its input, a
file is written whole or not at all, and every mistake gets one line and exit status 2
(Ctrl-C and SIGTERM 130), never a traceback."""
import os
import shutil
import signal
import socket
import subprocess
import sys
import time

import pytest

from mixstep import cli, paths

SHORT = paths.ROOT / "testdata" / "short_3tool_m117_prusaslicer.gcode"
MATRIX = "1,0,0;0,1,0;0,0,1"


def run(capsys, *argv):
    """exit status, stderr of `mixstep argv` run in-process."""
    status = cli.main([str(a) for a in argv])
    return status, capsys.readouterr().err


def one_line(err):
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


@pytest.fixture
def part(tmp_path):
    copy = tmp_path / "part.gcode"
    shutil.copy(SHORT, copy)
    return copy


@pytest.mark.parametrize("tool", [["advance", "--purge-mm", "2.5"],
                                  ["detool", "--matrix", MATRIX],
                                  ["arcfit", "--tolerance-mm", "0.01"]])
def test_an_output_that_is_the_input_is_refused_and_the_input_kept(capsys, part, tool):
    before = part.read_bytes()
    # The same file, also by another spelling of its path.
    for out in (part, part.parent / ".." / part.parent.name / part.name):
        status, err = run(capsys, tool[0], part, "-o", out, *tool[1:])
        assert status == 2
        assert "is the input file" in one_line(err)
        assert part.read_bytes() == before


def test_a_failed_run_leaves_the_old_output_and_no_temporary_file(capsys, part, tmp_path):
    out = tmp_path / "out.gcode"
    out.write_text("kept\n")
    status, err = run(capsys, "advance", part, "-o", out, "--purge-mm", "-1")
    assert status == 2 and ">= 0" in one_line(err)
    assert out.read_text() == "kept\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.gcode", "part.gcode"]


@pytest.mark.parametrize("argv", [
    ["sim", "missing.gcode"],
    ["preview", "missing.gcode", "-o", "p.png"],
    ["advance", "missing.gcode", "-o", "a.gcode", "--purge-mm", "1"],
    ["detool", "missing.gcode", "-o", "d.gcode", "--matrix", MATRIX],
    ["arcfit", "missing.gcode", "-o", "f.gcode"],
    ["trace", "check", "missing.vcd", "--gcode", str(SHORT)],
])
def test_a_missing_input_is_one_line_and_status_2(capsys, tmp_path, monkeypatch, argv):
    monkeypatch.chdir(tmp_path)
    status, err = run(capsys, *argv)
    assert status == 2
    line = one_line(err)
    assert "missing" in line and ("No such file" in line or "not found" in line), line
    assert not (tmp_path / "p.png").exists()


@pytest.mark.parametrize("argv,words", [
    (["esteps", "--motor-steps", "-200", "--microsteps", "16", "--drive-diameter-mm", "7",
      "--filament-mm", "1.75"], "motor_steps must be > 0"),
    (["esteps", "--motor-steps", "200", "--microsteps", "16", "--drive-diameter-mm", "0",
      "--filament-mm", "1.75"], "> 0"),
    (["esteps", "--motor-steps", "200", "--microsteps", "16", "--drive-diameter-mm", "7",
      "--filament-mm", "1.75", "--drive", "9"], "drives are 0 to 5"),
    (["advance", str(SHORT), "-o", "a.gcode", "--l1-mm", "-1", "--l2-mm", "4"], ">= 0"),
    (["preview", str(SHORT), "-o", "p.png", "--l2-mm", "-1"], ">= 0"),
    (["arcfit", str(SHORT), "-o", "f.gcode", "--tolerance-mm", "0"], "tolerance must be > 0"),
    (["arcfit", str(SHORT), "-o", "f.gcode", "--max-radius-mm", "-5"], "radius must be > 0"),
    (["preview", str(SHORT), "-o", "p.png", "--layer", "999"], "has no layer 999"),
    (["preview", str(SHORT), "-o", "p.png", "--colors", "#ff0000"], "colours are given"),
    (["emu", "print", "--set", "step_backend=pio"], "--set tick_us=50"),
])
def test_a_bad_argument_is_one_line_and_status_2(capsys, tmp_path, monkeypatch, argv,
                                                words):
    monkeypatch.chdir(tmp_path)
    status, err = run(capsys, *argv)
    assert status == 2 and words in one_line(err)
    assert list(tmp_path.iterdir()) == []  # no empty PNG, no half-written file


def test_serve_on_a_port_in_use_says_so_before_announcing_it(tmp_path):
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        proc = subprocess.run([sys.executable, "-m", "mixstep.cli", "serve", "--tcp",
                               "127.0.0.1:%d" % port], capture_output=True, text=True,
                              timeout=60, cwd=tmp_path)
    assert proc.returncode == 2
    assert "Address already in use" in one_line(proc.stderr)
    assert "simulated printer on" not in proc.stdout


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_sim_stopped_leaves_no_temporary_file_and_no_traceback(tmp_path, sig):
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    proc = subprocess.Popen([sys.executable, "-m", "mixstep.cli", "sim", str(SHORT)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=dict(os.environ, TMPDIR=str(tmp)), cwd=tmp_path,
                            # A test runner's worker may ignore SIGINT, and the child
                            # would inherit that: a user's Ctrl-C is never ignored.
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    deadline = time.monotonic() + 60
    while not any(tmp.rglob("*.edges")):  # the run has begun
        assert proc.poll() is None and time.monotonic() < deadline, proc.communicate()
        time.sleep(0.1)
    proc.send_signal(sig)
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 130
    assert "interrupted" in one_line(err)
    assert list(tmp.iterdir()) == []


def test_the_readme_commands_are_ones_mixstep_takes():
    """A newcomer copies the README's commands: each `mixstep` line in its shell blocks
    must parse (arguments, required options), here without running it."""
    import re
    import shlex
    text = (paths.ROOT / "README.md").read_text()
    blocks = re.findall(r"```sh\n(.*?)```", text, re.S)
    commands = [line.split("#")[0].split() for block in blocks for line in block.splitlines()
                if re.match(r"(\.venv/bin/)?mixstep ", line)]
    assert commands  # the tour has some
    for words in commands:
        cli.parser().parse_args(shlex.split(" ".join(words[1:])))
