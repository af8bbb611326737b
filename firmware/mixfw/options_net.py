# The options of a board with a network (its settings take defaults.NETWORK) and the
# password's kind, options.SECRET. A module of its own, loaded by the configuration
# only on such a board: a Pico keeps the code and constants of every module it loads
# in RAM, and has no network to spend them on. Pure data and checks: imports on
# CPython too.

# Rows as options.SCHEMA's (the TCP console's own two are there, older than this).
NETWORK_ROWS = (
    ("drive_colour_rgb",           "each", "int",   0,       0xFFFFFF,    False),
    ("net_password",               "",     "secret_text", 8,  64,          False),
    ("net_idle_timeout_s",         "",     "int",   0,       86400,       False),
    ("web_page_port",              "",     "int",   0,       65535,       True),
)


def check_secret(option, v, error):
    """The password as M926 carries it: one word (a ";" would begin a comment), empty
    or option.lo to option.hi characters. error: the configuration's exception."""
    if not isinstance(v, str) or v and not (option.lo <= len(v) <= option.hi
                                            and v.split() == [v]):
        raise error("%s: must be empty or %d to %d characters without spaces"
                    % (option.name, option.lo, option.hi))
    return v


def describe_secret(name, text, value):
    """M925's line for the password: a comment (so M503's lines sent back leave it as
    it is) that says whether one is set, never what it is."""
    return "; M926 I%s V... ; %s (%s)" % (name, text,
                                          "set, not shown" if value else "none set yet")
