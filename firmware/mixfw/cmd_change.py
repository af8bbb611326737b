# M600: a filament change in the middle of a print, as Marlin's ADVANCED_PAUSE_FEATURE
# makes it, for a mixing nozzle: the input to change (D) or the whole mix is unloaded
# and loaded, and the new filament purged through the mix the print goes on with.
# The wait tells the host (OctoPrint's //action: commands and its prompt) and ends on
# M108 or the prompt's answer (M876); the hot end waits hot, then turns off after
# change_heater_timeout_s, and heats again before the print goes on.
import time
from array import array
from mixfw.gcode import GcodeError
from mixfw.filament import nm_from_mm

# The park's speed, as Marlin's NOZZLE_PARK_XY_FEEDRATE (Z keeps its max_feed_mm_s).
_PARK_FEED_MM_S = const(100)
_PROMPT = ("//action:prompt_begin Filament change: load the new filament, then Continue",
           "//action:prompt_button Continue", "//action:prompt_show")


class FilamentChange:
    def __init__(self, printer, motion, thermal, settings):
        self.printer = printer
        self.motion = motion
        self.thermal = thermal
        self.settings = settings
        self.heater_off_at_ms = None  # while a change waits with the hot end on
        self.cooled = False  # the wait turned the hot end off

    def _mm(self, line, letter, default, top):
        v = line.float(letter, default)
        if not 0 <= v <= top:
            raise GcodeError("M600 %s%s out of range 0..%g" % (letter, v, top))
        return v

    # M600 [X<mm>] [Y<mm>] [Z<mm>] [E<mm>] [U<mm>] [L<mm>] [P<mm>] [D<drive>]: change
    # filament. After the queued moves: retract E (retract_mm), raise Z by Z, park at X
    # Y (change_park_mm), unload U of drive D (without D, of the active mix), tell the
    # host and wait for M108 or the prompt's Continue (M876); then heat again if the
    # wait turned the hot end off, push E back, load L, purge P with the active mix,
    # retract E for the way back, go back and push it back: the drives end U less L
    # and P more than they were. Example: M600 D2 U80 L80
    def m600(self, line):
        s = self.settings
        m = self.motion
        park = s["change_park_mm"]
        travel = m.travel_mm
        most = m.max_extrude_mm
        x = self._mm(line, "X", park[0], travel[0])
        y = self._mm(line, "Y", park[1], travel[1])
        lift = self._mm(line, "Z", park[2], travel[2])
        retract = nm_from_mm(self._mm(line, "E", s["retract_mm"], most))
        unload = nm_from_mm(self._mm(line, "U", s["change_unload_mm"], most))
        load = nm_from_mm(self._mm(line, "L", s["change_load_mm"], most))
        purge = nm_from_mm(self._mm(line, "P", s["change_purge_mm"], most))
        drive = line.int("D", -1, lo=0, hi=m.drives - 1)
        feed = s["change_feed_mm_s"]
        planner = m.planner
        planner.synchronize()
        back = array("i", m.pos_nm)
        to = array("i", back)
        to[2] = min(back[2] + nm_from_mm(lift), m._travel_nm[2] - m.offset_nm[2])
        m.feed_filament(-retract, m.retract_feed_mm_s)
        m.travel_to(to, _PARK_FEED_MM_S)
        to[0] = nm_from_mm(x) - m.offset_nm[0]
        to[1] = nm_from_mm(y) - m.offset_nm[1]
        m.travel_to(to, _PARK_FEED_MM_S)
        if unload:
            m.feed_filament(-unload, feed, drive)
        planner.synchronize()
        if not self._wait():
            return
        m.feed_filament(retract, m.unretract_feed_mm_s)  # the pause's retraction back
        if load:
            m.feed_filament(load, feed, drive)
        if purge:
            m.feed_filament(purge, feed)
        m.feed_filament(-retract, m.retract_feed_mm_s)  # no ooze on the way back
        to[0], to[1] = back[0], back[1]
        m.travel_to(to, _PARK_FEED_MM_S)  # over the print, still raised
        m.travel_to(back, _PARK_FEED_MM_S)
        m.feed_filament(retract, m.unretract_feed_mm_s)

    def _wait(self):
        """The change's wait: the host told, M108 or M876 ends it; the hot end turned
        off after the timeout, heated again after. False if the printer halted."""
        p = self.printer
        heater = self.thermal.hotend
        target_c = heater.target_c if heater else 0.0
        timeout_s = self.settings["change_heater_timeout_s"]
        self.heater_off_at_ms = None
        self.cooled = False
        if heater and target_c and timeout_s:
            self.heater_off_at_ms = time.ticks_add(time.ticks_ms(), timeout_s * 1000)
        p.broadcast("//action:paused")
        for text in _PROMPT:
            p.broadcast(text)
        p.reply("echo:filament change: change the filament, then M108 or Continue")
        p.prompt_open = True
        try:
            if not p.wait_until(self._heater_timeout, breakable=True):
                return False
        finally:
            p.prompt_open = False
            p.broadcast("//action:prompt_end")
        if self.cooled:
            p.reply("echo:filament change: heating the hot end to %.0f C" % target_c)
            self.thermal.set_target(heater, target_c)
            if not p.wait_until(lambda: heater.fault or heater.reached()):
                return False
        p.broadcast("//action:resumed")
        return True

    def _heater_timeout(self):
        """wait_until's test: never done; turns the hot end off once the time is up."""
        if self.heater_off_at_ms is not None and \
                time.ticks_diff(time.ticks_ms(), self.heater_off_at_ms) >= 0:
            self.heater_off_at_ms = None
            self.cooled = True
            self.thermal.set_target(self.thermal.hotend, 0.0)
            self.printer.broadcast("echo:filament change: hot end off after %d s; it "
                                   "heats again when the print goes on"
                                   % self.settings["change_heater_timeout_s"])
        return False
