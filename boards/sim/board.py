# The simulated board: a 30-GPIO chip like an RP2040, with X, Y, Z and six mixing
# drives e0..e5 on external STEP/DIR drivers, one ENABLE per driver, min endstops and
# a filament runout input per drive (set by the sim-only M7107, simswitch.py) and a
# BLTouch bed probe (simbed.py puts a bed under it).
# Plain data: how to step is the firmware's business, not the board's.
from mixfw import defaults, defaults_net

NAME = "sim"

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
    "x_enable": 18, "y_enable": 19, "z_enable": 20,
    "e0_enable": 21, "e1_enable": 22, "e2_enable": 23,
    "e3_enable": 24, "e4_enable": 25, "e5_enable": 26,
    "x_min": 27, "y_min": 28, "z_min": 29,
    "hotend_heater": 30, "bed_heater": 31, "part_fan": 32,
    "hotend_thermistor": 33, "bed_thermistor": 34,
    "e0_runout": 35, "e1_runout": 36, "e2_runout": 37,
    "e3_runout": 38, "e4_runout": 39, "e5_runout": 40,
    # A BLTouch: its input, and the servo pin that deploys and stows it.
    "z_probe": 41, "probe_servo": 42,
}

SETTINGS = dict(
    defaults.SETTINGS,
    **defaults_net.NETWORK,
    chip="sim",
    tick_us=20,  # step-loop period: 50 kHz
    drives=6,
    enable_active_low=True,
    # The simulation takes its consoles from sim_main, not from a UART.
    console_uart=-1,
)
