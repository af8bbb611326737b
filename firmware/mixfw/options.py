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
    "trace_records": 512,
}


def _heater(h):
    """The options of heater h (hotend, bed): its thermistor, PID and protection."""
    return (
        # setting              axes type   min      max          restart
        (h + "_beta",          "", FLOAT,  500.0,   20000.0,     LIVE,
         h + " thermistor Beta (K)"),
        (h + "_r25_ohm",       "", FLOAT,  1.0,     10000000.0,  LIVE,
         h + " thermistor resistance at 25 C"),
        (h + "_pullup_ohm",    "", FLOAT,  1.0,     10000000.0,  LIVE,
         h + " thermistor pull-up resistor"),
        (h + "_sh_a",          "", FLOAT,  -1.0,    1.0,         LIVE,
         h + " Steinhart-Hart A (A, B, C all 0: use Beta)"),
        (h + "_sh_b",          "", FLOAT,  -1.0,    1.0,         LIVE,
         h + " Steinhart-Hart B"),
        (h + "_sh_c",          "", FLOAT,  -1.0,    1.0,         LIVE,
         h + " Steinhart-Hart C"),
        (h + "_kp",            "", FLOAT,  0.0,     1000.0,      LIVE,
         h + " PID proportional gain (duty per C)"),
        (h + "_ki",            "", FLOAT,  0.0,     1000.0,      LIVE,
         h + " PID integral gain (duty per C s)"),
        (h + "_kd",            "", FLOAT,  0.0,     10000.0,     LIVE,
         h + " PID derivative gain (duty s per C)"),
        (h + "_pwm_hz",        "", INT,    1,       100000,      RESTART,
         h + " heater PWM frequency"),
        (h + "_min_c",         "", FLOAT,  -100.0,  100.0,       LIVE,
         h + " lowest sane reading (below: thermistor open)"),
        (h + "_max_c",         "", FLOAT,  0.0,     500.0,       LIVE,
         h + " highest target and sane reading"),
        (h + "_watch_s",       "", FLOAT,  1.0,     3600.0,      LIVE,
         h + " heating watch period"),
        (h + "_watch_rise_c",  "", FLOAT,  0.1,     100.0,       LIVE,
         h + " least rise per watch period while heating"),
        (h + "_runaway_c",     "", FLOAT,  1.0,     100.0,       LIVE,
         h + " runaway: this far below the reached target..."),
        (h + "_runaway_s",     "", FLOAT,  1.0,     3600.0,      LIVE,
         h + " ...for this long"),
    )


SCHEMA = (
    # setting                      axes    type   min      max          restart
    ("steps_per_mm",               "xyze", FLOAT, 0.001,   100000.0,    LIVE,
     "steps per mm (E: per mm of filament, every drive)"),
    ("max_feed_mm_s",              "xyze", FLOAT, 0.01,    10000.0,     LIVE,
     "maximum speed"),
    ("max_accel_mm_s2",            "xyze", FLOAT, 0.1,     1000000.0,   LIVE,
     "maximum acceleration"),
    ("acceleration_mm_s2",         "",     FLOAT, 0.1,     1000000.0,   LIVE,
     "print and travel acceleration"),
    ("retract_acceleration_mm_s2", "",     FLOAT, 0.1,     1000000.0,   LIVE,
     "acceleration of E-only moves"),
    ("junction_deviation_mm",      "",     FLOAT, 0.001,   10.0,        LIVE,
     "cornering: larger is faster through corners"),
    ("default_feed_mm_s",          "",     FLOAT, 0.01,    10000.0,     LIVE,
     "feed rate before the first F"),
    ("travel_mm",                  "xyz",  FLOAT, 1.0,     100000.0,    LIVE,
     "axis length; soft limits are 0..travel"),
    ("soft_limits",                "",     BOOL,  0,       1,           LIVE,
     "refuse moves outside 0..travel"),
    ("max_extrude_mm",             "",     FLOAT, 0.1,     100000.0,    LIVE,
     "longest E move accepted in one line"),
    ("homing_feed_mm_s",           "xyz",  FLOAT, 0.01,    1000.0,      LIVE,
     "homing speed"),
    ("drives",                     "",     INT,   1,       6,           RESTART,
     "mixing drives fitted"),
    ("virtual_tools",              "",     INT,   1,       16,          RESTART,
     "virtual tools T0.."),
    ("queue_blocks",               "",     INT,   4,       256,         RESTART,
     "planner queue length"),
    ("line_buffer_bytes",          "",     INT,   32,      1024,        RESTART,
     "longest G-code line"),
    ("tick_us",                    "",     INT,   5,       1000,        RESTART,
     "step-loop period"),
    ("step_pulse_us",              "",     INT,   1,       100,         RESTART,
     "minimum STEP high time"),
    ("dir_setup_us",               "",     INT,   0,       100,         RESTART,
     "minimum DIR-to-STEP setup time"),
    ("enable_active_low",          "",     BOOL,  0,       1,           RESTART,
     "drivers are enabled by a low ENABLE pin"),
    ("endstop_active_high",        "",     BOOL,  0,       1,           RESTART,
     "endstop switches read high when hit"),
    ("endstop_pullup",             "",     BOOL,  0,       1,           RESTART,
     "enable the chip's pull-ups on the endstop inputs"),
) + _heater("hotend") + _heater("bed") + (
    ("min_extrude_c",              "",     FLOAT, 0.0,     500.0,       LIVE,
     "refuse extrusion below this hot end temperature"),
    ("fan_pwm_hz",                 "",     INT,   1,       100000,      RESTART,
     "part fan PWM frequency"),
    ("thermal_period_ms",          "",     INT,   10,      10000,       RESTART,
     "heater control period"),
    ("retract_policy",             "",     INT,   0,       2,           LIVE,
     "0: retractions follow the mix, exactly reversed; 1: all drives equally; "
     "2: replay each drive's latest steps exactly"),
    ("retract_mm",                 "",     FLOAT, 0.0,     50.0,        LIVE,
     "G10 retraction length"),
    ("retract_feed_mm_s",          "",     FLOAT, 0.1,     500.0,       LIVE,
     "G10 retraction speed"),
    ("unretract_feed_mm_s",        "",     FLOAT, 0.1,     500.0,       LIVE,
     "G11 unretraction speed"),
    ("transition_l1_mm",           "",     FLOAT, 0.0,     100.0,       RESTART,
     "mixing chamber delay L1; with L2, changes apply L1 + L2/2 of extrusion early"),
    ("transition_l2_mm",           "",     FLOAT, 0.0,     100.0,       RESTART,
     "transition length L2 over which a change blends"),
    ("transition_pairs",           EACH,   PAIR,  0.0,     100.0,       RESTART,
     "L1 and L2 for changes from one tool to another, from:to:l1_mm:l2_mm"),
    ("drive_steps_per_mm",         EACH,   FLOAT, 0.001,   100000.0,    LIVE,
     "steps per mm of filament of this mixing drive (M92 E sets them all)"),
    ("filament_used_mm",           EACH,   FLOAT, -1e9,    1e9,         LIVE,
     "filament this drive has fed, net of retractions (M167 reports, M167 R clears)"),
    ("tool_mixes",                 EACH,   MIX,   0,       0,           LIVE,
     "mix of this virtual tool, drive weights w0:w1:... (M164/M165/M567 set it)"),
    ("trace_records",              "",     INT,   0,       100000,      RESTART,
     "step events the on-board trace ring holds (M7300/M7301), 12 bytes each"),
    ("console_uart",               "",     INT,   -1,      4,           RESTART,
     "UART id of a serial console besides USB, -1 for none"),
    ("console_baud",               "",     INT,   300,     4000000,     RESTART,
     "serial console baud rate"),
    ("tcp_port",                   "",     INT,   1,       65535,       RESTART,
     "TCP G-code console port"),
    ("tcp_max_clients",            "",     INT,   1,       8,           RESTART,
     "TCP G-code connections at once"),
)
