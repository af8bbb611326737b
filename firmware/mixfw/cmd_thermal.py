# Temperature and fan commands. There are no heaters yet: targets are kept and
# reported as reached, so hosts and slicer start G-code run unchanged.
from mixfw.gcode import GcodeError


class Thermal:
    def __init__(self, settings):
        self.max_hotend_c = settings["max_hotend_c"]
        self.max_bed_c = settings["max_bed_c"]
        self.hotend_c = 0.0
        self.bed_c = 0.0
        self.fan = 0

    def _temp(self, line, limit):
        line.require("S")
        t = line.float("S")
        if not 0 <= t <= limit:
            raise GcodeError("temperature S%s out of range 0..%s" % (t, limit))
        return t

    # M104/M109 S<celsius>: hot end target (M109 also waits). Example: M104 S200
    def m104(self, line):
        self.hotend_c = self._temp(line, self.max_hotend_c)

    # M140/M190 S<celsius>: bed target (M190 also waits). Example: M140 S60
    def m140(self, line):
        self.bed_c = self._temp(line, self.max_bed_c)

    # M105: report temperatures in Marlin's form.
    def m105(self, line):
        return "T:%.1f /%.1f B:%.1f /%.1f @:0 B@:0" % (
            self.hotend_c, self.hotend_c, self.bed_c, self.bed_c)

    # M106 [S<0-255>]: fan speed. M107: fan off.
    def m106(self, line):
        s = line.float("S", 255.0)
        if not 0 <= s <= 255:
            raise GcodeError("fan speed S%s out of range 0..255" % s)
        self.fan = int(s + 0.5)

    def m107(self, line):
        self.fan = 0


def register(printer, thermal):
    printer.register("M104", thermal.m104, "set hot end temperature")
    printer.register("M109", thermal.m104, "set hot end temperature and wait")
    printer.register("M140", thermal.m140, "set bed temperature")
    printer.register("M190", thermal.m140, "set bed temperature and wait")
    printer.register("M105", thermal.m105, "report temperatures")
    printer.register("M106", thermal.m106, "fan on S<0-255>")
    printer.register("M107", thermal.m107, "fan off")
