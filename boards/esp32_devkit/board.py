# ESP32-WROOM-32 DevKit (DevKitC / "DevKit V1") with external STEP/DIR drivers:
# X, Y, Z and four mixing drives.
#
# GPIO budget. The header brings out 26 GPIOs besides the SPI flash (6-11, never
# used): 0-5, 12-19, 21-23, 25-27, 32-36, 39.
#   1, 3   UART0 to the USB bridge: the REPL and the firmware's USB console
#   34-39  input only, without pull-ups: endstops (external pull-ups) and ADC
#   ADC2 (0, 2, 4, 12-15, 25-27) is unusable while WiFi runs, so both thermistors go
#   on ADC1: 36 (VP, ADC1_CH0) and 39 (VN, ADC1_CH3).
# That leaves 20 output-capable pins for 6 + 2 x drives STEP/DIR, a shared ENABLE,
# two heaters and the fan (10 + 2 x drives), plus the Z endstop, which no longer fits
# on 34-39: four drives use 19 of them, and GPIO 0 stays free. GPIO 0 is the BOOT strap
# below: a filament runout sensor or a bed probe holding it low at reset would start
# the download mode (a BLTouch or an NPN probe may), so no drive has a runout input and
# there is no probe (z_probe): G29 and G30 answer an error.
#
# Strapping pins, and why each got what it got:
#   0   BOOT button, low at reset = download mode: left free.
#   2   low/floating at reset for download mode: the part fan (off at reset).
#   5   pulled up at reset: the shared ENABLE, so active-low drivers stay off while
#       the chip boots.
#   12  MTDI, high at reset selects 1.8 V flash and the module won't boot: the bed
#       heater, whose MOSFET gate pull-down also holds it low. Never put a pull-up here.
#   15  MTDO, pulled up at reset (low only mutes the boot log): the Z endstop.
# GPIO 14 puts out a PWM burst at reset, so it carries a DIR line, never a heater.
# GPIO 16/17 are free on WROOM modules; on WROVER modules they belong to the PSRAM,
# so move e0 elsewhere there.
# STEP/DIR on 32/33 works: the step path maps them onto mask bits 28/29.
from mixfw import defaults, defaults_net

NAME = "esp32_devkit"
CHIP = "esp32"
SOURCE = ("Espressif ESP32-DevKitC V4 user guide (header pinout) and ESP32-WROOM-32 "
          "datasheet (pin definitions, strapping pins); ESP32 technical reference "
          "manual, IO_MUX and ADC chapters (input-only 34-39, ADC1 on 32-39). The "
          "assignment of functions to header pins is mixstep's.")

RESERVED = {1: "UART0 TX to the USB bridge (console)", 3: "UART0 RX from the USB bridge"}

PINS = {
    "x_step": 23, "x_dir": 22,
    "y_step": 21, "y_dir": 19,
    "z_step": 18, "z_dir": 17,
    "e0_step": 16, "e0_dir": 4,
    "e1_step": 27, "e1_dir": 26,
    "e2_step": 25, "e2_dir": 33,
    "e3_step": 32, "e3_dir": 14,
    "x_enable": 5, "y_enable": 5, "z_enable": 5,
    "e0_enable": 5, "e1_enable": 5, "e2_enable": 5, "e3_enable": 5,
    "x_min": 34, "y_min": 35, "z_min": 15,
    "hotend_heater": 13, "bed_heater": 12, "part_fan": 2,
    "hotend_thermistor": 36, "bed_thermistor": 39,
}

SHARED_PINS = (
    ("x_enable", "y_enable", "z_enable", "e0_enable", "e1_enable", "e2_enable", "e3_enable"),
)

TMC_UART = None  # external drivers, set up by their own jumpers

SETTINGS = dict(
    defaults.SETTINGS,
    **defaults_net.NETWORK,
    chip="esp32",
    # ESP32 timer callbacks are always soft (scheduled by the interpreter), so the
    # tick is slower than on rp2: 10 kHz. `make board-check` shows the real rate and
    # the worst gap between ticks.
    tick_us=100,
    step_backend="timer",
    pin_writer="registers",  # GPIO_OUT_W1TS/W1TC, and OUT1 for GPIO 32/33
    drives=4,
    enable_active_low=True,
    steps_per_mm=(80.0, 80.0, 400.0, 415.0),
    console_uart=-1,  # UART0 is the USB console already; no pins left for another
)
