"""`mixstep preview`: draw a toolpath coloured by the mixture that leaves the nozzle.

The mixture model is Ovenbird's moving average (the mixing-nozzle model). Let m(s) be the mix the
drives are fed with at extruded length s (a stochastic vector over the filaments) and
r(x) the mix that comes out of the nozzle at extruded length x:

    r(x) = (1/L2) * integral of m(s) ds over [x - L1 - L2, x - L1]

so a step change of m at x = 0 comes out as a linear ramp from x = L1 to x = L1 + L2
(L1: delay length, L2: transition length, both in mm of filament).

Conventions:
- x is the outflow: the highest net filament fed so far. A retraction and the prime
  that follows it push nothing new out of the nozzle, so they do not move x; Travel
  does not move it either.
- Before the first extrusion the nozzle holds the first mix used (m(s) for s < 0 is
  the first mix), i.e. the print starts primed.
- Tool T<n> is 100 % filament n unless a matrix is given; a tool beyond the filaments
  is an equal mix, as in the firmware. M163/M164 and M567 in the file redefine tools.
- A filament has one colour; a mixture's colour is the linear mix of the colours by
  the mixture's fractions.
- "Blend" marks where r is more than BLEND_TOLERANCE away from every tool mix the file
  uses: the mixture-of-mixtures zones where colours bleed.

The file is read one line at a time (by `mixstep.gcodeio`, whose modal rules are the
firmware's). A top view keeps only the drawn layer in memory.
"""
import math
import re

import numpy as np

from mixstep import gcodeio
from mixstep.outfile import temporary_path
from mixfw.colours import DRIVE_RGB
from mixfw.mixer import MAX_DRIVES

DEFAULT_COLORS = ",".join("#%06x" % c for c in DRIVE_RGB)
EXTRUDATE_WIDTH_MM = 0.45  # drawn line width; slicers' usual width for a 0.4 mm nozzle
BLEND_TOLERANCE = 0.05  # 5 % of a filament: below what a viewer can tell apart
_ARC_CHORD_MM = 0.5  # arcs are drawn as chords at most this long


class MixHistory:
    """m(s), piecewise constant over extruded length s, and the outgoing r(x)."""

    def __init__(self, first_mix):
        first = np.asarray(first_mix, dtype=float)
        self.starts_mm = [0.0]          # where each constant piece of m begins
        self.cumulative = [np.zeros_like(first)]  # integral of m from 0 to that start
        self.mixes = [first]

    def change(self, x_mm, mix):
        """From extruded length x_mm on, the drives are fed with mix."""
        mix = np.asarray(mix, dtype=float)
        last_x = self.starts_mm[-1]
        if x_mm < last_x:
            raise ValueError("mix changes must come in order of extruded length")
        if x_mm == last_x:
            self.mixes[-1] = mix  # nothing was extruded with the previous mix
            return
        self.cumulative.append(self.cumulative[-1] + self.mixes[-1] * (x_mm - last_x))
        self.starts_mm.append(x_mm)
        self.mixes.append(mix)

    def integral(self, s_mm):
        """Integral of m from 0 to each s (negative s: the first mix reaches back)."""
        s_mm = np.atleast_1d(np.asarray(s_mm, dtype=float))
        starts = np.asarray(self.starts_mm)
        i = np.clip(np.searchsorted(starts, s_mm, side="right") - 1, 0, None)
        cumulative = np.asarray(self.cumulative)
        mixes = np.asarray(self.mixes)
        return cumulative[i] + mixes[i] * (s_mm - starts[i])[:, None]

    def outgoing(self, x_mm, l1_mm, l2_mm):
        """r(x) for each x: rows are the mixtures coming out of the nozzle."""
        x_mm = np.atleast_1d(np.asarray(x_mm, dtype=float))
        if l2_mm <= 0:  # no mixing chamber: a pure delay
            starts = np.asarray(self.starts_mm)
            i = np.clip(np.searchsorted(starts, x_mm - l1_mm, side="right") - 1, 0, None)
            return np.asarray(self.mixes)[i]
        return (self.integral(x_mm - l1_mm) - self.integral(x_mm - l1_mm - l2_mm)) / l2_mm

    def forget_before(self, s_mm):
        """Drop pieces that end before s_mm; queries from then on are all >= s_mm."""
        while len(self.starts_mm) > 1 and self.starts_mm[1] <= s_mm:
            del self.starts_mm[0], self.cumulative[0], self.mixes[0]


def moving_average(x_mm, changes, l1_mm, l2_mm):
    """r(x) for a feed given as [(x_mm, mix), ...], the first mix also before it."""
    history = MixHistory(changes[0][1])
    for x, mix in changes:
        history.change(x, mix)
    return history.outgoing(x_mm, l1_mm, l2_mm)


def _number(words, letter, default):
    """A word's value as a number; default when absent or bare."""
    value = words.get(letter)
    return float(value) if value else default


def parse_colors(text):
    colors = []
    for c in text.split(","):
        c = c.strip().lstrip("#")
        if not re.fullmatch(r"[0-9a-fA-F]{6}", c):
            raise ValueError("colour %r is not #rrggbb" % c)
        colors.append([int(c[i:i + 2], 16) / 255.0 for i in (0, 2, 4)])
    return np.asarray(colors)


class Toolpath:
    """Streams G-code and yields the printing moves cut into short pieces, each with
    the mixture fed (designed) and the mixture coming out (r)."""

    def __init__(self, drives, l1_mm, l2_mm, matrix=None):
        if l1_mm < 0 or l2_mm < 0:
            raise ValueError("lengths must be >= 0 mm, got L1 %g, L2 %g" % (l1_mm, l2_mm))
        self.drives = drives
        self.l1_mm, self.l2_mm = l1_mm, l2_mm
        self.tools = {}
        for t, row in enumerate(matrix or []):
            self.tools[t] = self._normalise(row)
        self.piece_mm = l2_mm / 12 if l2_mm > 0 else 0.05  # extrusion per drawn piece
        self.used_mixes = []
        self.tool_changes = []  # (layer, x, y, z, label) where the G-code changes mix

    def _normalise(self, weights):
        w = np.zeros(self.drives)
        w[:len(weights)] = weights[:self.drives]
        if len(weights) > self.drives and any(weights[self.drives:]):
            raise ValueError("a mix uses drive %d but only %d colours are given"
                             % (len(weights) - 1, self.drives))
        if w.sum() <= 0:
            raise ValueError("all-zero mix")
        return w / w.sum()

    def tool_mix(self, tool):
        if tool not in self.tools:
            w = np.zeros(self.drives)
            if tool < self.drives:
                w[tool] = 1.0
            elif self.drives < MAX_DRIVES:
                raise ValueError("the file selects T%d but only %d colours are given: give "
                                 "one per filament (--colors) or a --matrix"
                                 % (tool, self.drives))
            else:
                w[:] = 1.0 / self.drives  # the firmware's default above the drive count
            self.tools[tool] = w
        return self.tools[tool]

    def pieces(self, path):
        """Yield (layer, z_mm, points (k+1, 2), fed mix (n,), outgoing mixes (k, n))."""
        fed_mm = 0.0         # net filament fed, across G92 resets
        outflow_mm = 0.0     # x of the model: the highest fed_mm so far
        tool = None
        history = None
        collector = np.zeros(self.drives)
        layer, layer_z = -1, None
        pending_label = None
        with open(path, "r", encoding="ascii", errors="replace") as f:
            for ln in gcodeio.Reader(f):
                code, words = ln.code, ln.words
                if code in gcodeio.MOVES:
                    fed_mm += ln.de_mm
                    x0_mm, x1_mm = outflow_mm, max(outflow_mm, fed_mm)
                    outflow_mm = x1_mm
                    target = ln.end
                    points = self._path(code, ln.start, target, words)
                    moved_xy = any(abs(points[-1][i] - points[0][i]) > 1e-9 for i in (0, 1)) \
                        or len(points) > 2
                    if x1_mm <= x0_mm or not moved_xy:
                        continue
                    if tool is None:
                        tool = 0
                    mix = self.tool_mix(tool)
                    if history is None:
                        history = MixHistory(mix)
                        self._use(mix)
                    if abs(target[2] - (layer_z if layer_z is not None else -1e9)) > 1e-6:
                        layer, layer_z = layer + 1, target[2]
                    if pending_label is not None:
                        self.tool_changes.append((layer, points[0][0], points[0][1],
                                                  target[2], pending_label))
                        pending_label = None
                    history.change(x0_mm, mix)
                    yield self._cut(layer, target[2], points, x0_mm, x1_mm, mix, history)
                    history.forget_before(x0_mm - self.l1_mm - self.l2_mm)
                elif code[:1] == "T" and code[1:].isdigit():
                    if history is not None and ln.tool != tool:
                        pending_label = "T%d" % ln.tool  # marked where it next extrudes
                    tool = ln.tool
                    self._use(self.tool_mix(tool))
                elif code == "M163":
                    collector[int(_number(words, "S", 0))] = _number(words, "P", 0.0)
                elif code == "M164":
                    t = int(_number(words, "S", tool or 0))
                    self.tools[t] = self._normalise(collector)
                    if t == tool and history is not None:
                        pending_label = "T%d mix" % t
                    self._use(self.tools[t])
                elif code == "M567" and words.get("E"):
                    t = int(_number(words, "P", 0))
                    self.tools[t] = self._normalise([float(v) for v in words["E"].split(":")])
                    self._use(self.tools[t])

    def _use(self, mix):
        if not any(np.allclose(mix, u) for u in self.used_mixes):
            self.used_mixes.append(mix)

    def _path(self, code, start, end, words):
        """Points of a move in XY; arcs as chords."""
        if code not in gcodeio.ARCS or not ("I" in words or "J" in words or "R" in words):
            return [start[:2], end[:2]]
        cx, cy, radius, a0, sweep = gcodeio.arc(start, end, words, code == "G2")
        n = max(2, int(math.ceil(abs(sweep) * radius / _ARC_CHORD_MM)))
        angles = a0 + sweep * np.linspace(0, 1, n + 1)
        pts = [[cx + radius * math.cos(a), cy + radius * math.sin(a)] for a in angles]
        pts[-1] = end[:2]
        return pts

    def _cut(self, layer, z_mm, points, x0_mm, x1_mm, mix, history):
        """The move cut into pieces of at most piece_mm of extrusion; flow is constant
        along a move, so extruded length is proportional to distance."""
        pts = np.asarray(points, dtype=float)
        seg_len = np.hypot(*np.diff(pts, axis=0).T)
        along = np.concatenate([[0.0], np.cumsum(seg_len)])
        total = along[-1]
        k = max(1, min(400, int(math.ceil((x1_mm - x0_mm) / self.piece_mm))))
        cuts = np.linspace(0.0, total, k + 1)
        # Keep the arc's own vertices too, so a curve stays a curve.
        d = np.union1d(cuts, along)
        xy = np.column_stack([np.interp(d, along, pts[:, 0]), np.interp(d, along, pts[:, 1])])
        mid = (d[:-1] + d[1:]) / 2
        x_mid_mm = x0_mm + (x1_mm - x0_mm) * mid / total
        return layer, z_mm, xy, mix, history.outgoing(x_mid_mm, self.l1_mm, self.l2_mm)


def blend_mask(outgoing, used_mixes):
    """True where the outgoing mixture is none of the mixes the file feeds."""
    if not used_mixes:
        return np.zeros(len(outgoing), bool)
    used = np.asarray(used_mixes)
    distance = np.abs(outgoing[:, None, :] - used[None, :, :]).max(axis=2)
    return distance.min(axis=1) > BLEND_TOLERANCE


class _Drawn:
    """What one file contributes to the figure."""

    def __init__(self, path):
        self.path = path
        self.segments = []   # (k, 2, 3) arrays
        self.outgoing = []   # (k, n) arrays
        self.layer = None
        self.z_mm = None
        self.tool_changes = []
        self.used_mixes = []


def collect(path, drives, l1_mm, l2_mm, matrix=None, layer=None, all_layers=False):
    """Read path and keep what is drawn: every layer, the given layer, or (layer None)
    the first layer where colours blend (layer 0 if none does)."""
    tp = Toolpath(drives, l1_mm, l2_mm, matrix)
    keep = []            # (layer, z_mm, xy, outgoing) of what will be drawn
    first_layer = None   # in automatic mode, layer 0 in case no layer blends
    current = None
    chosen = layer
    finished = False
    last = -1
    for lay, z_mm, xy, mix, out in tp.pieces(path):
        last = lay
        item = (lay, z_mm, xy, out)
        if all_layers:
            keep.append(item)
        elif layer is not None:
            if lay > layer:
                break
            if lay == layer:
                keep.append(item)
        else:
            if lay != current:
                if current is not None:
                    if _blends(keep, tp.used_mixes):
                        chosen, finished = current, True
                        break
                    if first_layer is None:
                        first_layer = keep
                keep, current = [], lay
            keep.append(item)
    if layer is not None and not keep:
        raise ValueError("%s has no layer %d: its layers are 0 to %d" % (path, layer, last))
    if not all_layers and layer is None and not finished:
        if keep and _blends(keep, tp.used_mixes) or first_layer is None:
            chosen = current
        else:
            keep = first_layer
            chosen = keep[0][0]
    drawn = _Drawn(path)
    for lay, z_mm, xy, out in keep:
        seg = np.stack([xy[:-1], xy[1:]], axis=1)
        drawn.segments.append(
            np.concatenate([seg, np.full(seg.shape[:2] + (1,), z_mm)], axis=2))
        drawn.outgoing.append(out)
        drawn.z_mm = z_mm
    drawn.layer = None if all_layers else chosen
    drawn.tool_changes = [c for c in tp.tool_changes if all_layers or c[0] == chosen]
    drawn.used_mixes = tp.used_mixes
    return drawn


def _blends(items, used_mixes):
    return any(blend_mask(item[3], used_mixes).any() for item in items)


def _colour(outgoing, colors):
    return np.clip(outgoing @ colors[:outgoing.shape[1]], 0.0, 1.0)


_BACKGROUND = "#3a3a3a"  # dark, so red, blue and yellow all stand out
_HALO = "#ffffff"


def _draw_top(ax, drawn, colors):
    """Returns the line collections, whose widths are set once the layout is known."""
    from matplotlib.collections import LineCollection
    ax.set_facecolor(_BACKGROUND)
    if not drawn.segments:
        ax.text(0.5, 0.5, "nothing printed", transform=ax.transAxes, ha="center", color="w")
        return []
    seg = np.concatenate(drawn.segments)[:, :, :2]
    out = np.concatenate(drawn.outgoing)
    blend = blend_mask(out, drawn.used_mixes)
    # A white halo under every blended piece: the eye finds the bleed before it
    # judges the colours.
    halo = LineCollection(seg[blend], colors=_HALO, capstyle="round", zorder=1)
    lines = LineCollection(seg, colors=_colour(out, colors), capstyle="round", zorder=2)
    ax.add_collection(halo)
    ax.add_collection(lines)
    for _, x, y, _, label in drawn.tool_changes:
        ax.plot([x], [y], marker="v", ms=9, mfc="k", mec="w", mew=1.2, zorder=4)
        ax.annotate(label, (x, y), xytext=(4, 6), textcoords="offset points", color="w",
                    fontsize=8, fontweight="bold", zorder=5)
    lo, hi = seg.reshape(-1, 2).min(axis=0), seg.reshape(-1, 2).max(axis=0)
    margin = 0.04 * max(hi - lo) + 1.0
    ax.set_xlim(lo[0] - margin, hi[0] + margin)
    ax.set_ylim(lo[1] - margin, hi[1] + margin)
    ax.set_aspect("equal")
    ax.set_xlabel("X mm")
    ax.set_ylabel("Y mm")
    return [(halo, 2.6), (lines, 1.0)]


def _set_widths(ax, collections, width_mm):
    """Lines as wide as the extrudate, so filled areas look filled."""
    box = ax.get_window_extent()
    x0, x1 = ax.get_xlim()
    y0, y1 = ax.get_ylim()
    pt_per_mm = min(box.width / (x1 - x0), box.height / (y1 - y0)) * 72.0 / ax.figure.dpi
    for collection, factor in collections:
        collection.set_linewidth(max(0.5, width_mm * pt_per_mm * factor))


def _draw_3d(ax, drawn, colors):
    from mpl_toolkits.mplot3d.art3d import Line3DCollection
    ax.set_facecolor(_BACKGROUND)
    if not drawn.segments:
        return
    seg = np.concatenate(drawn.segments)
    out = np.concatenate(drawn.outgoing)
    blend = blend_mask(out, drawn.used_mixes)
    ax.add_collection3d(Line3DCollection(seg, colors=_colour(out, colors), linewidths=0.8))
    ax.add_collection3d(Line3DCollection(seg[blend], colors=_HALO, linewidths=1.6))
    lo, hi = seg.reshape(-1, 3).min(axis=0), seg.reshape(-1, 3).max(axis=0)
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_zlim(lo[2], hi[2])
    # Height drawn at 4x so the layers can be told apart.
    ax.set_box_aspect(np.maximum((hi - lo) * (1, 1, 4), 1e-3))
    from matplotlib.ticker import MaxNLocator
    ax.zaxis.set_major_locator(MaxNLocator(3))
    ax.set_xlabel("X mm")
    ax.set_ylabel("Y mm")
    ax.set_zlabel("Z mm")


def render(paths, out_png, l1_mm=1.0, l2_mm=1.5, colors=DEFAULT_COLORS, matrix=None,
           layer=None, all_layers_3d=False):
    """Draw one file, or several side by side (the same layer of each), to out_png.
    Returns the collected drawings (layer chosen, pieces) for callers and tests."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    colors = parse_colors(colors) if isinstance(colors, str) else np.asarray(colors)
    drives = len(matrix[0]) if matrix else len(colors)
    if drives > len(colors):
        raise ValueError("the matrix has %d drives but only %d colours are given"
                         % (drives, len(colors)))
    drawn = []
    for i, path in enumerate(paths):
        # The side-by-side files show the layer the first one showed.
        want = layer if (layer is not None or i == 0) else drawn[0].layer
        drawn.append(collect(path, drives, l1_mm, l2_mm, matrix, want, all_layers_3d))
    fig = plt.figure(figsize=(7.5 * len(paths), 7.4), dpi=110)
    widths = []
    for i, d in enumerate(drawn):
        name = str(d.path).rsplit("/", 1)[-1]
        if all_layers_3d:
            ax = fig.add_subplot(1, len(paths), i + 1, projection="3d")
            _draw_3d(ax, d, colors)
            ax.set_title(name, fontsize=10)
        else:
            ax = fig.add_subplot(1, len(paths), i + 1)
            widths.append((ax, _draw_top(ax, d, colors)))
            z = "" if d.z_mm is None else ", Z %.2f mm" % d.z_mm
            ax.set_title("%s\nlayer %s%s" % (name, d.layer, z), fontsize=10)
    shown = [n for n in range(drives) if any(m[n] > 0 for d in drawn for m in d.used_mixes)]
    handles = [Patch(color=colors[n], label="filament %d" % n) for n in shown]
    handles.append(Line2D([], [], color=_HALO, lw=5, label="blend: mixture of mixtures "
                          "(> %d %% off every tool)" % round(BLEND_TOLERANCE * 100)))
    if not all_layers_3d:
        handles.append(Line2D([], [], ls="", marker="v", ms=9, mfc="k", mec="w",
                              label="tool change in the G-code"))
    fig.legend(handles=handles, loc="lower center", ncol=min(len(handles), 3),
               fontsize=9, facecolor=_BACKGROUND, labelcolor="w", edgecolor="w")
    fig.suptitle("Colour leaving the nozzle (moving-average model)\ndelay L1 = %g mm, "
                 "transition L2 = %g mm of filament" % (l1_mm, l2_mm), fontsize=11)
    fig.tight_layout(rect=(0, 0.08, 1, 0.98))
    for ax, collections in widths:
        _set_widths(ax, collections, EXTRUDATE_WIDTH_MM)
    with temporary_path(out_png) as part:
        fig.savefig(part, format="png")
    plt.close(fig)
    return drawn


def add_parser(sub):
    p = sub.add_parser("preview", help="draw the toolpath coloured by the mixture leaving the nozzle")
    p.add_argument("gcode")
    p.add_argument("-o", "--output", required=True, help="PNG to write")
    p.add_argument("--l1-mm", type=float, default=1.0, help="delay length, mm of filament")
    p.add_argument("--l2-mm", type=float, default=1.5, help="transition length, mm of filament")
    p.add_argument("--colors", default=DEFAULT_COLORS, help="one #rrggbb per filament")
    p.add_argument("--matrix", help="mixing matrix (as for detool): row n is tool T<n>")
    view = p.add_mutually_exclusive_group()
    view.add_argument("--layer", type=int,
                      help="layer to draw, from 0 (default: the first one where colours blend)")
    view.add_argument("--all-layers-3d", action="store_true", help="3-D view of every layer")
    p.add_argument("--compare", help="a second file (e.g. after `mixstep advance`) to draw beside")
    p.set_defaults(run=_run)


def _run(args):
    import sys
    from mixstep.detool import parse_matrix
    try:
        matrix = parse_matrix(args.matrix) if args.matrix else None
        paths = [args.gcode] + ([args.compare] if args.compare else [])
        drawn = render(paths, args.output, args.l1_mm, args.l2_mm, args.colors, matrix,
                       args.layer, args.all_layers_3d)
    except ValueError as e:
        print("mixstep preview: %s" % e, file=sys.stderr)
        return 2
    for d in drawn:
        pieces = sum(len(o) for o in d.outgoing)
        blended = sum(int(blend_mask(o, d.used_mixes).sum()) for o in d.outgoing)
        print("%s: %s, %d pieces, %d blended -> %s" % (
            d.path, "all layers" if d.layer is None else "layer %d" % d.layer, pieces,
            blended, args.output))
    return 0
