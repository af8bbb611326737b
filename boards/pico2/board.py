# Raspberry Pi Pico 2 (RP2350A, Cortex-M33) on a carrier with external STEP/DIR
# drivers: the same header as the Pico, so the same pin map (see boards/pico).
#
# GPIO budget. The Pico 2 brings out GPIO 0-22 and 26-28: 26 pins. GPIO 23, 24, 25
# and 29 stay on the board (SMPS power save, VBUS sense, LED, VSYS/3).
#   X, Y, Z STEP/DIR        6
#   5 drives STEP/DIR      10
#   one shared ENABLE       1   (a driver each would need 8 more pins)
#   X/Y/Z min endstops      3
#   hot end, bed, part fan  3
#   thermistors (ADC0/1)    2   GPIO 26, 27
#   bed probe input         1   GPIO 28 (ADC2): an inductive or capacitive probe
#                               (z_probe); a BLTouch's servo would need one more
#                               pin, and none is left. The probe has it rather than
#                               a filament runout input: G29 is in the start G-code
#                               of nearly every printer with a probe
# A sixth drive needs two more pins and only GPIO 28 (the probe's) is left, so this
# runs five; six take the RP2350B (48 GPIOs) or drives on an I/O expander.
# Heaters and fan sit on three different PWM slices, as on the Pico.
# RP2350 erratum E9: an input with the internal pull-down enabled can latch high, so
# the endstops need external pull resistors (or switches that drive both levels).

from mixfw import defaults

NAME = "pico2"
CHIP = "rp2350"
SOURCE = ("Raspberry Pi Pico 2 datasheet, 'Pinout' and 'GPIO' sections; "
          "https://datasheets.raspberrypi.com/pico/pico-2-datasheet.pdf; RP2350 "
          "datasheet, errata (E9). The assignment of functions to header pins is mixstep's.")

# GPIOs the Pico board itself uses; nothing of the printer may go there.
RESERVED = {23: "SMPS power-save", 24: "VBUS sense", 25: "on-board LED",
            29: "VSYS/3 ADC"}

PINS = {
    "x_step": 0, "x_dir": 1,
    "y_step": 2, "y_dir": 3,
    "z_step": 4, "z_dir": 5,
    "e0_step": 6, "e0_dir": 7,
    "e1_step": 8, "e1_dir": 9,
    "e2_step": 10, "e2_dir": 11,
    "e3_step": 12, "e3_dir": 13,
    "e4_step": 14, "e4_dir": 15,
    # One ENABLE for every driver: M18 X then releases all motors at once.
    "x_enable": 16, "y_enable": 16, "z_enable": 16,
    "e0_enable": 16, "e1_enable": 16, "e2_enable": 16, "e3_enable": 16, "e4_enable": 16,
    "hotend_heater": 17,
    "x_min": 18,
    "bed_heater": 19,
    "y_min": 20,
    "part_fan": 21,
    "z_min": 22,
    "hotend_thermistor": 26, "bed_thermistor": 27,
    "z_probe": 28,
}

SHARED_PINS = (
    ("x_enable", "y_enable", "z_enable",
     "e0_enable", "e1_enable", "e2_enable", "e3_enable", "e4_enable"),
)

TMC_UART = None  # external drivers, set up by their own jumpers

SETTINGS = dict(
    defaults.SETTINGS,
    chip="rp2350",
    # A hard machine.Timer (MicroPython >= 1.26) at 25 kHz: the M33 at 150 MHz runs
    # viper faster than the RP2040's M0+; `make board-check` shows what it achieves.
    tick_us=40,
    step_backend="timer",
    pin_writer="registers",  # SIO set/clear registers (at other offsets than RP2040)
    drives=5,
    enable_active_low=True,  # A4988/DRV8825/TMC2209 all enable on a low EN
    steps_per_mm=(80.0, 80.0, 400.0, 415.0),
    console_uart=-1,  # no pins left for a UART console; USB serial only
)
