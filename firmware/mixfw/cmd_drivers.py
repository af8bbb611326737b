# Stepper driver commands for boards whose TMC2209s share a UART (board.TMC_UART):
# Marlin's M906 (run current), M569 (stealthChop or spreadCycle) and M122 (driver
# report). Handlers parse; the settings live in the configuration (driver_* options,
# M503 lists them) and tmc.Drivers writes them to the drivers.
from mixfw.gcode import GcodeError, command_key
from mixfw.tmc import Drivers, TmcError

_LETTERS = "XYZE"


class DriverCommands:
    def __init__(self, printer, config, drivers, diagnostics):
        self.printer = printer
        self.config = config
        self.drivers = drivers
        self.diagnostics = diagnostics  # M122's report of the printer, which comes first

    def _set(self, pairs):
        """Store driver options and write them; a setting no driver can take is
        refused before anything changes, and a driver that doesn't take it is an error."""
        before = [(name, self.config.get(name)) for name, _ in pairs]
        self.config.update(pairs)
        try:
            self.drivers.check(self.config.settings)
        except TmcError:
            self.config.update(before)
            raise
        problems = self.drivers.apply(self.config.settings)
        if problems:
            raise TmcError("; ".join(problems) + "; the setting is kept, and M122 writes "
                           "it once the driver answers")

    def _letters(self, line):
        return [ch for ch in _LETTERS if line.has(ch)]

    # M906 [X<mA>] [Y<mA>] [Z<mA>] [E<mA>]: RMS run current of each axis's driver (E:
    # the E socket's); the motor holds at half of it. No words: report. Example:
    # M906 X800 Y800 Z800 E650
    def m906(self, line):
        letters = self._letters(line)
        if not letters:
            self.printer.reply("echo:M906 " + " ".join(
                ch + self.config.format("driver_current_ma_" + ch.lower())
                for ch in _LETTERS))
            return
        self._set([("driver_current_ma_" + ch.lower(), line.int(ch)) for ch in letters])

    # M569 S<0|1> [X] [Y] [Z] [E]: chopper of the named drivers (none named: all):
    # S0 stealthChop (quiet), S1 spreadCycle (more torque at speed). No S: report.
    # Example: M569 S1 X Y
    def m569(self, line):
        if not line.has("S"):
            for mode in (0, 1):
                named = [ch for ch in _LETTERS if bool(self.config.get(
                    "driver_spreadcycle_" + ch.lower())) == bool(mode)]
                if named:
                    self.printer.reply("echo:M569 S%d %s" % (mode, " ".join(named)))
            return
        mode = line.int("S", lo=0, hi=1)
        for ch in _LETTERS:
            if line.has_value(ch):
                raise GcodeError("M569 %s takes no value: name the axes, S0 or S1 sets "
                                 "the mode" % ch)
        self._set([("driver_spreadcycle_" + ch.lower(), mode)
                   for ch in (self._letters(line) or _LETTERS)])

    # M122: each driver's microsteps, run current and chopper as it reports them, or
    # why it doesn't answer. A driver that was reset (its motor power cycled) or
    # never answered is set up again first. Example: M122
    def m122(self, line):
        if self.diagnostics is not None:
            self.diagnostics(line)
        for text in self.drivers.status(self.config.settings):
            self.printer.reply("echo:" + text)


def setup(machine, tmc_uart, config, printer):
    """Open the drivers' UART, configure every driver and register the commands. A
    driver that doesn't answer (its motor power off, most often) is a warning: the
    printer still starts, and M122 sets it up once it answers."""
    uart = machine.UART(tmc_uart["uart"], baudrate=tmc_uart["baud"],
                        tx=machine.Pin(tmc_uart["tx"]), rx=machine.Pin(tmc_uart["rx"]),
                        timeout=20, timeout_char=5)
    drivers = Drivers(uart, tmc_uart)
    try:
        problems = drivers.apply(config.settings)
    except TmcError as e:
        problems = [str(e)]
    for text in problems:
        config.warn("echo:Warning: %s; it steps on its MS1/MS2 straps until M122 sets "
                    "it up" % text)
    c = DriverCommands(printer, config, drivers,
                       printer.commands.get(command_key("M", 122)))

    def apply(settings):
        for text in drivers.apply(settings):
            printer.reply("echo:Warning: " + text)

    config.appliers.append(apply)
    printer.add_command("M", 906, c.m906)  # driver run current mA: X Y Z E
    printer.add_command("M", 569, c.m569)  # driver chopper: S0 stealthChop, S1 spreadCycle
    printer.add_command("M", 122, c.m122)  # driver report; sets up drivers that were reset
    return drivers
