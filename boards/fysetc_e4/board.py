# FYSETC E4 (ESP32-WROOM-32E): four TMC2209s (X, Y, Z, E) on one UART and a shared
# ENABLE, plus two more mixing drives on external STEP/DIR drivers.
#
# The E4 has no spare header pin: every GPIO goes to a socket, an endstop, a heater,
# the fan, the thermistors, the TMC UART, the USB bridge (1, 3), the BOOT button (0)
# or the TF card (5, 18, 19, 23). mixstep prints from the ESP32's own flash, not the
# TF card, so e1 and e2 use the four TF card lines, reached with a microSD breakout
# ("sniffer") adapter plugged into the empty slot:
#   e1  STEP on SCK (GPIO 18), DIR on MOSI (GPIO 23)
#   e2  STEP on MISO (GPIO 19), DIR on CS (GPIO 5, a strapping pin that must be high
#       at reset; the card's pull-up keeps it so)
# Their drivers take EN from the shared ENABLE (GPIO 25, on the board's EN net).
# Without them, set drives=1 and mixing is off. No pin is left for a filament runout
# input, so no drive has one, nor for a bed probe (z_probe): G29 and G30 answer an
# error; with drives=1, a TF card line (SCK, GPIO 18) could take one.
# GPIO 12 (Z DIR) is the MTDI strap: it must be low at reset, as the board wires it.
from mixfw import defaults, defaults_net

NAME = "fysetc_e4"
CHIP = "esp32"
SOURCE = ("Marlin src/pins/esp32/pins_FYSETC_E4.h and pins_ESPA_common.h (steppers, "
          "shared enable, endstops, heaters, fan, thermistors, TF card, TMC UART RX 21 "
          "/ TX 22); FYSETC-E4 repository examples/Ender-3/Configuration_adv.h "
          "(TMC2209 addresses X1 Y3 Z0 E2) and hardware/FYSETC E4_V1.0 SCH.pdf "
          "(https://github.com/FYSETC/FYSETC-E4).")

RESERVED = {0: "BOOT button (low at reset = download mode)",
            1: "UART0 TX to the CH340 USB bridge (console)",
            3: "UART0 RX from the CH340 USB bridge"}

PINS = {
    "x_step": 27, "x_dir": 26,
    "y_step": 33, "y_dir": 32,
    "z_step": 14, "z_dir": 12,
    "e0_step": 16, "e0_dir": 17,
    "e1_step": 18, "e1_dir": 23,
    "e2_step": 19, "e2_dir": 5,
    "x_enable": 25, "y_enable": 25, "z_enable": 25,
    "e0_enable": 25, "e1_enable": 25, "e2_enable": 25,
    "x_min": 34, "y_min": 35, "z_min": 15,
    "hotend_heater": 2, "bed_heater": 4, "part_fan": 13,
    "hotend_thermistor": 36, "bed_thermistor": 39,
}

SHARED_PINS = (
    ("x_enable", "y_enable", "z_enable", "e0_enable", "e1_enable", "e2_enable"),
)

# The four TMC2209s on one UART (TX joined to RX through a resistor), addressed by
# their MS1/MS2 straps, with 0.11 ohm sense resistors. The firmware sets them up over
# it (mixfw/tmc.py): without that, the straps would give X 32, Y 16, Z 8 and E 64
# microsteps.
TMC_UART = {
    "uart": 1, "tx": 22, "rx": 21, "baud": 115200, "sense_mohm": 110,
    "addresses": {"x": 1, "y": 3, "z": 0, "e0": 2},
}

SETTINGS = dict(
    defaults.SETTINGS,
    **defaults_net.NETWORK,
    chip="esp32",
    tick_us=100,  # soft timer callbacks on ESP32: 10 kHz (see boards/esp32_devkit)
    step_backend="timer",
    pin_writer="registers",
    drives=3,
    enable_active_low=True,  # TMC2209 EN is active low
    # 16 microsteps (the drivers' setting below), GT2 belts on 20-tooth pulleys on X/Y,
    # an 8 mm lead screw on Z.
    steps_per_mm=(80.0, 80.0, 400.0, 415.0),
    driver_microsteps=(16, 16, 16, 16),
    driver_current_ma=(580, 580, 580, 650),  # as the SKR Pico's: raise to the motors' rating
    driver_spreadcycle=(False, False, False, False),  # stealthChop
    console_uart=-1,
)
