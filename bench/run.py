"""`make bench`: measure the firmware and host tools, write bench.json at the repository
root and print one row per figure: key, value, target, pass/miss ("report" where there
is no target). A missed target is not an error; a measurement that fails is (exit 1).

Ratios are taken within one run against a reference timed in the same run; where an
absolute time is reported, its reference is reported next to it.

    python bench/run.py [--quick] [--only NAME,...]

--only chip runs just the rows measured on the emulated Pico (bench/chip_rows.py);
they are skipped, with the reason, where node, rp2040js or the image are missing.
--quick uses ~100 MB inputs for the host tools instead of 1 GB. Generated inputs live
in out/bench/ (the 1 GB G-code is kept there and reused).
"""
import argparse
import json
import math
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from mixstep import deploy, paths, sim, steptiming
from mixstep.simprinter import SimPrinter
from mixfw.gcode import Parser
import chip_print
import chip_rows

ROOT = paths.ROOT
WORK = ROOT / "out" / "bench"
EXAMPLE = paths.EXAMPLE_GCODE
SLICER_100K = ROOT / "testdata" / "slic3r_part_x4_100k.gcode"
BENCH_DIR = Path(__file__).resolve().parent
MB = 1000 * 1000
FULL_BYTES = 1000 * MB
QUICK_BYTES = 100 * MB
# A print at 150 mm/s made of 0.2 mm segments needs this many moves per second.
REQUIRED_LINES_PER_S = 150 / 0.2
SNIPPET_LINES = 600  # of the example, for the step timing and heap-size searches

# key: (comparison, target); None: reported only.
TARGETS = {
    "step_loop_ratio": ("<=", 2.5),
    "idle_tick_ratio": ("<=", 1.5),
    "step_loop_pin_ratio": None,
    "heap_peak_bytes": ("<=", 65536),
    "heap_at_rest_bytes": None,
    "heap_peak_over_rest_bytes": None,
    "heap_module_objects_bytes": None,
    "heap_frozen_peak_bytes": ("<=", 65536),
    "heap_frozen_peak_32bit_estimate_bytes": None,
    "heap_code_bytes": None,
    "heap_total_peak_bytes": None,
    "min_heap_bytes_that_prints": None,
    "planner_lines_per_s": (">=", 50000),
    "required_lines_per_s": None,
    "step_time_error_max_us": ("<=", 25),
    "step_time_error_p99_us": None,
    "step_time_error_all_axes_max_us": None,
    "sim_speedup": (">=", 20),
    "advance_lines_per_s": (">=", 300000),
    "advance_peak_mb": ("<", 50),
    "detool_lines_per_s": (">=", 300000),
    "detool_peak_mb": ("<", 50),
    "trace_check_mb_per_s": None,
    "trace_check_peak_mb": None,
    # On the emulated Pico (bench/chip_rows.py): estimates, real silicon is slower.
    "chip_planner_lines_per_s": (">=", 1000),
    "chip_planner_lines_per_s_no_stepping": None,
    "chip_planner_circles_lines_per_s_no_stepping": None,
    "chip_cpu_left_while_stepping": (">=", 0.80),
    "chip_max_step_rate": (">=", 100000),
    "chip_max_step_rate_keeping_rate": None,
    "chip_step_time_error_max_us": ("<=", 2),
    "chip_underruns": ("<=", 0),
    "chip_heap_free_min_bytes": None,
    "chip_print_ratio_usb": ("<=", 1.05),
    "chip_print_ratio_flash": ("<=", 1.05),
    "chip_print_cpu_busy": ("<=", 0.70),
    "chip_arc_print_ratio_usb": ("<=", 1.02),
    "sim_circles_speed_ratio": (">=", 0.95),
}


def micropython(script, *args, heap="2M"):
    """Run a bench script on the MicroPython unix port; its last line is JSON."""
    cmd = [paths.micropython(), "-X", "heapsize=" + heap, str(BENCH_DIR / script)]
    cmd += [str(a) for a in args]
    done = subprocess.run(cmd, cwd=ROOT, env=paths.micropython_env(), capture_output=True,
                          text=True)
    if done.returncode != 0:
        raise RuntimeError("%s failed: %s" % (script, done.stderr.strip()[-2000:]))
    return json.loads(done.stdout.strip().splitlines()[-1])


# Started between the bench and a tool so the tool's peak RSS is its own: a child
# forked straight from this (large) process would start out with its RSS.
_LAUNCHER = ("import resource, subprocess, sys; code = subprocess.call(sys.argv[2:]); "
             "open(sys.argv[1], 'w').write(str(resource.getrusage("
             "resource.RUSAGE_CHILDREN).ru_maxrss)); sys.exit(code)")


def child_usage(cmd, ok_codes=(0,)):
    """Run cmd; returns (wall seconds, peak RSS in MB) of that child alone."""
    peak_file = WORK / "peak_rss_kib"
    t0 = time.perf_counter()
    done = subprocess.run([sys.executable, "-c", _LAUNCHER, str(peak_file)] + [str(c) for c in cmd],
                          cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    wall = time.perf_counter() - t0
    if done.returncode not in ok_codes:
        raise RuntimeError("%s failed (%d): %s" % (" ".join(map(str, cmd)), done.returncode,
                                                  done.stderr.decode(errors="replace")[-2000:]))
    return wall, int(peak_file.read_text()) * 1024 / MB  # ru_maxrss is in KiB on Linux


def example_snippet():
    """The example's first lines as the step timing measurement runs them."""
    path = WORK / "snippet.gcode"
    path.write_text(steptiming.snippet(EXAMPLE, SNIPPET_LINES))
    return path


# --- the step loop ---------------------------------------------------------------

def bench_step_loop(res):
    r = micropython("step_cost.py")
    for key in ("step_loop_ratio", "idle_tick_ratio", "step_loop_pin_ratio"):
        res[key] = r[key]
    res["step_loop_reference_empty_viper_us"] = r["empty_viper_us"]
    for key in ("step_tick_us", "idle_tick_us", "step_tick_pin_us"):
        res["step_loop_" + key] = r[key]
    res["step_loop_note"] = ("one step-loop call writing the set/clear registers of a "
                             "simulated RP2040 bank, as on the chip; step_loop_pin_ratio: "
                             "the Pin.value path, mostly the simulated chip recording edges")


# --- heap ------------------------------------------------------------------------

def prints_in(heap_bytes, gcode):
    """Does the simulated printer run gcode without an error in a heap this small?"""
    try:
        printer = SimPrinter(heap_size="%d" % heap_bytes)
    except RuntimeError:
        return False
    try:
        with open(gcode) as f:
            for raw in f:
                if any(t.startswith("Error:") for t in printer.send(raw.rstrip("\n"))):
                    printer.proc.kill()
                    printer.proc.wait()
                    return False
        printer.finish()
    except (RuntimeError, BrokenPipeError):
        printer.proc.kill()
        printer.proc.wait()
        return False
    return True


def bench_heap(res):
    r = sim.run(EXAMPLE, heap_lock=True)
    if r["errors"]:
        raise RuntimeError("example print with the heap locked: %s" % r["errors"][:3])
    code = sim.code_heap(r["firmware_modules"])
    data_peak, data_rest = r["heap_data_peak_bytes"], r["heap_data_at_rest_bytes"]
    res["heap_peak_bytes"] = res["heap_data_peak_bytes"] = data_peak
    res["heap_at_rest_bytes"] = res["heap_data_at_rest_bytes"] = data_rest
    res["heap_peak_over_rest_bytes"] = data_peak - data_rest
    res["heap_data_after_print_bytes"] = r["heap_data_after_bytes"]
    res["heap_module_objects_bytes"] = code["module_body_bytes"]
    res["heap_frozen_peak_bytes"] = code["module_body_bytes"] + data_peak
    res["heap_code_bytes"] = r["heap_code_bytes"]
    res["heap_code_compiled_bytes"] = code["compiled_bytes"]
    res["heap_code_mpy_bytes"] = mpy_code_bytes()
    res["heap_total_peak_bytes"] = r["heap_code_bytes"] + data_peak
    # On a 32-bit chip every object is half as many bytes (words of 4 bytes, GC blocks
    # of 16, single-precision floats boxed in one block as here); byte buffers are
    # not. Only the step-loop array is counted as a buffer: the few smaller ones (line
    # and receive buffers, under 1 KB) are halved too.
    buffers = r["step_memory_bytes"]
    res["heap_frozen_peak_32bit_estimate_bytes"] = (
        buffers + (res["heap_frozen_peak_bytes"] - buffers) // 2)
    res["heap_sim_buffer_bytes"] = r["sim_buffer_bytes"]
    res["heap_note"] = (
        "bytes of heap on the 64-bit unix port (objects twice a 32-bit chip's size), "
        "example print, default queue, step loop run with the heap locked; the "
        "simulation's own heap (chip, edge buffer, thermal model) is in none of them. "
        "heap_peak_bytes = heap_data_peak_bytes (the target): the firmware's data, what "
        "building the printer and printing allocate, at the peak of the print (live "
        "heap sampled after a collection); heap_at_rest_bytes = heap_data_at_rest_bytes: "
        "the same after boot, before the first line. heap_module_objects_bytes: what "
        "the module bodies make at import (globals, function and class objects, module "
        "tables), which a board with the firmware frozen into flash also holds in RAM; "
        "heap_frozen_peak_bytes: that plus the data peak, the whole heap of a frozen "
        "board; heap_frozen_peak_32bit_estimate_bytes: the same with every object but "
        "the step-loop array halved. heap_code_bytes: importing the modules from .py, "
        "bytecode included; heap_code_mpy_bytes: from .mpy files made by mpy-cross "
        "(make deploy), which load onto the heap as well; heap_code_compiled_bytes: the "
        "compiled modules alone (bytecode and constants, without the names they intern), "
        "which a frozen board keeps in flash; "
        "heap_total_peak_bytes: heap_code_bytes plus the data peak.")
    # The smallest heap the print runs in: bisect on a snippet (fast), then confirm
    # with the whole example, growing by 8 KiB steps if it needs more.
    snippet = example_snippet()
    lo, hi = 16 * 1024, 2 * 1024 * 1024
    step = 8 * 1024
    if not prints_in(hi, snippet):
        raise RuntimeError("snippet does not print in the default 2 MB heap")
    while hi - lo > step:
        mid = (lo + hi) // 2 // step * step
        if prints_in(mid, snippet):
            hi = mid
        else:
            lo = mid
    for _ in range(4):
        if prints_in(hi, EXAMPLE):
            res["min_heap_bytes_that_prints"] = hi
            res["min_heap_note"] = ("smallest -X heapsize (8 KiB steps) in which the whole "
                                    "example prints without an error, simulated chip included")
            return
        hi += step
    raise RuntimeError("the example does not print in %d bytes of heap" % hi)


def mpy_code_bytes():
    """The firmware's code heap when its modules are .mpy files from the pinned
    mpy-cross, as `make deploy` puts them on a board (the unix port loads x64 ones)."""
    out = WORK / "mpy"
    if out.exists():
        shutil.rmtree(out)
    deploy.compile_mixfw(out, "x64")
    printer = SimPrinter(code_dir=out)
    report = printer.finish()
    return report["heap_code_bytes"]


# --- planner ---------------------------------------------------------------------

def bench_planner(res):
    figures = {}
    for name, path in (("example", EXAMPLE), ("100k", SLICER_100K)):
        for mode in ("full", "empty"):
            r = micropython("plan_rate.py", path, mode)
            if r["errors"]:
                raise RuntimeError("planning %s: %s" % (path.name, r["errors"][:3]))
            figures[(name, mode)] = r
    res["planner_lines_per_s"] = min(figures[(n, "full")]["move_lines_per_s"]
                                     for n in ("example", "100k"))
    for (name, mode), r in figures.items():
        suffix = "" if mode == "full" else "_queue_emptied"
        res["planner_lines_per_s_%s%s" % (name, suffix)] = r["move_lines_per_s"]
    res["planner_100k_lines"] = figures[("100k", "full")]["lines"]
    res["required_lines_per_s"] = REQUIRED_LINES_PER_S
    res["planner_note"] = ("G0/G1 lines per second through parser, command table and "
                           "planner on the unix port, no stepping; the smaller of the "
                           "example and %s, with the block ring kept full (after each "
                           "line the oldest block retired where the ring is full, by "
                           "boards/sim/plan_only.py's make_room: full look-ahead, and "
                           "the planner never waits; it works out the retired block's "
                           "ramp schedule, as the step path does at a block's start); "
                           "_queue_emptied: every block retired at each wait" % SLICER_100K.name)


# --- step timing -----------------------------------------------------------------

def bench_step_timing(res):
    r = steptiming.measure(example_snippet(), WORK)
    errors = r.pop("firmware_errors")
    if errors:
        raise RuntimeError("step timing snippet: %s" % errors[:3])
    res.update(r)
    res["step_time_note"] = ("lead-axis STEP edges vs the ideal trapezoid of each block "
                             "(see mixstep/steptiming.py), first %d lines of the example"
                             % SNIPPET_LINES)


# --- simulation speed ------------------------------------------------------------

def bench_sim_speed(res):
    vcd = WORK / "example.vcd"
    r = sim.run(EXAMPLE, trace_path=vcd)
    if r["errors"]:
        raise RuntimeError("example print: %s" % r["errors"][:3])
    res["sim_speedup"] = r["sim_seconds"] / r["wall_seconds"]
    res["sim_seconds"] = r["sim_seconds"]
    res["sim_wall_seconds"] = r["wall_seconds"]
    vcd.unlink()
    ratio, asked = chip_print.speed_ratio(work=WORK)
    res["sim_circles_speed_ratio"] = round(ratio, 4)
    res["sim_circles_speed_ratio_method"] = (
        "testdata/circles_tube_emu_excerpt.gcode in mixstep sim on %s: the time its "
        "extrusion would take if the queue never held it back (each run of extrusion, "
        "read off the trace as the drives stepping forward with no pause over 5 ms, from "
        "rest to rest along its X/Y path at the file's %g mm/s and the board's "
        "acceleration) over its time in the trace" % (chip_print.BOARD, asked))


# --- host tools on big inputs ----------------------------------------------------

def big_gcode(size_bytes):
    """Copies of the example until size_bytes (kept in out/bench/ for the next run)."""
    one = EXAMPLE.read_bytes()
    copies = max(1, round(size_bytes / len(one)))
    path = WORK / ("example_x%d.gcode" % copies)
    if not path.exists() or path.stat().st_size != copies * len(one):
        tmp = path.with_suffix(".tmp")
        with open(tmp, "wb") as f:
            for _ in range(copies):
                f.write(one)
        tmp.rename(path)
    return path, copies * one.count(b"\n")


def bench_gcode_tools(res, size_bytes):
    src, lines = big_gcode(size_bytes)
    out = WORK / "tool_output.gcode"
    res["host_input_gcode_bytes"] = src.stat().st_size
    res["host_input_gcode_lines"] = lines
    for name, args in (("advance", ["advance", src, "-o", out, "--purge-mm", "2.5"]),
                       ("detool", ["detool", src, "-o", out, "--matrix", "1,0,0;0,1,0;0,0,1"])):
        wall, peak_mb = child_usage([str(Path(sys.executable).parent / "mixstep")] + args)
        res[name + "_lines_per_s"] = lines / wall
        res[name + "_peak_mb"] = peak_mb
        res[name + "_seconds"] = wall
        out.unlink()


def drive_mm_after(path, drives=6):
    """Each drive's filament (mm) after a print with single-drive tools and relative or
    absolute E, summed as mixstep trace check sums it."""
    parser = Parser()
    tool, absolute_e, pos_e = 0, False, 0.0
    drive_mm = [0.0] * drives
    with open(path, "rb") as f:
        for raw in f:
            data = raw.rstrip(b"\r\n")
            try:
                ln = parser.parse(data, len(data))
            except ValueError:
                continue
            cmd = "%s%d" % (ln.letter, ln.number) if ln.letter else ""
            if cmd in ("G0", "G1") and ln.has_value("E"):
                target = ln.float("E") if absolute_e else pos_e + ln.float("E")
                drive_mm[tool] += target - pos_e
                pos_e = target
            elif cmd == "G92" and (ln.has("E") or not any(ln.has(c) for c in "XYZ")):
                pos_e = ln.float("E", 0.0)
            elif cmd in ("M82", "G90"):
                absolute_e = True
            elif cmd in ("M83", "G91"):
                absolute_e = False
            elif ln.letter == "T":
                tool = ln.number
    return drive_mm


def repeatable_end(drive_mm, steps_per_mm):
    """Lines that make a print repeatable after itself with exactly the same steps: X,
    Y and Z go back to 0, where the next copy's G28 finds them, and E moves bring
    every drive's filament to (very nearly) a whole step, so the drives' rounding
    starts the next copy where it started the first. E is written with 9 decimals
    (the parser's limit): of the next 64 whole steps, the one the 9-decimal grid
    reaches most closely is taken."""
    lines = ["G90", "G1 X0 Y0 F6000", "G1 Z0 F600", "M302 P1", "M83"]
    for d, mm in enumerate(drive_mm):
        if not mm:
            continue
        best = None
        for extra in range(1, 65):
            whole = math.floor(mm * steps_per_mm) + extra
            e = round(whole / steps_per_mm - mm, 9)
            off = abs((mm + e) * steps_per_mm - whole)
            if best is None or off < best[0]:
                best = (off, e)
        lines += ["T%d" % d, "G1 E%.9f F300" % best[1]]
    return lines


def big_vcd(size_bytes):
    """A VCD of about size_bytes: the example print (made repeatable, see
    repeatable_end) simulated once, its changes then repeated later and later in
    time; and the G-code it shows, as many copies of that print."""
    settings = paths.load_board("sim")["SETTINGS"]
    text = EXAMPLE.read_text()
    base_gcode = WORK / "vcd_base.gcode"
    base_gcode.write_text(text + "\n".join(repeatable_end(drive_mm_after(EXAMPLE),
                                                          settings["steps_per_mm"][3])) + "\n")
    base_vcd = WORK / "vcd_base.vcd"
    r = sim.run(base_gcode, trace_path=base_vcd)
    if r["errors"]:
        raise RuntimeError("VCD base print: %s" % r["errors"][:3])
    data = base_vcd.read_bytes()
    base_vcd.unlink()
    # Header and initial values stay; every later "#<time>" line becomes
    # "#<copy><time, 10 digits>", so copy c runs from c * 10**10 us on.
    body_at = data.index(b"$end", data.index(b"$dumpvars")) + len(b"$end\n")
    head, body = data[:body_at], data[body_at:]
    del data
    last = body.rindex(b"\n#") + 2
    if int(body[last:body.index(b"\n", last)]) >= 10 ** 10:
        raise RuntimeError("the example's trace is longer than 10**10 us")
    padded = re.sub(rb"(?m)^#(\d+)$", lambda m: b"#10%010d" % int(m.group(1)), body)
    del body
    arr = np.frombuffer(padded, dtype=np.uint8).copy()
    stamps = np.flatnonzero((arr[1:] == ord("#")) & (arr[:-1] == ord("\n"))) + 1
    if padded[:1] == b"#":
        stamps = np.concatenate(([0], stamps))
    copies = max(1, round((size_bytes - len(head)) / len(padded)))
    if copies > 89:
        raise RuntimeError("too many copies for two digits: %d" % copies)
    vcd = WORK / "big.vcd"
    with open(vcd, "wb") as f:
        f.write(head)
        for c in range(10, 10 + copies):
            arr[stamps + 1] = ord("0") + c // 10
            arr[stamps + 2] = ord("0") + c % 10
            f.write(arr.tobytes())
    gcode = WORK / "big_vcd.gcode"
    gcode.write_text(base_gcode.read_text() * copies)
    return vcd, gcode, copies


def bench_trace_check(res, size_bytes):
    vcd, gcode, copies = big_vcd(size_bytes)
    report = WORK / "trace_check.json"
    wall, peak_mb = child_usage([str(Path(sys.executable).parent / "mixstep"), "trace",
                                 "check", vcd, "--gcode", gcode, "--json", report],
                                ok_codes=(0, 1))  # 1: checks failed, reported below
    checked = json.loads(report.read_text())
    if not checked["ok"]:
        bad = [c for c in checked["checks"] if c["ok"] is False]
        raise RuntimeError("the generated VCD does not pass trace check: %s" % bad[:3])
    size = vcd.stat().st_size
    res["trace_check_mb_per_s"] = size / MB / wall
    res["trace_check_peak_mb"] = peak_mb
    res["trace_check_seconds"] = wall
    res["host_input_vcd_bytes"] = size
    res["host_input_vcd_copies"] = copies
    vcd.unlink()


# --- table -----------------------------------------------------------------------

def verdict(key, value):
    target = TARGETS.get(key)
    if target is None:
        return "-", "report"
    op, limit = target
    ok = {"<=": value <= limit, "<": value < limit, ">=": value >= limit}[op]
    return "%s %g" % (op, limit), "pass" if ok else "miss"


def table(res):
    rows = [("key", "value", "target", "result")]
    for key in TARGETS:
        if key in res:
            target, result = verdict(key, res[key])
            rows.append((key, "%.6g" % res[key], target, result))
    widths = [max(len(r[i]) for r in rows) for i in range(4)]
    return "\n".join("  ".join(c.ljust(w) for c, w in zip(r, widths)).rstrip() for r in rows)


MEASUREMENTS = {
    "step_loop": lambda res, size: bench_step_loop(res),
    "planner": lambda res, size: bench_planner(res),
    "step_timing": lambda res, size: bench_step_timing(res),
    "heap": lambda res, size: bench_heap(res),
    "sim_speed": lambda res, size: bench_sim_speed(res),
    "gcode_tools": bench_gcode_tools,
    "trace_check": bench_trace_check,
    "chip": lambda res, size: chip_rows.bench_chip(res, WORK),
}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="~100 MB host-tool inputs, not 1 GB")
    ap.add_argument("--only", help="comma-separated: " + ",".join(MEASUREMENTS))
    ap.add_argument("--json", default=str(ROOT / "bench.json"), help="where to write the figures")
    args = ap.parse_args(argv)
    WORK.mkdir(parents=True, exist_ok=True)
    size = QUICK_BYTES if args.quick else FULL_BYTES
    res = {"host_input_size": "100MB" if args.quick else "1GB", "host_input_target_bytes": size}
    failed = {}
    names = args.only.split(",") if args.only else list(MEASUREMENTS)
    for name in names:
        t0 = time.perf_counter()
        print("bench: %s ..." % name, file=sys.stderr, flush=True)
        try:
            MEASUREMENTS[name](res, size)
        except Exception as e:  # reported, and the bench exits non-zero
            failed[name] = "%s: %s" % (type(e).__name__, e)
            print("bench: %s FAILED: %s" % (name, failed[name]), file=sys.stderr)
        res["bench_seconds_" + name] = round(time.perf_counter() - t0, 1)
    res["targets"] = {k: "%s %g" % v if v else "report" for k, v in TARGETS.items()}
    if failed:
        res["failed"] = failed
    Path(args.json).write_text(json.dumps(res, indent=2, sort_keys=True) + "\n")
    print(table(res))
    if failed:
        print("failed measurements: %s" % ", ".join(failed), file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
