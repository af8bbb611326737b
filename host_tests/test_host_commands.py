"""What hosts such as OctoPrint and Pronterface send besides G-code to print: free
text (M117, M118), the emergency commands (M108, M410, M876) that act as soon as their
line arrives, temperatures while waiting and on request (M155), the busy interval
(M113), the storage M115 promises, and `mixstep serve` ending cleanly."""
import os
import signal
import socket
import subprocess
import sys
import threading
import time

import pytest

from mixstep import paths, serve
from net import free_port
from test_protocol import TcpHost, group

X_SPM = 80


def ask(printer, line):
    return printer.send(line)


def console_log(path):
    """[(us, way, text)] from a --console-log file."""
    rows = []
    for raw in open(path):
        us, way, text = raw.rstrip("\n").split(" ", 2)
        rows.append((int(us), way, text))
    return rows


def test_text_commands_are_text(sim_printer):
    p = sim_printer()
    # Letters that would be parameter words elsewhere are the message here.
    assert ask(p, "M117 Printing...") == ["ok"]
    assert ask(p, "M117 I I E E X") == ["ok"]
    assert ask(p, "M117") == ["ok"]
    assert ask(p, "M118 E1 layer 3") == ["echo:layer 3", "ok"]
    assert ask(p, "M118 A1 action:pause") == ["//action:pause", "ok"]
    assert ask(p, "M118 A1 E1 P0 both flags") == ["echo://both flags", "ok"]
    assert ask(p, "M118 E0 E1 said twice") == ["echo:said twice", "ok"]
    assert ask(p, "M118 Hello E1 X2") == ["Hello E1 X2", "ok"]
    assert ask(p, "N1 M117 numbered text*%d" % _checksum("N1 M117 numbered text")) == ["ok"]
    # A command we don't know is unknown, whatever its words: its text is not judged.
    assert ask(p, "M0 Click to resume") == ['echo:Unknown command: "M0"', "ok"]
    assert ask(p, "M9998 S1 S2") == ['echo:Unknown command: "M9998"', "ok"]
    # A command we know still gets its words checked.
    assert ask(p, "G1 X1 X2") == ["Error:parameter X given twice", "ok"]
    p.finish()


def _checksum(text):
    cs = 0
    for c in text.encode():
        cs ^= c
    return cs


def test_m115_promises_only_what_is_there(sim_printer, tmp_path):
    bare = sim_printer()
    caps = [l for l in ask(bare, "M115") if l.startswith("Cap:")]
    assert "Cap:EEPROM:0" in caps and "Cap:SDCARD:0" in caps
    assert "Cap:AUTOREPORT_TEMP:1" in caps and "Cap:EMERGENCY_PARSER:1" in caps
    assert ask(bare, "M501") == ["Error:this printer has no configuration storage", "ok"]
    bare.finish()
    (tmp_path / "files").mkdir()
    full = sim_printer(config_path=tmp_path / "mixstep.cfg", files_dir=tmp_path / "files")
    caps = [l for l in ask(full, "M115") if l.startswith("Cap:")]
    assert "Cap:EEPROM:1" in caps and "Cap:SDCARD:1" in caps
    assert ask(full, "M21") == ["echo:SD card ok", "ok"]
    assert ask(full, "M20") == ["Begin file list", "End file list", "ok"]
    assert ask(full, "M501")[0].startswith("Error:no saved configuration")
    assert ask(full, "M500") == ["ok"]
    assert ask(full, "M501") == ["ok"]
    full.finish()


def test_m113_sets_the_busy_interval(sim_printer):
    p = sim_printer()
    assert ask(p, "M113") == ["echo:M113 S2", "ok"]
    assert ask(p, "M113 S1") == ["ok"]
    assert ask(p, "G4 P3500") == ["busy: processing"] * 3 + ["ok"]  # at 1, 2 and 3 s
    assert ask(p, "M113 S0") == ["ok"]
    assert ask(p, "G4 S3") == ["ok"]
    assert ask(p, "M113 S61") == ["Error:S61 out of range 0..60", "ok"]
    p.finish()


def test_heating_wait_reports_temperatures_every_second_and_m108_ends_it(sim_printer, tmp_path):
    log = tmp_path / "console.log"
    p = sim_printer(settings=None, console_log=log)
    replies = ask(p, "M109 S60")
    temps = [l for l in replies[:-1] if l.startswith("T:")]
    assert replies[:-1] == temps, "nothing but temperatures during the wait: %r" % replies
    rows = console_log(log)
    start = [us for us, way, text in rows if text == "M109 S60"][0]
    ok_us = [us for us, way, text in rows if way == ">" and text == "ok"][-1]
    wait_s = (ok_us - start) / 1e6
    assert wait_s > 5
    assert abs(len(temps) - int(wait_s)) <= 1
    # The graph moves: each line a rising hot end, the target beside it.
    seen = [float(t.split()[0][2:]) for t in temps]
    assert seen == sorted(seen) and seen[0] < 40 and seen[-1] > 55
    assert all(" /60.0 " in t for t in temps)
    # M108 ends a wait at once (here it is in the pipe when the wait starts); the
    # target stays and the host hears no error.
    answers, _ = _flood(p, ["M109 S200", "M108", "M105"])
    assert answers[0] == ["ok"] and answers[1] == ["ok"]
    assert " /200.0 " in answers[2][-1] and float(answers[2][-1].split()[1][2:]) < 100


def _flood(p, lines):
    """Write lines without waiting; returns their answers and what followed."""
    p.proc.stdin.write(("\n".join(lines) + "\n").encode())
    out = []
    while len([l for l in out if l == "ok" or l.startswith("ok ")]) < len(lines):
        out.append(p._readline())
    return group(out)


def test_m155_reports_temperatures_to_the_host_that_asked(sim_printer):
    p = sim_printer()
    assert ask(p, "M155") == ["Error:missing parameter S", "ok"]
    assert ask(p, "M155 S1") == ["ok"]
    replies = ask(p, "G4 S3")
    assert len([l for l in replies if l.startswith("T:")]) == 3
    assert ask(p, "M155 S0") == ["ok"]
    assert [l for l in ask(p, "G4 S3") if l.startswith("T:")] == []
    p.finish()


@pytest.fixture
def realtime_printer(tmp_path):
    """The printer over TCP in real time, so a host's line arrives mid-move."""
    port = free_port()
    log = tmp_path / "console.log"
    proc = serve.serve_tcp("127.0.0.1:%d" % port, realtime=1, announce=lambda s: None,
                           console_log=log)
    yield port, log
    serve.stop(proc)


def test_m410_stops_the_moves_at_once_and_keeps_the_heaters(realtime_printer):
    port, log = realtime_printer
    host = TcpHost(port)
    assert host.ask("M104 S180") == ["ok"]
    assert host.ask("G91") == ["ok"]
    assert host.ask("G1 X200 F3000") == ["ok"]  # 4 s
    time.sleep(1.5)
    assert host.ask("M410") == ["ok"]
    first = host.ask("M114")[0]
    time.sleep(0.5)
    second = host.ask("M114")[0]
    # Stopped part-way, and it stays there; logical and step positions agree.
    assert first == second, (first, second)
    count_x = int(first.split("Count X:")[1].split()[0])
    assert 10 * X_SPM < count_x < 150 * X_SPM
    assert abs(float(first.split()[0][2:]) - count_x / X_SPM) < 0.006
    # The printer moves on from there, exactly; the heater kept its target.
    assert host.ask("G1 X10") == ["ok"]
    assert host.ask("M400") == ["ok"]
    assert host.ask("M114")[0].endswith("Count X:%d Y:0 Z:0" % (count_x + 10 * X_SPM))
    assert " /180.0 " in host.ask("M105")[-1]
    host.close()


def test_m410_ends_a_wait_for_moves_and_m876_is_harmless(realtime_printer):
    port, log = realtime_printer
    host = TcpHost(port)
    for line in ("G91", "G1 X200 F3000"):
        assert host.ask(line) == ["ok"]
    host.send_all(b"M400\n").join()
    time.sleep(1.0)
    host.send_all(b"M410\nM876 S1\nM114\n").join()
    answers = host.answers(4)
    assert answers[0] == ["echo:command stopped: quick stop (M410)", "ok"]
    assert answers[1] == ["ok"] and answers[2] == ["ok"]
    rows = console_log(log)
    m410_us = [us for us, way, text in rows if text == "M410"][0]
    stopped_us = [us for us, way, text in rows if text.startswith("echo:command stopped")][0]
    assert stopped_us - m410_us < 20000
    host.close()


def test_m108_from_a_host_ends_m109_in_real_time(realtime_printer):
    port, log = realtime_printer
    host = TcpHost(port)
    host.send_all(b"M109 S210\n").join()
    time.sleep(2.5)
    host.send_all(b"M108\n").join()
    answers = host.answers(2)
    temps = [l for l in answers[0] if l.startswith("T:")]
    assert answers[0][-1] == "ok" and 1 <= len(temps) <= 4
    assert answers[1] == ["ok"]
    rows = console_log(log)
    m108_us = [us for us, way, text in rows if text == "M108"][0]
    ok_us = [us for us, way, text in rows if way == ">" and text == "ok"][0]
    assert 0 <= ok_us - m108_us < 20000, "the wait ended %d us after M108" % (ok_us - m108_us)
    host.close()


def _serve_process(args, tmp_path):
    env = dict(os.environ)
    # As from a terminal: SIGINT is Ctrl-C even where the test runner was started in
    # the background, which leaves it ignored for its children.
    proc = subprocess.Popen([sys.executable, "-m", "mixstep.cli", "serve"] + args,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, cwd=tmp_path,
                            env=env, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    first = proc.stdout.readline()
    assert first.startswith("mixstep: simulated printer on"), first
    return proc


def _port_is_free(port):
    with socket.socket() as s:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            s.bind(("127.0.0.1", port))
        except OSError:
            return False
        return True


@pytest.mark.parametrize("how", [signal.SIGTERM, signal.SIGINT])
def test_serve_ends_cleanly_with_its_firmware(tmp_path, how):
    port = free_port()
    proc = _serve_process(["--tcp", "127.0.0.1:%d" % port, "--realtime", "0"], tmp_path)
    again = None
    try:
        host = TcpHost(port)
        # The default flash is under out/printer/ where serve runs: M500 and M20 work.
        assert host.ask("M500") == ["ok"]
        assert host.ask("M21") == ["echo:SD card ok", "ok"]
        host.close()
        proc.send_signal(how)
        out, _ = proc.communicate(timeout=20)
        assert proc.returncode == 0
        assert "Traceback" not in out and "mixstep: stopped" in out
        assert (tmp_path / "out" / "printer" / "mixstep.cfg").exists()
        assert _port_is_free(port), "the firmware still holds its port"
        # And the next serve starts on the same port.
        again = _serve_process(["--tcp", "127.0.0.1:%d" % port, "--realtime", "0"], tmp_path)
        TcpHost(port).close()
        again.send_signal(signal.SIGTERM)
        again.communicate(timeout=20)
        assert again.returncode == 0
    finally:
        for p in (proc, again):
            if p is not None and p.poll() is None:
                p.kill()  # its firmware follows (it dies with its parent)
                p.wait()


def test_serve_pty_dies_with_a_killed_parent(tmp_path):
    proc = _serve_process(["--pty", "--realtime", "0"], tmp_path)
    pids = subprocess.run(["pgrep", "-P", str(proc.pid)], capture_output=True,
                          text=True).stdout.split()
    assert pids, "no firmware child"
    proc.kill()
    proc.wait()
    deadline = time.time() + 10
    while any(os.path.exists("/proc/%s" % pid) and _alive(pid) for pid in pids):
        assert time.time() < deadline, "the firmware outlived a killed serve"
        time.sleep(0.1)


def _alive(pid):
    try:
        with open("/proc/%s/stat" % pid) as f:
            return f.read().split(")")[-1].split()[0] != "Z"
    except OSError:
        return False
