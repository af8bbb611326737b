"""Heater and fan PWM frequencies: what each chip's machine.PWM makes at its system
clock, the options checked against it, and the software PWM that drives a heater
slower than the chip can (a solid-state relay on a bed), on the firmware running on
the MicroPython unix port against the simulated chip."""
import re

import numpy as np
import pytest

from mixstep import trace
from mixstep.simprinter import SimPrinter

MHZ = 1000000


def test_pwm_range_is_what_the_simulated_chip_takes(mp):
    """mixfw.pwm.range_hz, the firmware's closed form, against the simulated chips'
    PWM, which follows MicroPython's divider arithmetic: the ends are taken and one
    Hz beyond each is refused, at the clocks boards boot with and overclocked."""
    got = mp.script_json("pwm_range")
    for chip, mhz, lo, hi, lo_ok, hi_ok, below_ok, above_ok in got:
        assert (lo_ok, hi_ok, below_ok, above_ok) == (True, True, False, False), (chip, mhz)
    lowest = {(chip, mhz): lo for chip, mhz, lo, *_ in got}
    # rp2: 16 * clock / (65534 * 4095), rounded up (7.45 Hz at 125 MHz).
    assert lowest["rp2040", 125] == 8 and lowest["rp2350", 150] == 9
    assert lowest["rp2040", 200] == 12  # the 10 Hz default is out of reach
    assert all(lowest["esp32", mhz] == 1 for mhz in (20, 80, 160, 240))
    highest = {(chip, mhz): hi for chip, mhz, _, hi, *_ in got}
    assert highest["esp32", 240] == 40 * MHZ and highest["esp32", 20] == 10 * MHZ


def m503_value(p, name):
    for line in p.send("M503"):
        m = re.match(r"echo:M926 I%s V(\S+) ;" % name, line)
        if m:
            return m.group(1)
    raise AssertionError("%s not in M503" % name)


def test_m926_refuses_a_pwm_frequency_the_chip_cannot_make():
    p = SimPrinter(board="pico2")  # an RP2350 at 150 MHz
    try:
        assert p.send("M926 Ifan_pwm_hz V8") == [
            "Error:fan_pwm_hz = 8 is below the minimum 9 (the rp2350's PWM makes "
            "9..75000000 Hz at 150 MHz)", "ok"]
        assert m503_value(p, "fan_pwm_hz") == "1000"  # unchanged
        assert p.send("M926 Ifan_pwm_hz V9") == ["ok"]
        # A heater goes below the chip's range, in software.
        assert p.send("M926 Ibed_pwm_hz V1") == ["ok"]
        assert m503_value(p, "bed_pwm_hz") == "1"
    finally:
        p.finish()
    p = SimPrinter(board="pico2", clock_hz=200 * MHZ)  # overclocked: the range moves up
    try:
        reply = p.send("M926 Ifan_pwm_hz V11")
        assert reply[0] == ("Error:fan_pwm_hz = 11 is below the minimum 12 (the rp2350's "
                            "PWM makes 12..100000000 Hz at 200 MHz)")
        assert m503_value(p, "fan_pwm_hz") == "1000"
    finally:
        p.finish()


def test_the_simulation_runs_the_chip_at_the_boards_clock():
    """The Pico board's 200 MHz, as its boot.py sets it: the PWM's range is that
    clock's."""
    p = SimPrinter(board="pico")
    try:
        assert p.send("M926 Ifan_pwm_hz V11")[0] == (
            "Error:fan_pwm_hz = 11 is below the minimum 12 (the rp2040's PWM makes "
            "12..100000000 Hz at 200 MHz)")
    finally:
        p.finish()


def test_a_saved_pwm_frequency_the_chip_cannot_make_boots_with_a_warning(tmp_path):
    """Saved at 125 MHz, where the chip makes 8 Hz; loaded at 200 MHz, where it does
    not: the firmware starts on the defaults and says why."""
    cfg = tmp_path / "mixstep.cfg"
    p = SimPrinter(config_path=cfg)
    try:
        assert p.send("M926 Ifan_pwm_hz V8") == ["ok"]
        assert p.send("M500") == ["ok"]
    finally:
        p.finish()
    p = SimPrinter(config_path=cfg, clock_hz=200 * MHZ)
    try:
        boot = p.send("M106 S255")
        assert re.fullmatch(
            r"echo:config %s: line \d+: fan_pwm_hz = 8 is below the minimum 12 \(the "
            r"sim's PWM makes 12\.\.100000000 Hz at 200 MHz\); kept the default"
            % re.escape(str(cfg)), boot[0]), boot
        assert boot[1:] == ["ok"]
        assert m503_value(p, "fan_pwm_hz") == "1000"
    finally:
        p.finish()


def on_fractions(edges_path, gpio):
    """(period_us, high time / period) of each whole period of the pin's recorded
    square wave, a period running from one rising edge to the next."""
    times, gpios, levels = trace.read_edges(edges_path)
    keep = gpios == gpio
    times, levels = times[keep].astype(np.int64), levels[keep]
    rises = times[levels == 1]
    out = []
    for start, end in zip(rises[:-1], rises[1:]):
        fall = times[(levels == 0) & (times > start) & (times < end)]
        assert len(fall) == 1, (start, end)
        out.append((int(end - start), (fall[0] - start) / (end - start)))
    return out


def test_a_1_hz_bed_heats_with_its_duty_in_software(tmp_path, board):
    """A bed on a solid-state relay at 1 Hz, below the chip's PWM: the firmware
    switches the pin itself, once a second, high for the PID's share of it."""
    edges = tmp_path / "edges.bin"
    p = SimPrinter(edges_path=edges, settings={"bed_pwm_hz": 1})
    try:
        assert p.send("M190 S60")[-1] == "ok"
        temps = []
        for _ in range(12):
            p.send("G4 S2")
            temps.append(float(re.search(r"B:([\d.]+)", p.send("M105")[0]).group(1)))
    finally:
        p.finish()
    assert all(abs(t - 60.0) <= 1.0 for t in temps), temps
    held = on_fractions(edges, board["PINS"]["bed_heater"])[-20:]
    # Each period one second, to the main loop's turn (a simulated millisecond).
    assert all(abs(us - MHZ) <= 1000 for us, _ in held), held
    assert all(0.0 < f < 1.0 for _, f in held), held
    # Holding 60 C takes what the bed loses: 1.2 W/K over 38 K of a 150 W heater.
    assert np.mean([f for _, f in held]) == pytest.approx(1.2 * 38.0 / 150.0, abs=0.03)


def test_a_halt_turns_a_software_pwm_heater_off_at_once():
    """Not at the end of its period: M112 leaves the bed's pin low before its reply."""
    p = SimPrinter(settings={"bed_pwm_hz": 1})
    try:
        p.send("M140 S100")
        p.send("G4 P1500")  # the first pulse starts with the period after the target
        assert "duty:1.000" in p.send("M7100 H1")[0]  # the pin is high, heating
        p.send("M112")
        assert "duty:0.000" in p.send("M7100 H1")[0]
    finally:
        p.finish()


def test_an_overclocked_chip_boots_and_heats_with_the_default_10_hz():
    """At 200 MHz rp2's PWM stops at 12 Hz: the heaters' 10 Hz default is made in
    software instead of stopping the firmware at boot."""
    p = SimPrinter(clock_hz=200 * MHZ)
    try:
        assert p.send("M190 S50")[-1] == "ok"
        assert p.send("M109 S200")[-1] == "ok"
        t = re.match(r"ok T:([\d.]+) /200\.0 B:([\d.]+) /50\.0", p.send("M105")[-1])
        assert float(t.group(1)) >= 199.0 and float(t.group(2)) >= 49.0
    finally:
        p.finish()
