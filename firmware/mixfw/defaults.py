# Settings every board starts from: a typical printer (16x microstepping, GT2 belts on
# X/Y, an 8 mm lead screw on Z, a geared extruder) with a 100k-NTC hot end and bed.
# A board's board.py takes these and overrides what its hardware decides:
#     SETTINGS = dict(defaults.SETTINGS, chip="rp2040", drives=5, ...)
# Left out on purpose, so every board has to state them: "drives" and "tick_us" (what
# the board can drive and how fast its chip ticks) and "enable_active_low" (a wrong
# guess would power every motor at boot); `mixstep boards check` insists on them.
SETTINGS = {
    "chip": "sim",  # "rp2040", "rp2350" or "esp32" on a real board
    # "timer": machine.Timer runs the step loop; rp2 also "pio" (the timer feeds a PIO
    # state machine a word per tick) and "pio_dma" (the step loop fills 2 ms batches of
    # timed edges that DMA feeds to a state machine: one interrupt per batch).
    "step_backend": "timer",
    "pin_writer": "pin",  # "pin": Pin.value() (portable); "registers": set/clear registers
    # The system clock boot.py sets before anything else runs; 0: the one MicroPython
    # boots with (rp2040 125 MHz, rp2350 150 MHz, esp32 160 MHz).
    "clock_hz": 0,
    "invert_dir": (),  # axes/drives whose motor turns the other way, e.g. ("x", "e0")
    "step_pulse_us": 2,  # minimum STEP high time (DRV8825 needs 1.9)
    "dir_setup_us": 1,  # minimum DIR-to-STEP setup time
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
    "endstop_active_high": True,
    # The chip's own pull-up on the endstop inputs, for switches that only pull low.
    # ESP32 GPIO 34-39 have none: endstops there need external pull-ups.
    "endstop_pullup": False,
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
    # Bed probe (a board's z_probe pin; BLTouch deploy and stow on probe_servo), as
    # Marlin's defaults: the probe 10 mm right of and behind the nozzle (M851), each
    # dive from 5 mm (Z_CLEARANCE_BETWEEN_PROBES), a 3 x 3 mesh 10 mm inside what the
    # probe reaches, its correction faded out by Z 10 mm.
    "probe_active_high": True,
    "probe_offset_mm": (10.0, 10.0, 0.0),
    "probe_feed_mm_s": 4.0,
    "probe_travel_feed_mm_s": 100.0,
    "probe_clearance_mm": 5.0,
    "probe_dive_mm": 10.0,
    "mesh_points": (3, 3),
    "mesh_min_mm": (20.0, 20.0),
    "mesh_max_mm": (230.0, 230.0),
    "mesh_fade_mm": 10.0,
    # The mesh G29 made (M500 saves it): its heights at the grid's points, X first
    # then Y, a row of X per Y; up to 5 x 5.
    "mesh_probed": False,
    "mesh_enabled": False,
    "mesh_z_nm": (0,) * 25,
    "fan_pwm_hz": 1000,
    "thermal_period_ms": 100,
    # Consoles: USB serial always; a UART (console_uart: its id, -1 for none) and, on
    # boards with a network, a TCP console.
    "console_uart": -1,
    "console_baud": 115200,
    "tcp_port": 8888,
    "tcp_max_clients": 4,
}
