# The simulated bed under a bed probe, and the probe, set by a sim-only command:
#   M7108 [Z<mm>] [I<mm/mm>] [J<mm/mm>] [H<mm>] [X<mm>] [Y<mm>] [R<mm>]
#         [U<mm>] [V<mm>] [W<mm>]
# The bed's height at machine X Y (mm) is a tilted plane with a smooth bump on it,
#   Z + I x + J y + H exp(-((x - X)^2 + (y - Y)^2) / R^2),
# so tests know the truth a probe should measure. U V W: where the probe really is
# from the nozzle (its trigger point W above the nozzle's tip is -W, as M851 Z says):
# the firmware's probe_offset_mm is what it has been told, this is what is so.
# The probe input (the board's z_probe) reads triggered (high) while the nozzle's Z
# plus W is at or below the bed at the probe's X Y; a board with a probe_servo (a
# BLTouch) must have deployed it first: a 50 Hz pulse under 1 ms deploys it (Marlin's
# 10 degrees, 647 us), a longer one stows it. M7108 with no words reports the model.
# Defaults: a flat bed at Z 0, the probe where the firmware's defaults put it.
from math import exp, floor

import simanalog
import simmachine
from mixfw.gcode import GcodeError

_SERVO_PERIOD_US = 20000
_DEPLOYED_BELOW_US = 1000


class Bed:
    def __init__(self, printer, pins):
        self.printer = printer
        self.servo = pins.get("probe_servo")
        # Z I J H X Y R U V W
        self.words = {"Z": 0.0, "I": 0.0, "J": 0.0, "H": 0.0, "X": 0.0, "Y": 0.0,
                      "R": 1.0, "U": 10.0, "V": 10.0, "W": 0.0}
        self._at = None  # (x steps, y steps) the threshold below was worked out for
        self._below_steps = 0  # the nozzle's Z steps at or below which it triggers

    def height_mm(self, x_mm, y_mm):
        w = self.words
        d2 = (x_mm - w["X"]) ** 2 + (y_mm - w["Y"]) ** 2
        return (w["Z"] + w["I"] * x_mm + w["J"] * y_mm
                + w["H"] * exp(-d2 / (w["R"] * w["R"])))

    def deployed(self):
        if self.servo is None:
            return True
        pulse_us = simanalog.duty_of(self.servo) * _SERVO_PERIOD_US
        return 0 < pulse_us < _DEPLOYED_BELOW_US

    def level(self):
        """The probe input: the threshold is worked out again only when X or Y moved,
        so a dive (Z alone) reads it in small ints."""
        if not self.deployed():
            return 0
        pos = simmachine.positions
        at = (pos[0], pos[1])
        if at != self._at:
            spm = self.printer.settings["steps_per_mm"]
            w = self.words
            x = pos[0] / spm[0] + w["U"]
            y = pos[1] / spm[1] + w["V"]
            self._below_steps = floor((self.height_mm(x, y) - w["W"]) * spm[2])
            self._at = at
        return 1 if pos[2] <= self._below_steps else 0

    # M7108 [Z I J H X Y R U V W]: the bed's surface and the probe's true offset;
    # without words, report them. Simulation only. Example: M7108 Z0.2 I0.001 H0.15
    # X120 Y100 R60
    def m7108(self, line):
        changed = False
        for letter in self.words:
            if line.has(letter):
                v = line.float(letter)
                if letter == "R" and not v > 0:
                    raise GcodeError("M7108 R (the bump's radius) must be > 0")
                self.words[letter] = v
                changed = True
        self._at = None
        if not changed:
            self.printer.reply("//simbed " + " ".join(
                "%s%g" % (k, v) for k, v in sorted(self.words.items())))


def install(printer, board):
    if "z_probe" not in board.PINS:
        return None
    bed = Bed(printer, board.PINS)
    simmachine.model_input(board.PINS["z_probe"], bed.level)
    printer.register("M7108", bed.m7108)  # simulation: the bed's surface, the probe
    return bed
