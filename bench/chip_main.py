# The chip bench's planner run on the emulated Pico: bench/chip_rows.py puts it on the
# flash compiled as chip_main.mpy, with a main.py that imports it in place of the
# firmware's main.py; the firmware's modules are the board's mixfw/*.mpy.
# It answers requests on the USB console, one line each, then `ok`:
#   M115                   ok (the harness asks it once it has booted)
#   plan FILE STEP         parse and plan FILE's lines (in RAM: see Lines) through
#                          the firmware's parser, command table and planner, with the
#                          queue retired by hand (boards/sim/plan_only.py's make_room
#                          after each line, so the look-ahead stays full and the
#                          planner never waits); with STEP 1 the step path runs meanwhile (see
#                          stepping_printer). Answers `bench:{json}`.
#   profile FILE           plan FILE without stepping, then again with the planner's
#                          functions timed (bench/chip_profile.py): `bench:{json}`.
#   functions              where each loaded function's code starts, for
#                          bench/chip_pcprofile.py.
# Written against the firmware's API: heap.reserve/release and planner.step_loop_bytes
# (one more reserve, for the second printer), assemble.build(config, files_root=None),
# assemble.drop(), Config, safety.start_timer(machine, printer, tick_us) (returns what
# has deinit()), printer.parser.parse,
# printer.run_line, printer.planner (.idle, .queue, .synchronize), printer.mem with the
# stepper's S_HEAD/S_TAIL/S_ACTIVE/S_POS words (plan_only.retire_one).
import sys
import gc
import json
import os
import time
import machine
import micropython
from array import array

# Constants and locals rather than globals where they can be, and the answer's keys
# split from strings: each name takes a slot in the rp2 port's name pools, which this
# and the firmware's modules fill to just below the next pool's 7.7 kB (see
# intern_names). The heap the two printers leave has no room for that pool: a
# firmware that needs it needs a lighter harness.
# WATCHDOG SCRATCH0, free for programs: 1 while the lines are planned, for the
# emulator's program counter profile (bench/chip_pcprofile.py, emu/harness.mjs).
_PROFILED = const(0x4005800C)
_LINE_MAX = const(256)


@micropython.viper
def _copy(dst, src, start: int, n: int):
    d = ptr8(dst)
    s = ptr8(src)
    for i in range(n):
        d[i] = s[start + i]


class Lines:
    """A G-code file in RAM as one block and its lines' bounds, read before the
    firmware's modules load: the modules' code leaves the heap in pieces too small for a
    list of lines, and the printers' arrays need the whole blocks left. Each line is
    copied into one buffer, as the firmware receives a line, and parsed from there."""

    def __init__(self, path):
        size = os.stat(path)[6]
        self.blob = bytearray(size)
        with open(path, "rb") as f:
            f.readinto(self.blob)
        blob = self.blob
        # 16-bit offsets where they fit: the heap holds two printers beside this.
        bounds = array("H" if size < 0x10000 else "i")
        self.moves = 0
        at = 0
        while at < size:
            end = blob.find(b"\n", at)
            end = size if end < 0 else end
            stop = end
            while stop > at and blob[stop - 1] in (10, 13):
                stop -= 1
            head = bytes(blob[at:at + 4])
            if head not in (b"M109", b"M190", b"M116"):
                bounds.append(at)
                bounds.append(stop)
                self.moves += head[:3] in (b"G1 ", b"G0 ")
            at = end + 1
        self.bounds = bounds
        self.count = len(bounds) // 2
        self.buf = bytearray(_LINE_MAX)

    def line(self, i):
        """Line i in the buffer; returns its length."""
        a = self.bounds[2 * i]
        n = self.bounds[2 * i + 1] - a
        _copy(self.buf, self.blob, a, n)
        return n

    def first(self, prefix, k):
        """The first k lines that start with prefix, as bytes."""
        out = []
        for i in range(self.count):
            n = self.line(i)
            if bytes(self.buf[:len(prefix)]) == prefix:
                out.append(bytes(self.buf[:n]))
                if len(out) == k:
                    break
        return out


def intern_names(path):
    """Intern the names the modules to come intern as they load (bench/chip_rows.py
    lists them), while the heap is whole. MicroPython keeps its names in pools whose
    sizes double (20, 40, ... 640 entries: 1,260 names): the next takes 7.7 kB in one
    block, which a pool first needed late in the modules' loading, beside the lines
    and the reserves, would not find. getattr interns the name it is given."""
    with open(path) as f:
        for line in f:
            getattr(None, line[:-1].replace("\\n", "\n"), None)
    gc.collect()


intern_names("names.txt")
# What a session keeps: the lines by path, the printers, the spacers (one dict: each
# global is a name).
KEPT = {"plan.gcode": Lines("plan.gcode"), "spacers": []}
# The firmware reserves the heap its printer's arrays take while its modules load
# (mixfw/heap.py), and the stepping printer, built second, gets a reserve too. Each
# printer is built once and kept: a request's garbage would split a later one's heap.
import board  # noqa: E402
from mixfw import heap, planner  # noqa: E402
# A reserve for each printer's arrays (the second is the one assemble takes as it
# loads), each of the board's size: bench/chip_rows.py gives the board no trace records.
heap.reserve(planner.step_loop_bytes(board.SETTINGS))
from mixfw import assemble  # noqa: E402
from mixfw import safety  # noqa: E402
from mixfw.config import Config  # noqa: E402
from mixfw import stepper as st  # noqa: E402
from plan_only import make_room, retire_one  # noqa: E402



def stepping_printer():
    """A second printer, built as main.py builds the board's, whose only job is to keep
    the step path busy with one long six-drive mixed move, as while printing. The
    planner measured is another printer whose queue is retired by hand, so what it
    plans never reaches the pins and never waits for them; both share the CPU."""
    if not KEPT.get("stepper"):
        gc.collect()
        # Its one move needs neither the trace's records (3 kB at the firmware's 256)
        # nor a long queue: the heap they took left too little for the PIO programs
        # its step path assembles when it starts, once a change of the firmware's
        # code had moved the pieces (MemoryError).
        # Its config first, and its garbage collected (22 kB of it, in pieces across
        # the heap): then build() gives a reserve back, whole for its tables and arrays.
        config = Config(dict(board.SETTINGS, queue_blocks=4), None)
        printer = assemble.build(config, files_root=None)
        # The step path's move while planning: X 100 mm/s, Y 75 mm/s and E 14.46 mm/s
        # of filament mixed over all six drives, i.e. 8,000 + 6,000 + 6,000 steps/s at
        # the pico_6drives steps/mm (80, 80, 415), for 8 s: longer than any planning
        # run here.
        for line in (b"M302 P1", b"M211 S0", b"G91", b"M83",
                     b"M567 P6 E0.1:0.15:0.2:0.25:0.12:0.18", b"T6",
                     b"G1 X800 Y600 E115.66 F7500"):
            printer.run_line(printer.parser.parse(line, len(line)))
        # From here on only its step path runs: what else it holds goes, and the
        # planned printer's tables find room in the holes it leaves.
        for name in ("commands", "guarded", "parser", "motion", "thermal", "background",
                     "each_turn", "on_halt", "on_quick_stop", "heaters_off", "finish"):
            setattr(printer, name, None)
        gc.collect()
        KEPT["stepper"] = printer
    return KEPT["stepper"]


def planned_printer():
    """The printer whose planning is measured, its queue retired by hand."""
    if not KEPT.get("plan"):
        gc.collect()
        # The board's settings have no trace records (3 kB at the firmware's 256): its
        # step loop never runs, and the heap holds two printers beside the lines.
        config = Config(board.SETTINGS, None)
        printer = assemble.build(config, files_root=None)
        printer.planner.idle = retire_one(printer.mem, printer.planner.queue)
        # The excerpts are relative E (their file's M83 comes before them).
        for line in (b"M302 P1", b"M83"):
            printer.run_line(printer.parser.parse(line, len(line)))
        KEPT["plan"] = printer
    return KEPT["plan"]




def plan(path, stepping, profile=0):
    """profile 1: also what a line allocates and what a collection costs; 2: the
    planner's functions timed (chip_profile)."""
    # A collection every kB while the printers are built: their garbage, collected
    # early, leaves holes the next tables fill, and the heap in fewer pieces (built
    # with none, the second printer's tables once found no room, with 31 kB free in
    # pieces of under 584 bytes: MemoryError).
    gc.threshold(1024)
    # The stepping printer first, while the heap is whole: the planned one is built
    # where its table and arrays then find room, as a board's printer is.
    stepper = stepping_printer() if stepping else None
    printer = planned_printer()
    if not stepping:
        heap.release()  # the stepping printer's reserve: heap as a board has it
    gc.threshold(-1)
    planner = printer.planner
    run_line = printer.run_line
    data = KEPT.get(path) or Lines(path)
    moves = data.moves
    timer = None
    steps0 = 0
    if stepper:
        timer = safety.start_timer(machine, stepper, stepper.settings["tick_us"])
        time.sleep_ms(300)  # past the move's acceleration, into its cruise
        m = stepper.mem
        steps0 = m[st.S_POS + st.X] + m[st.S_POS + st.Y] + abs(m[st.S_POS + st.E])
    # As main.py on a board: once the printers are built, the code that built them
    # goes (a session's one plan request builds them; a later one builds none).
    global assemble
    if assemble is not None:
        assemble.drop()
        assemble = None
    if profile:
        import chip_profile
    if profile == 2:
        from mixfw.gcode import command_key
        timed = chip_profile.install(printer, command_key)
    parse = printer.parser.parse
    gc.collect()
    free = gc.mem_free()
    errors = []
    mem = printer.mem
    full = planner.queue - 1
    machine.mem32[_PROFILED] = 1  # the program counter's profile, if one is taken
    t0 = time.ticks_us()
    buf = data.buf
    line = data.line
    for number in range(1, data.count + 1):
        try:
            run_line(parse(buf, line(number - 1)))
        except Exception as e:  # the firmware would answer Error: and go on
            if len(errors) < 5:
                errors.append("line %d: %r" % (number, e))
        # As a board's step path would: the ring keeps its one free slot, so the
        # planner never waits (its wait hook stays for a line of several blocks).
        make_room(mem, full)
    planner.synchronize()
    us = time.ticks_diff(time.ticks_us(), t0)
    machine.mem32[_PROFILED] = 0
    if profile == 1:
        # What a line allocates (the collector held off for a few lines), and what one
        # collection costs with the printer built.
        gc.collect()
        t = time.ticks_us()
        gc.collect()
        collect_us = time.ticks_diff(time.ticks_us(), t)
        few = data.first(b"G1 ", 5)
        allocated = chip_profile.bytes_allocated(run_line, parse, few)
        planner.synchronize()
    # The keys split from strings: see the name pools above.
    out = dict(zip("lines move_lines seconds move_lines_per_s errors mem_free_before "
                   "mem_free_after".split(), (data.count, moves, us / 1e6, moves * 1e6 / us,
                                              errors, free, gc.mem_free())))
    if stepper:
        m = stepper.mem
        steps1 = m[st.S_POS + st.X] + m[st.S_POS + st.Y] + abs(m[st.S_POS + st.E])
        out.update(zip("stepper_steps_per_s stepper_still_moving".split(), (
            (steps1 - steps0) * 1e6 / us, bool(stepper.planner.busy()))))
        timer.deinit()
    if profile == 2:
        out["functions"] = chip_profile.report(timed[0], timed[1], moves)
    if profile == 1:
        out.update(zip("bytes_allocated_per_line collect_us".split(), (
            allocated / len(few), collect_us)))
    return out


def functions():
    """A line `FUN address name` for each function of the loaded modules and their
    classes. The address is the function object's code pointer (its fourth word): for
    native and viper code, its first instruction."""
    for mname, mod in list(sys.modules.items()):
        for name, v in mod.__dict__.items():
            if type(v) is type:
                for attr, f in v.__dict__.items():
                    if "function" in str(type(f)):
                        print("FUN", machine.mem32[id(f) + 12],
                              "%s.%s" % (mname, name + "." + attr))
            elif "function" in str(type(v)):
                print("FUN", machine.mem32[id(v) + 12], "%s.%s" % (mname, name))


def serve():
    while True:
        words = sys.stdin.readline().split()
        if not words:
            continue
        if words[0] == "functions":
            functions()
        elif words[0] in ("plan", "profile"):
            try:
                if words[0] == "plan":
                    # A spacer of that many bytes first, kept: the printers' objects
                    # then lie elsewhere in the heap (see chip_rows.LAYOUTS).
                    if len(words) > 3:
                        KEPT["spacers"].append(bytearray(int(words[3])))
                    res = plan(words[1], words[2] == "1")
                else:
                    res = plan(words[1], False, 1)
                    gc.collect()
                    res["timed"] = plan(words[1], False, 2)
            except Exception as e:  # said with its traceback and the heap left
                res = None  # the heap may be too full for the answer: the traceback first
                gc.collect()
                sys.print_exception(e)
                # The name pools too: n_pool=7 is the seventh pool's 7.7 kB, which the
                # heap the two printers leave does not hold (see the pools above).
                micropython.qstr_info()
                res = {"failed": repr(e), "mem_free": gc.mem_free()}
            gc.collect()
            print("bench:", end="")  # one line, with no copy of the answer made for it
            json.dump(res, sys.stdout)
            print()
        print("ok")


serve()
