# Temperature and fan commands: M104/M109, M140/M190, M116, M105, M155, M106/M107,
# M302, M922. Handlers parse and check; mixfw.thermal does the heating and the
# protection.
import time
from mixfw.gcode import GcodeError
from mixfw.thermal import REACHED_C


class ThermalCommands:
    def __init__(self, printer, thermal):
        self.printer = printer
        self.thermal = thermal
        self.cold_extrusion_allowed = False
        self.autoreport_ms = 0  # M155: temperatures every so often, 0 for never
        self._autoreport_to = None  # the host that asked
        self._autoreport_at_ms = 0

    def _heater(self, name):
        h = getattr(self.thermal, name)
        if h is None:
            raise GcodeError("this board has no %s heater" % name)
        return h

    def _target(self, line, heater):
        letter = "R" if line.has("R") and not line.has("S") else "S"
        line.require(letter)
        t = line.float(letter)
        if not 0 <= t <= heater.max_c:
            raise GcodeError("temperature %s%s out of range 0..%s (%s_max_c)"
                             % (letter, t, heater.max_c, heater.name))
        self.thermal.set_target(heater, t)
        return letter

    def _wait(self, heater, both_ways):
        """Wait for a heater to come within REACHED_C of its target: from below only
        (S), or from either side (R, cooling too)."""
        if both_ways:
            done = lambda: heater.fault or abs(heater.temp_c - heater.target_c) <= REACHED_C
        else:
            done = lambda: heater.fault or heater.reached()
        self._wait_reporting(done)

    def _wait_reporting(self, done):
        """A heating wait: temperatures go to the host every second (the graph moves),
        and M108 ends it."""
        self.printer.wait_until(done, breakable=True, report=self.temperatures)

    def temperatures(self):
        """Marlin's temperature report: T:210.0 /210.0 B:60.0 /60.0 @:45 B@:30"""
        self.thermal.refresh()
        text = ""
        for h, label in ((self.thermal.hotend, "T"), (self.thermal.bed, "B")):
            if h is not None:
                text += "%s:%.1f /%.1f " % (label, h.temp_c, h.target_c)
        for h, label in ((self.thermal.hotend, "@"), (self.thermal.bed, "B@")):
            if h is not None:
                text += "%s:%d " % (label, int(h.duty * 127 + 0.5))
        return text.rstrip()

    def autoreport(self, now_ms):
        """M155's reports, from the main loop and every wait."""
        if self.autoreport_ms and time.ticks_diff(now_ms, self._autoreport_at_ms) >= 0:
            self._autoreport_at_ms = time.ticks_add(now_ms, self.autoreport_ms)
            ch = self._autoreport_to
            if ch is None:  # asked by a file being printed
                self.printer.broadcast(self.temperatures())
            elif ch.open:
                ch.write(self.temperatures() + "\n")

    # M104 S<celsius>: hot end target, no wait. Example: M104 S210
    def m104(self, line):
        self._target(line, self._heater("hotend"))

    # M109 S<celsius> | R<celsius>: hot end target, then wait until it is reached
    # (S: while heating only; R: cooling too). Example: M109 S210
    def m109(self, line):
        h = self._heater("hotend")
        self._wait(h, self._target(line, h) == "R")

    # M140 S<celsius>: bed target, no wait. Example: M140 S60
    def m140(self, line):
        self._target(line, self._heater("bed"))

    # M190 S<celsius> | R<celsius>: bed target, then wait as M109. Example: M190 S60
    def m190(self, line):
        h = self._heater("bed")
        self._wait(h, self._target(line, h) == "R")

    # M116 [T] [B]: wait until the heaters named (T the hot end, B the bed; with
    # neither, every heater with a target) reach their targets. A named heater with no
    # target is an error, as APrinter's: the wait would be for nothing. Example: M116 B
    def m116(self, line):
        heaters = self.thermal.heaters
        if line.has("T") or line.has("B"):
            heaters = [self._heater(name) for letter, name in (("T", "hotend"), ("B", "bed"))
                       if line.has(letter)]
            for h in heaters:
                if h.target_c <= 0:
                    raise GcodeError("%s has no target to wait for" % h.name)
        self._wait_reporting(lambda: all(h.fault or h.reached() for h in heaters))

    # M105: temperatures in Marlin's form, heater power as 0..127.
    # Example reply: ok T:210.0 /210.0 B:60.0 /60.0 @:45 B@:30
    def m105(self, line):
        return self.temperatures()

    # M155 S<seconds>: send the temperatures to this host every S seconds (0: stop),
    # as Marlin's AUTO_REPORT_TEMPERATURES. Example: M155 S1
    def m155(self, line):
        line.require("S")
        self.autoreport_ms = line.int("S", lo=0, hi=60) * 1000
        self._autoreport_to = self.printer.current
        self._autoreport_at_ms = time.ticks_ms()

    # M106 [P0] [S<0-255>]: part fan speed, full without S. Example: M106 S128
    # A board without a part fan (PINS has no part_fan) refuses it, so a print that
    # counts on cooling hears so; M107 (off) is then simply true.
    def m106(self, line):
        if self.thermal.fan is None:
            raise GcodeError("this board has no part fan")
        line.int("P", 0, lo=0, hi=0)
        s = line.float("S", 255.0)
        if not 0 <= s <= 255:
            raise GcodeError("fan speed S%s out of range 0..255" % s)
        self.thermal.set_fan(s / 255.0)

    # M107: part fan off.
    def m107(self, line):
        self.thermal.set_fan(0.0)

    # M302 [P<0|1>] [S<celsius>]: allow (P1) or refuse (P0) cold extrusion, or set the
    # minimum temperature; alone, report. Example: M302 P1
    def m302(self, line):
        if line.has("S"):
            s = line.float("S")
            if s < 0:
                raise GcodeError("min_extrude_c S%s must be >= 0" % s)
            self.thermal.min_extrude_c = s
        if line.has("P"):
            self.cold_extrusion_allowed = line.int("P", lo=0, hi=1) == 1
        for fn in self.thermal.on_change:
            fn()
        if not line.has("S") and not line.has("P"):
            self.printer.reply("echo:Cold extrudes are %s (min temp %.0fC)" % (
                "enabled" if self.cold_extrusion_allowed else "disabled",
                self.thermal.min_extrude_c))

    # M922: re-arm the heaters after a thermal fault and clear the halt. Targets stay
    # 0 until set again. Example: M922
    def m922(self, line):
        self.thermal.rearm()
        self.printer.clear_halt()

    def check_extrusion(self):
        if not self.cold_extrusion_allowed:
            self.thermal.check_extrusion()


def register(printer, thermal, motion):
    c = ThermalCommands(printer, thermal)
    for letter, number, fn, guarded in (
        ("M", 104, c.m104, True),  # set hot end temperature S<C>
        ("M", 109, c.m109, True),  # set hot end temperature S<C> and wait
        ("M", 140, c.m140, True),  # set bed temperature S<C>
        ("M", 190, c.m190, True),  # set bed temperature S<C> and wait
        ("M", 116, c.m116, True),  # wait for heaters to reach their targets: [T] [B]
        ("M", 105, c.m105, False),  # report temperatures
        ("M", 155, c.m155, False),  # report temperatures every S<s> seconds (S0: stop)
        ("M", 106, c.m106, False),  # part fan on S<0-255>
        ("M", 107, c.m107, False),  # part fan off
        ("M", 302, c.m302, False),  # cold extrusion: P1 allow, P0 refuse, S<C> minimum
        ("M", 922, c.m922, False),  # re-arm heaters after a thermal fault
    ):
        printer.add_command(letter, number, fn, guarded)
    motion.extrusion_guards.append(c.check_extrusion)
    thermal.on_change.append(motion.recheck_guards)
    printer.add_background(c.autoreport)
    return c

