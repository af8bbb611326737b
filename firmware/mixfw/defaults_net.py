# What a board with a network adds to defaults.SETTINGS (SETTINGS =
# dict(defaults.SETTINGS, **defaults_net.NETWORK, ...)); their options are
# options_net.py's. Plain data, as defaults.py, in a module of its own: a board without
# a network never loads it, and a Pico keeps every module it loads in RAM.

# The web page and the network console's password (none: both off, M926
# Inet_password V... sets one). A connection that sends no whole line for
# net_idle_timeout_s is closed (0: never). The filaments' colours, 0xRRGGBB, one per
# drive (the rest dropped), which the web page shows mixed (`mixstep preview`'s
# defaults too). The TCP console's port is defaults.SETTINGS', older than this.
NETWORK = {
    "drive_colour_rgb": (0xE03030, 0x30A0E0, 0xF0D020, 0x40C040, 0xA050D0, 0xF0F0F0),
    "net_password": "",
    "net_idle_timeout_s": 600,
    "web_page_port": 80,
}
