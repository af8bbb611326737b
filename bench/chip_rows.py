"""The chip rows of `make bench`: the firmware on the emulated Pico.

Every figure comes from the real MicroPython v1.28 rp2 firmware running mixstep on
rp2040js (mixstep.emu.Chip and emu/harness.mjs, the image in mixstep.emu.DEFAULT_IMAGE),
board pico_6drives. The emulator is optimistic (no flash wait states, free interrupt
entry, see ../shared/rp2emu/README.md): each figure is an estimate, and real silicon
is slower. Three emulator sessions, one at a time:

  planner   bench/chip_main.py run by main.py, compiled with mpy-cross as `make
            deploy` compiles mixfw, with the board's mixfw beside it:
            plans an excerpt of the example with the queue retired by hand, alone
            and while a second printer's step path runs a six-drive mixed move.
  stepping  the firmware as deployed, over USB: one move at 20,000 steps/s for the CPU
            share and the step times, then moves at rising step rates for the highest
            rate whose pulses, DIR setup and step times are all in spec.
  print     the firmware as deployed: testdata/circles_tube_emu_excerpt.gcode streamed
            over USB, then the same file printed from the emulated flash (M23/M24), for
            the underruns and the free heap.
  prints    whole prints of two files, over USB and from flash, against their time in
            `mixstep sim` (bench/chip_print.py).

    python bench/run.py --only chip
    python bench/chip_rows.py [planner,stepping,cpu,print,prints,mixer,profile] [--board B] [--set K=V ...]
                                                        (figures as JSON)

`cpu` is the stepping part without its step-rate search. `profile` plans the planner
part's lines with the planner's functions timed (bench/chip_profile.py): microseconds
per G1 line in each, inclusive of what it calls and of the timing's own cost (about 15 us
for each timed call below it). --board and --set run the
rows on another board or with settings laid over the board's (as `mixstep emu --set`),
e.g. `--set step_backend=timer` for the hard-timer path, or `--board pico`; the move
is then mixed over the board's drives.
"""
import ast
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from mixstep import boards, deploy, emu, paths, steptiming

BOARD = "pico_6drives"
ROOT = paths.ROOT
BENCH_DIR = Path(__file__).resolve().parent
CIRCLES = ROOT / "testdata" / "circles_tube_emu_excerpt.gcode"
# The example's lines planned on the chip: perimeters and infill, 289 of 301 are G1.
PLAN_LINES = (3000, 3300)
CAVEAT = ("An estimate from the emulated RP2040 (rp2040js, the real MicroPython v1.28 "
          "rp2 firmware, at the board's 200 MHz), which charges no flash wait states and "
          "no interrupt entry: real silicon is slower.")

# The stepping moves: X, Y and E in the ratio 8 : 6 : 6 of steps, E mixed over all
# six drives (weights below, tool 6). At 20,000 steps/s: X 100 mm/s, Y 75 mm/s and
# 14.46 mm/s of filament at 80, 80 and 415 steps/mm.
SHARE = (0.4, 0.3, 0.3)
MIX = "M567 P6 E0.1:0.15:0.2:0.25:0.12:0.18"
CPU_RATE = 20000  # total steps/s of the CPU-share move
CPU_MOVE_S = 1.0
CPU_WINDOW = (0.25, 0.85)  # seconds after the move's ok: its cruise
# The same move accelerating to that rate over this long (M204 P), for the CPU share on
# a ramp, in the same window: inside its acceleration.
RAMP_S = 1.0
# The step-rate search: total steps/s tried, doubling from the first, then halving the
# gap between the highest passing and lowest failing rate this many times.
SWEEP_START = 2500
SWEEP_MAX = 320000
SWEEP_BISECT = 3
SWEEP_CRUISE_S = 0.08
SWEEP_RAMP_S = 0.02  # each move's acceleration (M204 P) ramps to its cruise in this
# A step's time is in spec within this of the ideal trapezoid (the target of
# chip_step_time_error_max_us). The search also reports the highest rate the step
# path keeps: every step made, pulses and DIR setup in spec, and the first-to-last
# lead step time within this fraction of the ideal, whatever single steps' jitter.
STEP_TIME_SPEC_US = 2.0
RATE_TOLERANCE = 0.01
# The print: the emulated time each way of printing gets (today's firmware plans far
# slower than the file asks, so it is cut there; the count is then a lower bound).
PRINT_LIMIT_S = 7.0
# M122 collects the garbage (about 26 ms on the chip, a stall the queue may not
# cover): the counted prints ask it only at their ends, and the heap's low point comes
# from a third stretch of the print with M122 this often.
DIAG_EVERY_S = 1.0
HEAP_PRINT_S = 3.0
# The planner part builds two printers, and at ticks under 50 us the second one's
# pio_dma ring finds no whole block left in the heap: that part steps at 50 us ticks
# (a --set tick_us overrides it). The CPU share a step path leaves at 20,000 steps/s
# is the same at both ticks (chip_cpu_left_while_stepping, docs/Benchmarks.md).
PLANNER_TICK_US = 50
# And with queues of this many blocks: two of the board's own (48), or of 24, do not
# fit beside the firmware's code and the seventh name pool.
PLANNER_QUEUE_BLOCKS = 16
# The stepping planner row is the median over these heap layouts: a spacer of so many
# bytes allocated first moves both printers' objects. The same firmware's row moved by
# up to 7 % between layouts, in the planner's native code and bytecode (bench/
# chip_pcprofile.py), whose arithmetic is the same: where the objects lie changes what
# their lookups cost.
LAYOUTS = (0, 16, 48, 96, 160)

NOTES = {
    "chip_planner_lines_per_s": (
        "G1 lines per second parsed and planned by the firmware on the emulated Pico "
        "(board %s): lines %d-%d of the example (289 G1 of 301, read into RAM first; "
        "relative E, after M83, as in the file) "
        "through printer.parser.parse and printer.run_line into the planner, the queue "
        "retired by hand: after each line, the oldest block where the ring is full "
        "(boards/sim/plan_only.py's make_room, one viper call, which also works out the "
        "block's ramp schedule, as the step path does when it starts a block; the "
        "look-ahead leaves that to it), so the look-ahead stays "
        "full and the planner never waits, as on a board whose step path retires "
        "blocks (retiring them in the planner's wait hook would charge the hook's "
        "calls, about 0.1 ms a line, to the planner), WHILE the step path runs a six-drive mixed move of "
        "about 20,000 steps/s (X, Y, E 8:6:6). The stepping is a second step path built "
        "by the same assemble.build_step_path and started by safety.start_timer with one "
        "long move, so what is planned never waits for the pins (bench/chip_main.py); it "
        "has the planned printer's settings (no trace records). "
        "The row is the median over five heap layouts (chip_planner_lines_per_s_layouts, "
        "sorted: a spacer of 0, 16, 48, 96 or 160 bytes allocated before the printers "
        "are built moves their objects; one firmware's row moved by up to 7 %% between "
        "layouts). "
        "chip_planner_lines_per_s_no_stepping: the same with no step path running; "
        "chip_planner_stepper_steps_per_s: the steps the stepping printer made meanwhile. "
        "chip_planner_circles_lines_per_s_no_stepping: the same lines of the circles "
        "print (testdata/circles_tube_emu_excerpt.gcode, 0.2 mm segments at 150 mm/s) "
        "with no step path running: there the look-ahead rewrites about 13 records a "
        "line, as its 24-block queue is too short to reach the segments' speed. "
        "Both printers at %d us ticks and the planned one with a queue of %d blocks: "
        "two pio_dma rings for shorter ticks, or the board's own queue, do not fit in "
        "the heap beside the stepping printer. "
        % ((BOARD,) + PLAN_LINES + (PLANNER_TICK_US, PLANNER_QUEUE_BLOCKS))),
    "chip_cpu_left_while_ramping": (
        "Share of the emulated CPU time in thread mode, as chip_cpu_left_while_stepping, "
        "while the same six-drive mixed move accelerates towards its 20,000 steps/s over "
        "RAMP_S (1 s, M204 P), in the same window after its ok (0.25-0.85 s): "
        "chip_cpu_left_while_ramping_steps_per_s is the steps/s it made there. Curves' "
        "short segments never stop accelerating or braking."),
    "chip_cpu_left_while_stepping": (
        "Share of the emulated CPU time in thread mode (the main loop; interrupts "
        "excluded, from the harness's time per exception) during the cruise of one move "
        "at %d steps/s (X 100 mm/s, Y 75 mm/s, E 14.46 mm/s mixed over six drives), "
        "the firmware as deployed on %s, sent over USB; window %.2f-%.2f s after its ok. "
        "chip_cpu_step_fraction: the step path's interrupts (the DMA IRQ's batch fill with "
        "step_backend pio_dma, the board's default; the hard timer with timer); chip_cpu_left_steps_per_s: "
        "rising STEP edges per second in the window. " % ((CPU_RATE, BOARD) + CPU_WINDOW)),
    "chip_max_step_rate": (
        "Highest total steps/s (X, Y, E 4:3:3, E mixed over six drives; rates doubled from "
        "%d, then bisected %d times) at which one move of that cruise rate from rest to "
        "rest makes every step, with every STEP high and low time at least step_pulse_us "
        "and every DIR change at least dir_setup_us before its axis' next step (board "
        "settings; X and Y change direction at every move, the drives always extrude), "
        "and every X (lead-axis) step within %g us of the ideal trapezoid (the target "
        "of chip_step_time_error_max_us, whose ideal this is; M204 acceleration ramping "
        "to cruise in %g s, M201/M203 limits raised so the G-code is the plan). 0: no "
        "rate passed. "
        "chip_max_step_rate_keeping_rate: the same search with single steps' times left "
        "out: every step made, pulses and DIR setup in spec, and the first to last X step "
        "within %g %% of the ideal time (the rate the step path keeps up with); "
        "chip_max_step_rate_trials: every rate tried. "
        % (SWEEP_START, SWEEP_BISECT, STEP_TIME_SPEC_US, SWEEP_RAMP_S, RATE_TOLERANCE * 100)),
    "chip_step_time_error_max_us": (
        "Worst X (lead-axis) STEP rising edge in the emulator's GPIO capture against its "
        "ideal time in the trapezoid the G-code asks for (mixstep.steptiming."
        "ideal_times_us, the k-th step where the trapezoid reaches k steps): from rest to "
        "rest at the board's acceleration (the lead axis' share of it), entered and left "
        "at sqrt(a), the speed reached from rest within half a step, as planner.py plans "
        "a start and a stop; the move of chip_cpu_left_while_stepping. The trapezoid "
        "starts at the latest time that leaves no step early (the start of a move sent "
        "over USB is not step timing), so the figure is the spread of (edge - ideal). "
        "_p99_us: 99th percentile. "),
    "chip_underruns": (
        "Times the planner's queue ran dry between two moves (planner.underruns, M122) "
        "printing testdata/circles_tube_emu_excerpt.gcode (PrusaSlicer, 0.2 mm segments "
        "at 150 mm/s, 750 lines/s, about 4.7 s of motion), the firmware as deployed on "
        "%s: streamed over USB one line per ok, then from the emulated flash (M23/M24); "
        "the sum of both. Each is cut after %g emulated s (then the count is a lower "
        "bound: _usb_lines and _flash_bytes say how far it got). M122 (which collects "
        "the garbage) only at the end of each. The firmware's min_segment_time_us (Marlin's SLOWDOWN, 20 ms) "
        "slows short moves while the queue is under half full: the print then runs "
        "slower than the file asks, at about the lines/s the planner keeps "
        "(_usb_lines_per_s, _flash_lines_per_s), rather than stop between moves. "
        % (BOARD, PRINT_LIMIT_S)),
    "chip_heap_free_min_bytes": (
        "Lowest gc.mem_free() after a collection (M122's mem_free_collected) sampled "
        "at the end of both prints of chip_underruns and every %g emulated s for %g "
        "more emulated s of the print from flash; _uncollected: M122's mem_free before "
        "its collection, garbage included. " % (DIAG_EVERY_S, HEAP_PRINT_S)),
    "chip_print_ratio_usb": (
        "A whole print's emulated time on %s, from its first line to the ok of a final "
        "M400, over its time in `mixstep sim --board %s` (where planning costs no "
        "simulated time): the worse of testdata/circles_tube_emu_excerpt.gcode "
        "(PrusaSlicer, 0.2 mm segments at 150 mm/s) and testdata/vase_3mix_emu_excerpt."
        "gcode (PrusaSlicer spiral vase, 0.15-0.32 mm segments at 120 mm/s, three drives "
        "mixed), each on a chip of its own (chip_print_files has both). _usb: streamed "
        "as OctoPrint streams a file, comments and blank lines left out, every line "
        "numbered with its checksum after M110 N0, one line per ok, by a host that "
        "answers at once; _flash: printed from the emulated flash, from M24 to the ok "
        "of an M400 after 'Done printing file'. chip_print_cpu_busy: the share of the "
        "flash print's emulated time the CPU was not asleep (WFI), the worse file's. "
        "chip_arc_print_ratio_usb: the same over USB for testdata/circles_tube_arcs_"
        "emu_excerpt.gcode, the circles print with its circles fitted as G2/G3 "
        "(mixstep arcfit), which the firmware cuts into segments. "
        "bench/chip_print.py. " % (BOARD, BOARD)),
    "chip_mixer_forward_new_us": (
        "Microseconds per E step on the emulated Pico (board %s) of E-only blocks of "
        "2,000 steps, six drives weighted 1:2:3:4:5:6, run by the firmware's step loop "
        "from a Python loop that calls it once a step (stepper.run_mix, "
        "bench/chip_mixer.py): the loop's call and the tick are included, so the rows "
        "compare kinds of pick and versions of the mixer, not the mixer alone. "
        "_forward_new: forward from a fresh start (how a print runs); _back_new: "
        "backward from a fresh start (a retraction block); _back_known: back over the "
        "steps just made forward; _forward_known: forward over the steps just made "
        "back (the ring's picks). " % BOARD),
}
for _k in NOTES:
    NOTES[_k] += CAVEAT


def unavailable(image_dir=None):
    """Why the emulator can't run here (node, rp2040js, the image), or None."""
    try:
        emu.check_setup()
        emu.image_files(image_dir)
    except emu.EmuError as e:
        return str(e)
    return None


# Settings laid over the board's for every chip session (--set).
OVERRIDES = {}


def configure(board, overrides):
    """Run the rows on `board` with `overrides` laid over its settings."""
    global BOARD, MIX
    BOARD = board
    OVERRIDES.clear()
    OVERRIDES.update(overrides)
    drives = _settings()["drives"]
    if drives != 6:  # the same kind of uneven mix over the drives there are
        MIX = "M567 P6 E" + ":".join("%.4f" % ((i + 2) / sum(range(2, drives + 2)))
                                      for i in range(drives))


def _settings():
    return dict(paths.load_board(BOARD)["SETTINGS"], **OVERRIDES)


# --- planner ---------------------------------------------------------------------

def _compiled(out, modules, main="chip_main"):
    """{name.mpy: path} of each module compiled as `make deploy` compiles mixfw, and a
    main.py that imports `main`: compiling on the chip would take heap the two
    printers of the planner run need."""
    out.mkdir(parents=True, exist_ok=True)
    cross = deploy._tool("mpy-cross")
    files = {}
    for name, src in modules.items():
        dst = out / (name + ".mpy")
        subprocess.run([cross, "-march=" + deploy.MARCH["rp2040"], "-s", name + ".py",
                        "-o", str(dst), str(src)], check=True, capture_output=True)
        files[dst.name] = dst
    (out / "main.py").write_text("import %s\n" % main)
    files["main.py"] = out / "main.py"
    return files


# The firmware's modules that building the board's printer imports, listed by the
# simulated board on the unix port (which loads the same ones as the chip).
_BUILD_MODULES = """
import sys
sys.path.append(sys.path.pop(0))
import simmachine, simtime
sys.modules["machine"] = simmachine
sys.modules["time"] = simtime
import board
from mixfw import assemble
from mixfw.config import Config
assemble.build(Config(board.SETTINGS, None), files_root=None)
print(" ".join(m for m in sys.modules if m.startswith("mixfw.")))
"""


def _getattr_names(source):
    """The names a module's getattr and hasattr calls give as strings: mpy-cross keeps a
    string of 10 characters or more as an object, not a name, and the call interns it
    as it runs."""
    found = set()
    for node in ast.walk(ast.parse(Path(source).read_text())):
        if (isinstance(node, ast.Call) and isinstance(node.func, ast.Name)
                and node.func.id in ("getattr", "hasattr") and len(node.args) > 1
                and isinstance(node.args[1], ast.Constant)
                and isinstance(node.args[1].value, str)):
            found.add(node.args[1].value)
    return found


def _names(work, harness, settings):
    """A file of the names the chip interns as it boots and builds the board's printer,
    a line each: chip_main.py interns them first (see its intern_names). They are the
    names of the firmware's modules that building the printer imports and of the .mpy
    files `harness`; the names of the sources the chip compiles itself (boot.py, and
    board.py with `settings` laid over it); and each module's name and path, which an
    import interns. A name left out is interned late, and may be the one that needs a
    new pool."""
    listed = subprocess.run([paths.micropython(), "-X", "heapsize=4M", "-c", _BUILD_MODULES],
                            env=paths.micropython_env(BOARD), capture_output=True,
                            text=True, check=True).stdout.split()
    out = work / "chip_names"
    deploy.compile_mixfw(out, deploy.MARCH["rp2040"])
    sources = {"boot": paths.FIRMWARE / "boot.py", "board": out / "board.py"}
    sources["board"].write_text((paths.BOARDS / BOARD / "board.py").read_text()
                                + emu._settings_source(settings))
    compiled = list(_compiled(out / "sources", sources).values())
    names = {"mixfw", "mixfw/__init__.py", "mixfw/__init__.mpy", "main.py", "boot.py",
             "board.py"}
    for m in listed:
        names.update((m, m[6:], m.replace(".", "/") + ".mpy"))
        names.update(_getattr_names(paths.FIRMWARE / "mixfw" / (m[6:] + ".py")))
    for mpy in harness:
        names.update((mpy.stem, mpy.name))
    mpys = [out / "mixfw" / (m[6:] + ".mpy") for m in listed] + harness
    for mpy in mpys + [p for p in compiled if p.suffix == ".mpy"]:
        # A newline in a name (string constants are names too) is written as \n,
        # and a name with a backslash of its own is left out.
        names.update(n.replace("\n", "\\n") for n in deploy.mpy_qstrs(mpy)
                     if "\\" not in n)
    listing = out / "names.txt"
    listing.write_text("".join(n + "\n" for n in sorted(names)))
    return listing


def _planner_chip(work, requests, gcode=None, profile=None):
    """bench/chip_main.py's answers (JSON) to each request, on a chip of its own, with
    PLAN_LINES of gcode (the example) as plan.gcode. profile: a path for the program
    counter's profile of the last request (emu.Chip.profile), with where the chip's
    functions start (chip_main.py's `functions`, asked last) in the last answer's
    "functions"."""
    excerpt = work / "chip_plan.gcode"
    gcode = gcode or paths.EXAMPLE_GCODE
    lines = gcode.read_text().splitlines()[PLAN_LINES[0] - 1:PLAN_LINES[1]]
    excerpt.write_text("\n".join(lines) + "\n")
    files = _compiled(work / "chip_flash", {
        "chip_main": BENCH_DIR / "chip_main.py", "chip_profile": BENCH_DIR / "chip_profile.py",
        "plan_only": paths.BOARDS / "sim" / "plan_only.py"})
    files["plan.gcode"] = excerpt
    # No trace records: neither printer captures, and the reserve assemble takes as it
    # loads is then the planned printer's size.
    settings = dict({"tick_us": PLANNER_TICK_US, "queue_blocks": PLANNER_QUEUE_BLOCKS,
                     "trace_records": 0}, **OVERRIDES)
    files["names.txt"] = _names(work, [p for p in files.values() if p.suffix == ".mpy"
                                       and p.stem != "chip_profile"], settings)
    got = []
    with emu.Chip(BOARD, settings=settings, files=files, max_emu_s=120,
                  max_wall_s=900) as chip:
        for i, request in enumerate(requests):
            profiled = profile and i == len(requests) - 1
            if profiled:
                chip.profile(gated=True)  # chip_main.py opens it for its lines alone
            answer = chip.command(request, max_s=60)
            if profiled:
                chip.profile(profile)
            found = [t for t in answer if t.startswith("bench:")]
            if not found:
                raise RuntimeError("chip_main.py answered %s" % answer)
            r = json.loads(found[0][len("bench:"):])
            if r.get("failed") or r["errors"] or r.get("timed", {}).get("errors"):
                said = " | ".join(t for t in answer if not t.startswith("bench:"))
                raise RuntimeError("planning on the chip: %s (it said: %s)" % (r, said))
            got.append(r)
        if profile:  # after the plans: it makes garbage the printers' heap has no room for
            got[-1]["functions"] = [t for t in chip.command("functions")
                                    if t.startswith("FUN ")]
    return got


def chip_profile(res, work):
    """Where a G1 line's planning time goes on the chip, by function (inclusive)."""
    r = _planner_chip(work, ["profile plan.gcode"])[0]
    res["chip_profile_lines_per_s"] = r["move_lines_per_s"]
    res["chip_profile_lines_per_s_timed"] = r["timed"]["move_lines_per_s"]
    res["chip_profile_bytes_allocated_per_line"] = r["bytes_allocated_per_line"]
    res["chip_profile_collect_us"] = r["collect_us"]
    res["chip_profile_mem_free_bytes"] = r["mem_free_before"]
    res["chip_profile_us_per_line"] = {
        k: round(v["us_per_line"], 1) for k, v in sorted(
            r["timed"]["functions"].items(), key=lambda kv: -kv[1]["us_per_line"])}
    res["chip_profile_calls_per_line"] = {
        k: round(v["calls_per_line"], 2) for k, v in r["timed"]["functions"].items()}


def chip_planner(res, work):
    # A chip each: the stepping printer takes the heap the first run gives back.
    no_stepping = _planner_chip(work, ["plan plan.gcode 0"])[0]
    runs = []
    for spacer in LAYOUTS:
        r = _planner_chip(work, ["plan plan.gcode 1 %d" % spacer])[0]
        if not r["stepper_still_moving"]:
            raise RuntimeError("the stepping printer's move ended before the planning did")
        runs.append(r)
    runs.sort(key=lambda r: r["move_lines_per_s"])
    r = runs[len(runs) // 2]  # the median
    res["chip_planner_lines_per_s"] = r["move_lines_per_s"]
    res["chip_planner_lines_per_s_layouts"] = [round(x["move_lines_per_s"], 1)
                                               for x in runs]
    res["chip_planner_lines_per_s_no_stepping"] = no_stepping["move_lines_per_s"]
    res["chip_planner_stepper_steps_per_s"] = r["stepper_steps_per_s"]
    res["chip_planner_move_lines"] = r["move_lines"]
    res["chip_planner_mem_free_bytes"] = r["mem_free_before"]
    circles = _planner_chip(work, ["plan plan.gcode 0"], CIRCLES)[0]
    res["chip_planner_circles_lines_per_s_no_stepping"] = circles["move_lines_per_s"]


# --- stepping --------------------------------------------------------------------

def _move(rate, seconds, sign=1, accel=None):
    """A relative G1 of X, Y and E whose cruise makes `rate` total steps/s for
    `seconds` (plus its ramps at `accel`, if given, else `seconds` includes them):
    (line, X mm, X mm/s, path mm/s)."""
    spm = _settings()["steps_per_mm"]
    vx, vy, ve = (rate * s / k for s, k in zip(SHARE, (spm[0], spm[1], spm[3])))
    v = (vx * vx + vy * vy) ** 0.5
    if accel:
        seconds += v / accel
    dx, dy, de = vx * seconds, vy * seconds, ve * seconds
    line = "G1 X%.4f Y%.4f E%.5f F%.3f" % (sign * dx, sign * dy, de, v * 60)
    return line, dx, vx, v


def _window(edges, t0_s, t1_s):
    times, gpios, levels = edges
    keep = (times > t0_s * 1e9) & (times <= t1_s * 1e9)
    return times[keep], gpios[keep], levels[keep]


def _rises(edges, gpio):
    times, gpios, levels = edges
    return np.sort(times[(gpios == gpio) & (levels == 1)]).astype(np.int64)


def lead_errors_us(rises_ns, n, v_steps_s, a_steps_s2):
    """Each lead-axis step's time minus its ideal time (us), or None if the count is
    not n. The ideal: the trapezoid of a move from rest to rest at cruise v and
    acceleration a, entered and left at sqrt(a), the speed reached from rest within
    half a step (as the planner plans a start or stop: planner.py's rate floor), the
    k-th step where the trapezoid reaches k steps (steptiming.ideal_times_us), and
    placed at the latest start that leaves no step early."""
    if len(rises_ns) != n:
        return None
    v_rest = min(a_steps_s2 ** 0.5, v_steps_s)
    ideal = steptiming.ideal_times_us(np.arange(1, n + 1), 0.0, n, v_rest / 1e6,
                                      v_steps_s / 1e6, v_rest / 1e6, a_steps_s2 / 1e12)
    d = rises_ns / 1000.0 - ideal
    return d - d.min()


def duration_error(rises_ns, n, v_steps_s, a_steps_s2):
    """The first-to-last lead step time over its ideal, minus 1 (see lead_errors_us)."""
    v_rest = min(a_steps_s2 ** 0.5, v_steps_s)
    ideal = steptiming.ideal_times_us(np.array([1, n]), 0.0, n, v_rest / 1e6,
                                      v_steps_s / 1e6, v_rest / 1e6, a_steps_s2 / 1e12)
    return (rises_ns[-1] - rises_ns[0]) / 1000.0 / (ideal[1] - ideal[0]) - 1


def pulse_spec(edges, pins, names):
    """Shortest STEP high and low time and DIR setup (us) over the named motors."""
    times, gpios, levels = edges
    high = low = setup = float("inf")
    for name in names:
        step, direction = pins[name + "_step"], pins[name + "_dir"]
        sel = gpios == step
        t, lv = times[sel].astype(np.int64), levels[sel]
        if len(t) > 1:
            dt = np.diff(t) / 1000.0
            if np.any(lv[:-1] == 1):
                high = min(high, dt[lv[:-1] == 1].min())
            if np.any(lv[:-1] == 0):
                low = min(low, dt[lv[:-1] == 0].min())
        rise = t[lv == 1]
        for td in times[gpios == direction]:
            after = rise[rise > td]
            if len(after):
                setup = min(setup, (after[0] - td) / 1000.0)
    return high, low, setup


def chip_cpu(res, work):
    chip_stepping(res, work, sweep=False)


def chip_stepping(res, work, sweep=True):
    settings = _settings()
    pins = paths.load_board(BOARD)["PINS"]
    motors = ["x", "y"] + ["e%d" % i for i in range(settings["drives"])]
    spm = settings["steps_per_mm"]
    tick_us = settings["tick_us"]
    with emu.Chip(BOARD, settings=OVERRIDES, max_emu_s=120, max_wall_s=1200) as chip:
        for line in ("M302 P1", "M211 S0", "G91", "M83", MIX, "T6"):
            _command(chip, line)
        # CPU share and step times: one move at the board's own limits.
        line, dx, vx, v = _move(CPU_RATE, CPU_MOVE_S)
        _command(chip, line)
        start = chip.now
        chip.run(for_s=CPU_WINDOW[0])
        a = chip.cpu()
        chip.run(for_s=CPU_WINDOW[1] - CPU_WINDOW[0])
        b = chip.cpu()
        _command(chip, "M400", max_s=10)
        end = chip.now
        span = b["nanos"] - a["nanos"]
        res["chip_cpu_left_while_stepping"] = (b["exc"][0] - a["exc"][0]) / span
        res["chip_cpu_step_fraction"] = sum(b["exc"][n] - a["exc"][n]
                                            for n in emu.STEP_EXCEPTIONS) / span
        edges = chip.edges()
        win = _window(edges, a["nanos"] / 1e9, b["nanos"] / 1e9)
        steps = sum(len(_rises(win, pins[m + "_step"])) for m in motors)
        res["chip_cpu_left_steps_per_s"] = steps / (span / 1e9)
        move = _window(edges, start - 0.1, end)
        accel = settings["acceleration_mm_s2"]
        n = round(dx * spm[0])
        err = lead_errors_us(_rises(move, pins["x_step"]), n, vx * spm[0],
                             accel * vx / v * spm[0])
        if err is None:
            raise RuntimeError("the 20,000 steps/s move made %d X steps, not %d"
                               % (len(_rises(move, pins["x_step"])), n))
        res["chip_step_time_error_max_us"] = float(err.max())
        res["chip_step_time_error_p99_us"] = float(np.percentile(err, 99))
        late = _diagnose(chip, []).get("late_refills")
        if late is not None:
            res["chip_late_refills"] = late
        # CPU share on a ramp: curves' short segments never stop accelerating or
        # braking: the step path must pass over a ramp's ticks, not run each one.
        ramp_a = v / RAMP_S
        _command(chip, "M204 P%.3f" % ramp_a)
        _command(chip, _move(CPU_RATE, 0, sign=-1, accel=ramp_a)[0])
        chip.run(for_s=CPU_WINDOW[0])
        a = chip.cpu()
        chip.run(for_s=CPU_WINDOW[1] - CPU_WINDOW[0])
        b = chip.cpu()
        span = b["nanos"] - a["nanos"]
        res["chip_cpu_left_while_ramping"] = (b["exc"][0] - a["exc"][0]) / span
        win = _window(chip.edges(), a["nanos"] / 1e9, b["nanos"] / 1e9)
        res["chip_cpu_left_while_ramping_steps_per_s"] = sum(
            len(_rises(win, pins[m + "_step"])) for m in motors) / (span / 1e9)
        _command(chip, "M400", max_s=30)
        _command(chip, "M204 P%g" % settings["acceleration_mm_s2"])
        if not sweep:
            return
        # The highest step rate in spec.
        for line in ("M203 X10000 Y10000 E10000", "M201 X1000000 Y1000000 E1000000"):
            _command(chip, line)
        trials = {}

        def trial(rate):
            if rate in trials:
                return trials[rate]
            sign = -1 if len(trials) % 2 else 1  # DIR changes every move
            v = _move(rate, 1)[3]
            accel = round(v / SWEEP_RAMP_S, 1)
            _command(chip, "M204 P%g" % accel)
            line, dx, vx, v = _move(rate, SWEEP_CRUISE_S, sign, accel)
            t0 = chip.now
            _command(chip, line)
            _command(chip, "M400", max_s=20)
            win = _window(chip.edges(), t0, chip.now)
            n = round(dx * spm[0])
            rises = _rises(win, pins["x_step"])
            err = lead_errors_us(rises, n, vx * spm[0], accel * vx / v * spm[0])
            high, low, setup = pulse_spec(win, pins, motors)
            in_pulse = (high >= settings["step_pulse_us"] and low >= settings["step_pulse_us"]
                        and setup >= settings["dir_setup_us"] and err is not None)
            t = {"rate": rate, "x_steps": int(len(rises)), "x_steps_planned": n,
                 "error_max_us": None if err is None else round(float(err.max()), 3),
                 "min_high_us": _finite(high), "min_low_us": _finite(low),
                 "min_dir_setup_us": _finite(setup),
                 "duration_error": None if err is None else round(float(
                     duration_error(rises, n, vx * spm[0], accel * vx / v * spm[0])), 5),
                 "in_spec": bool(in_pulse and err.max() <= STEP_TIME_SPEC_US)}
            t["keeps_rate"] = bool(in_pulse and abs(t["duration_error"]) <= RATE_TOLERANCE)
            t.update({
                 "emulated_s": round(chip.now - t0, 4)})
            trials[rate] = t
            return t

        for key, ok in (("chip_max_step_rate", "in_spec"),
                        ("chip_max_step_rate_keeping_rate", "keeps_rate")):
            res[key] = _search(trial, ok)
    res["chip_max_step_rate_trials"] = [trials[r] for r in sorted(trials)]
    res["chip_step_tick_us"] = tick_us


def _finite(us):
    """None for a check with nothing to check (no DIR change in the move): JSON has
    no infinity."""
    return None if us == float("inf") else round(us, 3)


def _search(trial, ok):
    """Highest rate that passes: double from SWEEP_START, then bisect the gap."""
    good, bad = 0, None
    rate = SWEEP_START
    while rate <= SWEEP_MAX:
        if trial(rate)[ok]:
            good = rate
            rate *= 2
        else:
            bad = rate
            break
    if bad is None or good == 0:
        return good
    for _ in range(SWEEP_BISECT):
        mid = round((good + bad) / 2 / 100) * 100
        if trial(mid)[ok]:
            good = mid
        else:
            bad = mid
    return good


def _command(chip, line, max_s=5):
    answer = chip.command(line, max_s=max_s)
    errors = [t for t in answer if t.startswith("Error:")]
    if errors:
        raise RuntimeError("%s: %s" % (line, errors))
    return answer


# --- the print -------------------------------------------------------------------

def _diagnose(chip, samples):
    for text in chip.command("M122", max_s=10):
        if text.startswith("echo:underruns:"):
            samples.append(emu._diag(text))
            return samples[-1]
    raise RuntimeError("M122 gave no diagnostics")


def _print_for(chip, t0, seconds):
    """Let the print from flash (started at t0) run for `seconds`; True once done."""
    try:
        chip.run(match="Done printing file", for_s=seconds)
    except emu.Stopped:
        pass
    return any(t.startswith("Done printing file") for t in chip.lines_since(t0))


def chip_print(res, work):
    samples = []
    with emu.Chip(BOARD, settings=OVERRIDES, files={"circles.gcode": CIRCLES}, max_emu_s=120,
                  max_wall_s=1800) as chip:
        # Over USB, one line per ok, as a host streams it.
        t0 = chip.now
        sent = 0
        with open(CIRCLES, encoding="latin-1") as f:
            lines = [raw.rstrip("\r\n") for raw in f]
        for text in lines:
            if chip.now - t0 >= PRINT_LIMIT_S:
                break
            answer = chip.command(text, max_s=10)
            if any(t.startswith("Error:") for t in answer):
                raise RuntimeError("line %d: %s" % (sent + 1, answer))
            sent += 1
        usb_s = chip.now - t0
        _command(chip, "M400", max_s=30)
        usb = _diagnose(chip, samples)["underruns"]
        # From the emulated flash: back home first, then M23/M24.
        _command(chip, "G90")
        _command(chip, "G1 X5 Y5 F9000", max_s=10)
        _command(chip, "G28", max_s=30)
        if not any("File selected" in t for t in chip.command("M23 circles.gcode")):
            raise RuntimeError("M23 did not select circles.gcode")
        _command(chip, "M24")
        t0 = chip.now
        done = flash_done = _print_for(chip, t0, PRINT_LIMIT_S)
        flash_s = chip.now - t0
        progress = [t for t in chip.command("M27") if t.startswith("SD printing byte")]
        flash = _diagnose(chip, samples)["underruns"] - usb
        t1 = chip.now
        while not done and chip.now - t1 < HEAP_PRINT_S:
            done = _print_for(chip, t0, DIAG_EVERY_S)
            _diagnose(chip, samples)
        if not done:
            _command(chip, "M25")
        errors = [t for t in chip.lines_since(0) if t.startswith("Error:")]
        if errors:
            raise RuntimeError("the print: %s" % errors[:3])
    res["chip_underruns"] = usb + flash
    res["chip_underruns_usb"] = usb
    res["chip_underruns_flash"] = flash
    res["chip_underruns_usb_lines"] = sent
    res["chip_underruns_file_lines"] = len(lines)
    res["chip_underruns_usb_emulated_s"] = round(usb_s, 3)
    res["chip_underruns_usb_lines_per_s"] = round(sent / usb_s, 1)
    res["chip_underruns_flash_done"] = flash_done
    res["chip_underruns_flash_emulated_s"] = round(flash_s, 3)
    res["chip_underruns_flash_bytes"] = (progress[0][len("SD printing byte "):]
                                         if progress else None)
    if progress:
        # The lines the file printed from flash ran, per emulated second.
        upto = int(res["chip_underruns_flash_bytes"].split("/")[0])
        res["chip_underruns_flash_lines_per_s"] = round(
            CIRCLES.read_bytes()[:upto].count(b"\n") / flash_s, 1)
    res["chip_heap_free_min_bytes"] = min(s["mem_free_collected"] for s in samples)
    res["chip_heap_free_min_uncollected_bytes"] = min(s["mem_free"] for s in samples)
    res["chip_heap_samples"] = len(samples)


# --- mixer ----------------------------------------------------------------------

def chip_mixer(res, work):
    """What each kind of the mixer's pick costs the step loop (bench/chip_mixer.py)."""
    files = _compiled(work / "chip_mixer_flash", {"chip_mixer": BENCH_DIR / "chip_mixer.py"},
                      "chip_mixer")
    with emu.Chip(BOARD, settings=OVERRIDES, files=files, max_emu_s=60,
                  max_wall_s=600) as chip:
        answer = chip.command("mixer", max_s=30)
    found = [t for t in answer if t.startswith("bench:")]
    if not found:
        raise RuntimeError("chip_mixer.py answered %s" % answer)
    for kind, us in json.loads(found[0][len("bench:"):]).items():
        res["chip_mixer_" + kind] = us


# --- all of it -------------------------------------------------------------------

# --- whole prints against their time in mixstep sim ------------------------------

def chip_prints(res, work):
    """chip_print_ratio_usb / _flash / chip_print_cpu_busy: the worse of the two
    files (bench/chip_print.py)."""
    import chip_print as whole
    got = [whole.ratios(path, board=BOARD, settings=OVERRIDES or None)
           for path in (whole.CIRCLES, whole.VASE)]
    for way in ("usb", "flash"):
        res["chip_print_ratio_" + way] = max(g[way + "_ratio"] for g in got)
    res["chip_print_cpu_busy"] = max(g["flash_busy"] for g in got)
    arcs = whole.ratios(whole.CIRCLES_ARCS, flash=False, board=BOARD,
                        settings=OVERRIDES or None)
    res["chip_arc_print_ratio_usb"] = arcs["usb_ratio"]
    res["chip_print_files"] = got + [arcs]


PARTS = (("planner", chip_planner), ("stepping", chip_stepping), ("print", chip_print),
         ("prints", chip_prints), ("mixer", chip_mixer))


def bench_chip(res, work):
    """Every chip row into res, or chip_skipped with the reason when the emulator
    can't run here. A part that fails raises after the others ran."""
    reason = unavailable()
    if reason:
        res["chip_skipped"] = reason
        print("bench: chip rows skipped: %s" % reason, file=sys.stderr)
        return
    failed = []
    for name, part in PARTS:
        t0 = time.perf_counter()
        print("bench: chip %s ..." % name, file=sys.stderr, flush=True)
        try:
            part(res, work)
        except Exception as e:
            failed.append("%s: %s: %s" % (name, type(e).__name__, e))
            print("bench: chip %s FAILED: %s" % (name, failed[-1]), file=sys.stderr)
        res["bench_seconds_chip_" + name] = round(time.perf_counter() - t0, 1)
    res["chip_board"] = BOARD
    if OVERRIDES:
        res["chip_settings"] = dict(OVERRIDES)
    for key, text in NOTES.items():
        res[key + "_method"] = text
    if failed:
        raise RuntimeError("; ".join(failed))


if __name__ == "__main__":
    out = {}
    work = ROOT / "out" / "bench"
    work.mkdir(parents=True, exist_ok=True)
    import argparse
    ap = argparse.ArgumentParser()
    ap.add_argument("parts", nargs="?", default=",".join(n for n, _ in PARTS))
    ap.add_argument("--board", default=BOARD)
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    args = ap.parse_args()
    configure(args.board, boards.set_items(args.board, args.set))
    parts = args.parts.split(",")
    for name, part in PARTS + (("cpu", chip_cpu), ("profile", chip_profile)):
        if name in parts:
            part(out, work)
    if OVERRIDES or BOARD != "pico_6drives":
        out["chip_board"] = BOARD
        out["chip_settings"] = dict(OVERRIDES)
    print(json.dumps(out, indent=2))
