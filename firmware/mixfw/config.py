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
from mixfw.options import SCHEMA, FIRMWARE_DEFAULTS, FLOAT, INT, BOOL, MIX, PAIR, EACH
from mixfw.mixer import normalize, default_tool_mixes

HEADER = "# mixstep configuration, version 1\n"
_CRC_PREFIX = b"crc32 = "
_CRC_LINE = "crc32 = %08x\n"
_MAX_FILE_BYTES = 16384  # far above a real file; bounds what a junk file costs in RAM

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
    """The board's file system. Tests pass an object with the same four methods to
    simulate a reset in the middle of a save."""

    def open(self, path, mode):
        return open(path, mode)

    def rename(self, old, new):
        os.rename(old, new)

    def remove(self, path):
        os.remove(path)

    def stat(self, path):
        return os.stat(path)


class Option:
    def __init__(self, name, key, index, kind, lo, hi, restart, help_text):
        self.name = name
        self.key = key  # the settings key
        self.index = index  # position in the setting's tuple; -1 for a plain value
        self.kind = kind
        self.lo = lo
        self.hi = hi
        self.restart = restart
        self.help = help_text

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
                FLOAT: " number", INT: " whole number", BOOL: " 0 or 1"}[self.kind]))
        return self.check(v)

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
        if self.kind == INT and not isinstance(v, int):
            raise ConfigError("%s: %r is not a whole number" % (self.name, v))
        v = float(v) if self.kind == FLOAT else int(v)
        if not v >= self.lo:  # also refuses nan
            raise ConfigError("%s = %s is below the minimum %s" % (
                self.name, self.format(v), self.format(self.lo)))
        if v > self.hi:
            raise ConfigError("%s = %s is above the maximum %s" % (
                self.name, self.format(v), self.format(self.hi)))
        return v

    def format(self, v):
        if self.kind == PAIR:
            return "%d:%d:%r:%r" % (v[0], v[1], float(v[2]), float(v[3]))
        if self.kind == MIX:
            return ":".join("%d" % w for w in v)
        if self.kind == FLOAT:
            return repr(float(v))  # repr round-trips exactly through float()
        return "%d" % v


def _options(defaults):
    opts = []
    for key, axes, kind, lo, hi, restart, help_text in SCHEMA:
        if key not in defaults:
            continue
        if axes == EACH:
            axes = ["%d" % i for i in range(len(defaults[key]))]
        if not axes:
            opts.append(Option(key, key, -1, kind, lo, hi, restart, help_text))
        for i, axis in enumerate(axes):
            opts.append(Option(key + "_" + axis, key, i, kind, lo, hi, restart,
                               axis.upper() + ": " + help_text))
        if kind == MIX:
            for o in opts[-len(axes):]:
                o.width = defaults["drives"]
        if kind == PAIR:
            for o in opts[-len(axes):]:
                o.width = len(defaults["tool_mixes"])
    return opts


class Config:
    def __init__(self, board_settings, path, storage=None, warn=None):
        """board_settings: the board's SETTINGS (not modified). path: the file on flash.
        warn(text): prints one `echo:` line, used when the saved file can't be loaded."""
        self.path = path
        self.storage = storage or FileStorage()
        self.warn = warn or (lambda text: None)
        self.appliers = []  # fn(settings) each, called by apply() (M930)
        self.before_save = []  # fn() each: bring running state (counters) into settings
        defaults = dict(FIRMWARE_DEFAULTS)
        defaults.update(board_settings)
        if "drives" in defaults and "drive_steps_per_mm" not in defaults:
            defaults["drive_steps_per_mm"] = (defaults["steps_per_mm"][3],) * defaults["drives"]
        if "drives" in defaults and "filament_used_mm" not in defaults:
            defaults["filament_used_mm"] = (0.0,) * defaults["drives"]
        if "drives" in defaults and "tool_mixes" not in defaults:
            defaults["tool_mixes"] = default_tool_mixes(
                defaults["drives"], defaults.get("virtual_tools", 16))
        self.options = _options(defaults)
        self.by_name = {o.name: o for o in self.options}
        self.settings = dict(defaults)  # the live dict: changed in place, never replaced
        self.defaults = {}
        try:
            for o in self.options:
                self.defaults[o.name] = o.check(self._read_setting(o))
        except ConfigError as e:
            raise ConfigError("board default %s" % e)
        self.set_defaults()
        self._mark_running()

    # --- values ---
    def option(self, name):
        o = self.by_name.get(name)
        if o is None:
            raise ConfigError("unknown option %r (M503 lists them)" % name)
        return o

    def _read_setting(self, o):
        v = self.settings[o.key]
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
        s = self.settings
        for o, v in checked:
            if o.index < 0:
                s[o.key] = v
            else:
                t = list(s[o.key])
                t[o.index] = v
                s[o.key] = tuple(t)

    def set(self, name, value):
        self.update(((name, value),))

    def reset(self, name):
        """Back to the board's default (M926 without V)."""
        self.option(name)  # an unknown name is refused here
        self.set(name, self.defaults[name])

    def set_defaults(self):
        self.update(self.defaults.items())

    def format(self, name):
        o = self.option(name)
        return o.format(self._read_setting(o))

    def describe(self, name):
        """One line M926 takes back, its help as a comment."""
        o = self.option(name)
        limits = "" if o.kind in (MIX, PAIR) else ", %s..%s" % (o.format(o.lo), o.format(o.hi))
        return "M926 I%s V%s ; %s%s%s" % (
            name, self.format(name), o.help, limits, " (restart)" if o.restart else "")

    # --- applying ---
    def _mark_running(self):
        self.running = {o.name: self._read_setting(o) for o in self.options if o.restart}

    def pending_restart(self):
        """Restart options whose value differs from what the machine was built with."""
        return [o.name for o in self.options
                if o.restart and self._read_setting(o) != self.running[o.name]]

    def apply(self):
        """M930: hand the settings to every applier; returns pending_restart()."""
        for fn in self.appliers:
            fn(self.settings)
        return self.pending_restart()

    # --- storage ---
    def text(self):
        body = HEADER + "".join(
            "%s = %s\n" % (o.name, self.format(o.name)) for o in self.options)
        data = body.encode()
        return data + (_CRC_LINE % crc32(data)).encode()

    def save(self):
        """M500. Raises ConfigError if the file system refuses."""
        if self.path is None:
            raise ConfigError("this printer has no configuration storage")
        for fn in self.before_save:
            fn()
        tmp = self.path + ".tmp"
        fs = self.storage
        try:
            f = fs.open(tmp, "wb")
            try:
                f.write(self.text())
            finally:
                f.close()
            fs.rename(tmp, self.path)
        except OSError as e:
            raise ConfigError("could not save %s: %s" % (self.path, e))

    def _parse(self, data):
        """name -> value from a file's bytes; raises ConfigError naming the problem."""
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
        if lines[0] + "\n" != HEADER:
            raise ConfigError("unsupported header %r" % lines[0])
        values = {}
        for n in range(1, len(lines) - 1):
            name, eq, text = lines[n].partition("=")
            name = name.strip()
            try:
                if not eq:
                    raise ConfigError("expected name = value")
                if name in values:
                    raise ConfigError("%s given twice" % name)
                values[name] = self.option(name).parse(text.strip())
            except ConfigError as e:
                raise ConfigError("line %d: %s" % (n + 1, e))
        return values

    def _read(self, path):
        """The values saved in path, None if there is no such file."""
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
        interrupted save, else None; problem says what was wrong with the file."""
        problem = None
        if self.path is None:
            return None, None
        try:
            values = self._read(self.path)
            if values is not None:
                return values, None
        except ConfigError as e:
            problem = "%s: %s" % (self.path, e)
        tmp = self.path + ".tmp"
        try:
            values = self._read(tmp)
        except ConfigError:
            values = None
        if values is None:
            return None, problem
        # Finish the interrupted save, so the next save can't truncate the only copy.
        # If that fails the values are still good; the next complete save replaces both.
        try:
            self.storage.rename(tmp, self.path)
        except OSError:
            pass
        if problem:
            problem += "; took the complete %s" % tmp
        return values, problem

    def load(self):
        """M501: replace the settings with the saved ones (all or nothing). Returns a
        note if the file itself was bad but an interrupted save's copy was taken."""
        values, problem = self._read_saved()
        if values is None:
            raise ConfigError(problem or "no saved configuration in %s" % self.path)
        self.update(tuple(self.defaults.items()) + tuple(values.items()))
        return problem

    def boot(self):
        """At start-up, before the machine is assembled: load the saved configuration.
        A bad file leaves the defaults and warns; no file at all is a first boot."""
        values, problem = self._read_saved()
        if values is not None:
            self.update(tuple(self.defaults.items()) + tuple(values.items()))
        if problem:
            self.warn("echo:config %s%s" % (
                problem, "" if values is not None else "; using defaults"))
        self._mark_running()
