"""`mixstep arcfit`: replace runs of short G1 extrusion moves that lie on a circle by
G2/G3 arcs, as an arc-fitting post-processor (ArcWelder) does.

A slicer writes a round wall as many short straight moves; printed as one arc, the same
wall is one line for the printer to read and plan, which the firmware splits again
into segments of its own (docs/G-Codes.md, G2/G3).

What is fitted: a run of consecutive `G1` lines, each one a printing move in X and Y
only (positive E, Z unchanged), written as words alone (no comment, line number or
checksum), at one feed rate (the modal F the same after every line), in absolute X Y
(G90), each extruding within `E_RATE_TOLERANCE` of the run's E per mm. The run is grown
one move at a time while its points (the first move's start and every move's end) stay
within `tolerance_mm` of the circle through its first, middle and last points, and go
round it one way, each move under a quarter turn and the whole under one turn, with a
radius of at most `max_radius_mm` (a straight run fits only a huge circle: it stays
lines). A run of at least `MIN_MOVES` moves becomes one line:

    G2 X<last X> Y<last Y> I<centre X - start X> J<centre Y - start Y> E<E> [F<F>]

(G3 if it goes counter-clockwise): X and Y as the last move wrote them, I and J to
0.0001 mm, E the exact decimal sum of the moves' E (M83) or the last move's E (M82),
and the first move's F word if it had one. The arc passes through the start and the
end exactly (up to I J's rounding), so where the print goes next is unchanged.
Every other line comes out byte for byte.

    from mixstep import arcfit
    summary = arcfit.arcfit("in.gcode", "out.gcode", tolerance_mm=0.01)
    # {"arcs": n, "moves_fitted": m, "lines_in": ..., "lines_out": ...}
"""
import math
from decimal import Decimal

import numpy as np

from mixstep import gcodeio
from mixstep.outfile import refuse_input, replacing

MIN_MOVES = 3
E_RATE_TOLERANCE = 0.05  # a move's E per mm within 5 % of the run's: the arc extrudes evenly
MAX_RADIUS_MM = 1000.0


def circle_through(p, q, r):
    """(cx, cy, radius) of the circle through three points, None if they are in line."""
    ax, ay = q[0] - p[0], q[1] - p[1]
    bx, by = r[0] - p[0], r[1] - p[1]
    d = 2 * (ax * by - ay * bx)
    if d == 0:
        return None
    a2, b2 = ax * ax + ay * ay, bx * bx + by * by
    ux = (by * a2 - ay * b2) / d
    uy = (ax * b2 - bx * a2) / d
    return p[0] + ux, p[1] + uy, math.hypot(ux, uy)


def fit(points, tolerance_mm, max_radius_mm=MAX_RADIUS_MM):
    """The arc through points (an (n, 2) array, n >= 3) if they all lie within
    tolerance_mm of the circle through the first, middle and last and go round it one
    way, under a quarter turn a move and a turn in all: (cx, cy, radius, sweep), sweep
    in radians, counter-clockwise positive. None if they don't."""
    circle = circle_through(points[0], points[len(points) // 2], points[-1])
    if circle is None or circle[2] > max_radius_mm:
        return None
    cx, cy, radius = circle
    dx, dy = points[:, 0] - cx, points[:, 1] - cy
    if np.abs(np.hypot(dx, dy) - radius).max() > tolerance_mm:
        return None
    angle = np.arctan2(dy, dx)
    turn = (np.diff(angle) + math.pi) % (2 * math.pi) - math.pi
    if not ((turn > 0).all() or (turn < 0).all()) or np.abs(turn).max() >= math.pi / 2:
        return None
    sweep = float(turn.sum())
    if abs(sweep) >= 2 * math.pi - 1e-6:
        return None
    return cx, cy, radius, sweep


def _number(x, places):
    text = ("%.*f" % (places, x)).rstrip("0").rstrip(".")
    return "0" if text in ("-0", "") else text


class _Run:
    """Consecutive candidate moves, and the arc they fit so far."""

    def __init__(self, start_xy, relative_e):
        self.relative_e = relative_e
        self.points = [start_xy]
        self.lines = []  # (raw, words, de_mm, length_mm)
        self.arc = None

    def e_rate_fits(self, de, length):
        rates = [d / l for _, _, d, l in self.lines] + [de / length]
        mean = sum(d for _, _, d, _ in self.lines) + de
        mean /= sum(l for _, _, _, l in self.lines) + length
        return all(abs(r - mean) <= E_RATE_TOLERANCE * mean for r in rates)


def arcfit(in_path, out_path, tolerance_mm=0.01, max_radius_mm=MAX_RADIUS_MM):
    """Write in_path with its runs of G1 extrusion moves on a circle as G2/G3 arcs (see
    the module doc). Returns {"arcs", "moves_fitted", "lines_in", "lines_out"}."""
    if not tolerance_mm > 0:
        raise ValueError("the tolerance must be > 0 mm, got %r" % tolerance_mm)
    if not max_radius_mm > 0:
        raise ValueError("the largest radius must be > 0 mm, got %r" % max_radius_mm)
    refuse_input(out_path, in_path)
    counts = {"arcs": 0, "moves_fitted": 0, "lines_in": 0, "lines_out": 0}
    with open(in_path, newline="") as fin, replacing(out_path, newline="") as fout:
        reader = gcodeio.Reader(fin)
        run = None
        run_feed = None

        def flush():
            nonlocal run
            if run is None:
                return
            if run.arc is not None and len(run.lines) >= MIN_MOVES:
                fout.write(_arc_line(run))
                counts["arcs"] += 1
                counts["moves_fitted"] += len(run.lines)
                counts["lines_out"] += 1
            else:
                for raw, _, _, _ in run.lines:
                    fout.write(raw)
                counts["lines_out"] += len(run.lines)
            run = None

        for ln in reader:
            counts["lines_in"] += 1
            x0, y0, z0, _ = ln.start
            x1, y1, z1, _ = ln.end
            length = math.hypot(x1 - x0, y1 - y0)
            candidate = (ln.code == "G1" and ln.printing and z1 == z0 and length > 0
                         and not reader.rel_xyz and ";" not in ln.raw and "*" not in ln.raw
                         and ln.raw.lstrip()[:1] in "Gg")
            if candidate and run is not None and reader.feed_mm_min == run_feed \
                    and run.e_rate_fits(ln.de_mm, length):
                points = np.array(run.points + [(x1, y1)])
                arc = fit(points, tolerance_mm, max_radius_mm) if len(points) >= 3 else None
                if arc is not None or len(points) < 3:
                    run.points.append((x1, y1))
                    run.lines.append((ln.raw, ln.words, ln.de_mm, length))
                    run.arc = arc
                    continue
                # The run ends here; this move may start the next one, from the run's end.
                last = run.points[-1]
                flush()
                run = _Run(last, reader.rel_e)
                run.points.append((x1, y1))
                run.lines.append((ln.raw, ln.words, ln.de_mm, length))
                run_feed = reader.feed_mm_min
                continue
            flush()
            if candidate:
                run = _Run((x0, y0), reader.rel_e)
                run.points.append((x1, y1))
                run.lines.append((ln.raw, ln.words, ln.de_mm, length))
                run_feed = reader.feed_mm_min
                continue
            fout.write(ln.raw)
            counts["lines_out"] += 1
        flush()
    return counts


def _arc_line(run):
    cx, cy, _, sweep = run.arc
    (x0, y0), (x1, y1) = run.points[0], run.points[-1]
    first_words, last_words = run.lines[0][1], run.lines[-1][1]
    if run.relative_e:
        e = str(sum((Decimal(words["E"]) for _, words, _, _ in run.lines), Decimal(0)))
    else:
        e = last_words["E"]
    words = ["G2" if sweep < 0 else "G3",
             "X" + last_words.get("X", _number(x1, 4)),
             "Y" + last_words.get("Y", _number(y1, 4)),
             "I" + _number(cx - x0, 4), "J" + _number(cy - y0, 4), "E" + e]
    if "F" in first_words:
        words.append("F" + first_words["F"])
    raw = run.lines[-1][0]
    newline = raw[len(raw.rstrip("\r\n")):] or "\n"
    return " ".join(words) + newline


def add_parser(sub):
    p = sub.add_parser("arcfit", help="runs of G1 extrusion moves on a circle -> G2/G3 arcs")
    p.add_argument("gcode", help="the G-code file to fit")
    p.add_argument("-o", "--output", required=True, help="write the fitted G-code here")
    p.add_argument("--tolerance-mm", type=float, default=0.01,
                   help="how far a move's end may lie from its arc (default 0.01)")
    p.add_argument("--max-radius-mm", type=float, default=MAX_RADIUS_MM,
                   help="no arc of a larger radius: such runs stay lines (default %g)"
                        % MAX_RADIUS_MM)
    p.set_defaults(run=_run)


def _run(args):
    summary = arcfit(args.gcode, args.output, args.tolerance_mm, args.max_radius_mm)
    print("%d arcs of %d moves; %d lines -> %d -> %s" % (
        summary["arcs"], summary["moves_fitted"], summary["lines_in"], summary["lines_out"],
        args.output))
    return 0
