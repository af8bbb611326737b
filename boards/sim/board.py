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
    "max_hotend_c": 285.0,
    "max_bed_c": 120.0,
}
