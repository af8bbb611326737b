# The printer core: serves G-code channels (serial, TCP, simulation stdio), checks the
# host protocol (line numbers, checksums, resend), runs each line's handler and
# answers every line exactly once. Handlers come from the cmd_* modules, each of
# which registers its own commands.
#
# While a command waits (queue full, M400, M109...), the channels are still read into
# their ring buffers, so the emergency commands are seen at once (Marlin's emergency
# parser): M112 halts, M410 drops the queued moves, M108 ends a heating wait, M876
# answers a host prompt. Other lines wait their turn there. A full ring stops reading
# its channel: the host's transport holds the rest, and no `ok` goes out until there
# is room, so nothing is ever dropped.
import time
from array import array
from mixfw.gcode import Parser, GcodeError, WordsError, command_key
from mixfw.intake import Intake, LINE_OK, LINE_CUT, SCANNED, line_taken, ring_put

_BUSY_EVERY_MS = const(2000)
_REPORT_EVERY_MS = const(1000)  # temperatures while a heating wait runs, as Marlin
_BACKGROUND_EVERY_MS = const(10)  # background tasks at least this often, however busy
_FILE_LINES_PER_READ = const(4)  # a file's lines between reads of the channels
_ANY_TOOL = command_key("T", -1)  # the handler of every T<n>
# intake.py's (copies): its ring's size and the words of its state array read here.
_RX_BYTES = const(256)
_COUNT = const(1)
_LEN = const(3)


def run_each(hooks):
    """Call every hook, even after one raised, as safety hooks must: returns the first
    fault, or None."""
    fault = None
    for fn in hooks:
        try:
            fn()
        except Exception as err:
            if fault is None:
                fault = err
    return fault


class Halted(Exception):
    """Raised out of a wait when the printer halted meanwhile (M112, heater fault)."""


class Stopped(Halted):
    """Raised out of a wait when M410 dropped the queued moves meanwhile."""


class Resend(Exception):
    """A transmission error: the host must send the line again."""


# Words of _frame's answer.
_STAR = const(0)  # where the line's * is, or -1
_SUM_OK = const(1)  # 1: the number after * is the XOR of the bytes before it
_N_VALUE = const(2)  # the N word's number
_N_WORD = const(3)  # 0: no N word; 1: N and a number; 2: N and no number
_M_NUMBER = const(4)  # the M command's number after the N word, or -1
_FRAME_WORDS = const(5)
# _frame's verdicts, besides where the * is of the line numbered next.
_PLAIN = const(-1)  # no N word, no checksum: a person typing
_OTHER = const(-2)  # anything else: see Printer._check_numbered


@micropython.viper
def _frame(buf: ptr8, n: int, out: ptr32, last_n: int) -> int:
    """A line's N word, its command's M number and its checksum, read in one pass: a
    host printing a file numbers and checks every line, and each helper called from
    bytecode, or a loop there, costs the chip tens of us. For the line a host streams,
    numbered last_n + 1 with its checksum right (not M110), returns where its * is
    (where its words end); _PLAIN for a line with neither N nor *; else _OTHER.
    Numbers of more than nine digits are not read as numbers."""
    i = 0
    while i < n and (buf[i] == 32 or buf[i] == 9):
        i += 1
    out[_N_WORD] = 0
    out[_N_VALUE] = 0
    if i < n and (buf[i] == 78 or buf[i] == 110):
        i += 1
        while i < n and (buf[i] == 32 or buf[i] == 9):
            i += 1
        sign = 1
        if i < n and buf[i] == 45:
            sign = -1
            i += 1
        value = 0
        digits = 0
        while i < n and buf[i] >= 48 and buf[i] <= 57:
            value = value * 10 + buf[i] - 48
            digits += 1
            i += 1
        if digits > 0 and digits < 10:
            out[_N_WORD] = 1
            out[_N_VALUE] = sign * value
        else:
            out[_N_WORD] = 2
        while i < n and (buf[i] == 32 or buf[i] == 9):
            i += 1
    number = -1
    if i < n and (buf[i] == 77 or buf[i] == 109):
        i += 1
        while i < n and (buf[i] == 32 or buf[i] == 9):
            i += 1
        digits = 0
        value = 0
        while i < n and buf[i] >= 48 and buf[i] <= 57 and digits < 9:
            value = value * 10 + buf[i] - 48
            digits += 1
            i += 1
        if digits and not (i < n and buf[i] >= 48 and buf[i] <= 57):
            number = value
    out[_M_NUMBER] = number
    # The checksum: the XOR of every byte before the first *, and the number after it
    # (blanks and a CR around it allowed).
    cs = 0
    star = -1
    i = 0
    while i < n:
        c = buf[i]
        if c == 42:
            star = i
            break
        cs ^= c
        i += 1
    out[_STAR] = star
    out[_SUM_OK] = 0
    if star >= 0:
        i = star + 1
        while i < n and (buf[i] == 32 or buf[i] == 9):
            i += 1
        end = n
        while end > i and (buf[end - 1] == 32 or buf[end - 1] == 9 or buf[end - 1] == 13):
            end -= 1
        value = 0
        ok = 0
        if end > i:
            ok = 1
        while i < end:
            c = buf[i] - 48
            if c < 0 or c > 9 or value > 255:
                ok = 0
                break
            value = value * 10 + c
            i += 1
        if ok and value == cs:
            out[_SUM_OK] = 1
            if out[_N_WORD] == 1 and number != 110 and out[_N_VALUE] == last_n + 1:
                return star
    elif out[_N_WORD] == 0:
        return _PLAIN
    return _OTHER


_EMERGENCY = array("i", bytes(4 * _FRAME_WORDS))


def _emergency(scan, n):
    """The M number if this line starts (after an optional N<number>) with an emergency
    command, else 0: M112, M108, M410, M876 and M524, acted on as soon as their line
    arrives, before the lines queued ahead of them (when their turn comes they do
    nothing more, but M524, which then cancels the file)."""
    _frame(scan, n, _EMERGENCY, 0)
    number = _EMERGENCY[_M_NUMBER]
    if number == 112 or number == 108 or number == 410 or number == 876 or number == 524:
        return number
    return 0


class Channel:
    """One console, its receive ring and its protocol state."""

    def __init__(self, console, line_bytes):
        self.console = console
        self.intake = Intake(line_bytes)
        self.chunk = bytearray(64)
        self.chunk_mv = memoryview(self.chunk)
        self.last_n = 0  # last line number accepted
        self.open = True
        self.lockstep = getattr(console, "blocking", False)
        # The console's own write and the intake's own next_line: one call less for
        # every line.
        self.write = console.write
        self.next_line = self.intake.next_line

    def pump(self, printer, block=False):
        """Move waiting bytes into the ring. Returns the count read."""
        # The ring's calls written out here: each bytecode call costs the chip about
        # 25 us, and a host's line passes here every time. Locals and stack within 11
        # words (see Printer.answer).
        free = _RX_BYTES - self.intake.st[_COUNT]
        if free <= 0 or not self.open:
            return 0
        n = self.console.readinto(self.chunk_mv if free >= 64 else self.chunk_mv[:free],
                                  block)
        if n < 0:
            self.open = False
            return 0
        at = 0
        while at < n:
            at = ring_put(self.intake.rings, self.chunk, at, n)
            if at >= SCANNED:
                # An emergency command acts as its line ends.
                free = _emergency(self.intake.scan, at // SCANNED)  # its M number
                at %= SCANNED
                if free:
                    printer.emergency(free)
        return n


class Printer:
    def __init__(self, line_bytes, machine_idle, raw_commands=()):
        self.line_bytes = line_bytes
        self.parser = Parser(raw_commands)
        self._framing = array("i", bytes(4 * _FRAME_WORDS))
        self.commands = {}
        self.guarded = set()  # commands refused while halted
        self.machine_idle = machine_idle
        self.channels = []
        self.listeners = []  # objects with accept() -> console or None
        self.max_channels = 8
        self.current = None  # channel whose command is running
        # fn(now_ms) each, run from the main loop and every wait, every
        # _BACKGROUND_EVERY_MS; and each_turn's at every turn of a wait or of the idle
        # main loop besides (the heaters' control on its period, a software PWM's
        # edges).
        self.background = []
        self.each_turn = []
        self._background_at_ms = time.ticks_ms()
        # Heaters off: the first thing a halt and every way out of the main loop do, so
        # that nothing which can allocate or raise comes before it (thermal.py).
        self.heaters_off = []
        self.on_halt = []  # then, when the printer halts: motion stopped, a print paused
        self.on_quick_stop = []  # M410: drop the queued moves, the heaters stay on
        self.busy_every_ms = _BUSY_EVERY_MS  # M113; 0: no busy lines
        # M108s received, and those that ended a wait or whose turn has passed: an
        # M108 ends the heating wait running when it arrives, or one still ahead of
        # it in the ring; once its own line runs, no later wait sees it.
        self.breaks_received = 0
        self.breaks_used = 0
        self.prompt_open = False  # a host prompt waits for its answer (M876), as M108

        self._breaks_run = 0
        self.stop_count = 0  # M410s done
        self._cmd_stop_count = 0
        self._stop_pending = False
        self.finish = []  # run when the last channel closes (simulation)
        self.halted = None  # reason, while halted
        self.leaving = None  # the command that asked serve() to end (M997)
        self.halt_count = 0
        self._cmd_halt_count = 0
        self._busy_at_ms = 0
        self.refuse_after_error = False
        self.failed = False
        self.sink = None  # M28 upload: takes each received line's text instead of running it
        self.job = None  # a file being printed: next_line() -> its intake's status, .paused
        # fn() a background task asks the main loop to run between two lines, never
        # inside a handler: a filament runout's M600 (runout.py). run_pending runs it.
        self.pending = None
        # What the start-up found wrong (a saved configuration refused): said at start,
        # to every host that connects later and in M115's answer, as a host on USB
        # connects after the board has started; M500 and M501 clear it.
        self.warnings = []
        for letter, number, fn in (
            ("M", 110, self.m110),  # set the line number: M110 N<n>
            ("M", 112, self.m112),  # emergency stop
            ("M", 108, self.m108),  # end a heating wait
            ("M", 410, self.m410),  # quick stop: drop the queued moves, heaters stay on
            ("M", 876, self.m876),  # answer a host prompt: S<choice>
            ("M", 113, self.m113),  # busy keep-alive interval S<s> (0: none)
            ("M", 999, self.m999),  # clear a halt and resume
            ("M", 997, self.m997),  # stop serving and restart into the REPL (for an update)
            ("M", 932, self.m932),  # refuse commands after the first error
            ("M", 933, self.m933),  # leave refuse-after-error mode
        ):
            self.add_command(letter, number, fn)

    # --- registration and replies ---
    def register(self, name, handler, guarded=False):
        """name like "G1" or "M163"; "T" takes every tool number. The firmware's own
        commands use add_command: "G1" as text would be interned for good."""
        self.add_command(name[0], int(name[1:]) if len(name) > 1 else -1, handler, guarded)

    def add_command(self, letter, number, handler, guarded=False):
        """G1 as ("G", 1); ("T", -1) takes every tool number. guarded: refused
        while the printer is halted (moves, heating). Each command's help is a comment
        where it is registered: nothing prints it, and as strings the texts would hold
        about 3.5 KB of a chip's heap for good (a .mpy file's constants load into RAM)."""
        key = command_key(letter, number)
        self.commands[key] = handler
        if guarded:
            self.guarded.add(key)

    def add_lazy_command(self, letter, number, module, make, args, method, guarded=False):
        """A command whose module loads at its first use: a board keeps a module's
        code in RAM, and a rarely used command (M600, M486) would hold kilobytes of it
        from boot. make is the module's class, built with args; its method runs the
        command from then on."""
        key = command_key(letter, number)

        def first(line):
            mod = __import__(module, None, None, (make,))
            handler = getattr(getattr(mod, make)(*args), method)
            self.commands[key] = handler
            return handler(line)
        self.add_command(letter, number, first, guarded)

    def add_channel(self, console):
        """A console at start, or a host that connected over the network: it hears
        `start`, as Marlin's, and the warnings."""
        ch = Channel(console, self.line_bytes)
        self.channels.append(ch)
        ch.write("start\n")
        for text in self.warnings:
            ch.write(text + "\n")
        return ch

    def reply(self, text):
        """A line to the host whose command is running (all hosts if none)."""
        if self.current is None:
            self.broadcast(text)
        else:
            self.current.write(text + "\n")

    def broadcast(self, text):
        self.write(text + "\n")

    def write(self, text):
        """Text to every host. While run_pending runs a command the printer is its
        channel: the command's replies and busy lines reach every host."""
        for ch in self.channels:
            ch.write(text)

    # --- time passing ---
    def add_background(self, fn, each_turn=False):
        (self.each_turn if each_turn else self.background).append(fn)

    def _run_background(self):
        now = time.ticks_ms()
        self._background_at_ms = now
        for fn in self.background:
            fn(now)
        for fn in self.each_turn:
            fn(now)

    def _turn(self):
        """A turn of a wait or of the idle main loop, after the chip slept until an
        interrupt: those come a few times a millisecond, and the background's calls cost
        the chip tens of us each time, a tenth of its time. So the background runs every
        _BACKGROUND_EVERY_MS, as while lines come back to back, and each_turn's now."""
        now = time.ticks_ms()
        if time.ticks_diff(now, self._background_at_ms) >= _BACKGROUND_EVERY_MS:
            self._run_background()
        else:
            for fn in self.each_turn:
                fn(now)

    def pump_all(self):
        if self.listeners:
            self.accept()
        for ch in self.channels:
            ch.pump(self)

    def accept(self):
        for lst in self.listeners:
            # Called when full too: a connection beyond max_channels is turned away
            # with a reason, not left waiting in the backlog.
            console = lst.accept(self.max_channels - len(self.channels))
            if console is not None:
                self.add_channel(console)

    def idle(self):
        """Let time pass inside a command: the step loop runs, background tasks run,
        input is read (emergency commands act at once), and the host hears `busy:`
        every busy_every_ms. Raises Halted if the printer halted since the command
        started, Stopped if M410 dropped the moves."""
        self.machine_idle()
        self._turn()
        self.pump_all()
        self._quick_stop_if_asked()
        if self.current is not None and self.busy_every_ms:
            now = time.ticks_ms()
            if time.ticks_diff(now, self._busy_at_ms) >= self.busy_every_ms:
                self._busy_at_ms = now
                self.current.write("busy: processing\n")
        if self.halt_count != self._cmd_halt_count:
            raise Halted(self.halted)
        if self.stop_count != self._cmd_stop_count:
            raise Stopped("quick stop (M410)")

    def wait_until(self, done, breakable=False, report=None):
        """Wait until done() is true. Returns False if the printer halted or M410
        stopped it meanwhile. breakable: M108 ends the wait (heating waits, as in
        Marlin). report: fn() -> a line for the host every second meanwhile (it stands
        in for `busy:`)."""
        report_at_ms = time.ticks_ms()
        try:
            while not done():
                if breakable and self.breaks_received > self.breaks_used:
                    self.breaks_used = self.breaks_received
                    return True
                self.idle()
                if report is not None:
                    now = time.ticks_ms()
                    if time.ticks_diff(now, report_at_ms) >= _REPORT_EVERY_MS:
                        report_at_ms = self._busy_at_ms = now
                        self.reply(report())
        except Halted:
            return False
        return True

    # --- halting ---
    def halt(self, reason):
        """Heaters off first, then motion stopped, then every host told. A hook that
        raises skips none after it; its fault is reported after the reason."""
        fault = run_each(self.heaters_off)
        later = run_each(self.on_halt)
        self.halted = reason
        self.halt_count += 1
        self.broadcast("Error:%s" % reason)
        if fault is None:
            fault = later
        if fault is not None:
            self.broadcast("Error:halting raised %s: %s" % (type(fault).__name__, fault))

    def emergency_stop(self):
        if not self.halted or "M112" not in self.halted:
            self.halt("emergency stop (M112)")

    def emergency(self, number):
        """An emergency command has just arrived (see _emergency)."""
        if number == 112:
            self.emergency_stop()
        elif number == 108:
            self.breaks_received += 1
        elif number == 410:
            # Done between commands or at a wait, never inside the planner's work.
            self._stop_pending = True
        elif number == 524:
            # Cancel the file print, as Marlin's emergency parser: no line of it runs
            # from now on, and a wait of one (M109 heating) ends; M524's own line
            # cancels it when its turn comes.
            if self.job is not None:
                self.job.paused = True
                self.breaks_received += 1
        elif self.prompt_open:  # M876: the answer to the prompt a wait showed (M600)
            self.breaks_received += 1

    def _quick_stop_if_asked(self):
        if self._stop_pending:
            self._stop_pending = False
            self.quick_stop()

    def quick_stop(self):
        """M410: drop every queued move now; the position becomes where the axes
        stopped. Heaters, targets and the file print's state stay."""
        for fn in self.on_quick_stop:
            fn()
        self.stop_count += 1

    def clear_halt(self):
        self.halted = None

    # --- one line ---
    def _check_protocol(self, ch, buf, n):
        """Check a line's number and checksum before anything else looks at it.
        Returns the parsed line, or None for a repeat of a line already executed."""
        # Locals and stack within 11 words (see answer).
        end = _frame(buf, n, self._framing, ch.last_n)
        if end >= 0:
            # Taken now: a line that arrived intact uses up its number even if it is
            # bad G-code, so the host does not send it again.
            ch.last_n = self._framing[_N_VALUE]
            return self.parser.parse(buf, end)
        if end == _PLAIN:
            return self.parser.parse(buf, n)
        return self._check_numbered(ch, buf, n, self._framing)

    def _check_numbered(self, ch, buf, n, f):
        """_check_protocol's other lines with an N word or a checksum (f: _frame's
        answer): M110, repeats and transmission errors."""
        # Locals and stack within 11 words, or the frame comes from the heap.
        if f[_STAR] >= 0:
            if not f[_SUM_OK]:
                raise Resend("checksum mismatch, Last Line: %d" % ch.last_n)
            n = f[_STAR]  # the words end at the *
        if not f[_N_WORD]:
            raise Resend("No Line Number with checksum, Last Line: %d" % ch.last_n)
        if f[_M_NUMBER] == 110:  # M110 sets the number: its own N is not checked
            return self.parser.parse(buf, n)
        if f[_STAR] < 0:
            raise Resend("No Checksum with line number, Last Line: %d" % ch.last_n)
        if f[_N_WORD] != 1:
            raise Resend("malformed line number, Last Line: %d" % ch.last_n)
        i = f[_N_VALUE]
        if i <= ch.last_n:
            return None
        if i != ch.last_n + 1:
            raise Resend("Line Number is not Last Line Number+1, Last Line: %d" % ch.last_n)
        # Taken now: a line that arrived intact uses up its number even if it is bad
        # G-code, so the host does not send it again.
        ch.last_n = i
        return self.parser.parse(buf, n)

    def _unknown(self):
        """After the parser's WordsError: if the line's command is one we don't know,
        say so."""
        key = self.parser.command_of_failed()
        if not key or key in self.commands or (
                key // 10000 == 84 and _ANY_TOOL in self.commands):
            return False
        command = self.parser.failed_command()
        refused = self._unknown_command(command[0], command)
        if refused:
            self.reply("Error:" + refused)
            self.failed = True
        return True

    def _unknown_command(self, letter, command):
        """An M-code we lack is a setting or a report, and a host goes on past it, as
        Marlin's echo says; a G-code is motion, and a file that needs one would print
        wrong without it: its refusal is returned, to answer as an error (hosts stop
        the print)."""
        if letter == "G":
            return ('Unknown command: "%s" (a motion command this firmware lacks; the '
                    'print would go wrong without it)' % command)
        self.reply('echo:Unknown command: "%s"' % command)
        return None

    def run_line(self, line):
        """Run a parsed line; returns text to follow `ok` or None."""
        key = line.key
        if not key:
            return None
        handler = self.commands.get(key)
        if handler is None and line.letter == "T":
            key = _ANY_TOOL
            handler = self.commands.get(key)
        if handler is None:
            refused = self._unknown_command(line.letter, "%s%d" % (line.letter, line.number))
            if refused:
                raise GcodeError(refused)
            return None
        if self.refuse_after_error and self.failed and key not in self._always:
            raise GcodeError("refused: an earlier command failed (M933 leaves this mode)")
        if self.halted and key in self.guarded:
            raise GcodeError("printer halted (%s); M999 resumes" % self.halted)
        return handler(line)

    _always = (command_key("M", 932), command_key("M", 933), command_key("M", 112),
               command_key("M", 999), command_key("M", 110), command_key("M", 105),
               command_key("M", 114), command_key("M", 115), command_key("M", 27))

    # The functions every line runs keep their locals, stack and exception handlers
    # within 11 words: MicroPython gives a bytecode function with more its frame from
    # the heap at every call, up to hundreds of microseconds on a chip's fragmented
    # heap (test_heap probes it). A handler of `except ... as` takes too many words, so
    # a line's errors are caught in serve(), whose frame is made once; and there are
    # few new names: past the edge of the interned names' sixth pool, a seventh takes
    # 7.8 kB of a Pico's heap.
    def answer(self, ch, status):
        """Run ch's line and answer `ok`; an error is raised for report()."""
        intake = ch.intake
        self.current = ch
        self._cmd_halt_count = self.halt_count
        self._cmd_stop_count = self.stop_count
        self._busy_at_ms = time.ticks_ms()
        if status != LINE_OK and intake.cut_text(status) != LINE_OK:
            raise GcodeError(intake.error_text(status))
        if self.sink is not None:
            suffix = self._to_sink(ch, intake.buf, intake.st[_LEN])
        else:
            # The parsed line, then the text its handler gives: one local for both
            # keeps the frame within 11 words.
            suffix = self._check_protocol(ch, intake.buf, intake.st[_LEN])
            if suffix is not None:
                suffix = self.run_line(suffix)
        self.done(ch, suffix)

    def done(self, ch, text):
        """ch's line has run: `ok`, with text after it if any."""
        line_taken(ch.intake.st)  # ch.intake.take(), a bytecode call less
        if text:
            ch.write("ok " + text + "\n")
        else:
            ch.write("ok\n")
        self.current = None

    def report(self, ch, err):
        """answer() raised err: tell the host as it expects, then `ok`."""
        self.explain(err)
        self.done(ch, None)

    def explain(self, err):
        """What a command raised, told to its host (self.current) as it expects."""
        if isinstance(err, Resend):
            self.reply("Error:%s" % err)
            self.reply("Resend: %d" % (self.current.last_n + 1))
        elif isinstance(err, Stopped):
            self.reply("echo:command stopped: %s" % err)
        elif isinstance(err, Halted):
            self.reply("Error:command stopped: %s" % err)
        elif isinstance(err, WordsError) and self._unknown():
            pass  # bad words after a command we don't know: its arguments may be text
        elif isinstance(err, ValueError):  # GcodeError, MixError, PlanError: bad input
            self.reply("Error:%s" % err)
            self.failed = True
        else:  # a bug must not take the printer down with it
            self.reply("Error:internal error in this command: %r" % err)
            self.failed = True

    def _to_sink(self, ch, buf, n):
        """While uploading (M28): store the line's text; only M29 runs."""
        try:
            line = self._check_protocol(ch, buf, n)
        except GcodeError:
            line = False  # arrived intact but is no G-code we know: store it anyway
        if line is None:
            return None  # a repeat of a stored line
        if line and line.letter == "M" and line.number == 29:
            return self.run_line(line)
        start = 0
        if buf[0] in (78, 110):  # drop the N word, as the line is stored unnumbered
            while start < n and buf[start] != 32:
                start += 1
        end = start
        while end < n and buf[end] != 42:
            end += 1
        self.sink(bytes(buf[start:end]).strip())  # the bytes as they came
        return None

    def run_job_line(self):
        """Run the next line of the file being printed; an error is raised for serve(),
        which reports it to every host and pauses the print (M24 resumes after the
        failed line)."""
        job = self.job
        status = job.next_line()
        if not status:
            self.job = None
            job.done()
            return
        self._cmd_halt_count = self.halt_count
        self._cmd_stop_count = self.stop_count
        intake = job.intake
        if status != LINE_OK and intake.cut_text(status) != LINE_OK:
            raise GcodeError(intake.error_text(status))
        self.run_line(self.parser.parse(intake.buf, intake.st[_LEN]))
        line_taken(intake.st)  # intake.take(), a bytecode call less

    def run_pending(self):
        """Run what a background task asked for (self.pending) between two lines, as a
        line of its own that every host hears; its errors go to them all."""
        fn = self.pending
        self.pending = None
        self.current = self
        self._cmd_halt_count = self.halt_count
        self._cmd_stop_count = self.stop_count
        self._busy_at_ms = time.ticks_ms()
        try:
            fn()
        except Exception as err:
            self.explain(err)
        self.current = None

    # --- the main loop ---
    def serve(self):
        """Answer lines from every channel until all have closed and no listener is
        left."""
        unpumped = 0  # file lines run since the channels were last read
        while (self.channels or self.listeners) and not self.leaving:
            if self.pending is not None:
                self.run_pending()
            job = self.job
            printing = job is not None and not job.paused
            # While a file prints, the channels are read every few of its lines: a
            # read that finds nothing costs the chip about 0.2 ms, a fifth of a line's
            # time. Their lines wait that long (an emergency command's too: a few ms);
            # a line that waits for the planner reads them as it waits.
            if not printing or unpumped >= _FILE_LINES_PER_READ:
                unpumped = 0
                if self.listeners:  # pump_all(), written out: a call less every line
                    self.accept()
                for ch in self.channels:
                    ch.pump(self)
                if self._stop_pending:
                    self._quick_stop_if_asked()
                did = False
                for ch in self.channels:
                    status = ch.next_line()
                    if status:
                        try:
                            self.answer(ch, status)
                        except Exception as err:
                            self.report(ch, err)
                        did = True
                if not did:
                    job = self.job  # an emergency command read may have stopped it
                    printing = job is not None and not job.paused
            else:
                did = False
            if printing and not did:
                unpumped += 1
                try:
                    self.run_job_line()
                except Exception as err:
                    job.intake.take()
                    if not isinstance(err, Halted):
                        self.broadcast("Error:%s (file %s, line %d)" % (err, job.name, job.line))
                        job.paused = True
                did = True
            if did:
                # Between lines that need no wait: heater control, the step-loop check
                # and the watchdog must not starve while lines come back to back. (A
                # call of its own would cost every line the chip's tens of us.)
                if time.ticks_diff(time.ticks_ms(), self._background_at_ms) >= \
                        _BACKGROUND_EVERY_MS:
                    self._run_background()
                continue
            # Plain loops, no list or generator to allocate: this runs on every idle
            # turn.
            lockstep = True
            closed = None
            for ch in self.channels:
                if not ch.open and not ch.intake.waiting:
                    closed = ch
                    break
                lockstep = lockstep and ch.lockstep
            if closed is not None:
                if closed.intake.n or closed.intake.fault:  # a last line with no newline
                    self.current = closed
                    self.report(closed, GcodeError(closed.intake.error_text(LINE_CUT)))
                self.channels.remove(closed)
                continue
            if self.channels and not self.listeners and lockstep:
                # Simulation in lockstep: time only passes when the firmware waits.
                self.channels[0].pump(self, block=True)
                continue
            self.machine_idle()
            self._turn()
        for fn in self.finish:
            fn()

    # --- protocol commands ---
    # M110 N<n>: the next line number expected is n+1. Example: N0 M110 N0*125
    def m110(self, line):
        default = self.parser.line_number()
        if default is None:
            default = self.current.last_n
        self.current.last_n = line.int("N", default, lo=-1)

    # M112: emergency stop. The receive path acts on it before it is queued.
    def m112(self, line):
        self.emergency_stop()

    # M108: end the heating wait (M109, M190, M116) running when it arrives, or one
    # that arrived before it and has yet to start; the targets stay. From a file it
    # does nothing, as no wait runs beside it.
    def m108(self, line):
        if self.current is not None:
            self._breaks_run += 1
            if self.breaks_used < self._breaks_run:
                self.breaks_used = self._breaks_run

    # M410: quick stop. Queued moves are dropped at once and the position is where the
    # axes stopped; heaters stay on. Acted on when the line arrives from a host; from
    # a file it runs in its turn.
    def m410(self, line):
        if self.current is None:
            self.quick_stop()

    # M876 S<choice>: a host's answer to a prompt (M600's Continue). The receive path
    # acts on it, ending the wait that showed the prompt; in its turn it does nothing.
    # Example: M876 S0
    def m876(self, line):
        pass

    # M113 [S<seconds>]: how often a long command sends `busy: processing` (0: never,
    # at most 60); alone, report. Example: M113 S2
    def m113(self, line):
        if not line.has("S"):
            self.reply("echo:M113 S%d" % (self.busy_every_ms // 1000))
            return
        self.busy_every_ms = line.int("S", lo=0, hi=60) * 1000

    # M997: finish the queued moves, then leave the firmware: heaters and drivers off,
    # and the board restarts into the MicroPython REPL once, so `mixstep deploy`
    # (mpremote) can reach it: while serving, Ctrl-C bytes are data. Example: M997
    def m997(self, line):
        self.leaving = "M997"

    # M999: clear a halt; moves and heating are accepted again.
    def m999(self, line):
        self.clear_halt()

    # M932: clear the error state and refuse every command after the next failure.
    def m932(self, line):
        self.refuse_after_error = True
        self.failed = False

    # M933: leave refuse-after-error mode.
    def m933(self, line):
        self.refuse_after_error = False
        self.failed = False
