# Raspberry Pi Pico (RP2040) on a carrier with external STEP/DIR drivers (A4988,
# DRV8825, TMC2209 in standalone mode, ...): X, Y, Z and five mixing drives.
#
# GPIO budget. The Pico brings out GPIO 0-22 and 26-28: 26 pins. GPIO 23 (SMPS
# power save), 24 (VBUS sense), 25 (LED) and 29 (VSYS/3) stay on the board.
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
# A sixth drive needs two more pins and only GPIO 28 (the probe's) is left, so the
# Pico runs five; six take boards/pico_6drives (no part fan), a board with more GPIOs (RP2350B has
# 48) or drives on an I/O expander.
# The heaters and the fan sit on three different PWM slices (17: 0B, 19: 1B, 21: 2B),
# because the two channels of a slice share one frequency and the heaters run at
# 12 Hz while the fan runs at 1 kHz.
from mixfw import defaults

NAME = "pico"
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
    drives=5,
    # The look-ahead plans every move to stop by the end of its queue: 48 blocks of a
    # slicer's 0.2 mm curve segments hold 9.6 mm, from which 1,500 mm/s**2 stops from
    # about 170 mm/s, so curves print at the 150 mm/s a fast file asks (16 blocks
    # would hold them near 95 mm/s). A block costs 144 bytes of heap.
    queue_blocks=48,
    enable_active_low=True,  # A4988/DRV8825/TMC2209 all enable on a low EN
    steps_per_mm=(80.0, 80.0, 400.0, 415.0),
    console_uart=-1,  # no pins left for a UART console; USB serial only
)
