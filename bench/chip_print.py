"""Whole prints on the emulated Pico against the time the same file takes in `mixstep
sim` on the same board (where planning costs no simulated time): the rows
chip_print_ratio_usb, chip_print_ratio_flash, chip_print_cpu_busy and
chip_arc_print_ratio_usb of `make bench`,
and the sim's own speed on the circles print (sim_circles_speed_ratio).

    python bench/chip_print.py [circles|vase|arcs|FILE ...] [--usb] [--flash] [--board B]
                                                     [--set K=V ...] [--profile DIR]

Prints JSON. Estimates from the emulator, and optimistic ones (see chip_rows.CAVEAT).
"""
import argparse
import json
import re
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from mixstep import boards, emu, paths, sim, trace  # noqa: E402

ROOT = paths.ROOT
CIRCLES = ROOT / "testdata" / "circles_tube_emu_excerpt.gcode"
VASE = ROOT / "testdata" / "vase_3mix_emu_excerpt.gcode"
# The circles print with its circles as G2/G3 (mixstep arcfit, see its .txt).
CIRCLES_ARCS = ROOT / "testdata" / "circles_tube_arcs_emu_excerpt.gcode"
FILES = {"circles": CIRCLES, "vase": VASE, "arcs": CIRCLES_ARCS}
BOARD = "pico_6drives"


def host_lines(path):
    """The lines a host such as OctoPrint sends of a file: comments and blank lines
    left out, each numbered from 1 with its checksum (M110 N0 first, as OctoPrint
    starts a print)."""
    out = ["M110 N0"]
    n = 0
    with open(path, encoding="latin-1") as f:
        for raw in f:
            text = raw.split(";", 1)[0].strip()
            if not text:
                continue
            n += 1
            body = "N%d %s" % (n, text)
            cs = 0
            for b in body.encode("latin-1"):
                cs ^= b
            out.append("%s*%d" % (body, cs))
    return out


def sim_seconds(path, board=BOARD, settings=None, edges_path=None):
    r = sim.run(path, board=board, settings=settings, edges_path=edges_path)
    if r["errors"]:
        raise RuntimeError("%s in mixstep sim: %s" % (path.name, r["errors"][:3]))
    return r["sim_seconds"]


def _ok(answer, what):
    errors = [t for t in answer if t.startswith(("Error:", "Resend"))]
    if errors:
        raise RuntimeError("%s: %s" % (what, errors[:3]))


def chip_usb(chip, path):
    """Emulated seconds from the first line sent to the ok of a final M400, one line
    per ok; and the CPU's busy share over it."""
    lines = host_lines(path)
    t0 = chip.now
    c0 = chip.cpu()
    for i, text in enumerate(lines):
        _ok(chip.command(text, max_s=30), "line %d (%s)" % (i, text))
    _ok(chip.command("M400", max_s=60), "M400")
    c1 = chip.cpu()
    return chip.now - t0, _busy(c0, c1)


def chip_flash(chip, name):
    """The same, printed from the emulated flash: M23, then from M24 to the ok of an
    M400 after its 'Done printing file'."""
    answer = chip.command("M23 " + name)
    if not any("File selected" in t for t in answer):
        raise RuntimeError("M23 %s: %s" % (name, answer))
    t0 = chip.now
    c0 = chip.cpu()
    _ok(chip.command("M24"), "M24")
    chip.run(match="Done printing file", max_s=600)
    _ok(chip.command("M400", max_s=60), "M400")
    c1 = chip.cpu()
    errors = [t for t in chip.lines_since(t0) if t.startswith("Error:")]
    if errors:
        raise RuntimeError("%s from flash: %s" % (name, errors[:3]))
    return chip.now - t0, _busy(c0, c1)


def _busy(a, b):
    """Share of the emulated time the CPU was not asleep (WFI) between two cpu()s."""
    return 1 - (b["slept"] - a["slept"]) / (b["nanos"] - a["nanos"])


def ratios(path, usb=True, flash=True, board=BOARD, settings=None, profile_dir=None):
    """{sim_s, usb_s, usb_ratio, usb_busy, flash_s, flash_ratio, flash_busy} of one
    file, each print on a chip of its own (so neither inherits the other's heap)."""
    out = {"file": path.name, "sim_s": round(sim_seconds(path, board, settings), 3)}
    ways = ([("usb", None)] if usb else []) + ([("flash", path.name)] if flash else [])
    for way, name in ways:
        files = {name: path} if name else None
        with emu.Chip(board, settings=settings, files=files, max_emu_s=600,
                      max_wall_s=5400) as chip:
            if profile_dir:
                chip.profile()
            s, busy = chip_usb(chip, path) if way == "usb" else chip_flash(chip, name)
            if profile_dir:
                chip.profile(Path(profile_dir) / ("%s-%s.json" % (path.stem, way)))
        out[way + "_s"] = round(s, 3)
        out[way + "_ratio"] = round(s / out["sim_s"], 4)
        out[way + "_busy"] = round(busy, 4)
    return out


# --- the sim's speed on the circles print -------------------------------------------

def extrusion_runs(edges_path, board, gap_s=0.005):
    """[(seconds, xy_mm)] of each run of extrusion in a trace: the E drives stepping
    forward with no pause over gap_s, and the X/Y path (at the trace's resolution of
    1 ms) meanwhile."""
    t, g, lv = trace.read_edges(edges_path)
    unit = 1e-6  # the simulation's edge times are microseconds
    settings = paths.load_board(board)["SETTINGS"]
    spm = settings["steps_per_mm"]
    e_times = []
    for i in range(settings["drives"]):
        ts, pos = trace.positions_of(t, g, lv, board, "e%d" % i)
        steps = np.diff(np.concatenate([[0], pos]))
        e_times.append(ts[steps > 0])
    e = np.sort(np.concatenate(e_times)) * unit
    if not len(e):
        return []
    cut = np.nonzero(np.diff(e) > gap_s)[0]
    starts = np.concatenate([[e[0]], e[cut + 1]])
    ends = np.concatenate([e[cut], [e[-1]]])
    # X/Y positions sampled every millisecond.
    grid = np.arange(0, e[-1] + 0.002, 0.001)
    xy = []
    for axis, k in (("x", 0), ("y", 1)):
        ts, pos = trace.positions_of(t, g, lv, board, axis)
        at = np.searchsorted(ts * unit, grid, side="right") - 1
        xy.append(np.where(at >= 0, pos[np.maximum(at, 0)], 0) / spm[k])
    runs = []
    for s, e_end in zip(starts, ends):
        i0, i1 = int(s / 0.001), int(e_end / 0.001) + 1
        path_mm = float(np.hypot(np.diff(xy[0][i0:i1 + 1]), np.diff(xy[1][i0:i1 + 1])).sum())
        runs.append((e_end - s, path_mm))
    return runs


def asked_speed_mm_s(path):
    """The F (mm/s) of the file's extruding X/Y moves, which must all ask the same."""
    feeds = set()
    feed = None
    for raw in open(path, encoding="latin-1"):
        text = raw.split(";", 1)[0]
        if not re.match(r"\s*G[01]\b", text):
            continue
        f = re.search(r"F([\d.]+)", text)
        if f:
            feed = float(f.group(1)) / 60
        if re.search(r"[XY]-?[\d.]", text) and re.search(r"E[\d.]", text):
            feeds.add(feed)
    if len(feeds) != 1:
        raise RuntimeError("%s: extrusion at several feed rates %s" % (path, feeds))
    return feeds.pop()


def speed_ratio(path=CIRCLES, board=BOARD, work=None, settings=None):
    """The time the file's extrusion takes as a planner whose queue never holds it back
    would plan it (each run of extrusion from rest to rest at the file's feed rate and
    the board's acceleration) over its time in mixstep sim."""
    with tempfile.TemporaryDirectory(dir=work) as tmp:
        edges = Path(tmp) / "speed.edges"
        sim_seconds(path, board, settings, edges_path=edges)
        runs = extrusion_runs(edges, board)
    v = asked_speed_mm_s(path)
    a = paths.load_board(board)["SETTINGS"]["acceleration_mm_s2"]
    ideal = real = 0.0
    for seconds, mm in runs:
        # A trapezoid from rest to rest, or a triangle where the run is too short.
        ideal += mm / v + v / a if mm >= v * v / a else 2 * (mm / a) ** 0.5
        real += seconds
    return ideal / real, v


if __name__ == "__main__":
    ap = argparse.ArgumentParser()
    ap.add_argument("files", nargs="*", default=["circles", "vase"])
    ap.add_argument("--usb", action="store_true")
    ap.add_argument("--flash", action="store_true")
    ap.add_argument("--speed", action="store_true", help="sim_circles_speed_ratio only")
    ap.add_argument("--board", default=BOARD)
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    ap.add_argument("--profile", metavar="DIR")
    args = ap.parse_args()
    settings = boards.set_items(args.board, args.set) or None
    if args.speed:
        r, v = speed_ratio(board=args.board)
        print(json.dumps({"sim_circles_speed_ratio": round(r, 4), "asked_mm_s": v}))
        sys.exit(0)
    both = not (args.usb or args.flash)
    for f in args.files:
        path = FILES.get(f, Path(f))
        print(json.dumps(ratios(path, both or args.usb, both or args.flash, args.board,
                                settings, args.profile)), flush=True)
