# BIGTREETECH SKR Pico v1.0 (RP2040): four TMC2209 sockets (X, Y, Z, E) on one UART,
# plus two more mixing drives on external STEP/DIR drivers wired to free headers:
#   e0  the board's E socket.
#   e1  STEP on the servo pin of the BLTouch header (GPIO 29, an output there
#       anyway) and DIR on the RGB header (GPIO 24, the neopixel output).
#   e2  STEP on TX (GPIO 0) and DIR on RX (GPIO 1) of the Raspberry Pi UART header,
#       so that header can't carry a UART console (console_uart stays -1).
# The external drivers share the E socket's ENABLE (GPIO 15); run their EN input
# from it, or tie it low if the driver has none. Their DIR is not inverted: if a
# motor turns the wrong way, add its drive to invert_dir. With the board alone
# (no external drivers), set drives=1 and mixing is off.
# The board's filament runout header (GPIO 16, which Klipper's example reads with the
# chip's pull-up, as runout_pullup does) is e0's runout input; e1 and e2 have none.
# GPIO 22, the BLTouch header's probe input, is the bed probe's (z_probe). Its servo
# pin carries e1's STEP, so a BLTouch can't be deployed and stowed: an inductive or
# capacitive probe (no servo) goes there, or a board run with drives=2 gives GPIO 29
# back as probe_servo.
# The fan outputs 18 and 20 are low-side MOSFETs (12/24 V loads), not logic pins.
from mixfw import defaults

NAME = "skr_pico"
CHIP = "rp2040"
SOURCE = ("Klipper config/generic-bigtreetech-skr-pico-v1.0.cfg (steppers, DIR "
          "inversion, TMC2209 UART pins and addresses, endstops, heaters, thermistors, "
          "fans, neopixel, BLTouch, filament runout sensor); BIGTREETECH SKR-Pico "
          "repository, Hardware/BTT SKR Pico V1.0-PIN.pdf and -SCH.pdf "
          "(https://github.com/bigtreetech/SKR-Pico).")

RESERVED = {}

PINS = {
    "x_step": 11, "x_dir": 10, "x_enable": 12,
    "y_step": 6, "y_dir": 5, "y_enable": 7,
    "z_step": 19, "z_dir": 28, "z_enable": 2,
    "e0_step": 14, "e0_dir": 13, "e0_enable": 15,
    "e1_step": 29, "e1_dir": 24, "e1_enable": 15,
    "e2_step": 0, "e2_dir": 1, "e2_enable": 15,
    "x_min": 4, "y_min": 3, "z_min": 25,
    "z_probe": 22,  # the BLTouch header's probe input
    "hotend_heater": 23, "bed_heater": 21,
    "part_fan": 17,  # FAN1; FAN2 (18) and FAN3 (20) are left to the user
    "hotend_thermistor": 27, "bed_thermistor": 26,
    "e0_runout": 16,
}

SHARED_PINS = (
    ("e0_enable", "e1_enable", "e2_enable"),
)

# The four sockets' TMC2209s on one UART (UART1 on GPIO 8/9, TX joined to RX through
# a resistor), addressed by their MS1/MS2 straps, with 0.11 ohm sense resistors.
# The firmware sets them up over it (mixfw/tmc.py): without that, the straps would
# give X 8, Y 64, Z 32 and E 16 microsteps.
TMC_UART = {
    "uart": 1, "tx": 8, "rx": 9, "baud": 115200, "sense_mohm": 110,
    "addresses": {"x": 0, "y": 2, "z": 1, "e0": 3},
}

SETTINGS = dict(
    defaults.SETTINGS,
    chip="rp2040",
    tick_us=50,  # a hard machine.Timer (MicroPython >= 1.26) at 20 kHz
    step_backend="timer",
    pin_writer="registers",
    drives=3,
    enable_active_low=True,  # TMC2209 EN is active low
    invert_dir=("x", "y", "e0"),
    # Klipper's example: 16 microsteps, rotation_distance 40 (X/Y) and 8 (Z).
    steps_per_mm=(80.0, 80.0, 400.0, 415.0),
    # The TMC2209s, as Klipper's example sets them: 16 microsteps (what steps_per_mm
    # assumes), 580 mA (650 mA on E), stealthChop.
    driver_microsteps=(16, 16, 16, 16),
    driver_current_ma=(580, 580, 580, 650),
    driver_spreadcycle=(False, False, False, False),
    endstop_active_high=True,  # Klipper reads them as ^gpioN: pulled up, high = hit
    endstop_pullup=True,
    console_uart=-1,
)
