# The printer core: takes lines from the intake, parses them, runs the handler the
# command table names, and answers each line exactly once. Handlers come from the
# cmd_* modules, each of which registers its own commands.
from mixfw.gcode import Parser, GcodeError
from mixfw.intake import Intake, LINE_OK


def command_key(letter, number):
    return ord(letter) * 10000 + number


class Printer:
    def __init__(self, line_bytes, idle):
        self.intake = Intake(line_bytes)
        self.parser = Parser()
        self.commands = {}
        self.helps = {}
        self.idle = idle
        self.console = None
        self.finish = []  # called when a console stream ends (simulation)

    def register(self, name, handler, help_text):
        """name like "G1" or "M163"; "T" takes every tool number."""
        letter = name[0]
        number = int(name[1:]) if len(name) > 1 else -1
        self.commands[command_key(letter, number)] = handler
        self.helps[name] = help_text

    def reply(self, text):
        self.console.write(text)
        self.console.write("\n")

    def run_line(self, buf, n):
        """Parse and run one line; returns text to follow `ok` or None. Raises on bad input."""
        line = self.parser.parse(buf, n)
        if not line.letter:
            return None
        handler = self.commands.get(command_key(line.letter, line.number))
        if handler is None and line.letter == "T":
            handler = self.commands.get(command_key("T", -1))
        if handler is None:
            self.reply('echo:Unknown command: "%s%d"' % (line.letter, line.number))
            return None
        return handler(line)

    def answer(self, status):
        intake = self.intake
        suffix = None
        try:
            if status != LINE_OK:
                raise GcodeError(intake.error_text(status))
            suffix = self.run_line(intake.buf, intake.n)
        except ValueError as e:  # GcodeError, MixError, PlanError: bad input
            self.reply("Error:%s" % e)
        intake.take()
        if suffix:
            self.reply("ok " + suffix)
        else:
            self.console.write("ok\n")

    def serve(self, console):
        """Answer lines from the console until its stream ends."""
        self.console = console
        rx = bytearray(64)
        mv = memoryview(rx)
        feed = self.intake.feed
        while True:
            n = console.readinto(mv)
            if n < 0:
                break
            if n == 0:
                self.idle()
                continue
            for i in range(n):
                status = feed(rx[i])
                if status:
                    self.answer(status)
        for f in self.finish:
            f()
