# The simulated board: a 30-GPIO chip like an RP2040, with X, Y, Z and six mixing
# drives e0..e5 on external STEP/DIR drivers, one ENABLE per driver, and min endstops.
# Plain data: how to step is the firmware's business, not the board's.
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
}

SETTINGS = {
    "tick_us": 20,  # step-loop period: 50 kHz
    "step_pulse_us": 2,  # minimum STEP high time (DRV8825 needs 1.9)
    "dir_setup_us": 1,  # minimum DIR-to-STEP setup time
    "drives": 6,
    "virtual_tools": 16,
    "queue_blocks": 16,
    "line_buffer_bytes": 96,
    # Axis order X, Y, Z, E. E is millimetres of filament, shared by every drive.
    "steps_per_mm": (80.0, 80.0, 400.0, 415.0),
    "max_feed_mm_s": (250.0, 250.0, 10.0, 60.0),
    "max_accel_mm_s2": (3000.0, 3000.0, 100.0, 5000.0),
    "acceleration_mm_s2": 1500.0,
    "retract_acceleration_mm_s2": 3000.0,
    "junction_deviation_mm": 0.05,
    "default_feed_mm_s": 25.0,
    "travel_mm": (250.0, 250.0, 200.0),
    "homing_feed_mm_s": (50.0, 50.0, 5.0),
    "enable_active_low": True,
    "endstop_active_high": True,
    # Heaters: 100k NTC (Beta 3950) with a 4.7k pull-up. Steinhart-Hart replaces the
    # Beta model when any of *_sh_a/_sh_b/_sh_c is non-zero. PID gains act on a duty
    # of 0..1: kp per C of error, ki per C*s, kd per C/s of change.
    "hotend_beta": 3950.0, "hotend_r25_ohm": 100000.0, "hotend_pullup_ohm": 4700.0,
    "hotend_sh_a": 0.0, "hotend_sh_b": 0.0, "hotend_sh_c": 0.0,
    "hotend_kp": 0.15, "hotend_ki": 0.003, "hotend_kd": 0.5, "hotend_pwm_hz": 10,
    "hotend_min_c": 5.0, "hotend_max_c": 285.0,
    # Protection: after a target is set it must rise watch_rise_c within watch_s;
    # once reached, more than runaway_c below it for over runaway_s is a runaway.
    "hotend_watch_s": 20.0, "hotend_watch_rise_c": 2.0,
    "hotend_runaway_c": 10.0, "hotend_runaway_s": 20.0,
    "bed_beta": 3950.0, "bed_r25_ohm": 100000.0, "bed_pullup_ohm": 4700.0,
    "bed_sh_a": 0.0, "bed_sh_b": 0.0, "bed_sh_c": 0.0,
    "bed_kp": 0.6, "bed_ki": 0.006, "bed_kd": 3.0, "bed_pwm_hz": 10,
    "bed_min_c": 5.0, "bed_max_c": 120.0,
    "bed_watch_s": 60.0, "bed_watch_rise_c": 2.0,
    "bed_runaway_c": 5.0, "bed_runaway_s": 30.0,
    "min_extrude_c": 170.0,  # E moves are refused below this hot end temperature
    "fan_pwm_hz": 1000,
    "thermal_period_ms": 100,
    # Consoles: USB serial always; a UART (console_uart: its id, -1 for none) and, on
    # boards with a network, a TCP console. The simulation takes its own from sim_main.
    "console_uart": -1,
    "console_baud": 115200,
    "tcp_port": 8888,
    "tcp_max_clients": 4,
}
