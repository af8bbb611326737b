"""Real host software against the simulated printer: Printrun's printcore streams a
real slicer file over the TCP console and over a pseudo-terminal."""
import pytest
import threading
import time

from printrun import gcoder
from printrun.printcore import printcore

from mixstep import paths, serve
from gcode_model import expected_steps
from net import free_port, wait_for_port

GCODE = paths.ROOT / "testdata" / "part_3tool_prusaslicer_rel.gcode"


class Host:
    """printcore with every received line kept."""

    def __init__(self, port):
        self.lines = []
        self.core = printcore()
        self.core.recvcb = lambda line: self.lines.append(line.strip())
        self.core.connect(port, 115200)
        deadline = time.time() + 20
        while not self.core.online:
            assert time.time() < deadline, "printer never came online"
            time.sleep(0.05)
        # printcore sends M105 until the printer answers: on a slow start it sent more
        # than one, and their late oks would answer the test's first question. Replies
        # come in order, so once this marker's ok is in, they all are.
        start = len(self.lines)
        self.core.send_now("M118 host ready")
        while not any(l.startswith("ok") for l in self._after_marker(start)):
            assert time.time() < deadline, "no answer to M118"
            time.sleep(0.02)

    def _after_marker(self, start):
        lines = self.lines[start:]
        for i, line in enumerate(lines):
            if line.endswith("host ready"):
                return lines[i + 1:]
        return []

    def print_file(self, path, timeout_s=600):
        with open(path) as f:
            gcode = gcoder.LightGCode([l.rstrip("\r\n") for l in f])
        assert self.core.startprint(gcode)
        deadline = time.time() + timeout_s
        while self.core.printing:
            assert time.time() < deadline, "print did not finish"
            time.sleep(0.05)
        return gcode

    def ask(self, command, timeout_s=60):
        start = len(self.lines)
        self.core.send_now(command)
        deadline = time.time() + timeout_s
        while not any(l.startswith("ok") for l in self.lines[start:]):
            assert time.time() < deadline, "no ok for " + command
            time.sleep(0.02)
        return self.lines[start:]

    def close(self):
        self.core.disconnect()


def check_print(host, board):
    sent_before = len(host.core.sent)
    host.print_file(GCODE)
    sent = host.core.sent[sent_before:]
    time.sleep(0.2)
    oks = [l for l in host.lines if l.startswith("ok")]
    assert not [l for l in host.lines if l.startswith("Error")]
    # Every line printcore sent during the print (and the M110s around it) got its ok.
    assert len(oks) >= len(sent)
    host.ask("M400")
    reply = host.ask("M114")
    spm = board["SETTINGS"]["steps_per_mm"]
    want = expected_steps(GCODE, spm)
    position = [l.strip() for l in reply if l.startswith("X:")][0]
    assert position.endswith("Count X:%d Y:%d Z:%d" % (want["x"], want["y"], want["z"]))


@pytest.mark.slow
def test_printcore_prints_a_real_file_over_tcp(board):
    address = "127.0.0.1:%d" % free_port()
    proc = serve.serve_tcp(address, realtime=0, announce=lambda s: None)
    try:
        wait_for_port(address)
        host = Host(address)
        check_print(host, board)
        host.close()
    finally:
        proc.terminate()
        proc.wait()


@pytest.mark.slow
def test_printcore_prints_a_real_file_over_the_pty(board):
    bridge = serve.PtyBridge(realtime=0)
    thread = threading.Thread(target=bridge.run, daemon=True)
    thread.start()
    try:
        host = Host(bridge.path)
        check_print(host, board)
        host.close()
    finally:
        bridge.close()


def test_printcore_host_commands_over_the_pty(tmp_path):
    # In real time, so M108 arrives while M109 waits, as when a user cancels.
    (tmp_path / "files").mkdir()
    bridge = serve.PtyBridge(realtime=1, config=tmp_path / "mixstep.cfg",
                             files=tmp_path / "files")
    thread = threading.Thread(target=bridge.run, daemon=True)
    thread.start()
    try:
        host = Host(bridge.path)
        reply = host.ask("M115")
        assert reply[0].startswith("FIRMWARE_NAME:mixstep")
        assert "Cap:EMERGENCY_PARSER:1" in reply and "Cap:AUTOREPORT_TEMP:1" in reply
        assert "Cap:EEPROM:1" in reply and "Cap:SDCARD:1" in reply
        assert host.ask("M117 Printing...") == ["ok"]
        assert host.ask("M118 E1 layer 3") == ["echo:layer 3", "ok"]
        assert host.ask("M21") == ["echo:SD card ok", "ok"]
        assert host.ask("M500") == ["ok"]
        # Heating: the host hears the temperature every second, and M108 ends the wait.
        start = len(host.lines)
        host.core.send_now("M109 S210")
        time.sleep(2.5)
        host.core.send_now("M108")
        deadline = time.time() + 10
        while len([l for l in host.lines[start:] if l.startswith("ok")]) < 2:
            assert time.time() < deadline, host.lines[start:]
            time.sleep(0.05)
        waited = host.lines[start:]
        temps = [l for l in waited if l.startswith("T:")]
        assert 1 <= len(temps) <= 4 and all(" /210.0 " in t for t in temps), waited
        assert not [l for l in waited if l.startswith("Error")]
        # M155: temperatures without asking.
        start = len(host.lines)
        assert "ok" in host.ask("M155 S1")  # its first report may follow the ok at once
        time.sleep(2.5)
        assert len([l for l in host.lines[start:] if l.startswith("T:")]) >= 2
        assert "ok" in host.ask("M155 S0")
        host.close()
    finally:
        bridge.close()
