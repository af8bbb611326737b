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
    ("steps_per_mm",               "xyze", "float", 0.001,   100000,      False,
     "steps per mm (E: per mm of filament, every drive)"),
    ("max_feed_mm_s",              "xyze", "float", 0.01,    10000,       False,
     "maximum speed"),
    ("max_accel_mm_s2",            "xyze", "float", 0.1,     1000000,     False,
     "maximum acceleration"),
    ("acceleration_mm_s2",         "",     "float", 0.1,     1000000,     False,
     "print and travel acceleration"),
    ("retract_acceleration_mm_s2", "",     "float", 0.1,     1000000,     False,
     "acceleration of E-only moves"),
    ("junction_deviation_mm",      "",     "float", 0.001,   10,          False,
     "cornering: larger is faster through corners"),
    ("min_segment_time_us",        "",     "int",   0,       1000000,     False,
     "while the queue is under half full, short moves slow toward this; 0: off"),
    ("default_feed_mm_s",          "",     "float", 0.01,    10000,       False,
     "feed rate before the first F"),
    ("travel_mm",                  "xyz",  "float", 1,       100000,      False,
     "axis length; soft limits are 0..travel"),
    ("soft_limits",                "",     "bool",  0,       1,           False,
     "refuse moves outside 0..travel"),
    ("max_extrude_mm",             "",     "float", 0.1,     100000,      False,
     "longest E move accepted in one line"),
    ("min_arc_segment_mm",         "",     "float", 0.001,   100,         False,
     "G2/G3: shortest arc segment"),
    ("max_arc_segment_mm",         "",     "float", 0.001,   100,         False,
     "G2/G3: longest arc segment"),
    ("min_circle_segments",        "",     "int",   8,       3600,        False,
     "G2/G3: fewest segments a full turn"),
    ("homing_feed_mm_s",           "xyz",  "float", 0.01,    1000,        False,
     "homing speed"),
    ("drives",                     "",     "int",   1,       6,           True,
     "mixing drives fitted"),
    ("virtual_tools",              "",     "int",   1,       16,          True,
     "virtual tools T0.."),
    ("queue_blocks",               "",     "int",   4,       256,         True,
     "planner queue length"),
    ("line_buffer_bytes",          "",     "int",   32,      1024,        True,
     "longest G-code line"),
    ("tick_us",                    "",     "int",   5,       1000,        True,
     "step-loop period"),
    ("step_pulse_us",              "",     "int",   1,       100,         True,
     "minimum STEP high time"),
    ("dir_setup_us",               "",     "int",   0,       100,         True,
     "minimum DIR-to-STEP setup time"),
    ("enable_active_low",          "",     "bool",  0,       1,           True,
     "drivers are enabled by a low ENABLE pin"),
    ("endstop_active_high",        "",     "bool",  0,       1,           True,
     "endstop switches read high when hit"),
    ("endstop_pullup",             "",     "bool",  0,       1,           True,
     "enable the chip's pull-ups on the endstop inputs"),
    # TMC2209 drivers on the board's UART (boards with TMC_UART only); E is the E
    # socket. 1600 mA: about what the boards' 0.11 ohm sense resistors allow.
    ("driver_microsteps",          "xyze", "pow2",  1,       256,         False,
     "microsteps the driver is set to; steps_per_mm must match (M92)"),
    ("driver_current_ma",          "xyze", "int",   50,      1600,        False,
     "driver RMS run current (M906); the motor holds at half of it"),
    ("driver_spreadcycle",         "xyze", "bool",  0,       1,           False,
     "driver chopper: 0 stealthChop (quiet), 1 spreadCycle (M569)"),
    # Heaters (hotend, bed): thermistor (Beta or Steinhart-Hart), PID, protection.
    # Config narrows every *_pwm_hz row to what the chip's PWM makes at its clock
    # (pwm.range_hz); a heater's lowest stays 1 Hz, made in software.
    ("hotend_beta",                "",     "float", 500,     20000,       False,
     "hotend thermistor Beta (K)"),
    ("hotend_r25_ohm",             "",     "float", 1,       10000000,    False,
     "hotend thermistor resistance at 25 C"),
    ("hotend_pullup_ohm",          "",     "float", 1,       10000000,    False,
     "hotend thermistor pull-up resistor"),
    ("hotend_sh_a",                "",     "float", -1,      1,           False,
     "hotend Steinhart-Hart A (A, B, C all 0: use Beta)"),
    ("hotend_sh_b",                "",     "float", -1,      1,           False,
     "hotend Steinhart-Hart B"),
    ("hotend_sh_c",                "",     "float", -1,      1,           False,
     "hotend Steinhart-Hart C"),
    ("hotend_kp",                  "",     "float", 0,       1000,        False,
     "hotend PID proportional gain (duty per C)"),
    ("hotend_ki",                  "",     "float", 0,       1000,        False,
     "hotend PID integral gain (duty per C s)"),
    ("hotend_kd",                  "",     "float", 0,       10000,       False,
     "hotend PID derivative gain (duty s per C)"),
    ("hotend_pwm_hz",              "",     "int",   1,       100000,      True,
     "hotend heater PWM frequency; below the chip's PWM, in software (SSR)"),
    ("hotend_min_c",               "",     "float", -100,    100,         False,
     "hotend lowest sane reading (below: thermistor open)"),
    ("hotend_max_c",               "",     "float", 0,       500,         False,
     "hotend highest target and sane reading"),
    ("hotend_watch_s",             "",     "float", 1,       3600,        False,
     "hotend heating watch period"),
    ("hotend_watch_rise_c",        "",     "float", 0.1,     100,         False,
     "hotend least rise per watch period while heating"),
    ("hotend_runaway_c",           "",     "float", 1,       100,         False,
     "hotend runaway: this far below the reached target..."),
    ("hotend_runaway_s",           "",     "float", 1,       3600,        False,
     "hotend ...for this long"),
    # The bed's rows are the hot end's (a test holds them alike).
    ("bed_beta",                   "",     "float", 500,     20000,       False,
     "bed thermistor Beta (K)"),
    ("bed_r25_ohm",                "",     "float", 1,       10000000,    False,
     "bed thermistor resistance at 25 C"),
    ("bed_pullup_ohm",             "",     "float", 1,       10000000,    False,
     "bed thermistor pull-up resistor"),
    ("bed_sh_a",                   "",     "float", -1,      1,           False,
     "bed Steinhart-Hart A (A, B, C all 0: use Beta)"),
    ("bed_sh_b",                   "",     "float", -1,      1,           False,
     "bed Steinhart-Hart B"),
    ("bed_sh_c",                   "",     "float", -1,      1,           False,
     "bed Steinhart-Hart C"),
    ("bed_kp",                     "",     "float", 0,       1000,        False,
     "bed PID proportional gain (duty per C)"),
    ("bed_ki",                     "",     "float", 0,       1000,        False,
     "bed PID integral gain (duty per C s)"),
    ("bed_kd",                     "",     "float", 0,       10000,       False,
     "bed PID derivative gain (duty s per C)"),
    ("bed_pwm_hz",                 "",     "int",   1,       100000,      True,
     "bed heater PWM frequency; below the chip's PWM, in software (SSR)"),
    ("bed_min_c",                  "",     "float", -100,    100,         False,
     "bed lowest sane reading (below: thermistor open)"),
    ("bed_max_c",                  "",     "float", 0,       500,         False,
     "bed highest target and sane reading"),
    ("bed_watch_s",                "",     "float", 1,       3600,        False,
     "bed heating watch period"),
    ("bed_watch_rise_c",           "",     "float", 0.1,     100,         False,
     "bed least rise per watch period while heating"),
    ("bed_runaway_c",              "",     "float", 1,       100,         False,
     "bed runaway: this far below the reached target..."),
    ("bed_runaway_s",              "",     "float", 1,       3600,        False,
     "bed ...for this long"),
    # Temperatures, fan, retraction, transitions, per-drive and per-tool options.
    ("min_extrude_c",              "",     "float", 0,       500,         False,
     "refuse extrusion below this hot end temperature"),
    ("fan_pwm_hz",                 "",     "int",   1,       100000,      True,
     "part fan PWM frequency, within what the chip's PWM makes at its clock"),
    ("thermal_period_ms",          "",     "int",   10,      10000,       True,
     "heater control period"),
    ("retract_policy",             "",     "int",   0,       2,           False,
     "0: retractions follow the mix, exactly reversed; 1: all drives equally; "
     "2: replay each drive's latest steps exactly"),
    ("retract_mm",                 "",     "float", 0,       50,          False,
     "G10 retraction length"),
    ("retract_feed_mm_s",          "",     "float", 0.1,     500,         False,
     "G10 retraction speed"),
    ("unretract_feed_mm_s",        "",     "float", 0.1,     500,         False,
     "G11 unretraction speed"),
    ("change_park_mm",             "xyz",  "float", 0,       100000,      False,
     "M600 parks the nozzle at X, Y (within the travel), Z raised by this"),
    ("change_unload_mm",           "",     "float", 0,       100000,      False,
     "M600 unloads this much filament before the change (0: by hand)"),
    ("change_load_mm",             "",     "float", 0,       100000,      False,
     "M600 loads this much filament after the change, before the purge"),
    ("change_purge_mm",            "",     "float", 0,       100000,      False,
     "M600 purges this much filament with the active mix after the load"),
    ("change_feed_mm_s",           "",     "float", 0.1,     500,         False,
     "M600 unload, load and purge speed"),
    ("change_heater_timeout_s",    "",     "int",   0,       86400,       False,
     "M600 turns the hot end off after waiting this long (0: never); resuming heats it"),
    ("runout_enabled",             "",     "bool",  0,       1,           False,
     "a runout input reading empty starts M600 for its drive (M412)"),
    ("runout_active_high",         "",     "bool",  0,       1,           True,
     "runout inputs read high when the filament is gone"),
    ("runout_pullup",              "",     "bool",  0,       1,           True,
     "enable the chip's pull-ups on the runout inputs"),
    ("transition_l1_mm",           "",     "float", 0,       100,         True,
     "mixing chamber delay L1; with L2, changes apply L1 + L2/2 of extrusion early"),
    ("transition_l2_mm",           "",     "float", 0,       100,         True,
     "transition length L2 over which a change blends"),
    ("transition_pairs",           "each", "pair",  0.0,     100.0,       True,
     "L1 and L2 for changes from one tool to another, from:to:l1_mm:l2_mm"),
    ("drive_steps_per_mm",         "each", "float", 0.001,   100000,      False,
     "steps per mm of filament of this mixing drive (M92 E sets them all)"),
    ("filament_used_mm",           "each", "float", -1000000000,1000000000,  False,
     "filament this drive has fed, net of retractions (M167 reports, M167 R clears)"),
    ("tool_mixes",                 "each", "mix",   0,       0,           False,
     "mix of this virtual tool, drive weights w0:w1:... (M164/M165/M567 set it)"),
    ("tool_advance_k",             "each", "float", 0,       10,          False,
     "pressure advance K of this virtual tool, s: filament pushed ahead by K times its "
     "speed (M900 sets it; 0: off)"),
    ("trace_records",              "",     "int",   0,       100000,      True,
     "step events the on-board trace ring holds (M7300/M7301), 12 bytes each"),
    ("watchdog_ms",                "",     "int",   1000,    8388,        True,
     "a main loop stuck this long resets the board (hardware watchdog, always on)"),
    ("step_stall_ms",              "",     "int",   10,      10000,       True,
     "no step-loop tick for this long halts the printer, heaters off"),
    ("console_uart",               "",     "int",   -1,      4,           True,
     "UART id of a serial console besides USB, -1 for none"),
    ("console_baud",               "",     "int",   300,     4000000,     True,
     "serial console baud rate"),
    ("tcp_port",                   "",     "int",   1,       65535,       True,
     "TCP G-code console port"),
    ("tcp_max_clients",            "",     "int",   1,       8,           True,
     "TCP G-code connections at once"),
)
