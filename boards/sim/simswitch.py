# The printer's switches, set by sim-only commands:
#   M7105 S<us>  every min endstop bounces for S us after the step that reaches it and
#                after the one that leaves it: its level flips six times at irregular
#                points before it settles, as a mechanical switch's contacts do
#                (simmachine.set_bounce). S0, the default: clean edges.
#   M7107 D<drive> S<1|0>  drive D's filament runout input (the board's e<D>_runout)
#                reads the filament gone (S1) or present (S0), at the level
#                runout_active_high says. Every input starts present.
import board
import simmachine
from mixfw.gcode import GcodeError


# M7105 S<us>: bounce the endstops for S us (S0: no bounce). Simulation only.
# Example: M7105 S5000
def m7105(line):
    line.require("S")
    simmachine.set_bounce(line.int("S", lo=0, hi=1000000))


class Runout:
    def __init__(self, settings):
        self.settings = settings
        for key, gpio in board.PINS.items():
            if key.endswith("_runout"):
                self.set(gpio, False)

    def set(self, gpio, gone):
        simmachine.set_input(gpio, gone == bool(self.settings["runout_active_high"]))

    # M7107 D<drive> S<1|0>: drive D's runout input reads its filament gone (S1) or
    # present (S0). Simulation only. Example: M7107 D1 S1
    def m7107(self, line):
        line.require("D")
        line.require("S")
        drive = line.int("D", lo=0, hi=self.settings["drives"] - 1)
        gone = line.int("S", lo=0, hi=1)
        gpio = board.PINS.get("e%d_runout" % drive)
        if gpio is None:
            raise GcodeError("drive %d has no runout input (no e%d_runout in %s's PINS)"
                             % (drive, drive, board.NAME))
        self.set(gpio, gone)


def install(printer):
    printer.register("M7105", m7105)  # simulation: endstops bounce for S<us>
    # simulation: a runout input reads D<drive>'s filament gone S1 or present S0
    printer.register("M7107", Runout(printer.settings).m7107)
