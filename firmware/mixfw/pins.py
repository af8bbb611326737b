# Pins: turns the step loop's GPIO masks into pin writes, and owns the ENABLE and
# endstop pins. This is the portable Pin.value path; chips with set/clear registers
# get a faster writer with the same out(set_mask, clr_mask) signature.
from mixfw.compat import micropython, ptr32

AXIS_NAMES = ("x", "y", "z")


@micropython.viper
def _write(pins, gpio_top: int, set_mask: int, clr_mask: int):
    g = 0
    m = set_mask | clr_mask
    while g < gpio_top and m:
        if m & 1:
            pins[g].value(1 if (set_mask >> g) & 1 else 0)
        m = m >> 1
        g += 1


class Pins:
    def __init__(self, machine, pin_map, settings):
        self.drives = settings["drives"]
        Pin = machine.Pin
        self.by_gpio = [None] * 32
        self.step_masks = []  # X Y Z then drives
        self.dir_masks = []
        self.enable = []  # X Y Z then drives
        names = list(AXIS_NAMES) + ["e%d" % i for i in range(self.drives)]
        for name in names:
            self.step_masks.append(self._out(Pin, pin_map, name + "_step", 0))
            self.dir_masks.append(self._out(Pin, pin_map, name + "_dir", 0))
        self.enable_level = 0 if settings["enable_active_low"] else 1
        for name in names:
            gpio = pin_map[name + "_enable"]
            self.enable.append(Pin(gpio, Pin.OUT, value=1 - self.enable_level))
        endstop_high = settings["endstop_active_high"]
        self.endstop_pins = [Pin(pin_map[a + "_min"], Pin.IN) for a in AXIS_NAMES]
        self.endstop_level = 1 if endstop_high else 0
        top = 0
        for g in range(32):
            if self.by_gpio[g] is not None:
                top = g + 1
        by_gpio = self.by_gpio

        def out(set_mask, clr_mask):
            _write(by_gpio, top, set_mask, clr_mask)

        self.out = out
        e0, e1, e2 = self.endstop_pins
        lvl = self.endstop_level

        def endstops():
            return ((e0.value() == lvl) | ((e1.value() == lvl) << 1)
                    | ((e2.value() == lvl) << 2))

        self.endstops = endstops

    def _out(self, Pin, pin_map, name, level):
        gpio = pin_map[name]
        if not 0 <= gpio < 30:
            raise ValueError("%s on GPIO %d: the step path drives GPIO 0..29" % (name, gpio))
        self.by_gpio[gpio] = Pin(gpio, Pin.OUT, value=level)
        return 1 << gpio

    def axis_dir_masks(self):
        """DIR masks per planner axis: X Y Z, and E = every drive's DIR pin."""
        e = 0
        for m in self.dir_masks[3:]:
            e |= m
        return self.dir_masks[:3] + [e]

    def set_enabled(self, index, on):
        self.enable[index].value(self.enable_level if on else 1 - self.enable_level)

    def all_enabled(self, on):
        for i in range(len(self.enable)):
            self.set_enabled(i, on)
