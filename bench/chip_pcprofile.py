# Where the emulated Pico's time goes while it plans the planner rows' excerpt, function
# by function: the program counter's profile (emu/harness.mjs, mixstep.emu.Chip.profile)
# of bench/chip_main.py's planner run, the second of two (the first builds the
# printers), with or without the step path running.
#
#   python bench/chip_pcprofile.py [--stepping] [--gcode FILE] [--top N]
#
# Prints JSON: the run's move lines and lines/s, and per context (thread: the main loop;
# irq: the step path's interrupts) the microseconds a move line spent in each native or
# viper function, with the MicroPython runtime's code each called (flash), and in
# "(bytecode)": the interpreter, with the runtime it calls and the calls' way in and out
# of native code. Only the planning loop is profiled (chip_main.py marks it). Estimates
# of a real chip, optimistic ones: the emulator charges no flash wait states and no
# interrupt entry.
import argparse
import bisect
import json
import sys
import tempfile
from collections import Counter
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import chip_rows  # noqa: E402

NATIVE_FROM, SRAM_END = 0x20004000, 0x20042000  # as emu/harness.mjs's
BYTECODE = "(bytecode)"


def function_starts(lines):
    """[(address, name)] of the native code in the heap, sorted, from chip_main.py's
    `functions` lines (FUN address name); a function known by several names (a module's
    import of another's) by all of them, joined by " = "."""
    names = {}
    for line in lines:
        _, address, name = line.split()
        address = int(address) & ~1  # a Thumb address's low bit
        if NATIVE_FROM <= address < SRAM_END:
            names.setdefault(address, set()).add(name)
    return [(a, " = ".join(sorted(n))) for a, n in sorted(names.items())]


def by_function(part, starts, hz, lines):
    """{function: microseconds a line} of one context of a profile: the cycles at its
    own addresses and those of the code it called in flash."""
    addresses = [a for a, _ in starts]
    cycles = Counter()

    def name(address):
        if not address:
            return BYTECODE
        i = bisect.bisect_right(addresses, address) - 1
        return starts[i][1] if i >= 0 else "?%x" % address

    for address, n in part["self"].items():
        if NATIVE_FROM <= int(address) < SRAM_END:
            cycles[name(int(address))] += n
    for address, n in part["by"].items():
        cycles[name(int(address))] += n
    return {fn: round(n * 1e6 / hz / lines, 1) for fn, n in cycles.most_common()}


def profile(stepping=False, gcode=None, work=None):
    work = Path(work or tempfile.mkdtemp())
    path = work / "pcprofile.json"
    request = "plan plan.gcode %d" % (1 if stepping else 0)
    got = chip_rows._planner_chip(work, [request, request], gcode, profile=path)[-1]
    prof = json.loads(path.read_text())
    starts = function_starts(got["functions"])
    lines = got["move_lines"]
    out = {"move_lines": lines, "move_lines_per_s": round(got["move_lines_per_s"], 1),
           "stepping": stepping, "us_per_line": {}}
    for context in ("thread", "irq"):
        out["us_per_line"][context] = by_function(prof[context], starts,
                                                  prof["clk_sys_hz"], lines)
    return out


if __name__ == "__main__":
    ap = argparse.ArgumentParser()
    ap.add_argument("--stepping", action="store_true", help="with the step path running")
    ap.add_argument("--gcode", type=Path, help="a G-code file whose planner rows' lines "
                    "to plan (default: the example's)")
    ap.add_argument("--top", type=int, default=25, help="functions listed per context")
    args = ap.parse_args()
    got = profile(args.stepping, args.gcode)
    for context, fns in got["us_per_line"].items():
        got["us_per_line"][context] = dict(list(fns.items())[:args.top])
    print(json.dumps(got, indent=1))
