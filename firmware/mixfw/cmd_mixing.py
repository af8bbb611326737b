# Mixing commands: M163 (one drive's weight), M164 (store as a virtual tool), T<n>.
from mixfw.gcode import GcodeError
from mixfw.mixer import Tools, normalize


class Mixing:
    def __init__(self, planner, settings):
        self.planner = planner
        self.drives = settings["drives"]
        self.tools = Tools(self.drives, settings["virtual_tools"])
        self.collector = [0.0] * self.drives  # weights set by M163, stored by M164
        self.active = 0
        self.mix_id = 1
        planner.set_mix(self.mix_id, self.tools.mixes[0])

    def _activate(self, tool):
        self.active = tool
        self.mix_id += 1
        self.planner.set_mix(self.mix_id, self.tools.mixes[tool])

    # M163 S<drive> P<weight>: set one drive's weight in the mix being built.
    # Weights are any non-negative numbers; M164 normalises them. Example: M163 S0 P0.2
    def m163(self, line):
        line.require("S")
        line.require("P")
        drive = line.int("S", lo=0, hi=self.drives - 1)
        weight = line.float("P")
        if weight < 0:
            raise GcodeError("weight P must be >= 0, got %s" % weight)
        self.collector[drive] = weight

    # M164 [S<tool>]: store the M163 weights as a virtual tool, by default the active
    # one, which then prints with it. An all-zero mix is refused. Example: M164 S4
    def m164(self, line):
        tool = self.tools.check(line.int("S", self.active))
        self.tools.mixes[tool] = normalize(self.collector, self.drives)
        if tool == self.active:
            self._activate(tool)

    # T<n>: select virtual tool n. Example: T2
    def t(self, line):
        tool = line.number
        if not 0 <= tool < self.tools.count:
            raise GcodeError("tool T%d out of range T0..T%d" % (tool, self.tools.count - 1))
        if tool != self.active:
            self._activate(tool)


def register(printer, mixing):
    printer.register("M163", mixing.m163, "set a drive's weight: S<drive> P<weight>")
    printer.register("M164", mixing.m164, "store the weights as virtual tool S<tool>")
    printer.register("T", mixing.t, "select virtual tool")
