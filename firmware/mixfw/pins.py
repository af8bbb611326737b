# Pins: how the step loop's GPIO masks reach the pins, and the ENABLE and endstop
# pins. With pin_writer "registers" the step loop writes the chip's set/clear
# registers itself (see the end of stepper.tick); "pin" is the portable Pin.value path.

_AXIS_NAMES = const(("x", "y", "z"))
# Per chip: register block address, and byte offsets of the GPIO output set and clear
# registers, then of the set and clear registers for GPIO 32+ (0: none).
REGISTERS = {
    "rp2040": (0xD0000000, 0x014, 0x018, 0, 0),  # SIO GPIO_OUT_SET / GPIO_OUT_CLR
    "rp2350": (0xD0000000, 0x018, 0x020, 0, 0),  # SIO GPIO_OUT_SET / GPIO_OUT_CLR
    "esp32": (0x3FF44000, 0x008, 0x00C, 0x014, 0x018),  # GPIO_OUT_W1TS/W1TC, OUT1_W1TS/W1TC
}
# GPIOs the step path can drive: masks are 30 bits wide (31-bit small ints on the
# chips), and ESP32's GPIO 32/33 ride on bits 28/29, as it has no GPIO 28..31.
# Ranges and literal tuples: nothing to build in RAM at import.
STEP_GPIOS = {
    "rp2040": range(30), "rp2350": range(30), "sim": range(30),
    "esp32": (0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15, 16, 17, 18, 19,
              21, 22, 23, 25, 26, 27, 32, 33),
}


def mask_bit(chip, gpio):
    """The bit of a GPIO in step-loop masks."""
    return gpio - 4 if chip == "esp32" and gpio >= 32 else gpio


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
        self.chip = settings.get("chip", "sim")
        Pin = machine.Pin
        self.by_gpio = [None] * 32
        self.step_masks = []  # X Y Z then drives
        self.dir_masks = []
        self.enable = []  # X Y Z then drives
        names = list(_AXIS_NAMES) + ["e%d" % i for i in range(self.drives)]
        for name in names:
            self.step_masks.append(self._out(Pin, pin_map, name + "_step", 0))
            self.dir_masks.append(self._out(Pin, pin_map, name + "_dir", 0))
        self.enable_level = 0 if settings["enable_active_low"] else 1
        for name in names:
            gpio = pin_map[name + "_enable"]
            self.enable.append(Pin(gpio, Pin.OUT, value=1 - self.enable_level))
        endstop_high = settings["endstop_active_high"]
        pull = Pin.PULL_UP if settings.get("endstop_pullup") else None
        self.endstop_pins = [Pin(pin_map[a + "_min"], Pin.IN, pull) for a in _AXIS_NAMES]
        self.endstop_level = 1 if endstop_high else 0
        top = 0
        for g in range(32):
            if self.by_gpio[g] is not None:
                top = g + 1
        by_gpio = self.by_gpio

        def out(set_mask, clr_mask):
            _write(by_gpio, top, set_mask, clr_mask)

        self.out = out
        # The register path: where the step loop writes, and the word offsets it uses.
        self.registers = None
        if settings.get("pin_writer", "pin") == "registers":
            self.registers = self._register_block(machine)
        inverted = settings.get("invert_dir", ())
        self.dir_invert_mask = 0
        for i, name in enumerate(names):
            if name in inverted:
                self.dir_invert_mask |= self.dir_masks[i]
        # What homing moves stop at, X Y Z, and the level each reads when triggered:
        # a probing move puts the probe in Z's place (mesh.py), as the step loop calls
        # endstops() and cannot be handed another reader.
        stops = self.stops = list(self.endstop_pins)
        levels = self.stop_levels = [self.endstop_level] * 3

        def endstops():
            return ((stops[0].value() == levels[0]) | ((stops[1].value() == levels[1]) << 1)
                    | ((stops[2].value() == levels[2]) << 2))

        self.endstops = endstops

    def _register_block(self, machine):
        if self.chip not in REGISTERS:
            raise ValueError("pin_writer registers: no set/clear registers known for chip %r"
                             % self.chip)
        base, set_at, clr_at, hi_set_at, hi_clr_at = REGISTERS[self.chip]
        # The simulated chip offers a RAM bank laid out like this chip's registers.
        bank = getattr(machine, "register_bank", None)
        address = bank(self.chip) if bank else base
        return address, (set_at // 4, clr_at // 4, hi_set_at // 4, hi_clr_at // 4)

    def _out(self, Pin, pin_map, name, level):
        gpio = pin_map[name]
        if gpio not in STEP_GPIOS.get(self.chip, ()):
            raise ValueError("%s on GPIO %d: the step path of a %s drives GPIO %s" % (
                name, gpio, self.chip, tuple(STEP_GPIOS.get(self.chip, ()))))
        bit = mask_bit(self.chip, gpio)
        self.by_gpio[bit] = Pin(gpio, Pin.OUT, value=level)
        return 1 << bit

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
