# Heater and fan PWM: the frequencies each chip's machine.PWM can make at its system
# clock, and where a heater is slower than that (a solid-state relay on a bed wants
# 1-5 Hz; rp2's divider stops at 8 Hz at 125 MHz), a software PWM (softpwm.py).
#
# Pure logic: imports on CPython too. The machine module is passed in.

# The system clock each chip boots with; a board's boot code may change it with
# machine.freq(), so the firmware asks the chip rather than trusting this.
CLOCK_HZ = {"rp2040": 125000000, "rp2350": 150000000, "esp32": 160000000,
            "sim": 125000000}
# The options that set a heater's PWM frequency: below what the chip makes, a software
# PWM takes over. Other PWM frequencies (the fan's) must be within the chip's range.
HEATER_OPTIONS = ("hotend_pwm_hz", "bed_pwm_hz")
_ESP32_APB_HZ = const(80000000)
# rp2: the counter wraps at TOP + 1 with TOP at most 65534 (so duty 65535 is 100 %),
# behind an 8.4 fractional divider below 256. MicroPython takes the smallest divider
# that fits, div16 = ceil(16 * clock / (65534 * f)), and refuses a div16 of 4096: the
# lowest f is the one whose div16 is 4095.
_RP2_DIV16_TOP = const(65534 * 4095)


def range_hz(chip, clock_hz):
    """(lowest, highest) PWM frequency in whole Hz that machine.PWM makes on this chip
    with its system clock at clock_hz."""
    if chip == "esp32":
        # LEDC as MicroPython drives it: below 10 Hz from the 1 MHz REF_TICK, above
        # from the APB clock (80 MHz, or the CPU's if that is slower); 16 bits of
        # duty and an 18-bit divider reach 1 Hz. It refuses above half the APB clock.
        return 1, min(clock_hz, _ESP32_APB_HZ) // 2
    # rp2, and the simulated chip that stands in for one. Above half the clock the
    # period would be under two counts: MicroPython then makes another frequency.
    return -(-16 * clock_hz // _RP2_DIV16_TOP), clock_hz // 2


def clock_text(clock_hz):
    if clock_hz % 1000000:
        return "%d Hz" % clock_hz
    return "%d MHz" % (clock_hz // 1000000)


def heater_output(machine, chip, gpio, hz, add_background):
    """The heater's output at hz: the chip's PWM if it makes hz, else a SoftPwm run by
    add_background(fn(now_ms), each_turn). Either takes duty_u16(d); duty_u16(0) is off
    at once."""
    if hz >= range_hz(chip, machine.freq())[0]:
        return machine.PWM(machine.Pin(gpio), freq=hz, duty_u16=0)
    # Imported only here: most boards' heaters never need it.
    from mixfw.softpwm import SoftPwm
    out = SoftPwm(machine.Pin(gpio, machine.Pin.OUT, value=0), hz)
    add_background(out.update, True)  # its edges at every turn of the main loop
    return out
