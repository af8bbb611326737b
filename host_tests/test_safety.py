"""What keeps the board safe when the firmware itself fails (mixfw/safety.py): a step
timer that stopped halts the printer with the heaters off, a main loop that hangs is
reset by the watchdog, and every way out of the main loop leaves heaters and drivers
off. The faults are injected by the simulated board (boards/sim/simfaults.py)."""
import ast
import json
import subprocess
import zlib

import pytest

from mixstep import paths
from mixstep.simprinter import SIM_MAIN, set_args

STALL = "Error:step timer stopped (no tick for 250 ms); restart the board"


def test_a_dead_step_timer_halts_with_the_heaters_off(sim_printer):
    p = sim_printer()
    assert p.send("M104 S200") == ["ok"]
    assert p.send("G91") == ["ok"]
    assert p.send("G1 X10 F3000") == ["ok"]
    assert p.send("M400") == ["ok"]
    assert p.send("M7101") == ["ok"]  # the next tick raises; the timer is disabled
    # The move never finishes: within the stall time the printer halts, heaters off.
    got = p.send("G1 X10")
    got += p.send("M400")
    assert STALL in got, got
    assert "/0.0 B:" in p.send("M105")[-1]  # the hot end's target is gone
    assert p.send("G1 X1")[0].startswith("Error:printer halted (step timer stopped")
    # M999 can't bring a dead timer back: the check halts again.
    assert p.send("M999") == ["ok"]
    got = p.send("G4 P500")
    assert STALL in got, got
    report = p.finish()
    assert report["heater_duty_at_exit"] == {"hotend": 0.0, "bed": 0.0}
    assert report["steps"]["x"] < 20 * 80


def test_a_running_step_timer_never_trips_the_check(sim_printer):
    # A long print with waits, dwell and idle stretches: no false alarm.
    p = sim_printer()
    for line in ("G91", "G1 X100 F600", "G4 S3", "M400", "G1 X-100 F6000", "M400"):
        replies = p.send(line)
        assert not [r for r in replies if r.startswith("Error")], (line, replies)
    report = p.finish()
    assert report["steps"]["x"] == 0


def _run(lines, board="sim", settings=None):
    """Runs the lines through the simulated board: (exit status, output lines)."""
    proc = subprocess.run([paths.micropython(), "-X", "heapsize=2M", str(SIM_MAIN)]
                          + set_args(settings),
                          input=("\n".join(lines) + "\n").encode(), capture_output=True,
                          env=paths.micropython_env(board), timeout=120)
    return proc.returncode, proc.stdout.decode().splitlines()


def _duty(reply):
    """The heater duty (0..1) of an M7100 H<n> report line."""
    return float(reply.split(" duty:")[1].split()[0])


def test_the_watchdog_resets_a_main_loop_that_hangs():
    # The board's watchdog_ms is 4000: a 3.5 s hang is survived, a 5 s one is not.
    code, out = _run(["M104 S200", "M7102 S3500", "M105", "M7102 S5000", "M105"])
    assert code == 3
    assert out[-1].startswith("//sim watchdog reset at_us=")
    at_us = int(out[-1].split("at_us=")[1].split()[0])
    fed_us = int(out[-1].split("fed_us=")[1])
    assert 4000000 <= at_us - fed_us <= 4002000
    # The line after the reset never ran.
    assert [l for l in out if l.startswith("ok")] == ["ok", "ok", "ok T:%s" % out[3][5:]]


def test_the_watchdog_cant_be_turned_off(sim_printer, tmp_path):
    # Every board drives heaters: 1000 ms at least, and the RP2040's 8388 ms at most.
    cfg = tmp_path / "mixstep.cfg"
    p = sim_printer(config_path=cfg)
    assert p.send("M926 Iwatchdog_ms V0") == [
        "Error:watchdog_ms = 0 is below the minimum 1000", "ok"]
    assert p.send("M926 Iwatchdog_ms V8389") == [
        "Error:watchdog_ms = 8389 is above the maximum 8388", "ok"]
    assert p.send("M500") == ["ok"]
    p.finish()
    # A file saved when 0 was allowed still boots, with the default and a warning.
    lines = cfg.read_text().splitlines(keepends=True)
    at = lines.index("watchdog_ms = 4000\n")
    lines[at] = "watchdog_ms = 0\n"
    body = "".join(lines[:-1]).encode()
    cfg.write_bytes(body + b"crc32 = %08x\n" % zlib.crc32(body))
    p = sim_printer(config_path=cfg)
    assert p.send("M925 Iwatchdog_ms")[:2] == [
        "echo:config %s: line %d: watchdog_ms = 0 is below the minimum 1000; kept the "
        "default" % (cfg, at + 1),
        "echo:M926 Iwatchdog_ms V4000 ; a main loop stuck this long resets the board "
        "(hardware watchdog, always on), 1000..8388 (restart)"]
    p.finish()


def test_a_wait_runs_the_background_every_10_ms_and_each_turn_tasks_at_every_turn(mp):
    """A wait wakes at every interrupt, a few times a millisecond on a chip: the
    background tasks (the watchdog, the step-loop check, the reports) run every 10 ms
    of it, as while lines come back to back; the heaters' control and a software PWM
    (each_turn) at every turn."""
    got = mp.script_json("background_turns")
    assert got["turns"] == 201
    assert got["each_turn"] == 200
    assert 19 <= got["background"] <= 21, got


def test_back_to_back_lines_feed_the_watchdog():
    # Lines that never wait still let the main loop feed the watchdog (and run the
    # heater control): 3 s hangs, each under the timeout, 8 s in all.
    code, out = _run(["M7102 S3000", "M117 one", "M7102 S3000", "M117 two", "M7102 S2000"])
    assert code == 0, out[-3:]


def test_the_main_loop_leaves_heaters_and_drivers_off(sim_printer):
    p = sim_printer()
    for line in ("M104 S200", "M140 S60", "M106 S255", "G1 X10 F3000", "G4 S2"):
        p.send(line)
    report = p.finish()  # the host went away: the main loop ends
    assert report["heater_duty_at_exit"] == {"hotend": 0.0, "bed": 0.0}
    assert report["drivers_enabled_at_exit"] is False


def test_a_halt_turns_the_heaters_off_though_stopping_motion_raises(sim_printer):
    p = sim_printer()
    assert p.send("M7104") == ["ok"]  # from now on, stopping the step path raises
    for line in ("M104 S200", "M140 S60", "G4 S1"):
        assert p.send(line) == ["ok"]
    assert _duty(p.send("M7100 H0")[0]) > 0 and _duty(p.send("M7100 H1")[0]) > 0
    assert p.send("M112") == ["Error:emergency stop (M112)",
                              "Error:halting raised RuntimeError: fault injected by M7104",
                              "ok"]
    assert _duty(p.send("M7100 H0")[0]) == _duty(p.send("M7100 H1")[0]) == 0
    assert p.send("G1 X1")[0].startswith("Error:printer halted")
    p.proc.stdin.close()
    assert p.proc.wait(60) != 0  # the way out raises too (the next test)


@pytest.mark.parametrize("board,settings", [("sim", {}),
                                            ("pico", {"step_backend": "pio_dma"})])
def test_leaving_the_main_loop_turns_everything_off_though_stopping_steps_raises(
        board, settings):
    # The step timer's deinit (a DMA feed's stop) raises: the heaters went off before
    # it, the drivers and the fan after it, and the fault still ends the firmware.
    code, out = _run(["M7104", "M104 S200", "M140 S60", "M106 S255", "G1 X10 F3000",
                      "G4 S2", "M7100 H0", "M7100 H1"], board, settings)
    assert [_duty(l) > 0 for l in out if " duty:" in l] == [True, True]
    report = json.loads([l for l in out if l.startswith("//sim ")][0][6:])
    assert report["heater_duty_at_exit"] == {"hotend": 0.0, "bed": 0.0}
    assert report["drivers_enabled_at_exit"] is False
    assert report["steps"]["x"] == 800
    assert code == 1 and out[-1] == "RuntimeError: fault injected by M7104"


def test_m997_leaves_the_firmware_once_for_an_update(tmp_path, mp):
    # Ctrl-C bytes are data while serving, so mpremote can't stop the firmware: M997
    # finishes the moves, turns everything off and leaves; on a board the next boot
    # then skips the firmware once (assemble.repl_boot).
    code, out = _run(["G1 X10 F3000", "M104 S200", "M997", "G1 X20"])
    assert code == 0
    report = json.loads(out[-1][6:])
    assert report["steps"]["x"] == 800  # the queued move finished; the line after did not run
    assert report["heater_duty_at_exit"]["hotend"] == 0.0
    assert report["drivers_enabled_at_exit"] is False
    flag = tmp_path / "mixstep.repl"
    flag.write_text("M997\n")
    got = mp.run("""
        import sys, simmachine
        sys.modules['machine'] = simmachine
        from mixfw import assemble
        print(assemble.repl_boot(%r), assemble.repl_boot(%r))
    """ % (str(flag), str(flag)))
    assert got.splitlines()[-1] == "True False" and not flag.exists()


def test_deploy_asks_a_running_firmware_to_step_aside():
    from mixstep import deploy, serve
    import threading
    bridge = serve.PtyBridge(realtime=0)
    thread = threading.Thread(target=bridge.run, daemon=True)
    thread.start()
    try:
        assert deploy.send_m997(bridge.path) is True
        thread.join(20)
        assert bridge.proc.wait(10) == 0  # the firmware left on M997
    finally:
        bridge.close()


@pytest.mark.parametrize("board,active_low", [("sim", True), ("sim", False),
                                              ("pico", True), ("esp32_devkit", True)])
def test_boot_turns_every_driver_off_first(mp, tmp_path, board, active_low):
    flag = tmp_path / "mixstep.repl"
    flag.write_text("M997\n")
    at_boot, in_repl, started, clock = mp.script_json(
        "safety_boot", int(active_low), flag, env=paths.micropython_env(board))
    off = 1 if active_low else 0
    count = len([n for n in paths.load_board(board)["PINS"] if n.endswith("_enable")])
    assert at_boot == in_repl == [off] * count
    assert started is False
    # Then the board's clock: the Pico's 200 MHz with the regulator at 1.15 V (VSEL 12)
    # first; the others keep the clock and the 1.10 V they boot with.
    assert clock == ([200000000, 12] if board == "pico" else
                     [{"sim": 125000000, "esp32_devkit": 160000000}[board], 11])


def test_boot_imports_only_machine_time_and_board():
    # Anything else would run, and could fail, with the drivers still on (time is
    # built into MicroPython: nothing of it runs at import).
    tree = ast.parse((paths.FIRMWARE / "boot.py").read_text())
    imported = [alias.name for node in ast.walk(tree)
                if isinstance(node, (ast.Import, ast.ImportFrom))
                for alias in node.names]
    assert imported == ["machine", "time", "board"]
