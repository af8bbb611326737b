# Raspberry Pi Pico (RP2040) on a carrier with external STEP/DIR drivers, like
# boards/pico, but with six mixing drives and no part fan.
#
# GPIO budget. The Pico brings out GPIO 0-22 and 26-28: 26 pins. GPIO 23 (SMPS
# power save), 24 (VBUS sense), 25 (LED) and 29 (VSYS/3) stay on the board.
#   X, Y, Z STEP/DIR        6
#   6 drives STEP/DIR      12
#   one shared ENABLE       1
#   X/Y/Z min endstops      3
#   hot end, bed            2
#   thermistors (ADC0/1)    2   GPIO 26, 27
# Every pin is used, so no drive has a filament runout input. The sixth drive's STEP/DIR follow e4's on GPIO 16 and 17, so all
# 18 STEP/DIR pins are one run of GPIOs (0-17), as the PIO backends need; the shared
# ENABLE moves to the part fan's GPIO 21 and the hot end to the spare GPIO 28. With no
# fan output, M106 answers an error; run a part fan from the supply if the print needs
# cooling. Everything else is wired as on boards/pico. No pin is left for a bed probe
# (z_probe): G29 and G30 answer an error here; boards/pico gives its GPIO 28 to one.
# The heaters are on two PWM slices (28: 6A, 19: 1B), both at 12 Hz.
from mixfw import defaults

NAME = "pico_6drives"
CHIP = "rp2040"
SOURCE = ("Raspberry Pi Pico datasheet, 'Pinout' and 'GPIO' sections; "
          "https://datasheets.raspberrypi.com/pico/pico-datasheet.pdf. The assignment "
          "of functions to header pins is mixstep's.")

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
    "e5_step": 16, "e5_dir": 17,
    # One ENABLE for every driver: M18 X then releases all motors at once.
    "x_enable": 21, "y_enable": 21, "z_enable": 21, "e0_enable": 21, "e1_enable": 21,
    "e2_enable": 21, "e3_enable": 21, "e4_enable": 21, "e5_enable": 21,
    "hotend_heater": 28,
    "x_min": 18,
    "bed_heater": 19,
    "y_min": 20,
    "z_min": 22,
    "hotend_thermistor": 26, "bed_thermistor": 27,
}

SHARED_PINS = (
    ("x_enable", "y_enable", "z_enable", "e0_enable", "e1_enable", "e2_enable",
     "e3_enable", "e4_enable", "e5_enable"),
)

TMC_UART = None  # external drivers, set up by their own jumpers

SETTINGS = dict(
    defaults.SETTINGS,
    chip="rp2040",
    # 200 MHz, the RP2040's certified clock (at 1.15 V, which boot.py sets): a host
    # streaming a curved print's short segments over USB takes the CPU whole at 125.
    # A board whose flash or crystal misbehaves there (some clones') sets clock_hz=0.
    clock_hz=200_000_000,
    # The rp2040's PWM makes no slower than 12 Hz at 200 MHz: the heaters run there.
    hotend_pwm_hz=12,
    bed_pwm_hz=12,
    # No step timer: the step loop fills 2 ms batches of timed edges that DMA feeds to
    # a PIO state machine (mixfw/piodma.py), each step at its own time within its
    # tick. A motor steps at most every other tick: 50,000 steps/s at 10 us (a
    # 100 mm/s move on an 80 steps/mm axis is 8,000). Ramps run tick by tick, so 50 us
    # ticks would cost them a fifth of the CPU, but hold a motor to 10,000 steps/s.
    # step_backend="timer" (a hard machine.Timer, MicroPython >= 1.26) is the fallback,
    # with tick_us=50: a timer callback costs about 15 us.
    tick_us=10,
    step_backend="pio_dma",
    pin_writer="registers",  # SIO set/clear registers: one write per tick
    drives=6,
    # The look-ahead plans every move to stop by the end of its queue: 48 blocks of a
    # slicer's 0.2 mm curve segments hold 9.6 mm, from which 1,500 mm/s**2 stops from
    # about 170 mm/s, so curves print at the 150 mm/s a fast file asks (16 blocks
    # would hold them near 95 mm/s). A block costs 144 bytes of heap.
    queue_blocks=48,
    enable_active_low=True,  # A4988/DRV8825/TMC2209 all enable on a low EN
    steps_per_mm=(80.0, 80.0, 400.0, 415.0),
    console_uart=-1,  # no pins left for a UART console; USB serial only
)
