# Filament colours and the colour a mix prints: the web page's mix editor and `mixstep
# preview`. Not loaded at boot: a board keeps every name its modules use in RAM.

from mixfw.defaults_net import NETWORK

DRIVE_RGB = NETWORK["drive_colour_rgb"]


def mix_rgb(weights, drive_rgb):
    """The colour a mix prints, 0xRRGGBB: each channel the weights' mean of the
    filaments' (a linear mix, as `mixstep preview` draws it), rounded."""
    total = sum(weights)
    out = 0
    for shift in (16, 8, 0):
        level = sum(w * (c >> shift & 255) for w, c in zip(weights, drive_rgb))
        out |= ((2 * level + total) // (2 * total) if total else 0) << shift
    return out


def drive_rgb(settings):
    """The drives' colours: the board's setting, or the defaults."""
    return settings.get("drive_colour_rgb") or (DRIVE_RGB * 2)[:settings["drives"]]
