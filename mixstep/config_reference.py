"""docs/Config_Reference.md, generated from the firmware's option schema.

    python -m mixstep.config_reference            write docs/Config_Reference.md
    python -m mixstep.config_reference --stdout   print it instead
    python -m mixstep.config_reference --check    exit 1, showing the difference, if
                                                  the file is not what render() gives

Names, types, limits, restart flags and firmware defaults come from
firmware/mixfw/options.py; the boards' defaults from boards/*/board.py, read through
the firmware's own Config, so the document shows what M503 would print on each board.
The schema's help texts are kept short because the chips hold them in RAM; the units
and the fuller meanings live here, in DESCRIPTIONS, one entry per schema row
(host_tests/test_config_reference.py fails on a row without one).
"""
import argparse
import difflib
import sys
import textwrap

from mixstep import boards, paths
from mixfw import defaults, defaults_net, options, options_net
from mixfw.config import Config, Option
from mixfw.pwm import clock_text

DOC = paths.ROOT / "docs" / "Config_Reference.md"
REGENERATE = ".venv/bin/python -m mixstep.config_reference"
# Every option's row: the firmware's, and those a board with a network adds.
ALL_ROWS = options.SCHEMA + options_net.NETWORK_ROWS

# (key, title, what the group is): the document's sections, in order.
GROUPS = (
    ("motion", "Motion",
     "Axes, speeds, accelerations and the planner. `M92`, `M201`, `M203`, `M204` and "
     "`M205` set these options and apply them at once, as in Marlin."),
    ("mixing", "Mixing drives and virtual tools",
     "The filament drives that feed the one nozzle, the virtual tools' mixes, and colour "
     "changes moved ahead of time (see [Mixing](Mixing.md))."),
    ("retraction", "Retraction", "Firmware retraction (`G10`/`G11`) and how a "
     "retraction is shared among the drives."),
    ("change", "Filament change", "What `M600` does when its line gives no word of its "
     "own (see [G-Codes](G-Codes.md))."),
    ("runout", "Filament runout", "The runout inputs a board declares (`e<n>_runout` "
     "in its `PINS`, see [Boards](Boards.md)): an input that reads the filament gone "
     "while its drive feeds starts `M600 D<n>` (see [G-Codes](G-Codes.md), `M412`). A "
     "board without such pins ignores these options."),
    ("levelling", "Bed probe and levelling",
     "The bed probe on a board's `z_probe` pin (a BLTouch is deployed and stowed by its "
     "`probe_servo` pin), `G30` and `G29`'s grid, and the mesh `M420` levels by. `G29` "
     "writes the mesh into these options and `M500` saves it (see "
     "[G-Codes](G-Codes.md))."),
    ("step_path", "Step path and pins",
     "What the step loop runs at and how the drivers' and endstops' pins are read and "
     "driven (see [Step_Timing](Step_Timing.md) and [Boards](Boards.md))."),
    ("drivers", "TMC2209 drivers",
     "Only on boards with TMC2209 drivers on a UART (`TMC_UART` in `board.py`); `_e` is "
     "the driver in the E socket. `M906` and `M569` set these and apply them at once."),
    ("hotend", "Hot end", "The hot end's heater: thermistor, PID, thermal protection."),
    ("bed", "Bed", "The bed's heater, with the same options as the hot end's. A board "
     "without a bed has none of them."),
    ("thermal", "Heater control and part fan", "Shared by both heaters, and the fan."),
    ("safety", "Watchdog and trace", "What stops a firmware that hangs, and the "
     "on-board step trace."),
    ("consoles", "Consoles and network", "Where the firmware takes G-code from."),
)

# The heaters' rows alike for the hot end and the bed (a test in test_config.py holds
# options.py's rows alike too): "{h}" is the heater's prefix.
_HEATER = {
    "beta": ("K", "Thermistor Beta, for the Beta model, used while `{h}_sh_a`, "
             "`{h}_sh_b` and `{h}_sh_c` are all 0."),
    "r25_ohm": ("Ω", "Thermistor resistance at 25 °C."),
    "pullup_ohm": ("Ω", "Pull-up resistor of the thermistor's voltage divider."),
    "sh_a": ("1/K", "Steinhart–Hart coefficient A, in 1/T = A + B ln R + C (ln R)³ "
             "with T in K and R in Ω. Any of A, B, C non-zero replaces the Beta model."),
    "sh_b": ("1/K", "Steinhart–Hart coefficient B."),
    "sh_c": ("1/K", "Steinhart–Hart coefficient C."),
    "kp": ("1/°C", "PID proportional gain: heater duty (0..1) per °C of error."),
    "ki": ("1/(°C·s)", "PID integral gain: duty per °C·s of error (with anti-windup)."),
    "kd": ("s/°C", "PID derivative gain: duty per °C/s of change."),
    "pwm_hz": ("Hz", "Heater PWM frequency. Below the lowest the chip's PWM makes at its "
               "clock (8 Hz on an RP2040 at 125 MHz) a software PWM drives the pin, as "
               "a solid-state relay wants (1–5 Hz)."),
    "min_c": ("°C", "Lowest sane reading: below it the thermistor counts as open, and "
              "the heater turns off and motion stops with an error."),
    "max_c": ("°C", "Highest target accepted, and highest sane reading: above it the "
              "thermistor counts as shorted (a thermal fault, as below `{h}_min_c`)."),
    "watch_s": ("s", "Heating watch period: while heating toward its target, the "
                "temperature must rise `{h}_watch_rise_c` within each period this long, "
                "or the heater is off with an error (heater or thermistor loose)."),
    "watch_rise_c": ("°C", "Least rise per watch period while heating."),
    "runaway_c": ("°C", "Runaway band: the heating watch runs until the temperature is "
                  "within this of the target; from then on, more than this below the "
                  "target for over `{h}_runaway_s` is a thermal runaway."),
    "runaway_s": ("s", "How long the temperature may stay below the runaway band."),
}

# Every schema row (setting name): (group, unit, meaning). "-" is no unit.
DESCRIPTIONS = {
    "steps_per_mm": (
        "motion", "steps/mm",
        "X, Y, Z: motor steps per mm of travel. E: steps per mm of filament on the "
        "planner's E axis, and where each `drive_steps_per_mm_<n>` starts. `M92` sets "
        "them (`M92 E` every drive's too)."),
    "max_feed_mm_s": (
        "motion", "mm/s",
        "Highest speed of each axis: a move is slowed until no axis exceeds its own "
        "(`M203`)."),
    "max_accel_mm_s2": (
        "motion", "mm/s²",
        "Highest acceleration of each axis: a move's acceleration is lowered until no "
        "axis exceeds its own (`M201`)."),
    "acceleration_mm_s2": (
        "motion", "mm/s²",
        "Acceleration of printing and travel moves, within each axis's "
        "`max_accel_mm_s2` (`M204 P`, or `T` or `S`)."),
    "retract_acceleration_mm_s2": (
        "motion", "mm/s²",
        "Acceleration of moves of E alone: retractions, unretractions, E-only moves "
        "(`M204 R`)."),
    "junction_deviation_mm": (
        "motion", "mm",
        "Cornering, as Marlin's junction deviation: the look-ahead passes a corner "
        "faster the larger it is (`M205 J`). There is no jerk: `M205 X Y Z E` are "
        "ignored."),
    "min_segment_time_us": (
        "motion", "µs",
        "While fewer than half the planner's queue blocks wait, a move shorter than this "
        "(in time) is slowed toward it, the more the fewer wait, so the step path does "
        "not run dry between short segments a host is slow to send (Marlin's SLOWDOWN "
        "and DEFAULT_MINSEGMENTTIME, `M205 B`). 0: off."),
    "default_feed_mm_s": (
        "motion", "mm/s", "Feed rate of moves before the first `F` word."),
    "travel_mm": (
        "motion", "mm",
        "Length of each axis from its min endstop; with `soft_limits` on, a move outside "
        "0..travel is refused."),
    "soft_limits": (
        "motion", "-",
        "1: refuse moves of X, Y, Z outside 0..`travel_mm`; 0: allow them. `M211 S0`/`S1` "
        "switches them until a restart or a change of this option."),
    "max_extrude_mm": (
        "motion", "mm",
        "Longest E move taken in one line; a longer one is refused with an error (a "
        "guard against a mistaken E from a slicer or host)."),
    "min_arc_segment_mm": (
        "motion", "mm",
        "`G2`/`G3` arcs are cut into straight segments no shorter than this (a small "
        "circle gets fewer than `min_circle_segments`)."),
    "max_arc_segment_mm": (
        "motion", "mm",
        "`G2`/`G3` arcs are cut into straight segments no longer than this: a segment's "
        "chord strays from the arc by at most its sagitta, r - sqrt(r^2 - (s/2)^2)."),
    "min_circle_segments": (
        "motion", "segments",
        "`G2`/`G3` arcs get at least this many segments a full turn (a small circle "
        "stays round), unless segments would be shorter than `min_arc_segment_mm`."),
    "homing_feed_mm_s": (
        "motion", "mm/s", "Speed of X, Y and Z toward their min endstops in `G28`."),
    "queue_blocks": (
        "motion", "moves",
        "Moves the planner queues and looks ahead over. Every move is planned to be able "
        "to stop by the end of the queue, so a longer queue prints short segments "
        "faster, at a cost in RAM."),
    "drives": (
        "mixing", "drives",
        "Filament drives feeding the mixing nozzle, `e0` .. `e<drives-1>` in the board's "
        "pin map. Every board states it."),
    "virtual_tools": (
        "mixing", "tools", "Virtual tools `T0` .. `T<virtual_tools-1>`, each a mix "
        "(`tool_mixes_<n>`)."),
    "transition_l1_mm": (
        "mixing", "mm",
        "Mixing chamber delay L1: filament between where the drives meet and the nozzle "
        "tip. With L1 or L2 set, every mix or tool change is applied L1 + L2/2 of "
        "printing extrusion before the G-code places it. 0 with L2 0: off."),
    "transition_l2_mm": (
        "mixing", "mm",
        "Transition length L2: extrusion over which the nozzle's output blends from the "
        "old mix to the new."),
    "transition_pairs": (
        "mixing", "tool, tool, mm, mm",
        "Slots, each L1 and L2 for the changes from one tool to another, "
        "`from:to:l1_mm:l2_mm` (`0:1:0.5:1.0`), instead of `transition_l1_mm` and "
        "`transition_l2_mm`. `0:0:0.0:0.0` is an empty slot."),
    "drive_steps_per_mm": (
        "mixing", "steps/mm",
        "One per drive: steps per mm of filament of drive n, "
        "for drives geared differently. Defaults to `steps_per_mm_e`; `M92 E` sets every "
        "drive's."),
    "filament_used_mm": (
        "mixing", "mm",
        "One per drive: filament drive n has fed, net of "
        "retractions, counted while printing and saved by `M500`. `M167` reports it, "
        "`M167 R` clears it."),
    "tool_mixes": (
        "mixing", "weights",
        "One per virtual tool: the mix of tool Tn, a weight per drive "
        "`w0:w1:...`, kept as integers with their common factor taken out (`M164`, "
        "`M165`, `M567` set it). Default: Tn is drive n alone below `drives`, an equal "
        "mix of every drive above."),
    "tool_advance_k": (
        "mixing", "s",
        "One per virtual tool: pressure advance K (Marlin's LIN_ADVANCE K), `M900` sets "
        "it. A printing move's filament is pushed ahead by K times its speed, for the "
        "whole mix, shared among the drives by the same error diffusion; at rest every "
        "drive is where it would be without. Typical: 0.02-0.1 direct drive, 0.3-1 "
        "Bowden. 0: off."),
    "retract_policy": (
        "retraction", "-",
        "How a retraction (an E move backwards, a wipe, `G10`/`G11`) is shared among the "
        "drives. 0: the mix, exactly reversed. 1: every drive equally. 2: replay: each "
        "drive takes back exactly the steps it made in the latest extrusion, newest "
        "first, and the unretraction pushes those back, whatever tool is active by "
        "then."),
    "change_park_mm": (
        "change", "mm",
        "X, Y: where `M600` parks the nozzle, within the travel. Z: how far it raises the "
        "nozzle first (at most to the top of the travel)."),
    "change_unload_mm": (
        "change", "mm",
        "Filament `M600` unloads from the drive changed (`D`), or the mix, after parking. "
        "0: none, the change is made by hand."),
    "change_load_mm": (
        "change", "mm", "Filament `M600` loads into the drive changed after the wait."),
    "change_purge_mm": (
        "change", "mm",
        "Filament `M600` purges with the active mix after the load, before going back."),
    "change_feed_mm_s": ("change", "mm/s", "Speed of `M600`'s unload, load and purge."),
    "change_heater_timeout_s": (
        "change", "s",
        "How long `M600` waits with the hot end at its target; then the hot end turns "
        "off, and heats again before the print goes on. 0: it stays on."),
    "runout_enabled": (
        "runout", "-",
        "1: an input that reads the filament gone for five checks in a row (10 ms apart "
        "at the least) starts `M600 D<n>` for its drive once that drive feeds filament; "
        "0: the inputs are not watched. `M412 S0`/`S1` sets it, `M500` keeps it."),
    "runout_active_high": (
        "runout", "-",
        "1: a runout input reads high when the filament is gone; 0: low (Marlin's "
        "`FIL_RUNOUT_STATE LOW`)."),
    "runout_pullup": (
        "runout", "-",
        "1: turn on the chip's pull-ups on the runout inputs, for switches that only pull "
        "low; 0: none, for sensors that drive both levels or need a pull-down fitted."),
    "probe_active_high": (
        "levelling", "-", "1: the `z_probe` input reads high when the probe triggers "
        "(a BLTouch, a PNP probe); 0: low (an NPN probe, with `endstop_pullup`)."),
    "probe_offset_mm": (
        "levelling", "mm",
        "Where the probe is from the nozzle, as Marlin's `M851`: X and Y the probe's "
        "place less the nozzle's; Z the nozzle's height when the probe triggers, "
        "negated (a probe triggering 1.5 mm above the nozzle's tip: -1.5). A probed "
        "height is the trigger's Z plus this Z."),
    "probe_feed_mm_s": ("levelling", "mm/s", "Speed of a probe's dive toward the bed."),
    "probe_travel_feed_mm_s": (
        "levelling", "mm/s", "Speed of the moves between probed points."),
    "probe_clearance_mm": (
        "levelling", "mm", "Machine Z each dive starts from, and the travel between "
        "points is at (Marlin's Z_CLEARANCE_BETWEEN_PROBES); `G29` and `G30` end there."),
    "probe_dive_mm": (
        "levelling", "mm", "How far a dive goes down from `probe_clearance_mm` before "
        "it gives up with an error (the probe never triggered)."),
    "mesh_points": (
        "levelling", "-", "`G29`'s grid: points along X and along Y (2..5 each)."),
    "mesh_min_mm": (
        "levelling", "mm", "`G29`'s grid: the probe's first point along X and Y, "
        "machine coordinates; the points are spread evenly to `mesh_max_mm`. Every point "
        "must leave the nozzle within the travel."),
    "mesh_max_mm": ("levelling", "mm", "`G29`'s grid: the probe's last point."),
    "mesh_fade_mm": (
        "levelling", "mm", "The correction shrinks linearly from its whole at Z 0 to "
        "nothing at this Z (machine, unlevelled), as Marlin's `M420 Z`; 0: it never "
        "fades."),
    "mesh_probed": (
        "levelling", "-", "1: `mesh_z_nm` holds a mesh `G29` made on the grid the "
        "`mesh_*` options give; `M420 S1` needs it. Changing the grid (`M930`) clears it."),
    "mesh_enabled": (
        "levelling", "-", "1: moves are levelled by the mesh (`M420 S1`, `G29`); `G28`, "
        "`G29` and `G30` turn it off as they start. Saved on, the mesh levels from boot."),
    "mesh_z_nm": (
        "levelling", "nm", "The mesh: the bed's height at each grid point, row by row "
        "(X first, then the next Y), as `M420 V` prints it. `G29` writes them."),
    "retract_mm": ("retraction", "mm", "Length of `G10`; `G11` pushes it back."),
    "retract_feed_mm_s": ("retraction", "mm/s", "Speed of `G10`."),
    "unretract_feed_mm_s": ("retraction", "mm/s", "Speed of `G11`."),
    "tick_us": (
        "step_path", "µs",
        "Period of the step loop. A motor steps at most once every two ticks (10 µs: "
        "50,000 steps/s). Every board states it, to suit its chip and step backend."),
    "step_pulse_us": (
        "step_path", "µs",
        "Shortest STEP high time the drivers need (a DRV8825 needs 1.9 µs); with the "
        "timer step backend it is rounded up to whole ticks."),
    "dir_setup_us": (
        "step_path", "µs", "Shortest time from a DIR change to the next STEP edge."),
    "enable_active_low": (
        "step_path", "-",
        "1: the drivers are enabled by a low ENABLE pin (A4988, DRV8825, TMC2209); 0: by "
        "a high one. `boot.py` reads it from `board.py` to turn the drivers off at "
        "power-on, so set it there too. Every board states it."),
    "endstop_active_high": (
        "step_path", "-", "1: an endstop input reads high when its switch is hit; 0: low."),
    "endstop_pullup": (
        "step_path", "-",
        "1: turn on the chip's pull-ups on the endstop inputs, for switches that only "
        "pull low (the ESP32's GPIO 34-39 have none)."),
    "driver_microsteps": (
        "drivers", "microsteps",
        "Microsteps per full step the driver is set to; `steps_per_mm` must match."),
    "driver_current_ma": (
        "drivers", "mA",
        "RMS run current (`M906`); a motor standing still holds at half of it."),
    "driver_spreadcycle": (
        "drivers", "-", "Chopper: 0 stealthChop (quiet), 1 spreadCycle (`M569`)."),
    "min_extrude_c": (
        "thermal", "°C",
        "Extrusion is refused while the hot end is below this, judged by a reading at "
        "most two control periods old; `M302 P1` allows cold extrusion."),
    "fan_pwm_hz": (
        "thermal", "Hz",
        "Part fan PWM frequency, within what the chip's PWM makes at its clock (the fan "
        "has no software PWM)."),
    "thermal_period_ms": (
        "thermal", "ms",
        "Heater control period: each heater's thermistor is read and its PID run this "
        "often."),
    "trace_records": (
        "safety", "records",
        "Step events the on-board trace ring holds, 12 bytes of RAM each, held from "
        "boot: `M7300` records, `M7301` hands them to `mixstep trace pull`. 0: no ring."),
    "watchdog_ms": (
        "safety", "ms",
        "Hardware watchdog, always on: a main loop or interrupt stuck this long resets "
        "the board. 1000 ms is the ESP32's least, 8388 ms the RP2040's and RP2350's "
        "most."),
    "step_stall_ms": (
        "safety", "ms",
        "When the step loop has not ticked for this long (a timer callback that raised "
        "never runs again) the printer halts with an error, heaters off; only a restart "
        "revives it."),
    "line_buffer_bytes": (
        "consoles", "bytes",
        "Longest G-code line taken, from a console or a file; a longer one is refused "
        "with an error, except a plain M117/M118 message, which is cut to fit."),
    "console_uart": (
        "consoles", "UART id", "A serial console on this UART besides USB; -1: none."),
    "console_baud": ("consoles", "baud", "Baud rate of the UART console."),
    "tcp_port": (
        "consoles", "port",
        "Port of the TCP G-code console, on boards connected to a network. The "
        "simulation takes `mixstep serve --tcp HOST:PORT` instead."),
    "tcp_max_clients": ("consoles", "connections", "TCP G-code connections at once."),
    "drive_colour_rgb": (
        "mixing", "0xRRGGBB",
        "The colour of the filament each drive feeds, as a whole number (0xFF0000 = "
        "16711680 is red). The web page shows the colour each mix prints from them: "
        "each channel the weights' mean of the filaments' (`colours.mix_rgb`, as "
        "`mixstep preview` draws it). Defaults: `mixstep preview`'s colours."),
    "net_password": (
        "consoles", "text",
        "Password a network connection must send as its first line before any "
        "G-code. Empty (the default): the network console is off, except "
        "`mixstep serve --tcp` on a loopback address. 8 to 64 characters without "
        "spaces. Kept by M500, compared in constant time, never shown by M503, M925 "
        "or any report."),
    "web_page_port": (
        "consoles", "port",
        "Port of the web page, on boards connected to a network, behind "
        "`net_password`; 0: off. The simulation takes `mixstep serve --http HOST:PORT` "
        "instead."),
    "net_idle_timeout_s": (
        "consoles", "s",
        "A network connection that sends no complete line for this long is closed, "
        "so a forgotten client doesn't hold one of `tcp_max_clients`; 0: never."),
}
DESCRIPTIONS.update({
    "%s_%s" % (heater, key): (heater, unit, text.replace("{h}", heater))
    for heater in ("hotend", "bed") for key, (unit, text) in _HEATER.items()})

INTRO = """\
# Config Reference

Every runtime option of the firmware: the values `M503` prints and `M926` sets, with
unit, range, default and meaning. This document is generated from the option schema
(`firmware/mixfw/options.py`) and the boards' settings by
`python -m mixstep.config_reference`: edit those, not this file.

## Setting options

- **On the board**, `boards/<name>/board.py` holds the defaults in `SETTINGS`: it starts
  from `firmware/mixfw/defaults.py` (a typical printer) and overrides what its hardware
  decides. Options it leaves out take the firmware's defaults (`FIRMWARE_DEFAULTS` in
  `options.py`).
- **On a running printer** (see [G-Codes](G-Codes.md)): `M503` prints every option as an
  `M926` line that can be pasted back, with its help, limits and `(restart)`;
  `M925 I<name>` prints one; `M926 I<name> V<value>` sets one (without `V`: back to the
  board's default); `M930` applies what was set; `M500` saves the configuration to
  `/mixstep.cfg` on the board's flash, `M501` loads it, `M502` sets every option back to
  the board's defaults. Marlin's `M92`, `M201`, `M203`, `M204`, `M205` and the drivers'
  `M906`, `M569` set their options and apply them at once.
- **Restart** options are read once, when the printer is assembled (buffer sizes, pins,
  the tick): `M930` lists those set but not yet in effect; `M500` and a restart apply
  them.
- **In simulation**, `mixstep serve --set KEY=VALUE` (also `mixstep emu` and
  `mixstep trace check`) overrides a board setting for the run, a whole setting at a
  time: `--set retract_policy=2`, `--set steps_per_mm=80,80,400,415`.

An option is named after its setting. A setting with a value per axis gives one option
per axis (`steps_per_mm_x` .. `steps_per_mm_e`); a setting with a value per drive, tool
or slot gives one per index (`tool_mixes_0`, `tool_mixes_1`, ...). Values are numbers;
`0 or 1` options are booleans; a mix is `w0:w1:...`; a tool pair is
`from:to:l1_mm:l2_mm`.

The tables give, for each option:
- **range**: what `M926` takes; where a chip's PWM narrows it, per chip at its clock;
- **default** and where it comes from: `firmware` (`FIRMWARE_DEFAULTS` in `options.py`,
  unless a board sets it), `defaults.py` (`firmware/mixfw/defaults.py`, unless a board
  overrides it: the boards that do are named), `defaults_net.py` (the same, for the
  options of boards with a network), `board.py` (each board states it) or
  `derived` (from other settings when the board gives none); values per axis or index
  in the order of the names;
- **applies**: `M930` (or at once, by the Marlin commands named) or `restart`."""

_HEAD = ("| option | unit | range | default | from | applies | meaning |\n"
         "|---|---|---|---|---|---|---|")
# A default longer than this (per-tool mixes) is left to the meaning to describe.
_MAX_DEFAULT_CHARS = 60


def _board_configs():
    """{board: Config} at every board's defaults, as the firmware builds them."""
    return {name: Config(paths.load_board(name)["SETTINGS"], None)
            for name in boards.board_names()}


def _option_texts(config):
    """{setting: [each of its options' default as M503 prints it]} of one board."""
    texts = {}
    for o in config.options:
        texts.setdefault(o.key, []).append(config.format(o.name))
    return texts


def _join(texts, per_index):
    if per_index and len(set(texts)) == 1:
        return "%s each" % texts[0]
    return ", ".join(texts)


def _by_value(texts_of):
    """'v1 (board, board); v2 (board)' for {board: text}, most boards first."""
    groups = {}
    for name, text in texts_of.items():
        groups.setdefault(text, []).append(name)
    order = sorted(groups, key=lambda t: (-len(groups[t]), groups[t]))
    return "; ".join("%s (%s)" % (t, ", ".join(groups[t])) for t in order)


def _source(key, configs):
    if key in options.FIRMWARE_DEFAULTS:
        return "firmware"
    if key in defaults.SETTINGS:
        return "defaults.py"
    if key in defaults_net.NETWORK:
        return "defaults_net.py"
    if any(key in c.board_settings for c in configs.values()):
        return "board.py"
    return "derived"


def _option(row, index):
    """An option of the row, of its own kind if it names one (as Config._option)."""
    return (Option if len(row) < 7 else row[6])(row, index, "", 0)


def _base_text(row, value):
    """A firmware or defaults.py value as M503 prints it, before any board's say."""
    if not row[1]:
        return _option(row, -1).format(value)
    return _join([_option(row, i).format(v) for i, v in enumerate(value)],
                 row[1] == options.EACH)


def _default_cell(row, source, texts_of):
    """texts_of: {board: its default text} of the boards that have the option."""
    key = row[0]
    base = {"firmware": options.FIRMWARE_DEFAULTS, "defaults.py": defaults.SETTINGS,
            "defaults_net.py": defaults_net.NETWORK}.get(source)
    if base is not None:
        common = _base_text(row, base[key])
        others = {b: t for b, t in texts_of.items() if t != common}
        if not others:
            return common or "none"
        return "%s; %s" % (common, _by_value(others))
    if len(set(texts_of.values())) == 1:
        text = next(iter(texts_of.values()))
        return text if len(text) <= _MAX_DEFAULT_CHARS else "per board: see meaning"
    if max(len(t) for t in texts_of.values()) > _MAX_DEFAULT_CHARS:
        return "per board: see meaning"
    return _by_value(texts_of)


def _limits(o):
    return "%s..%s" % (o.format(o.lo), o.format(o.hi))


def _range_cell(row, configs):
    key, _axes, kind, lo, hi = row[:5]
    base = _option(row, -1)
    if kind == options.BOOL:
        return "0 or 1"
    if kind == options.POW2:
        return "%s, a power of two" % _limits(base)
    if kind == options.MIX:
        return "weights ≥ 0, not all 0, one per drive"
    if kind == options.PAIR:
        return "tools 0..virtual_tools-1; lengths %r..%r mm" % (float(lo), float(hi))
    if kind == "text":  # options_net.SecretOption's
        return "empty, or %d..%d characters" % (lo, hi)
    # Limits a board's chip narrows (PWM frequencies), once per chip and clock.
    narrowed = {}
    for c in configs.values():
        if key in c.settings:
            o = c.option(next(o.name for o in c.options if o.key == key))
            if (o.lo, o.hi) != (lo, hi):
                narrowed["%s at %s" % (c.chip, clock_text(c.clock_hz))] = _limits(o)
    return "; ".join([_limits(base)] + ["%s: %s" % kv for kv in sorted(narrowed.items())])


def _names_cell(row, counts):
    """counts: how many options the row gives on each board that has it."""
    key, axes = row[:2]
    if not axes:
        return "`%s`" % key
    if axes == options.EACH:
        if len(set(counts)) == 1:  # the same on every board: say how many
            return "`%s_<n>`, n = 0..%d" % (key, counts[0] - 1)
        return "`%s_<n>`" % key
    return ", ".join("`%s_%s`" % (key, a) for a in axes)


def _wrap(text):
    return textwrap.fill(text, 88, break_long_words=False, break_on_hyphens=False)


def _cell(text):
    return text.replace("|", "\\|")


def _row_line(row, configs, texts):
    key = row[0]
    _group, unit, meaning = DESCRIPTIONS[key]
    having = [b for b in configs if key in texts[b]]
    texts_of = {b: _join(texts[b][key], row[1] == options.EACH) for b in having}
    source = _source(key, configs)
    if not having:
        default = "no board has it"
    else:
        default = _default_cell(row, source, texts_of)
        if len(having) < len(configs):
            default += "; only on " + ", ".join(having)
    counts = [len(texts[b][key]) for b in having]
    cells = (_names_cell(row, counts), unit, _range_cell(row, configs), default, source,
             "restart" if row[5] else "M930", meaning)
    return "| " + " | ".join(_cell(c) for c in cells) + " |"


def undocumented():
    """What keeps DESCRIPTIONS from matching the schema, one text each; empty if none."""
    keys = [row[0] for row in ALL_ROWS]
    groups = [g[0] for g in GROUPS]
    return (["%s: in the schema, not described" % k for k in keys if k not in DESCRIPTIONS]
            + ["%s: described, not in the schema" % k for k in DESCRIPTIONS if k not in keys]
            + ["%s: group %r is not in GROUPS" % (k, d[0])
               for k, d in DESCRIPTIONS.items() if d[0] not in groups]
            + ["%s: no unit (\"-\" for none) or no meaning" % k
               for k, d in DESCRIPTIONS.items() if not (d[1].strip() and d[2].strip())])


def render():
    """The whole of docs/Config_Reference.md."""
    problems = undocumented()
    if problems:
        raise ValueError("mixstep/config_reference.py DESCRIPTIONS: " + "; ".join(problems))
    configs = _board_configs()
    texts = {b: _option_texts(c) for b, c in configs.items()}
    out = [INTRO]
    for group, title, intro in GROUPS:
        out += ["", "## " + title, "", _wrap(intro), "", _HEAD]
        out += [_row_line(row, configs, texts) for row in ALL_ROWS
                if DESCRIPTIONS[row[0]][0] == group]
    schema_keys = {row[0] for row in ALL_ROWS}
    plain = sorted({k for c in configs.values() for k in c.board_settings} - schema_keys)
    out += ["", "## Board settings that are not options", "", _wrap(
            "`board.py` also holds settings read only there (and by `--set` in "
            "simulation), never by `M926`: %s. The comments in "
            "`firmware/mixfw/defaults.py` and [Boards](Boards.md) describe them."
            % ", ".join("`%s`" % k for k in plain))]
    return "\n".join(out) + "\n"


def difference(path=DOC):
    """A unified diff from the file at path to render(); empty if they agree."""
    have = path.read_text(encoding="utf-8").splitlines(True) if path.exists() else []
    return "".join(difflib.unified_diff(have, render().splitlines(True), str(path),
                                        "render()"))


def main(argv=None, path=DOC):
    p = argparse.ArgumentParser(prog="python -m mixstep.config_reference",
                                description="Write docs/Config_Reference.md from the "
                                            "firmware's option schema.")
    how = p.add_mutually_exclusive_group()
    how.add_argument("--stdout", action="store_true", help="print it, write nothing")
    how.add_argument("--check", action="store_true",
                     help="exit 1 if the file differs from what would be written")
    args = p.parse_args(argv)
    if args.stdout:
        sys.stdout.write(render())
        return 0
    if args.check:
        diff = difference(path)
        if diff:
            sys.stdout.write(diff)
            print("%s is out of date: run `%s`" % (path, REGENERATE), file=sys.stderr)
            return 1
        return 0
    path.write_text(render(), encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())
