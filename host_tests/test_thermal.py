"""Heaters, fans and thermal protection, on the firmware running on the unix port.

The simulated printer has a first-order thermal model of the hot end and bed
(boards/sim/simthermal.py); M7100 H<n> F<code> injects faults into it and M7100 H<n>
reports it, including how long after a fault the heater's PWM went to 0."""
import json
import math
import re

import pytest

from mixstep.simprinter import SimPrinter

AMBIENT_C = 22.0


def beta_raw(temp_c, r25_ohm=100000.0, beta=3950.0, pullup_ohm=4700.0):
    """What the ADC reads at temp_c, from the Beta equation (independent of the firmware)."""
    r = r25_ohm * math.exp(beta * (1 / (temp_c + 273.15) - 1 / 298.15))
    return round(65535 * r / (r + pullup_ohm))


# A 10 kOhm NTC with its published Steinhart-Hart coefficients.
SH = (1.009249522e-03, 2.378405444e-04, 2.019202697e-07)


def sh_celsius(raw, pullup_ohm=10000.0):
    ln_r = math.log(pullup_ohm * raw / (65535 - raw))
    return 1 / (SH[0] + SH[1] * ln_r + SH[2] * ln_r ** 3) - 273.15


def test_thermistor_conversion_beta_and_steinhart_hart(mp):
    beta_points = [0.0, 25.0, 100.0, 150.0, 200.0, 250.0, 285.0]
    sh_raws = [60000, 45000, 32768, 20000, 8000, 2000]
    got = mp.script_json("thermal_thermistor", json.dumps(
        [SH, [beta_raw(t) for t in beta_points], sh_raws]))
    for t, c in zip(beta_points, got["beta"]):
        # One ADC count is at most 0.1 C over this range.
        assert c == pytest.approx(t, abs=0.1), (t, c)
    assert got["beta"][1] == pytest.approx(25.0, abs=0.02)  # R25 is the Beta model's anchor
    for raw, c in zip(sh_raws, got["sh"]):
        assert c == pytest.approx(sh_celsius(raw), abs=1e-6)
    assert got["sh"][2] == pytest.approx(24.7, abs=0.1)  # 10 kOhm at mid-scale: ~25 C
    assert got["open"] == got["open_c"] < -200
    assert got["short"] == got["short_c"] > 1000


def test_sim_thermistor_reads_back_what_the_firmware_converts(mp):
    """The model's inverse curves (Beta and Cardano's for Steinhart-Hart) agree with
    the firmware, so simulated temperatures are what the firmware reports."""
    got = mp.script_json("thermal_sim_thermistor", json.dumps(SH))
    for row in got:
        for want, c in zip((20.0, 60.0, 120.0, 200.0), row):
            assert c == pytest.approx(want, abs=0.5), (want, c)  # ADC noise


def test_pid_anti_windup(mp):
    got = mp.script_json("thermal_pid")
    max_out, min_out, i_saturated, past, low, i_low = got
    assert max_out == min_out == 1.0
    assert i_saturated == 0.0  # no integral growth while saturated
    assert past == 0.0
    assert low == 0.0 and i_low == 0.0


def test_protection_state_machine_times(mp):
    """Each rule fires within its configured time, measured on a heater driven by hand
    every control period (100 ms): readings come from a fake ADC."""
    got = mp.script_json("thermal_protection")
    assert got["ok"][0] is None and got["dip"][0] is None and got["slow"][0] is None
    assert got["open"][:1] == [70000] and "below hotend_min_c" in got["open"][1]
    assert got["short"][:1] == [70000] and "above hotend_max_c" in got["short"][1]
    # Watched from the last 2 C of progress (0.7 s before the stall at 3 C/s).
    assert 30000 + 20000 - 700 <= got["stall"][0] <= 30000 + 20000 + 100
    assert "heating failed" in got["stall"][1]
    assert 70000 + 20000 < got["runaway"][0] <= 70000 + 20000 + 200
    assert "thermal runaway" in got["runaway"][1]
    for case in ("open", "short", "stall", "runaway"):
        assert got[case][2] == 0, case  # the heater is off when the fault is reported


class Printer:
    """The simulated printer with its thermal model, as a host sees it."""

    def __init__(self):
        self.sim = SimPrinter()
        self.report = None

    def send(self, *lines):
        out = []
        for line in lines:
            out = self.sim.send(line)
        return out

    def temps(self):
        m = re.match(r"ok T:(-?[\d.]+) /([\d.]+) B:(-?[\d.]+) /([\d.]+) @:(\d+) B@:(\d+)$",
                     self.send("M105")[-1])
        assert m, "M105 reply not in Marlin's form"
        return [float(v) for v in m.groups()]

    def model(self, heater):
        reply = self.send("M7100 H%d" % heater)[-1]
        return {k: float(v) for k, v in re.findall(r"(\w+):(-?[\d.]+)", reply)}

    def x_mm(self):
        return float(re.match(r"X:(-?[\d.]+)", self.send("M114")[0]).group(1))

    def close(self):
        if self.report is None:
            self.report = self.sim.finish()
        return self.report


@pytest.fixture
def printer():
    """This module's own printer, in place of conftest's: cold extrusion stays refused
    (no M302 P1), as the heaters' tests need."""
    p = Printer()
    yield p
    p.close()


def test_m105_reports_cold_printer_in_marlin_form(printer):
    t, t_target, b, b_target, power, b_power = printer.temps()
    assert t == pytest.approx(AMBIENT_C, abs=0.5) and b == pytest.approx(AMBIENT_C, abs=0.5)
    assert t_target == b_target == power == b_power == 0


def test_m109_waits_reporting_temperatures_then_pid_holds_the_target(printer):
    replies = printer.send("M109 S200")
    reports = [r for r in replies if r.startswith("T:")]
    assert replies[-1] == "ok" and len(reports) == len(replies) - 1
    t = printer.temps()
    assert t[0] >= 199.0 and t[1] == 200.0
    # About 45 s from cold at full power: the temperatures every second meanwhile
    # (they keep the host from timing out, in place of busy lines).
    assert len(reports) >= 30
    samples = []
    for _ in range(30):
        printer.send("G4 S2")
        samples.append(printer.temps()[0])
    assert all(197.0 <= s <= 203.0 for s in samples), samples
    assert abs(samples[-1] - 200.0) <= 0.5
    # The part fan at full is a disturbance the PID rides out.
    printer.send("M106 S255")
    for _ in range(30):
        printer.send("G4 S2")
        samples.append(printer.temps()[0])
    assert all(196.0 <= s <= 203.0 for s in samples[30:]), samples[30:]
    assert printer.model(0)["duty"] > 0.5  # working harder against the fan
    # M922 with no fault leaves a working heater alone.
    printer.send("M922")
    assert printer.temps()[1] == 200.0 and printer.model(0)["duty"] > 0


def test_m190_bed_and_m116_wait_for_every_heater(printer):
    printer.send("M140 S60", "M104 S180")
    assert printer.temps()[3] == 60.0
    assert printer.send("M116")[-1] == "ok"
    t = printer.temps()
    assert t[0] >= 179.0 and t[2] >= 59.0
    assert printer.send("M190 S70")[-1] == "ok"
    assert printer.temps()[2] >= 69.0
    for _ in range(10):
        printer.send("G4 S3")
        assert abs(printer.temps()[2] - 70.0) <= 1.5


def test_m116_waits_for_the_heaters_it_names(printer):
    # A named heater with no target would wait for nothing: an error at once.
    assert printer.send("M116 B") == ["Error:bed has no target to wait for", "ok"]
    assert printer.send("M116 T B") == ["Error:hotend has no target to wait for", "ok"]
    printer.send("M104 S180", "M140 S50")
    assert printer.send("M116 B")[-1] == "ok"
    t = printer.temps()
    assert t[2] >= 49.0 and t[0] < 179.0  # the bed reached, the hot end not waited for
    assert printer.send("M116 T")[-1] == "ok"
    assert printer.temps()[0] >= 179.0


def test_out_of_range_values_are_refused(printer):
    assert printer.send("M104 S300")[0].startswith(
        "Error:temperature S300.0 out of range 0..285.0")
    assert printer.send("M140 S121")[0].startswith("Error:temperature S121.0 out of range")
    assert printer.send("M104 S-5")[0].startswith("Error:temperature")
    assert printer.send("M109")[0] == "Error:missing parameter S"
    assert printer.send("M106 S256")[0].startswith("Error:fan speed")
    assert printer.send("M106 P1 S10")[0].startswith("Error:P1 out of range")
    assert printer.temps()[1] == 0 and printer.temps()[3] == 0  # nothing was set


def test_settings_changes_apply_with_m930(printer):
    printer.send("M926 Ihotend_max_c V250", "M926 Imin_extrude_c V10", "M930")
    assert printer.send("M104 S260")[0] == (
        "Error:temperature S260.0 out of range 0..250.0 (hotend_max_c)")
    assert printer.send("G1 E1 F600") == ["ok"]  # 22 C is above the new minimum


def test_fan_drives_its_pwm(mp):
    got = mp.script_json("thermal_fan")
    assert got[0] == pytest.approx(128 / 255, abs=1e-4)
    assert got[1:] == [1.0, 0.0]


def test_cold_extrusion_is_refused(printer):
    reply = printer.send("G1 E5 F600")
    assert re.match(r"Error:cold extrusion prevented: hot end 2\d\.\dC below min_extrude_c "
                    r"170\.0C$", reply[0]), reply
    assert printer.send("G1 X5 E-1 F600")[-1] == "ok"  # travel and retraction are fine
    assert printer.send("M302")[0] == "echo:Cold extrudes are disabled (min temp 170C)"
    printer.send("M109 S175")
    assert printer.send("G1 E5 F600") == ["ok"]
    # Passed, the guard is not asked again until a control period's readings: which
    # find the hot end cooling.
    printer.send("M104 S0")
    printer.send("G4 S20")
    assert printer.send("G1 E10 F600")[0].startswith("Error:cold extrusion prevented")
    report = printer.close()
    assert report["steps"]["e0"] == 5 * 415


def test_m302_p1_allows_cold_extrusion(printer):
    printer.send("M302 P1")
    assert printer.send("G1 E2 F600") == ["ok"]
    printer.send("M302 P0")
    assert printer.send("G1 E3")[0].startswith("Error:cold extrusion prevented")


def test_the_cold_extrusion_guard_reads_the_sensor_once_a_control_period(mp):
    """Each extruding line is checked, but against a reading at most a control period
    old (as Marlin's guard): a fresh reading, four ADC reads and the thermistor's float
    arithmetic, cost the chip every line. No simulated time passes here, so after the
    first line's reading no other is taken."""
    got = mp.script_json("thermal_cold_guard")
    assert [r[1] for r in got[2:6]] == [4, 4, 4, 4]  # the first extrusion reads: once
    assert [r[2] for r in got[:6]] == ["ok"] * 6
    assert got[7] == ["G1 E0.1", 4, "cold extrusion prevented: "]


# --- fault injection -----------------------------------------------------------

# (name, heater, fault code, how it is caught, expected words in the halt message)
FAULTS = {
    "hotend thermistor open": (0, 1, "temperature", "below hotend_min_c"),
    "hotend thermistor short": (0, 2, "temperature", "above hotend_max_c"),
    "hotend cartridge out while heating": (0, 3, "watch", "heating failed"),
    "hotend cartridge out at target": (0, 3, "runaway", "thermal runaway"),
    "hotend fan stuck at target": (0, 4, "runaway", "thermal runaway"),
    "bed thermistor open": (1, 1, "temperature", "below bed_min_c"),
    "bed thermistor short": (1, 2, "temperature", "above bed_max_c"),
    "bed cartridge out while heating": (1, 3, "watch", "heating failed"),
}
# Several injection moments per fault, spread over the control period and the heating.
PHASES_MS = (0, 1, 37, 99, 2513)


def _inject_and_measure(p, board, heater, code, kind, words, phase_ms):
    name = ("hotend", "bed")[heater]
    s = board["SETTINGS"]
    target = (200, 60)[heater]
    p.send("G90", "G1 X0 F6000", "M400")
    if kind == "watch":
        # Part way up from wherever the last round left it.
        p.send("M%d S%d" % ((104, 140)[heater], target), "G4 P%d" % (3000 + phase_ms))
    else:
        p.send("M%d S%d" % ((109, 190)[heater], target), "G4 P%d" % (2000 + phase_ms))
    # Long moves in the queue: a fault must drop them.
    p.send("G1 X200 F150", "G1 X0")
    assert p.send("M7100 H%d F%d" % (heater, code)) == ["ok"]
    replies = p.send("M400")
    halt = [r for r in replies if r.startswith("Error:%s: " % name)]
    assert len(halt) == 1 and words in halt[0], replies
    assert replies[-2].startswith("Error:command stopped: %s: " % name)
    model = p.model(heater)
    off_ms = model["off_after_ms"]
    assert model["duty"] == 0 and off_ms >= 0
    period_ms = s["thermal_period_ms"]
    if kind == "temperature":
        assert off_ms <= period_ms + 1
    elif kind == "watch":
        assert off_ms <= s[name + "_watch_s"] * 1000 + period_ms + 1
    else:
        # Not before runaway_s, and no later than the fall to runaway_c below plus it.
        runaway_ms = s[name + "_runaway_s"] * 1000
        assert runaway_ms < off_ms <= runaway_ms + 10000
    # Motion stopped: the queued moves were dropped, the printer still answers.
    x = p.x_mm()
    assert 0 <= x < 200
    t = p.temps()
    # Off, and its target cleared (as Marlin's kill): M922 re-arms it cold.
    assert t[4 + heater] == 0 and t[1 + 2 * heater] == 0
    assert p.send("M104 S200")[0].startswith("Error:printer halted (%s: " % name)
    assert p.send("G1 X10")[0].startswith("Error:printer halted")
    # Repair, re-arm, and the heater works again.
    p.send("M7100 H%d F0" % heater)
    assert p.send("M922") == ["ok"]
    p.send("G4 S1")
    assert p.x_mm() == x  # dropped, not paused
    return off_ms


# make test injects each fault once, at one of the moments (a different one per fault);
# make test-all at every moment, repairing and re-arming between them.
@pytest.mark.parametrize("fault,phases_ms", [
    (fault, phases) if len(phases) == 1 else pytest.param(fault, phases, marks=pytest.mark.slow)
    for i, fault in enumerate(FAULTS)
    for phases in ((PHASES_MS[i % len(PHASES_MS)],), PHASES_MS)])
def test_fault_turns_heater_off_and_stops_motion(fault, phases_ms, board):
    heater, code, kind, words = FAULTS[fault]
    p = Printer()
    times = [_inject_and_measure(p, board, heater, code, kind, words, ph) for ph in phases_ms]
    # After the last repair and M922 it heats and holds again.
    target = (200, 60)[heater]
    assert p.send("M%d S%d" % ((109, 190)[heater], target))[-1] == "ok"
    assert p.temps()[2 * heater] >= target - 1
    p.close()
    print("%s: fault to heater off %s ms" % (fault, times))


def test_fault_at_idle_is_found_without_a_target(printer):
    printer.send("M7100 H0 F1")
    replies = printer.send("G4 P300")
    assert replies[0].startswith("Error:hotend: temperature -273.")
    assert "below hotend_min_c 5.0C (thermistor open?)" in replies[0]
    assert printer.model(0)["duty"] == 0
    # A fault that persists is found again right after M922.
    printer.send("M922")
    assert printer.send("G4 P300")[0].startswith("Error:hotend: temperature")
    printer.send("M7100 H0 F0", "M922")
    assert printer.send("G4 P300") == ["ok"]
