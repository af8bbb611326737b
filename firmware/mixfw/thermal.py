# Heaters and the part fan: thermistor conversion, PID control and thermal protection.
#
# Runs from the main loop as a background task (never on the step interrupt path): every
# thermal_period_ms each heater reads its thermistor, checks its protection state, then
# sets its PWM duty. A fault turns that heater off first and halts the printer second,
# which stops motion and every other heater.
#
# Pure logic: imports on CPython too. The machine objects (ADC, PWM, Pin) are passed in.
import math
import time
from mixfw.gcode import GcodeError
from mixfw.pwm import heater_output

_HEATER_NAMES = const(("hotend", "bed"))

# Protection states of one heater.
_OFF = const(0)  # no target: only the safe-range check runs
_HEATING = const(1)  # more than runaway_c below the target: the watch checks the rise
_HOLDING = const(2)  # near or at the target: the runaway check runs

# "Reached" for M109/M190/M116: within this of the target, as Marlin's TEMP_WINDOW.
# A PID settles from below, so waiting for the exact target could last forever.
REACHED_C = 1.0
_ADC_FULL = const(65535)
_ADC_SAMPLES = const(4)  # averaged per control period against ADC noise
_KELVIN = 273.15
_T25_K = 298.15
# What a dead sensor reads: open is colder than anything real, short hotter.
OPEN_C = -273.15
SHORT_C = 2000.0
_DERIV_SMOOTHING = 0.3  # weight of a new derivative sample; tames ADC noise


class Thermistor:
    """An NTC thermistor from the ADC input to ground, pulled up to the ADC reference."""

    def __init__(self, pullup_ohm, r25_ohm, beta, sh_a=0.0, sh_b=0.0, sh_c=0.0):
        self.pullup_ohm = pullup_ohm
        self.r25_ohm = r25_ohm
        self.beta = beta
        self.sh = (sh_a, sh_b, sh_c) if (sh_a or sh_b or sh_c) else None

    def resistance_ohm(self, raw_u16):
        """Thermistor resistance from a read_u16() value of 1..65534."""
        return self.pullup_ohm * raw_u16 / (_ADC_FULL - raw_u16)

    def celsius(self, raw_u16):
        if raw_u16 >= _ADC_FULL:
            return OPEN_C
        if raw_u16 <= 0:
            return SHORT_C
        ln_r = math.log(self.resistance_ohm(raw_u16))
        if self.sh:
            a, b, c = self.sh
            inv_k = a + b * ln_r + c * ln_r * ln_r * ln_r
        else:
            inv_k = 1.0 / _T25_K + (ln_r - math.log(self.r25_ohm)) / self.beta
        if inv_k <= 0.0:  # beyond the curve's range on the hot side
            return SHORT_C
        return 1.0 / inv_k - _KELVIN


class Pid:
    """PID on a duty of 0..1. kp in duty/C, ki in duty/(C·s), kd in duty·s/C.

    Anti-windup: the integral term is held to 0..1 and does not grow while the output
    is saturated in the direction the error pushes, so after a long heat-up at full
    power there is no stored surplus to overshoot with. The derivative acts on the
    measurement, not the error, so a new target gives no kick."""

    def __init__(self):
        self.kp = self.ki = self.kd = 0.0
        self.reset(0.0)

    def reset(self, temp_c):
        self.i_term = 0.0
        self.last_c = temp_c
        self.d_c_s = 0.0

    def update(self, target_c, temp_c, dt_s):
        error = target_c - temp_c
        if dt_s > 0:
            rate = (temp_c - self.last_c) / dt_s
            self.d_c_s += _DERIV_SMOOTHING * (rate - self.d_c_s)
        self.last_c = temp_c
        p = self.kp * error - self.kd * self.d_c_s
        i = self.i_term + self.ki * error * dt_s
        i = 0.0 if i < 0.0 else 1.0 if i > 1.0 else i
        out = p + i
        if out > 1.0:
            out = 1.0
            if error > 0:
                i = min(i, self.i_term)
        elif out < 0.0:
            out = 0.0
            if error < 0:
                i = max(i, self.i_term)
        self.i_term = i
        return out


def _setting(settings, key, lo, hi=None):
    v = settings[key]
    if v < lo or (hi is not None and v > hi):
        raise ValueError("%s = %s is outside %s..%s" % (key, v, lo, "" if hi is None else hi))
    return v


class Heater:
    """One heater with its thermistor, PID and protection state."""

    def __init__(self, name, adc, pwm):
        self.name = name
        self.adc = adc
        self.pwm = pwm
        self.pid = Pid()
        self.thermistor = None
        self.target_c = 0.0
        self.temp_c = 0.0
        self.read_ms = None  # when temp_c was read (None: not since start-up)
        self.duty = 0.0
        self.duty_u16 = 0
        self.state = _OFF
        self.fault = None  # reason, until M922 re-arms
        self.watch_ms = 0  # watch period start (_HEATING)
        self.watch_c = 0.0  # temperature then
        self.below_ms = None  # since when too far below the target (_HOLDING)

    def configure(self, settings):
        n = self.name
        self.thermistor = Thermistor(
            _setting(settings, n + "_pullup_ohm", 1), _setting(settings, n + "_r25_ohm", 1),
            _setting(settings, n + "_beta", 1), settings[n + "_sh_a"],
            settings[n + "_sh_b"], settings[n + "_sh_c"])
        pid = self.pid
        pid.kp = _setting(settings, n + "_kp", 0)
        pid.ki = _setting(settings, n + "_ki", 0)
        pid.kd = _setting(settings, n + "_kd", 0)
        self.min_c = settings[n + "_min_c"]
        self.max_c = _setting(settings, n + "_max_c", self.min_c)
        self.watch_period_ms = int(_setting(settings, n + "_watch_s", 1) * 1000)
        self.watch_rise_c = _setting(settings, n + "_watch_rise_c", 0)
        self.runaway_c = _setting(settings, n + "_runaway_c", REACHED_C)
        self.runaway_ms = int(_setting(settings, n + "_runaway_s", 0) * 1000)
        # *_pwm_hz takes a restart: the output was made for its frequency (heater_output).

    def read_c(self):
        raw = 0
        for _ in range(_ADC_SAMPLES):
            raw += self.adc.read_u16()
        self.temp_c = self.thermistor.celsius(raw // _ADC_SAMPLES)
        self.read_ms = time.ticks_ms()
        return self.temp_c

    def output(self, duty):
        self.duty = duty
        d = int(duty * 65535 + 0.5)
        if d != self.duty_u16:
            self.duty_u16 = d
            self.pwm.duty_u16(d)

    def off(self):
        self.target_c = 0.0
        self.state = _OFF
        self.duty_u16 = -1  # written whatever it says: a write that raised left it wrong
        self.output(0.0)

    def set_target(self, target_c, now_ms):
        self.target_c = target_c
        if target_c <= 0:
            self.off()
            return
        self.read_c()  # the last control period may be long ago, in a lockstep simulation
        if self.state == _OFF:
            self.pid.reset(self.temp_c)
        self._arm(now_ms)

    def _arm(self, now_ms):
        self.below_ms = None
        if self.temp_c < self.target_c - self.runaway_c:
            self.state = _HEATING
            self.watch_ms = now_ms
            self.watch_c = self.temp_c
        else:
            self.state = _HOLDING

    def reached(self):
        return self.target_c <= 0 or self.temp_c >= self.target_c - REACHED_C

    def check(self, now_ms):
        """The protection state machine: a fault reason, or None."""
        t = self.temp_c
        if t < self.min_c:
            return "temperature %.1fC below %s_min_c %.1fC (thermistor open?)" % (
                t, self.name, self.min_c)
        if t > self.max_c:
            return "temperature %.1fC above %s_max_c %.1fC (thermistor short?)" % (
                t, self.name, self.max_c)
        target = self.target_c
        if self.state == _HEATING:
            # The watch covers the climb to runaway_c below the target, the runaway
            # check the rest: a PID that creeps up the last degrees is not a fault.
            if t >= target - self.runaway_c:
                self.state = _HOLDING
                self.below_ms = None
                return None
            # Re-armed at every step of progress, so a heater that stops heating is
            # caught at most one watch period after its last progress.
            if t >= self.watch_c + self.watch_rise_c:
                self.watch_ms = now_ms
                self.watch_c = t
            elif time.ticks_diff(now_ms, self.watch_ms) >= self.watch_period_ms:
                return "heating failed: rose %.1fC in %d s, needs %s_watch_rise_c %.1fC" % (
                    t - self.watch_c, self.watch_period_ms // 1000, self.name,
                    self.watch_rise_c)
        elif self.state == _HOLDING:
            if t < target - self.runaway_c:
                if self.below_ms is None:
                    self.below_ms = now_ms
                elif time.ticks_diff(now_ms, self.below_ms) > self.runaway_ms:
                    return "thermal runaway: %.1fC, more than %s_runaway_c %.1fC below " \
                        "target %.1fC for over %s_runaway_s %d s" % (
                            t, self.name, self.runaway_c, target, self.name,
                            self.runaway_ms // 1000)
            else:
                self.below_ms = None
        return None

    def control(self, now_ms, dt_s):
        """One control period. Returns a fault reason (heater already off) or None."""
        if self.fault:
            self.output(0.0)
            return None
        self.read_c()
        reason = self.check(now_ms)
        if reason:
            self.off()
            self.fault = reason
            return reason
        if self.state == _OFF:
            self.output(0.0)
        else:
            self.output(self.pid.update(self.target_c, self.temp_c, dt_s))
        return None


class Thermal:
    """Every heater and the part fan of the board. Built by assemble.py."""

    def __init__(self, machine, pin_map, settings, printer):
        self.printer = printer
        self.heaters = []
        self.hotend = self.bed = None
        chip = settings.get("chip", "sim")
        for name in _HEATER_NAMES:
            if name + "_heater" not in pin_map or name + "_thermistor" not in pin_map:
                continue  # the bed is optional
            adc = machine.ADC(machine.Pin(pin_map[name + "_thermistor"]))
            pwm = heater_output(machine, chip, pin_map[name + "_heater"],
                                int(settings[name + "_pwm_hz"]), printer.add_background)
            heater = Heater(name, adc, pwm)
            self.heaters.append(heater)
            setattr(self, name, heater)
        self.fan = None
        self.fan_duty = 0.0
        if "part_fan" in pin_map:
            self.fan = machine.PWM(machine.Pin(pin_map["part_fan"]),
                                   freq=int(settings["fan_pwm_hz"]), duty_u16=0)
        # Called where the extrusion guard's verdict may change: a control period's
        # readings, the settings (the guard is not called every line: cmd_motion).
        self.on_change = []
        self.apply(settings)
        now = time.ticks_ms()
        for h in self.heaters:
            h.read_c()
            h.pid.reset(h.temp_c)
            h.read_ms = None  # for the PID's start only: the guard reads anew
        self.last_ms = now
        self.next_ms = now
        # At every turn: the control held up to 10 ms past its period (the rest of the
        # background's pace) let a 1 Hz software-PWM bed settle a degree low.
        printer.add_background(self.background, True)
        # One hook per heater: a heater whose PWM write raises leaves no other one on.
        for h in self.heaters:
            printer.heaters_off.append(h.off)

    def apply(self, settings):
        """Re-read every thermal setting (after M930, M502...)."""
        for h in self.heaters:
            h.configure(settings)
        self.period_ms = int(_setting(settings, "thermal_period_ms", 1, 10000))
        self.min_extrude_c = settings["min_extrude_c"]
        for fn in self.on_change:
            fn()

    def background(self, now_ms):
        # Runs at every turn of the main loop and of every wait: the control period's
        # work is a method of its own, as a bytecode function whose locals and stack
        # pass 11 words takes its frame from the heap at every call (printer.answer).
        if time.ticks_diff(now_ms, self.next_ms) >= 0:
            self.control(now_ms)

    def control(self, now_ms):
        """A control period: every heater's PID, and its checks."""
        dt_s = time.ticks_diff(now_ms, self.last_ms) / 1000.0
        self.last_ms = now_ms
        self.next_ms = time.ticks_add(now_ms, self.period_ms)
        for h in self.heaters:
            reason = h.control(now_ms, dt_s)
            if reason:
                self.printer.halt("%s: %s" % (h.name, reason))
        for fn in self.on_change:
            fn()

    def refresh(self):
        """Read every sensor now, for reports between control periods."""
        for h in self.heaters:
            h.read_c()

    def set_target(self, heater, target_c):
        heater.set_target(target_c, time.ticks_ms())

    def rearm(self):
        """M922: forget heater faults. A fault that persists is found again at once.
        Faulted heaters stay off until given a target; the others carry on."""
        for h in self.heaters:
            if h.fault:
                h.fault = None
                h.off()

    def set_fan(self, fraction):
        self.fan_duty = fraction
        if self.fan is not None:
            self.fan.duty_u16(int(fraction * 65535 + 0.5))

    def check_extrusion(self):
        """An extrusion guard: refuses E moves while the hot end is too cold. It reads
        the sensor only where the last reading is a control period old: Marlin's guard
        reads its temperature interrupt's too, and a reading would take every line four
        ADC reads and the thermistor's float arithmetic."""
        h = self.hotend
        if h is None:
            return
        if h.read_ms is None or time.ticks_diff(time.ticks_ms(), h.read_ms) >= self.period_ms:
            h.read_c()
        if h.temp_c < self.min_extrude_c:
            raise GcodeError("cold extrusion prevented: hot end %.1fC below min_extrude_c "
                             "%.1fC" % (h.temp_c, self.min_extrude_c))
