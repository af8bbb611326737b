# The options of a board with a network (its settings take defaults_net.NETWORK): their
# rows in the configuration and the password's kind of option. A module of its own,
# which the configuration imports only on such a board: a Pico keeps the code and
# constants of every module it loads in RAM, and has no network to spend them on.
# Imports on CPython too.
from mixfw.config import Config, Option, ConfigError
from mixfw.options import SCHEMA


class SecretOption(Option):
    """Text kept by M500 and never shown: the password. lo..hi is its length, or
    empty for none; M503 and M925 say whether it is set, never what it is."""

    def parse(self, text):
        return self.check(text)

    def check(self, v):
        """One word (a ";" would begin a comment), empty or lo to hi characters."""
        if not isinstance(v, str) or v and not (self.lo <= len(v) <= self.hi
                                                and v.split() == [v]):
            raise ConfigError("%s: must be empty or %d to %d characters without spaces"
                              % (self.name, self.lo, self.hi))
        return v

    def format(self, v):
        return v

    def describe(self, text, v):
        """A comment (so M503's lines sent back leave the password as it is) that says
        whether one is set."""
        return "; M926 I%s V... ; %s (%s)" % (self.name, text,
                                              "set, not shown" if v else "none set yet")


# Rows as options.SCHEMA's, with a row's own kind of option as a seventh field.
NETWORK_ROWS = (
    ("drive_colour_rgb",           "each", "int",   0,       0xFFFFFF,    False),
    ("net_password",               "",     "text",  8,       64,          False, SecretOption),
    ("net_idle_timeout_s",         "",     "int",   0,       86400,       False),
    ("web_page_port",              "",     "int",   0,       65535,       True),
)

# Every configuration made from now on knows them; they are a board's options only if
# its settings have them.
Config.schema = SCHEMA + NETWORK_ROWS
