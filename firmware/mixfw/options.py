# The runtime configuration schema: every option M503 prints and M926 sets.
#
# One row per setting of the board's SETTINGS dict. A row with axes stands for one
# option per axis, stored back into that setting's tuple: steps_per_mm with axes
# "xyze" gives steps_per_mm_x .. steps_per_mm_e. A row whose setting the board does
# not have is left out, so a board without a bed simply has no bed_* options.
# Restart options are read once when the machine is assembled (buffer sizes, pin
# polarity, the tick); M930 reports them instead of pretending to apply them.
# Pure data: imports on CPython too.

FLOAT = "float"
INT = "int"
BOOL = "bool"  # written and read as 0 or 1, as in APrinter
MIX = "mix"  # drive weights w0:w1:..., normalised to integers (mixer.normalize)
PAIR = "pair"  # a tool pair's transition from:to:l1_mm:l2_mm; 0:0:0:0 is an empty slot
EACH = "each"  # axes of a row whose setting is a tuple of any length: _0, _1, ...
POW2 = "pow2"  # a whole number that is a power of two (microsteps)
LIVE = False  # takes effect with M930
RESTART = True  # takes effect after a restart

# Settings the firmware owns a default for, so a board needn't name them.
FIRMWARE_DEFAULTS = {
    "soft_limits": True,
    "max_extrude_mm": 200.0,
    "retract_policy": 0,
    "retract_mm": 2.0,
    "retract_feed_mm_s": 40.0,
    "unretract_feed_mm_s": 40.0,
    "transition_l1_mm": 0.0,
    "transition_l2_mm": 0.0,
    "transition_pairs": ((0, 0, 0.0, 0.0),) * 8,
    # 3 KB of RAM held from boot for a debugging aid: enough for a short burst (about
    # 128 steps); a longer capture sets more and restarts.
    "trace_records": 256,
    # A main loop or interrupt stuck this long resets the board. Never off, as every
    # board drives heaters: 1000 ms at least (the ESP32's least), 8388 ms at most (the
    # RP2040's and RP2350's most).
    "watchdog_ms": 4000,
    # The step loop counts as stopped after this long without a tick.
    "step_stall_ms": 250,
    # G2/G3 segments: Marlin's MIN_ARC_SEGMENT_MM, MAX_ARC_SEGMENT_MM and
    # MIN_CIRCLE_SEGMENTS.
    "min_arc_segment_mm": 0.1,
    "max_arc_segment_mm": 1.0,
    "min_circle_segments": 72,
    # Marlin's SLOWDOWN and its DEFAULT_MINSEGMENTTIME (M205 B).
    "min_segment_time_us": 20000,
    # M600: park at X 10 Y 10 with Z 5 mm up; no unload or load (a change by hand),
    # a purge of 30 mm at 10 mm/s; the hot end off after 5 minutes' wait.
    "change_park_mm": (10.0, 10.0, 5.0),
    "change_unload_mm": 0.0,
    "change_load_mm": 0.0,
    "change_purge_mm": 30.0,
    "change_feed_mm_s": 10.0,
    "change_heater_timeout_s": 300,
    # Filament runout inputs (a board's e<n>_runout pins), as Marlin's defaults: on,
    # "gone" reads low, the chip's pull-up on.
    "runout_enabled": True,
    "runout_active_high": False,
    "runout_pullup": True,
}


# The rows spell out the values of the names above (type "float" for FLOAT, restart
# True for RESTART, False for LIVE): a tuple of literals is one constant, which a
# frozen firmware keeps in flash, while a row naming FLOAT or LIVE is built in RAM at
# import (these 74 rows: 11 KB of heap on a 64-bit port).
# A limit that is a whole number is written as an int, also for a float option: from a
# .mpy file each float constant is an object of its own in the heap (16 bytes on the
# chips, 84 of them here), a small int is none. Option.check and format take either.
SCHEMA = (
    # setting                      axes    type     min      max          restart
    ("steps_per_mm",               "xyze", "float", 0.001,   100000,      False),
    ("max_feed_mm_s",              "xyze", "float", 0.01,    10000,       False),
    ("max_accel_mm_s2",            "xyze", "float", 0.1,     1000000,     False),
    ("acceleration_mm_s2",         "",     "float", 0.1,     1000000,     False),
    ("retract_acceleration_mm_s2", "",     "float", 0.1,     1000000,     False),
    ("junction_deviation_mm",      "",     "float", 0.001,   10,          False),
    ("min_segment_time_us",        "",     "int",   0,       1000000,     False),
    ("default_feed_mm_s",          "",     "float", 0.01,    10000,       False),
    ("travel_mm",                  "xyz",  "float", 1,       100000,      False),
    ("soft_limits",                "",     "bool",  0,       1,           False),
    ("max_extrude_mm",             "",     "float", 0.1,     100000,      False),
    ("min_arc_segment_mm",         "",     "float", 0.001,   100,         False),
    ("max_arc_segment_mm",         "",     "float", 0.001,   100,         False),
    ("min_circle_segments",        "",     "int",   8,       3600,        False),
    ("homing_feed_mm_s",           "xyz",  "float", 0.01,    1000,        False),
    ("drives",                     "",     "int",   1,       6,           True),
    ("virtual_tools",              "",     "int",   1,       16,          True),
    ("queue_blocks",               "",     "int",   4,       256,         True),
    ("line_buffer_bytes",          "",     "int",   32,      1024,        True),
    ("tick_us",                    "",     "int",   5,       1000,        True),
    ("step_pulse_us",              "",     "int",   1,       100,         True),
    ("dir_setup_us",               "",     "int",   0,       100,         True),
    ("enable_active_low",          "",     "bool",  0,       1,           True),
    ("endstop_active_high",        "",     "bool",  0,       1,           True),
    ("endstop_pullup",             "",     "bool",  0,       1,           True),
    # TMC2209 drivers on the board's UART (boards with TMC_UART only); E is the E
    # socket. 1600 mA: about what the boards' 0.11 ohm sense resistors allow.
    ("driver_microsteps",          "xyze", "pow2",  1,       256,         False),
    ("driver_current_ma",          "xyze", "int",   50,      1600,        False),
    ("driver_spreadcycle",         "xyze", "bool",  0,       1,           False),
    # Heaters (hotend, bed): thermistor (Beta or Steinhart-Hart), PID, protection.
    # Config narrows every *_pwm_hz row to what the chip's PWM makes at its clock
    # (pwm.range_hz); a heater's lowest stays 1 Hz, made in software.
    ("hotend_beta",                "",     "float", 500,     20000,       False),
    ("hotend_r25_ohm",             "",     "float", 1,       10000000,    False),
    ("hotend_pullup_ohm",          "",     "float", 1,       10000000,    False),
    ("hotend_sh_a",                "",     "float", -1,      1,           False),
    ("hotend_sh_b",                "",     "float", -1,      1,           False),
    ("hotend_sh_c",                "",     "float", -1,      1,           False),
    ("hotend_kp",                  "",     "float", 0,       1000,        False),
    ("hotend_ki",                  "",     "float", 0,       1000,        False),
    ("hotend_kd",                  "",     "float", 0,       10000,       False),
    ("hotend_pwm_hz",              "",     "int",   1,       100000,      True),
    ("hotend_min_c",               "",     "float", -100,    100,         False),
    ("hotend_max_c",               "",     "float", 0,       500,         False),
    ("hotend_watch_s",             "",     "float", 1,       3600,        False),
    ("hotend_watch_rise_c",        "",     "float", 0.1,     100,         False),
    ("hotend_runaway_c",           "",     "float", 1,       100,         False),
    ("hotend_runaway_s",           "",     "float", 1,       3600,        False),
    # The bed's rows are the hot end's (a test holds them alike).
    ("bed_beta",                   "",     "float", 500,     20000,       False),
    ("bed_r25_ohm",                "",     "float", 1,       10000000,    False),
    ("bed_pullup_ohm",             "",     "float", 1,       10000000,    False),
    ("bed_sh_a",                   "",     "float", -1,      1,           False),
    ("bed_sh_b",                   "",     "float", -1,      1,           False),
    ("bed_sh_c",                   "",     "float", -1,      1,           False),
    ("bed_kp",                     "",     "float", 0,       1000,        False),
    ("bed_ki",                     "",     "float", 0,       1000,        False),
    ("bed_kd",                     "",     "float", 0,       10000,       False),
    ("bed_pwm_hz",                 "",     "int",   1,       100000,      True),
    ("bed_min_c",                  "",     "float", -100,    100,         False),
    ("bed_max_c",                  "",     "float", 0,       500,         False),
    ("bed_watch_s",                "",     "float", 1,       3600,        False),
    ("bed_watch_rise_c",           "",     "float", 0.1,     100,         False),
    ("bed_runaway_c",              "",     "float", 1,       100,         False),
    ("bed_runaway_s",              "",     "float", 1,       3600,        False),
    # Temperatures, fan, retraction, transitions, per-drive and per-tool options.
    ("min_extrude_c",              "",     "float", 0,       500,         False),
    ("fan_pwm_hz",                 "",     "int",   1,       100000,      True),
    ("thermal_period_ms",          "",     "int",   10,      10000,       True),
    ("retract_policy",             "",     "int",   0,       2,           False),
    ("retract_mm",                 "",     "float", 0,       50,          False),
    ("retract_feed_mm_s",          "",     "float", 0.1,     500,         False),
    ("unretract_feed_mm_s",        "",     "float", 0.1,     500,         False),
    ("change_park_mm",             "xyz",  "float", 0,       100000,      False),
    ("change_unload_mm",           "",     "float", 0,       100000,      False),
    ("change_load_mm",             "",     "float", 0,       100000,      False),
    ("change_purge_mm",            "",     "float", 0,       100000,      False),
    ("change_feed_mm_s",           "",     "float", 0.1,     500,         False),
    ("change_heater_timeout_s",    "",     "int",   0,       86400,       False),
    ("runout_enabled",             "",     "bool",  0,       1,           False),
    ("runout_active_high",         "",     "bool",  0,       1,           True),
    ("runout_pullup",              "",     "bool",  0,       1,           True),
    ("probe_active_high",           "",     "bool",  0,       1,           False),
    ("probe_offset_mm",             "xyz",  "float", -500,    500,         False),
    ("probe_feed_mm_s",             "",     "float", 0.1,     50,          False),
    ("probe_travel_feed_mm_s",      "",     "float", 1,       1000,        False),
    ("probe_clearance_mm",          "",     "float", 0,       100,         False),
    ("probe_dive_mm",               "",     "float", 0.1,     100,         False),
    ("mesh_points",                 "xy",   "int",   2,       5,           False),
    ("mesh_min_mm",                 "xy",   "float", 0,       100000,      False),
    ("mesh_max_mm",                 "xy",   "float", 0,       100000,      False),
    ("mesh_fade_mm",                "",     "float", 0,       1000,        False),
    ("mesh_probed",                 "",     "bool",  0,       1,           False),
    ("mesh_enabled",                "",     "bool",  0,       1,           False),
    ("mesh_z_nm",                   "each", "int",   -10000000, 10000000,    False),
    ("transition_l1_mm",           "",     "float", 0,       100,         True),
    ("transition_l2_mm",           "",     "float", 0,       100,         True),
    ("transition_pairs",           "each", "pair",  0.0,     100.0,       True),
    ("drive_steps_per_mm",         "each", "float", 0.001,   100000,      False),
    ("filament_used_mm",           "each", "float", -1000000000,1000000000,  False),
    ("tool_mixes",                 "each", "mix",   0,       0,           False),
    ("tool_advance_k",             "each", "float", 0,       10,          False),
    ("trace_records",              "",     "int",   0,       100000,      True),
    ("watchdog_ms",                "",     "int",   1000,    8388,        True),
    ("step_stall_ms",              "",     "int",   10,      10000,       True),
    ("console_uart",               "",     "int",   -1,      4,           True),
    ("console_baud",               "",     "int",   300,     4000000,     True),
    ("tcp_port",                   "",     "int",   1,       65535,       True),
    ("tcp_max_clients",            "",     "int",   1,       8,           True),
)
