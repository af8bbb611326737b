# Runtime configuration commands: APrinter's M503 M925 M926 M502 M501 M500 M930 and
# Marlin's aliases M92 M201 M203 M204 M205. Handlers parse; Config checks and stores.
# M926 and friends change the settings only; M930 applies them. The Marlin aliases
# apply at once, as Marlin users expect.
from mixfw.gcode import GcodeError

# Option names are text, so the parser hands these commands their arguments raw.
RAW_COMMANDS = (("M", 925), ("M", 926))

_JERK_LETTERS = const("XYZEST")


def _words(text, letters):
    """'Isteps_per_mm_x V80' -> {'I': 'steps_per_mm_x', 'V': '80'}"""
    words = {}
    for w in text.split():
        letter = w[0].upper()
        if letter not in letters:
            raise GcodeError("unexpected %r: expected %s" % (
                w, " ".join(ch + ("<option>" if ch == "I" else "<value>") for ch in letters)))
        if letter in words:
            raise GcodeError("parameter %s given twice" % letter)
        words[letter] = w[1:]
    if not words.get("I"):
        raise GcodeError("missing option name: I<option>, M503 lists them")
    words["I"] = words["I"].lower()
    return words


class ConfigCommands:
    def __init__(self, printer, config):
        self.printer = printer
        self.config = config

    def _set_or_report(self, pairs, report):
        if not pairs:
            self.printer.reply("echo:" + report)
            return
        self.config.update(pairs)
        self.config.apply()

    def _axes(self, line, code, key, letters):
        names = [key + "_" + ch.lower() for ch in letters]
        pairs = [(n, line.float(ch)) for n, ch in zip(names, letters) if line.has(ch)]
        self._set_or_report(pairs, code + " " + " ".join(
            ch + self.config.format(n) for ch, n in zip(letters, names)))

    # M503: print every option as an M926 line that can be sent back, with its help,
    # limits and whether it needs a restart as a comment; the network's password as a
    # comment that says whether one is set. Example: M503
    def m503(self, line):
        texts = _help_texts()
        for o in self.config.options:
            self.printer.reply("echo:" + self.config.describe(o.name, texts))

    # M925 I<option>: print one option the way M503 does. Example: M925 Isteps_per_mm_x
    def m925(self, line):
        name = _words(line.args_text, "I")["I"]
        self.printer.reply("echo:" + self.config.describe(name, _help_texts()))

    # M926 I<option> [V<value>]: set one option; without V, back to the board's
    # default. Booleans are 0 or 1. M930 applies it. Example: M926 Isteps_per_mm_x V80
    def m926(self, line):
        words = _words(line.args_text, "IV")
        if "V" in words:
            self.config.set(words["I"], words["V"])
        else:
            self.config.reset(words["I"])

    # M502: every option back to the board's default; M930 applies. Example: M502
    def m502(self, line):
        self.config.set_defaults()

    # M501: load the saved configuration, all or nothing; M930 applies. Example: M501
    def m501(self, line):
        note = self.config.load()
        self.printer.warnings = []  # the start-up's, about the file now loaded
        if note:
            self.printer.reply("echo:config " + note)

    # M500: save the configuration to flash; a reset meanwhile keeps the old or the
    # new one. It first waits for the queued moves to run, as M400 (flash is
    # programmed with interrupts off, which would freeze the axes mid-move).
    # Example: M500
    def m500(self, line):
        self.config.save()
        self.printer.warnings = []  # the start-up's, about the file now replaced

    # M930: apply the configuration, reporting options that need a restart. Example: M930
    def m930(self, line):
        pending = self.config.apply()
        if pending:
            self.printer.reply("echo:takes effect after a restart (M500 saves it): "
                               + " ".join(pending))

    # M92 [X Y Z E]: steps per mm; E is every mixing drive's. No words: report.
    # Example: M92 E415
    def m92(self, line):
        if line.has("E"):  # every drive, then the E axis through the usual path
            e = line.float("E")
            self.config.update([("drive_steps_per_mm_%d" % i, e)
                                for i in range(len(self.config.settings["drive_steps_per_mm"]))]
                               + [("steps_per_mm_e", e)])
        self._axes(line, "M92", "steps_per_mm", "XYZE")

    # M201 [X Y Z E]: maximum acceleration per axis, mm/s^2. Example: M201 X3000 Y3000
    def m201(self, line):
        self._axes(line, "M201", "max_accel_mm_s2", "XYZE")

    # M203 [X Y Z E]: maximum speed per axis, mm/s (as in Marlin). Example: M203 Z10
    def m203(self, line):
        self._axes(line, "M203", "max_feed_mm_s", "XYZE")

    # M204 [P<accel>] [R<accel>] [T<accel>] [S<accel>]: print (P) and retract (R)
    # acceleration, mm/s^2. Travel moves share the print acceleration, so T (and S,
    # Marlin's older P) set it when P is absent. No words: report. Example: M204 P1500 R3000
    def m204(self, line):
        accel = line.float("P", line.float("S", line.float("T")))
        pairs = [(name, v) for name, v in (("acceleration_mm_s2", accel),
                 ("retract_acceleration_mm_s2", line.float("R"))) if v is not None]
        self._set_or_report(pairs, "M204 P%s R%s" % (
            self.config.format("acceleration_mm_s2"),
            self.config.format("retract_acceleration_mm_s2")))

    # M205 [J<mm>] [B<us>]: junction deviation, and the shortest time a move takes
    # while the queue is under half full (Marlin's SLOWDOWN; 0: off). Marlin's jerk
    # and minimum-feed words (X Y Z E S T) have no meaning here; they are reported as
    # ignored. No words: report. Example: M205 J0.05 B20000
    def m205(self, line):
        ignored = [ch for ch in _JERK_LETTERS if line.has(ch)]
        if ignored:
            self.printer.reply("echo:M205 ignored %s: mixstep uses junction deviation J"
                               % " ".join(ignored))
        pairs = [(name, v) for name, v in (("junction_deviation_mm", line.float("J")),
                 ("min_segment_time_us", line.int("B"))) if v is not None]
        self._set_or_report(pairs, "M205 J%s B%s" % (
            self.config.format("junction_deviation_mm"),
            self.config.format("min_segment_time_us")))



def _help_texts():
    """The options' help, for one reply: its module goes again, off the heap while
    printing (about 4 kB of text a board would hold from boot)."""
    import sys
    import mixfw
    from mixfw import options_help
    texts = options_help.HELP
    del sys.modules["mixfw.options_help"]
    delattr(mixfw, "options_help")
    return texts


def register(printer, config):
    c = ConfigCommands(printer, config)
    printer.add_command("M", 503, c.m503)  # print the configuration as M926 lines
    printer.add_command("M", 925, c.m925)  # print one option: I<option>
    printer.add_command("M", 926, c.m926)  # set an option: I<option> V<value> (no V: default)
    printer.add_command("M", 502, c.m502)  # every option to its default
    printer.add_command("M", 501, c.m501)  # load the saved configuration
    printer.add_command("M", 500, c.m500)  # save the configuration
    printer.add_command("M", 930, c.m930)  # apply the configuration
    printer.add_command("M", 92, c.m92)  # steps per mm: X Y Z E
    printer.add_command("M", 201, c.m201)  # maximum acceleration mm/s^2: X Y Z E
    printer.add_command("M", 203, c.m203)  # maximum speed mm/s: X Y Z E
    printer.add_command("M", 204, c.m204)  # acceleration mm/s^2: P print, R retract
    printer.add_command("M", 205, c.m205)  # junction deviation J<mm>, min move time B<us>
    return c
