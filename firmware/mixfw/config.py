# Runtime configuration: owns the live `settings` dict every module reads, checks
# each value against the schema in options.py, and keeps it in a text file on the
# board's flash.
#
# The file is one `name = value` per line between a version header and a CRC-32 line,
# so a partial or corrupt file is told apart from a good one. Saving writes
# `<path>.tmp` and renames it over the file. littlefs and the unix port replace the
# old file atomically; FAT removes it first, so a reset can leave only the complete
# `.tmp`, which loading then takes and renames into place. A reset at any point of a
# save thus leaves the old or the new configuration loadable.
#
# Pure logic: no `machine`; the file system is passed in (see FileStorage).
import os
from mixfw.options import SCHEMA, FIRMWARE_DEFAULTS, FLOAT, INT, BOOL, MIX, PAIR, EACH, POW2
from mixfw.mixer import normalize, default_tool_mixes
from mixfw.pwm import CLOCK_HZ, HEATER_OPTIONS, range_hz, clock_text

_HEADER = const("# mixstep configuration, version 1\n")
# The file is the firmware's: an edit by hand fails the checksum, and the printer then
# starts with its defaults and says so.
_NOTE = const("# written by M500; set options with M926\n")
_CRC_PREFIX = const(b"crc32 = ")
_CRC_LINE = const("crc32 = %08x\n")
_MAX_FILE_BYTES = const(16384)  # far above a real file; bounds what a junk file costs in RAM

# CRC-32 (zlib's polynomial) four bits at a time: a 16-entry table instead of 256.
_CRC_NIBBLE = (
    0x00000000, 0x1DB71064, 0x3B6E20C8, 0x26D930AC, 0x76DC4190, 0x6B6B51F4,
    0x4DB26158, 0x5005713C, 0xEDB88320, 0xF00F9344, 0xD6D6A3E8, 0xCB61B38C,
    0x9B64C2B0, 0x86D3D2D4, 0xA00AE278, 0xBDBDF21C,
)


def crc32(data):
    crc = 0xFFFFFFFF
    table = _CRC_NIBBLE
    for b in data:
        crc ^= b
        crc = (crc >> 4) ^ table[crc & 15]
        crc = (crc >> 4) ^ table[crc & 15]
    return crc ^ 0xFFFFFFFF


class ConfigError(ValueError):
    """A value, name or file that can't be taken: answered with `Error:` and the reason."""


class FileStorage:
    """The board's file system, and the one way the firmware changes what is on it
    (the configuration, uploads, deletions). The rp2 port erases and programs flash
    with every interrupt off, 45 ms typically and up to 400 ms for a 4 KB sector,
    while the step path runs a few ms ahead of the pins: a write while the axes move
    would stop them dead and restart them at full speed (a layer shift and a blob).
    So every change (a file opened for writing, a rename, a removal) first waits,
    through wait_idle, until the step path has no work, as M400 does: the moves end
    with their planned deceleration and the `ok` waits. A file opened for writing is
    written and closed before anything else runs, so no move can start in between.
    Tests pass an object with the same four methods to simulate a reset in the
    middle of a save."""

    def __init__(self):
        self.wait_idle = None  # fn(): the planner's synchronize, once the machine is built

    def _settle(self):
        if self.wait_idle is not None:
            self.wait_idle()

    def open(self, path, mode):
        if "r" not in mode:
            self._settle()
        return open(path, mode)

    def rename(self, old, new):
        self._settle()
        os.rename(old, new)

    def remove(self, path):
        self._settle()
        os.remove(path)

    def stat(self, path):
        return os.stat(path)


class Option:
    """One option, made from its schema row when it is asked for. The configuration
    keeps no object per option: the 116 options of a six-drive board would hold
    about 30 KB of heap on a 64-bit port (15 KB on a chip) for text that lives in
    the schema anyway."""

    def __init__(self, row, index, axis, width):
        """row: options.SCHEMA's; index: position in the setting's tuple, -1 for a plain
        value; axis: the name's suffix ("x", "3"); width: drives of a MIX, tools of a
        PAIR."""
        self.key, _axes, self.kind, self.lo, self.hi, self.restart = row[:6]
        self.index = index
        self.axis = axis
        self.name = self.key if index < 0 else self.key + "_" + axis
        self.width = width
        self.why = ""  # where a limit comes from, if not from the schema

    def parse(self, text):
        """The typed value of text as M926 or the file gives it."""
        if self.kind == PAIR:
            words = text.split(":")
            try:
                if len(words) != 4:
                    raise ValueError("4 fields")
                v = (int(words[0]), int(words[1]), float(words[2]), float(words[3]))
            except ValueError:
                raise ConfigError("%s: %r is not a tool pair from:to:l1_mm:l2_mm"
                                  % (self.name, text))
            return self.check(v)
        if self.kind == MIX:
            try:
                return self.check(tuple(float(w) for w in text.split(":")))
            except ValueError as e:
                raise ConfigError("%s: %r is not a mix w0:w1:...: %s" % (self.name, text, e))
        try:
            v = float(text) if self.kind == FLOAT else int(text)
        except ValueError:
            raise ConfigError("%s: %r is not a%s" % (self.name, text, {
                FLOAT: " number", BOOL: " 0 or 1"}.get(self.kind, " whole number")))
        return self.check(v)

    def describe(self, text, v):
        """Config.describe's line for value v, text the option's help."""
        if self.index >= 0:
            text = self.axis.upper() + ": " + text
        limits = "" if self.kind in (MIX, PAIR) else ", %s..%s" % (
            self.format(self.lo), self.format(self.hi))
        return "M926 I%s V%s ; %s%s%s" % (
            self.name, self.format(v), text, limits, " (restart)" if self.restart else "")

    def check(self, v):
        if self.kind == PAIR:
            tools = self.width
            if len(v) != 4 or not (0 <= v[0] < tools and 0 <= v[1] < tools):
                raise ConfigError("%s: tools %r must be T0..T%d" % (self.name, v[:2], tools - 1))
            for mm in v[2:]:
                if not self.lo <= mm <= self.hi:
                    raise ConfigError("%s: length %s is outside %s..%s mm" % (
                        self.name, mm, self.lo, self.hi))
            return (int(v[0]), int(v[1]), float(v[2]), float(v[3]))
        if self.kind == MIX:
            try:
                return normalize(v, self.width)
            except ValueError as e:
                raise ConfigError("%s: %s" % (self.name, e))
        if self.kind == BOOL:
            if v not in (0, 1):
                raise ConfigError("%s: %r is not 0 or 1" % (self.name, v))
            return bool(v)
        if self.kind in (INT, POW2) and not isinstance(v, int):
            raise ConfigError("%s: %r is not a whole number" % (self.name, v))
        if self.kind == POW2 and v & (v - 1):
            raise ConfigError("%s = %d is not a power of two (1, 2, 4, ...)" % (self.name, v))
        v = float(v) if self.kind == FLOAT else int(v)
        if not v >= self.lo:  # also refuses nan
            raise ConfigError("%s = %s is below the minimum %s%s" % (
                self.name, self.format(v), self.format(self.lo), self.why))
        if v > self.hi:
            raise ConfigError("%s = %s is above the maximum %s%s" % (
                self.name, self.format(v), self.format(self.hi), self.why))
        return v

    def format(self, v):
        if self.kind == PAIR:
            return "%d:%d:%r:%r" % (v[0], v[1], float(v[2]), float(v[3]))
        if self.kind == MIX:
            return ":".join("%d" % w for w in v)
        if self.kind == FLOAT:
            return repr(float(v))  # repr round-trips exactly through float()
        return "%d" % v


def _axes(row, settings):
    """The name suffixes of a schema row's options: letters, tuple positions, or none
    (a plain value)."""
    axes = row[1]
    if axes == EACH:
        return ["%d" % i for i in range(len(settings[row[0]]))]
    return list(axes)


def _put(settings, o, v):
    """Store option o's value v into a settings dict."""
    if o.index < 0:
        settings[o.key] = v
    else:
        t = list(settings[o.key])
        t[o.index] = v
        settings[o.key] = tuple(t)


class Config:
    schema = SCHEMA  # a board with a network adds its rows (options_net.py)

    def __init__(self, board_settings, path, storage=None, warn=None, clock_hz=None):
        """board_settings: the board's SETTINGS (not modified; kept for the defaults).
        path: the file on flash. warn(text): prints one `echo:` line, used when the
        saved file can't be loaded. clock_hz: the chip's system clock (machine.freq()),
        which bounds the PWM frequencies; None: the board's clock_hz (boot.py sets it),
        else the clock the chip boots with."""
        self.path = path
        self.storage = storage or FileStorage()
        self.warn = warn or (lambda text: None)
        self.appliers = []  # fn(settings) each, called by apply() (M930)
        self.before_save = []  # fn() each: bring running state (counters) into settings
        self.board_settings = board_settings
        if "net_password" in board_settings:  # a board with a network: its options too
            __import__("mixfw.options_net")  # (Config.schema; no name more on a Pico)
        defaults = self._board_defaults()
        self.chip = defaults.get("chip", "sim")
        self.clock_hz = (clock_hz or defaults.get("clock_hz")
                         or CLOCK_HZ.get(self.chip, CLOCK_HZ["sim"]))
        # Widths of the per-tool options, fixed by the board (as the firmware's arrays).
        self.mix_width = defaults.get("drives", 0)
        self.pair_width = len(defaults.get("tool_mixes", ()))
        self.settings = self._default_settings()  # the live dict: changed in place, never replaced
        self._mark_running()

    def _board_defaults(self):
        """The board's settings over the firmware's defaults, with the per-drive and
        per-tool settings the board leaves out filled in; not yet checked."""
        defaults = dict(FIRMWARE_DEFAULTS)
        defaults.update(self.board_settings)
        if "drives" in defaults and "drive_steps_per_mm" not in defaults:
            defaults["drive_steps_per_mm"] = (defaults["steps_per_mm"][3],) * defaults["drives"]
        if "drives" in defaults and "filament_used_mm" not in defaults:
            defaults["filament_used_mm"] = (0.0,) * defaults["drives"]
        if "drives" in defaults and "tool_mixes" not in defaults:
            defaults["tool_mixes"] = default_tool_mixes(
                defaults["drives"], defaults.get("virtual_tools", 16))
        if "drive_colour_rgb" in defaults:  # defaults_net.NETWORK's, for six drives
            defaults["drive_colour_rgb"] = defaults["drive_colour_rgb"][:defaults["drives"]]
        if "tool_mixes" in defaults and "tool_advance_k" not in defaults:
            defaults["tool_advance_k"] = (0.0,) * len(defaults["tool_mixes"])
        return defaults

    def _default_settings(self):
        """A whole settings dict at the board's defaults, every option checked."""
        defaults = self._board_defaults()
        try:
            for o in self._options_of(defaults):
                _put(defaults, o, o.check(self._read_setting(o, defaults)))
        except ConfigError as e:
            raise ConfigError("board default %s" % e)
        return defaults

    def _option(self, row, index, axis):
        width = self.mix_width if row[2] == MIX else self.pair_width if row[2] == PAIR else 0
        o = (Option if len(row) < 7 else row[6])(row, index, axis, width)  # its own kind
        if o.key.endswith("_pwm_hz"):
            self._pwm_limits(o)
        return o

    def _pwm_limits(self, o):
        """Narrow a PWM frequency's limits to what the chip makes at its clock; a
        heater's lowest stays the schema's (a software PWM goes below the chip's)."""
        chip_lo, chip_hi = range_hz(self.chip, self.clock_hz)
        lo = o.lo if o.key in HEATER_OPTIONS else max(o.lo, chip_lo)
        hi = min(o.hi, chip_hi)
        if (lo, hi) != (o.lo, o.hi):
            o.lo, o.hi = lo, hi
            o.why = " (the %s's PWM makes %d..%d Hz at %s)" % (
                self.chip, chip_lo, chip_hi, clock_text(self.clock_hz))

    def _options_of(self, settings):
        """Every option of these settings in schema order, made one at a time."""
        for row in self.schema:
            if row[0] not in settings:
                continue  # the board has no such setting (e.g. no bed)
            if not row[1]:
                yield self._option(row, -1, "")
            for i, axis in enumerate(_axes(row, settings)):
                yield self._option(row, i, axis)

    @property
    def options(self):
        """Every option, in the order M503 and the file list them."""
        return self._options_of(self.settings)

    # --- values ---
    def option(self, name):
        settings = self.settings
        for row in self.schema:
            key = row[0]
            if key not in settings or not name.startswith(key):
                continue
            if not row[1]:
                if name == key:
                    return self._option(row, -1, "")
            elif name[len(key):len(key) + 1] == "_":
                axes = _axes(row, settings)
                axis = name[len(key) + 1:]
                if axis in axes:
                    return self._option(row, axes.index(axis), axis)
        raise ConfigError("unknown option %r (M503 lists them)" % name)

    def _read_setting(self, o, settings=None):
        v = (self.settings if settings is None else settings)[o.key]
        return v if o.index < 0 else v[o.index]

    def get(self, name):
        return self._read_setting(self.option(name))

    def update(self, pairs):
        """Set (name, value) pairs, all or none: every value is checked first. A value
        may be text as M926 gives it."""
        checked = []
        for name, v in pairs:
            o = self.option(name)
            checked.append((o, o.parse(v) if isinstance(v, str) else o.check(v)))
        for o, v in checked:
            _put(self.settings, o, v)

    def set(self, name, value):
        self.update(((name, value),))

    def reset(self, name):
        """Back to the board's default (M926 without V)."""
        o = self.option(name)
        self.set(name, o.check(self._read_setting(o, self._board_defaults())))

    def set_defaults(self):
        self.settings.update(self._default_settings())

    def format(self, name):
        o = self.option(name)
        return o.format(self._read_setting(o))

    def describe(self, name, texts):
        """One line M926 takes back, its help (from texts: options_help.HELP) as a
        comment."""
        o = self.option(name)
        return o.describe(texts.get(o.key, ""), self._read_setting(o))

    # --- applying ---
    def _mark_running(self):
        """Keep the restart settings the machine is built with (the values are shared
        with the settings, which replace rather than change them)."""
        self.running = {row[0]: self.settings[row[0]] for row in self.schema
                        if row[5] and row[0] in self.settings}

    def pending_restart(self):
        """Restart options whose value differs from what the machine was built with."""
        return [o.name for o in self.options
                if o.restart and self._read_setting(o) != self._read_setting(o, self.running)]

    def apply(self):
        """M930: hand the settings to every applier; returns pending_restart()."""
        for fn in self.appliers:
            fn(self.settings)
        return self.pending_restart()

    # --- storage ---
    def text(self):
        body = _HEADER + _NOTE + "".join(
            "%s = %s\n" % (o.name, o.format(self._read_setting(o))) for o in self.options)
        data = body.encode()
        return data + (_CRC_LINE % crc32(data)).encode()

    def save(self):
        """M500. Waits until the queued moves have run (see FileStorage). Raises
        ConfigError if the file system refuses."""
        if self.path is None:
            raise ConfigError("this printer has no configuration storage")
        tmp = self.path + ".tmp"
        fs = self.storage
        try:
            f = fs.open(tmp, "wb")  # waits for the moves: the counters are where they end
            try:
                for fn in self.before_save:
                    fn()
                f.write(self.text())
            finally:
                f.close()
            fs.rename(tmp, self.path)
        except OSError as e:
            raise ConfigError("could not save %s: %s" % (self.path, e))

    def _parse(self, data):
        """(name -> value, skipped) from a file's bytes; raises ConfigError naming the
        problem if the file is damaged. The checksum says the file is as it was saved,
        so a value this firmware no longer takes (an option it doesn't have, a limit
        that changed with the firmware or the chip's clock) skips that line alone:
        skipped lists why, and the option keeps its default."""
        if not data.endswith(b"\n"):
            raise ConfigError("truncated (no final newline)")
        cut = data.rfind(b"\n", 0, len(data) - 1) + 1
        if not data.startswith(_CRC_PREFIX, cut):
            raise ConfigError("truncated (no checksum line)")
        body = data[:cut]
        # The whole line, not its number: "0x1F" and " 1f" would parse the same.
        if data[cut:] != (_CRC_LINE % crc32(body)).encode():
            raise ConfigError("checksum mismatch (file corrupt)")
        try:
            lines = body.decode().split("\n")
        except UnicodeError:
            raise ConfigError("not text")
        if lines[0] + "\n" != _HEADER:
            raise ConfigError("unsupported header %r" % lines[0])
        values = {}
        skipped = []
        for n in range(1, len(lines) - 1):
            if lines[n].startswith("#"):
                continue
            name, eq, text = lines[n].partition("=")
            name = name.strip()
            if not eq or name in values:
                raise ConfigError("line %d: %s" % (n + 1, "%s given twice" % name if eq
                                                   else "expected name = value"))
            try:
                values[name] = self.option(name).parse(text.strip())
            except ConfigError as e:
                skipped.append("line %d: %s" % (n + 1, e))
        return values, skipped

    def _read(self, path):
        """(values, skipped) saved in path (_parse), None if there is no such file."""
        fs = self.storage
        try:
            size = fs.stat(path)[6]
        except OSError:
            return None
        if size > _MAX_FILE_BYTES:
            raise ConfigError("%d bytes is too large for a configuration" % size)
        try:
            f = fs.open(path, "rb")
            try:
                data = f.read()
            finally:
                f.close()
        except OSError as e:
            raise ConfigError("unreadable: %s" % e)
        return self._parse(data)

    def _read_saved(self):
        """(values, problem): values from the file, else from a complete `.tmp` left by an
        interrupted save, else None; problem says what was wrong with the file, or
        which of its values were left out."""
        problem = None
        if self.path is None:
            return None, None
        try:
            read = self._read(self.path)
            if read is not None:
                return read[0], self._skipped(self.path, read[1])
        except ConfigError as e:
            problem = "%s: %s" % (self.path, e)
        tmp = self.path + ".tmp"
        try:
            read = self._read(tmp)
        except ConfigError:
            read = None
        if read is None:
            return None, problem
        values = read[0]
        # Finish the interrupted save, so the next save can't truncate the only copy.
        # If that fails the values are still good; the next complete save replaces both.
        try:
            self.storage.rename(tmp, self.path)
        except OSError:
            pass
        if problem:
            problem += "; took the complete %s" % tmp
        skipped = self._skipped(tmp, read[1])
        if skipped:
            problem = problem + "; " + skipped if problem else skipped
        return values, problem

    @staticmethod
    def _skipped(path, skipped):
        if not skipped:
            return None
        return "%s: %s; kept the default%s" % (path, "; ".join(skipped),
                                               "s" if len(skipped) > 1 else "")

    def load(self):
        """M501: replace the settings with the saved ones (all or nothing, but for values
        this firmware no longer takes). Returns a note if the file itself was bad but an
        interrupted save's copy was taken, or if values were left out."""
        if self.path is None:
            raise ConfigError("this printer has no configuration storage")
        values, problem = self._read_saved()
        if values is None:
            raise ConfigError(problem or "no saved configuration in %s" % self.path)
        self._take(values)
        return problem

    def _take(self, values):
        """The defaults overridden by values (option name -> checked value), all at once."""
        settings = self._default_settings()
        for name, v in values.items():
            _put(settings, self.option(name), v)
        self.settings.update(settings)

    def boot(self):
        """At start-up, before the machine is assembled: load the saved configuration.
        A bad file leaves the defaults and warns, as does a value left out for that
        option; no file at all is a first boot."""
        values, problem = self._read_saved()
        if values is not None:
            self._take(values)
        if problem:
            self.warn("echo:config %s%s" % (
                problem, "" if values is not None else "; using defaults"))
        self._mark_running()
