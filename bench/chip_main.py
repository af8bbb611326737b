# The chip bench's planner run on the emulated Pico: bench/chip_rows.py puts it on the
# flash compiled as chip_main.mpy, with a main.py that imports it in place of the
# firmware's main.py; the firmware's modules are the board's mixfw/*.mpy.
# It answers requests on the USB console, one line each, then `ok`:
#   M115                   ok (the harness asks it once it has booted)
#   plan FILE STEP         parse and plan FILE's lines (in RAM: see Lines) through
#                          the firmware's parser, command table and planner, with the
#                          queue retired by hand (boards/sim/plan_only.py's make_room
#                          after each line, so the look-ahead stays full and the
#                          planner never waits); with STEP 1 a step path runs meanwhile
#                          (see stepping_path). Answers `bench:{json}`.
#   profile FILE           plan FILE without stepping, then again with the planner's
#                          functions timed (bench/chip_profile.py): `bench:{json}`.
#   functions              where each loaded function's code starts, for
#                          bench/chip_pcprofile.py.
# Written against the firmware's API: heap.reserve/release and planner.step_loop_bytes
# (one more reserve, for the second step path), assemble.build(config, files_root=None),
# assemble.build_step_path(settings, pins), assemble.drop(), Config, planner.set_mix and
# add_move, pins.axis_dir_masks(), mixer.normalize, safety.start_timer(machine, printer, tick_us) (returns what
# has deinit()), printer.parser.parse,
# printer.run_line, printer.planner (.idle, .queue, .synchronize), printer.mem with the
# stepper's S_HEAD/S_TAIL/S_ACTIVE/S_POS words (plan_only.retire_one).
import sys
import gc
import json
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
_CHUNK = const(1024)
_CHUNK_LINES = const(128)  # at most: a slicer's shortest lines take 8 bytes
_TABLES = const(6144)
_PATH_TABLES = const(4096)


@micropython.viper
def _copy(dst, src, start: int, n: int):
    d = ptr8(dst)
    s = ptr8(src)
    for i in range(n):
        d[i] = s[start + i]


class Lines:
    """A G-code file read a chunk at a time into one buffer, made before the firmware's
    modules load: the file whole would take kilobytes of the heap that the printers'
    tables need. plan() times the lines of each chunk, not the reading. Each line is
    copied into one buffer, as the firmware receives a line, and parsed from there.
    Lines that wait for the heaters are left out."""

    def __init__(self, path):
        self.path = path
        self.chunk = bytearray(_CHUNK)
        self.bounds = array("H", range(2 * _CHUNK_LINES))
        self.buf = bytearray(_LINE_MAX)
        self.f = None
        self.count = self.moves = 0
        self.rewind()
        while True:
            n = self.fill()
            if n < 0:
                break
            for i in range(n):
                self.count += 1
                self.moves += bytes(self.chunk[self.bounds[2 * i]:][:3]) in (b"G1 ", b"G0 ")

    def rewind(self):
        # Opened once: a file object takes a kilobyte in one piece, which the heap the
        # printers leave may not have.
        if self.f is None:
            self.f = open(self.path, "rb")
        self.f.seek(0)
        self.size = self.at = 0  # the chunk's bytes, and where its next line starts

    def fill(self):
        """The next chunk's whole lines, their bounds in self.bounds: how many, or -1
        at the end of the file. A line cut by the chunk's end goes to its start."""
        chunk = self.chunk
        held = self.size - self.at
        chunk[:held] = chunk[self.at:self.size]
        got = self.f.readinto(memoryview(chunk)[held:])
        size = held + got
        if not size:
            return -1
        bounds = self.bounds
        n = at = 0
        while at < size:
            end = chunk.find(b"\n", at)
            if end < 0 or end >= size:
                if got:
                    break  # the rest of this line comes with the next read
                end = size
            stop = end
            while stop > at and chunk[stop - 1] in (10, 13):
                stop -= 1
            if n == _CHUNK_LINES:
                break  # the rest with the next chunk
            if bytes(chunk[at:at + 4]) not in (b"M109", b"M190", b"M116"):
                bounds[2 * n] = at
                bounds[2 * n + 1] = stop
                n += 1
            at = end + 1
        self.size, self.at = size, min(at, size)
        return n

    def line(self, i):
        """Line i of the chunk in the buffer; returns its length."""
        a = self.bounds[2 * i]
        n = self.bounds[2 * i + 1] - a
        _copy(self.buf, self.chunk, a, n)
        return n

    def first(self, prefix, k):
        """The first k lines that start with prefix, as bytes."""
        out = []
        self.rewind()
        while len(out) < k:
            n = self.fill()
            if n < 0:
                break
            for i in range(n):
                m = self.line(i)
                if bytes(self.buf[:len(prefix)]) == prefix and len(out) < k:
                    out.append(bytes(self.buf[:m]))
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
# And room for the tables of the planned printer (its command table alone grows to
# 776 bytes in one piece) and of the step path (the planner's), held whole while the
# modules load, whose code would leave the heap in pieces too small for them; each
# given back just before its build.
KEPT["tables"] = bytearray(_TABLES)
KEPT["path_tables"] = bytearray(_PATH_TABLES)
from mixfw import assemble  # noqa: E402
from mixfw import safety  # noqa: E402
from mixfw.config import Config  # noqa: E402
from mixfw import stepper as st  # noqa: E402
from mixfw.mixer import normalize  # noqa: E402
from plan_only import make_room, retire_one  # noqa: E402



class StepPath:
    """A step path alone, as safety.start_timer takes a printer's."""

    def __init__(self, settings, parts):
        self.settings = settings
        self.mem, self.pins, self.planner, self.feed, self.irq = parts


def stepping_path():
    """A second step path, built as the board's printer's is (assemble.build_step_path),
    whose only job is to keep the step loop busy with one long six-drive mixed move, as
    while printing. The planner measured is a printer's whose queue is retired by hand,
    so what it plans never reaches the pins and never waits for them; both share the
    CPU. Without a printer of its own around it, it takes a few kB beside the planned
    printer, its arrays the reserve held for them."""
    if not KEPT.get("stepper"):
        # The planned printer's settings: its arrays take the reserve held for them
        # (the board's size), and a second configuration would take the heap kilobytes.
        settings = KEPT["plan"].settings
        del KEPT["path_tables"]
        gc.collect()
        path = StepPath(settings, assemble.build_step_path(settings, board.PINS))
        # The move: X 100 mm/s, Y 75 mm/s and E 14.46 mm/s of filament mixed over all
        # six drives, i.e. 8,000 + 6,000 + 6,000 steps/s at the pico_6drives steps/mm
        # (80, 80, 415), for 8 s: longer than any planning run here.
        path.planner.set_mix(2, normalize([0.1, 0.15, 0.2, 0.25, 0.12, 0.18], 6))
        # T0's pressure advance, as the printer's: its follower then runs the drives.
        path.planner.set_advance(settings["tool_advance_k"][0])
        path.planner.add_move([64000, 48000, 0], 125.0, path.pins.axis_dir_masks(),
                              115660000)
        KEPT["stepper"] = path
    return KEPT["stepper"]


def planned_printer():
    """The printer whose planning is measured, its queue retired by hand."""
    if not KEPT.get("plan"):
        gc.collect()
        # The board's settings have no trace records (3 kB at the firmware's 256): its
        # step loop never runs, and the heap holds two step paths beside the lines.
        del KEPT["tables"]
        gc.collect()
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
    printer = planned_printer()
    if stepping:
        stepper = stepping_path()
    else:
        stepper = None
        heap.release()  # the step path's reserve: heap as a board has it
        KEPT.pop("path_tables", None)
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
    start_us = time.ticks_us()  # the step path's rate: over the reading too
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
    buf = data.buf
    line = data.line
    us = number = 0
    data.rewind()
    while True:
        n = data.fill()
        if n < 0:
            break
        machine.mem32[_PROFILED] = 1  # the program counter's profile, if one is taken
        t0 = time.ticks_us()
        for i in range(n):
            number += 1
            try:
                run_line(parse(buf, line(i)))
            except Exception as e:  # the firmware would answer Error: and go on
                if len(errors) < 5:
                    errors.append("line %d: %r" % (number, e))
            # As a board's step path would: the ring keeps its one free slot, so the
            # planner never waits (its wait hook stays for a line of several blocks).
            make_room(mem, full)
        us += time.ticks_diff(time.ticks_us(), t0)
        machine.mem32[_PROFILED] = 0
    machine.mem32[_PROFILED] = 1
    t0 = time.ticks_us()
    planner.synchronize()  # the look-ahead's last moves
    us += time.ticks_diff(time.ticks_us(), t0)
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
        wall_us = time.ticks_diff(time.ticks_us(), start_us)
        out.update(zip("stepper_steps_per_s stepper_still_moving".split(), (
            (steps1 - steps0) * 1e6 / wall_us, bool(stepper.planner.busy()))))
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
