# Filament runout sensors, as Marlin's FILAMENT_RUNOUT_SENSOR, for a mixing nozzle: one
# input per drive (a board's e<n>_runout pins). The main loop's background reads them;
# an input that reads the filament gone _DEBOUNCE_CHECKS times in a row marks its
# drive out, and once that drive then feeds filament (its steps in the step loop go
# past where they were), M600 D<n> runs between two lines (Printer.pending). So a
# runout counts while the drive prints, from a file or a host alike; a drive the mix
# gives no share (weight 0) is not fed, and its change waits until a mix uses it. One
# change at a time; a drive whose change started waits until its input has read the
# filament present again. Loaded only on boards with runout inputs, and small: a
# check reads the pins and a few words, and allocates nothing.
from array import array
from mixfw.stepper import S_DRIVE_POS

_DEBOUNCE_CHECKS = const(5)  # Marlin's FILAMENT_RUNOUT_THRESHOLD
# A drive's state: below _DEBOUNCE_CHECKS, its input's reads of "gone" in a row; then
_OUT = const(5)  # gone: its change starts once the drive feeds
_CHANGED = const(6)  # its change has started: nothing more until it reads present


class Runout:
    def __init__(self, printer, pins, settings, mem):
        """pins: per drive, its input (machine.Pin) or None."""
        self.printer = printer
        self.pins = pins
        self.settings = settings
        self.mem = mem
        self.gone = 1 if settings["runout_active_high"] else 0
        self.state = bytearray(len(pins))
        self.fed_from = array("i", bytes(4 * len(pins)))  # the drive's steps when out
        self.drive = 0  # whose change Printer.pending holds
        self.change = self._change  # bound once: a check allocates nothing
        printer.add_background(self.check)

    # The functions a check runs keep their locals and stack within 11 words: the VM
    # gives a bytecode function with more its frame from the heap at every call.
    def check(self, now_ms):
        if self.settings["runout_enabled"]:
            for d in range(len(self.state)):
                if self.pins[d] is not None:
                    self._read(d)

    def _read(self, d):
        state = self.state
        if self.pins[d].value() != self.gone:
            state[d] = 0
        elif state[d] < _OUT:
            state[d] += 1
            if state[d] == _OUT:
                self.fed_from[d] = self.mem[S_DRIVE_POS + d]
        elif state[d] == _OUT and self.mem[S_DRIVE_POS + d] > self.fed_from[d]:
            p = self.printer
            if p.pending is None and not p.halted:
                state[d] = _CHANGED
                self.drive = d
                p.pending = self.change

    def _change(self):
        """Printer.pending's: drive d's change, as the line M600 D<d>; OctoPrint pauses
        its job on //action:paused (its words after it are Marlin's)."""
        p = self.printer
        p.broadcast("//action:paused filament_runout %d" % self.drive)
        p.reply("echo:filament runout on drive %d: M600 D%d" % (self.drive, self.drive))
        text = b"M600 D%d" % self.drive
        p.run_line(p.parser.parse(text, len(text)))

    # M412 [S<0|1>] [R]: watch the runout inputs (S1) or not (S0), kept by M500; S and
    # R forget what the inputs read so far, as Marlin's (a drive still out starts a
    # change again). Alone: report, in Marlin's words. Example: M412 S0
    def m412(self, line):
        if line.has("S"):
            self.settings["runout_enabled"] = bool(line.int("S", lo=0, hi=1))
        elif not line.has("R"):
            self.printer.reply("echo:Filament runout %s" % (
                "ON" if self.settings["runout_enabled"] else "OFF"))
            return
        for d in range(len(self.state)):
            self.state[d] = 0


def setup(machine, printer, pins, settings, mem):
    """The watcher of the runout inputs in pins (per drive: its GPIO or None), and M412."""
    Pin = machine.Pin
    pull = Pin.PULL_UP if settings["runout_pullup"] else None
    watcher = Runout(printer, [None if g is None else Pin(g, Pin.IN, pull) for g in pins],
                     settings, mem)
    printer.add_command("M", 412, watcher.m412)  # runout inputs watched: S<0|1>; R forget
    return watcher
