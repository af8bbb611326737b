# The simulated printer's hot end and bed: a first-order thermal model of each, read
# by the firmware through the simulated ADC and driven through the simulated PWM.
#
# Each is one lumped mass: heater power x PWM duty in, loss to ambient out, and for the
# hot end extra loss while the part fan blows on it. Euler steps in virtual time, once
# per idle quantum of the simulated chip.
#
# Faults, injected by tests through the console with the simulation-only command
#   M7100 H<0 hot end | 1 bed> F<code>     (M7100 H<n> without F reports the model)
#   F0  no fault: the sensor and heater work again
#   F1  thermistor open: the input is pulled up to full scale (reads very cold)
#   F2  thermistor short: the input reads 0 (very hot)
#   F3  heater cartridge fallen out: its power no longer reaches the block and its
#       thermistor, which cool to ambient
#   F4  part fan stuck at full speed, its duct knocked onto the heater block (hot end
#       only): it takes more heat than the heater can give, so the hot end falls away
#       from its target while the heater runs flat out
# The report line gives the body's temperature, the heater duty, the fault and, once
# the firmware has turned the heater off after a fault, how long that took.
import math
from mixfw.gcode import GcodeError
import simanalog

AMBIENT_C = 22.0
_KELVIN = 273.15
_MAX_STEP_S = 0.01  # longer quanta are split so the Euler steps stay stable

FAULT_NONE = 0
FAULT_OPEN = 1
FAULT_SHORT = 2
FAULT_CARTRIDGE_OUT = 3
FAULT_FAN_STUCK = 4
FAULT_NAMES = ("none", "thermistor open", "thermistor short", "cartridge out", "fan stuck")

# Stuck fan blowing on the block: 0.4 W/K takes 71 W at 200 C, beyond a 40 W heater.
_STUCK_FAN_W_K = 0.4


class Body:
    """One heated mass with its heater, thermistor and pull-up as built."""

    def __init__(self, name, heater_gpio, thermistor_gpio, settings, capacity_j_k,
                 heater_w, loss_w_k, fan_loss_w_k=0.0):
        self.name = name
        self.heater_gpio = heater_gpio
        self.capacity_j_k = capacity_j_k
        self.heater_w = heater_w
        self.loss_w_k = loss_w_k
        self.fan_loss_w_k = fan_loss_w_k
        self.temp_c = AMBIENT_C
        self.fault = FAULT_NONE
        self.fault_at_us = 0
        self.pullup_ohm = settings[name + "_pullup_ohm"]
        self.r25_ohm = settings[name + "_r25_ohm"]
        self.beta = settings[name + "_beta"]
        sh = (settings[name + "_sh_a"], settings[name + "_sh_b"], settings[name + "_sh_c"])
        self.sh = sh if sh[0] or sh[1] or sh[2] else None
        self._noise = 12345

    def step(self, dt_s, fan_duty):
        heater = simanalog.duty_of(self.heater_gpio) * self.heater_w
        if self.fault == FAULT_CARTRIDGE_OUT:
            heater = 0.0
        fan_w_k = self.fan_loss_w_k * fan_duty
        if self.fault == FAULT_FAN_STUCK:
            fan_w_k = _STUCK_FAN_W_K
        loss = (self.loss_w_k + fan_w_k) * (self.temp_c - AMBIENT_C)
        self.temp_c += dt_s * (heater - loss) / self.capacity_j_k

    def resistance_ohm(self, temp_c):
        """The thermistor's resistance: inverse of the Beta or Steinhart-Hart curve."""
        inv_k = 1.0 / (temp_c + _KELVIN)
        if self.sh is None:
            return self.r25_ohm * math.exp(self.beta * (inv_k - 1.0 / 298.15))
        a, b, c = self.sh
        # Solve c*x^3 + b*x + (a - 1/T) = 0 for x = ln R (Cardano: one real root).
        y = (a - inv_k) / (2.0 * c)
        z = ((b / (3.0 * c)) ** 3 + y * y) ** 0.5
        return math.exp(_cbrt(z - y) - _cbrt(z + y))

    def read_u16(self):
        if self.fault == FAULT_OPEN:
            return 65535
        if self.fault == FAULT_SHORT:
            return 0
        r = self.resistance_ohm(self.temp_c)
        # A few counts of deterministic noise, as a real ADC has.
        self._noise = (self._noise * 1103515245 + 12345) & 0x3FFFFFFF
        return int(65535 * r / (r + self.pullup_ohm) + 0.5) + (self._noise >> 20) % 7 - 3

    def report(self, now_us):
        pwm = simanalog.pwm_of(self.heater_gpio)
        duty = simanalog.duty_of(self.heater_gpio)
        off_after_ms = -1
        if self.fault and pwm is not None and duty == 0:
            off_after_ms = max(0, pwm.off_since_us - self.fault_at_us) // 1000
        return "%s temp:%.2f duty:%.3f fault:%d since_ms:%d off_after_ms:%d" % (
            self.name, self.temp_c, duty, self.fault,
            (now_us - self.fault_at_us) // 1000 if self.fault else -1, off_after_ms)


def _cbrt(x):
    return x ** (1.0 / 3.0) if x >= 0 else -((-x) ** (1.0 / 3.0))


class World:
    def __init__(self, simmachine, pins, settings):
        self.simmachine = simmachine
        self.bodies = []
        # A 40 W cartridge in a small block: about 45 s from cold to 200 C flat out.
        self.bodies.append(Body("hotend", pins["hotend_heater"], pins["hotend_thermistor"],
                                settings, 10.0, 40.0, 0.08, fan_loss_w_k=0.06))
        if "bed_heater" in pins:
            # A 150 W bed: about 40 s to 60 C, 147 C at most.
            self.bodies.append(Body("bed", pins["bed_heater"], pins["bed_thermistor"],
                                    settings, 120.0, 150.0, 1.2))
        for b, name in zip(self.bodies, ("hotend", "bed")):
            simanalog.set_source(pins[name + "_thermistor"], b.read_u16)
        self.fan_gpio = pins.get("part_fan", -1)
        self.last_us = simmachine.now_us

    def advance(self, now_us):
        dt_s = (now_us - self.last_us) / 1000000
        self.last_us = now_us
        fan = simanalog.duty_of(self.fan_gpio) if self.fan_gpio >= 0 else 0.0
        while dt_s > 0:
            h = dt_s if dt_s < _MAX_STEP_S else _MAX_STEP_S
            for b in self.bodies:
                b.step(h, fan)
            dt_s -= h

    def inject(self, index, fault):
        b = self.bodies[index]
        b.fault = fault
        b.fault_at_us = self.simmachine.now_us

    # M7100 H<0|1> [F<code>]: inject a fault into the hot end (H0) or bed (H1), or with
    # no F report the model. Simulation only. Example: M7100 H0 F3
    def m7100(self, line):
        index = line.int("H", 0, lo=0, hi=len(self.bodies) - 1)
        if not line.has("F"):
            return self.bodies[index].report(self.simmachine.now_us)
        fault = line.int("F", lo=0, hi=len(FAULT_NAMES) - 1)
        if fault == FAULT_FAN_STUCK and index != 0:
            raise GcodeError("F4 (fan stuck) applies to the hot end H0 only")
        self.inject(index, fault)
        return None


world = None


def install(simmachine, board, printer=None):
    """Wire the thermal model to the simulated chip, and M7100 to the printer."""
    global world
    world = World(simmachine, board.PINS, board.SETTINGS)
    simmachine.add_world_hook(world.advance)
    if printer is not None:
        # simulation: inject a thermal fault H<n> F<code>
        printer.register("M7100", world.m7100)
    return world
