"""`mixstep trace check`: does a STEP/DIR trace do what a G-code file asks?

The trace is any VCD (the simulation's, the board's own capture pulled with `mixstep
trace pull`, or a logic analyser's, any $timescale) or a sigrok `.sr` capture, which
`sigrok-cli` converts to VCD first. Only 1-bit signals are read; vectors, reals, scopes
and x/z values are ignored, and a signal's first value is its starting level, not an
edge. Signals are named as on the board (`x_step x_dir ... e5_step e5_dir`); `--map
x_step=D0,x_dir=D1` names a logic analyser's channels.

What the G-code asks is worked out by `mixstep.tracemodel`, which shares no code
with the firmware (see its docstring for the arithmetic): its own G-code reading,
tool mixes, palettes, gradients, firmware transitions, G10/G11, the three retraction
policies, M92 and per-drive steps/mm, E absolute or relative, G92. Settings the
board applies before the G-code (steps/mm, drives, retract_policy, transition
lengths, ...) come from `--board` and `--set KEY=VALUE`, as for `mixstep serve`.

Checks
    steps_<axis>   net steps of X, Y, Z (the steps of every move, from where the trace
                   starts, which must be where the firmware counts 0, i.e. home, as in
                   the simulation) and of every drive. Exact: the firmware plans every
                   drive's step from its exact filament, so there is one right count.
                   An axis or drive that the G-code moves must have its STEP and DIR
                   in the trace, or the check fails and names the missing signal; one
                   it never moves may be left out of a capture (the check is then
                   skipped).
    moves          the drive steps follow the model's blocks in order: in each block
                   every drive goes monotonically to its planned step, exactly (the
                   firmware gives each block the exact count of every drive), and no
                   drive steps outside its block. Fails at the first step that does
                   not fit.
    mix            the order of the steps within a block is the mixer's and is not
                   predicted step by step (docs/Mixing.md specifies the rule, not the
                   weights a block hands it; only replays of part of a block need the
                   order, and there the model assumes the block's counts over their
                   common divisor): within each stretch of one mix, every window of
                   `window` drive steps gives each drive its share of the window's net
                   steps within `mix_tolerance` steps. The error diffusion keeps every
                   drive within about a step of its share at any point, so 2 is a
                   margin. A replayed retraction (retract_policy 2) has no one mix and
                   no windows: its exact counts are checked by `moves`.
    arc_path       over every G2/G3, the X Y Z position at each moment of the trace
                   keeps within a segment's sagitta and a step of each axis of the arc,
                   goes its way round and reaches its end (see _ArcPath). Only prints
                   with arcs have it.
    pulse_high_us, step_low_us
                   the shortest STEP high and low times, at least `step_pulse_us`.
    dir_setup_us   the shortest time from a DIR change to the next rising STEP on that
                   axis, at least `dir_setup_us`.
    rate_<axis>    the fastest run of RATE_RUN steps, at most max_feed_mm_s *
                   steps_per_mm (the board's, not M92's), with `rate_margin` and two
                   step-loop ticks of slack (steps fall on ticks).

Not modelled (reported as `unmodelled` when the G-code uses them; counts may then
differ): options changed while printing (M926, M930, M501, M502), printing from the
printer's flash (M23/M24/M32), M112/M410/M999 (the queue is dropped at a moment the
G-code does not say), the simulation's fault injections (M7100-M7102), and the
cold-extrusion guard (the hot end's temperature is not modelled: a print that
extrudes cold, without M302 P1, is refused by the firmware but expected here).
Lines the firmware refuses (see tracemodel) are not run, and `refused_lines` counts
them. The board's settings are read from boards/<name>/board.py as data. DIR high
means forward unless the board lists the axis in `invert_dir`. At a logic analyser's
sample rate, times are only as exact as a sample.

The trace is streamed in chunks parsed with numpy, so memory stays bounded whatever
its size; the expected moves are held in memory (they grow with the G-code only).
"""
import json
import math
import os
import re
import subprocess
import sys
import tempfile
import time
import zlib

import numpy as np

from mixstep import paths, tracemodel
from mixstep.boards import setting_value

AXES = ("x", "y", "z")
RATE_RUN = 20  # steps over which the step rate is measured
CHUNK_BYTES = 1 << 20  # larger chunks are no faster, and numpy's temporaries grow with them
_UNITS_S = {"s": 1.0, "ms": 1e-3, "us": 1e-6, "ns": 1e-9, "ps": 1e-12, "fs": 1e-15}


class TraceError(Exception):
    """Input that cannot be read: the command exits with status 2."""


# --- Expected: what the G-code asks ------------------------------------------------

def expected_from_gcode(gcode_path, settings):
    """Net steps per axis and drive, and the E moves in order, from a G-code file,
    worked out by mixstep.tracemodel (which shares no code with the firmware).

    Returns {"steps": {axis: n}, "moves": [(line, weights, drive_steps)], "moved":
    {axis}, "unmodelled": {command: first line}, "refused": [(line, reason)]}:
    drive_steps are every drive's absolute planned steps after a block, weights the
    mix it prints with; moved names every axis and drive that some block steps, even
    if it ends where it started."""
    return tracemodel.expected(gcode_path, settings)


def board_settings(board="sim", overrides=None, config=None):
    """A board's settings, then a configuration saved by M500 (config: its file), then
    --set overrides, in the order the firmware takes them. overrides: {key: value or
    value text}."""
    settings = dict(paths.load_board(board)["SETTINGS"])
    if config:
        settings = saved_settings(config, settings)
    for key, value in (overrides or {}).items():
        settings[key] = setting_value(value) if isinstance(value, str) else value
    return settings


_ELEMENT = re.compile(r"(.+)_([xyze]|[0-9]+)$")


def saved_settings(path, settings):
    """settings with the values of a configuration file saved by M500 over them, read
    here on their own: `name = value` lines after `#` comments, a checksum line last;
    an option with a value per axis, drive or tool is saved an element a line, named
    by axis (steps_per_mm_x) or index (tool_mixes_2), a row as a:b:c. A file whose
    checksum fails, which the firmware refuses too, is a TraceError."""
    try:
        data = open(path, "rb").read()
    except OSError as e:
        raise TraceError("can't read the configuration %s: %s" % (path, e.strerror or e))
    cut = data.rfind(b"\n", 0, len(data) - 1) + 1
    body = data[:cut]
    if not data.endswith(b"\n") or data[cut:] != b"crc32 = %08x\n" % zlib.crc32(body):
        raise TraceError("%s is not a configuration as M500 saved it (its checksum fails), "
                         "and the firmware starts with its defaults instead: leave out "
                         "--config" % path)
    out = dict(tracemodel.OPTION_DEFAULTS)
    out.update(settings)
    rows = {}
    for text in body.decode("utf-8", "replace").splitlines():
        name, eq, value = text.partition("=")
        name = name.strip()
        if text.startswith("#") or not eq:
            continue
        value = _saved_value(value.strip())
        element = _ELEMENT.match(name)
        if name in out or not element:
            out[name] = value
            continue
        key, index = element.group(1), element.group(2)
        rows.setdefault(key, {})["xyze".index(index) if index in "xyze" else int(index)] = value
    for key, given in rows.items():
        row = list(out.get(key) or ())
        row += [None] * (max(given) + 1 - len(row))
        for i, value in given.items():
            row[i] = value
        out[key] = tuple(row)
    return out


def _saved_value(text):
    if ":" in text:
        return tuple(_saved_value(t) for t in text.split(":"))
    return setting_value(text)


# --- Reading: VCD (or .sr via sigrok-cli), streamed ---------------------------------

class VcdReader:
    """A VCD file's 1-bit signals, streamed as chunks of (time, signal, value) arrays.

    names: the signal names wanted; `mapping` gives the VCD name of any of them that
    the file calls differently. `signals` lists the wanted names found, in the order
    their indices appear in the chunks; `timescale_s` is one time unit in seconds."""

    def __init__(self, path, names, mapping=None, chunk_bytes=CHUNK_BYTES):
        self.path = path
        self.chunk_bytes = chunk_bytes
        self.bytes_read = 0
        self.lines = 0
        try:
            self._f = open(path, "rb")
        except OSError as e:
            raise TraceError("cannot read %s: %s" % (path, e.strerror))
        header, self._rest = self._read_header()
        self.timescale_s, vars_ = _parse_header(header, path)
        mapping = mapping or {}
        by_vcd_name = {}
        for ident, name in vars_:
            by_vcd_name.setdefault(name, []).append(ident)
        self.signals = []
        self._ids = {}  # VCD identifier -> signal index
        for name in names:
            idents = by_vcd_name.get(mapping.get(name, name))
            if idents:
                for ident in idents:
                    self._ids.setdefault(ident, len(self.signals))
                self.signals.append(name)
        if not self.signals:
            raise TraceError("%s has none of the signals %s (name them with --map)"
                             % (path, ", ".join(mapping.get(n, n) for n in names[:4]) + ", ..."))
        self._by_len = {}
        for ident, sig in self._ids.items():
            if len(ident) <= 8:
                self._by_len.setdefault(len(ident), {})[_id_code(ident)] = sig
        self._long_ids = {i: s for i, s in self._ids.items() if len(i) > 8}
        self._time = 0
        self._in_comment = False

    def close(self):
        self._f.close()

    def _read_header(self):
        buf = b""
        while True:
            block = self._f.read(1 << 16)
            buf += block
            self.bytes_read += len(block)
            at = buf.find(b"$enddefinitions")
            if at >= 0:
                end = buf.find(b"$end", at + len(b"$enddefinitions"))
                if end >= 0:
                    return buf[:at], buf[end + 4:]
            if not block or len(buf) > 64 << 20:
                raise TraceError("%s is not a VCD file: no $enddefinitions" % self.path)

    def chunks(self):
        """Yield (times int64, signals int32, values int8) for every scalar change of a
        wanted signal, in file order, with `times` in units of the timescale."""
        rest = self._rest
        while True:
            block = self._f.read(self.chunk_bytes)
            self.bytes_read += len(block)
            buf = rest + block
            if block:
                cut = buf.rfind(b"\n") + 1
                if cut == 0:
                    rest = buf
                    continue
                buf, rest = buf[:cut], buf[cut:]
            else:
                rest = b""
            if buf:
                self.lines += buf.count(b"\n")
                out = self._parse(buf)
                if out is not None:
                    yield out
            if not block:
                return

    def _parse(self, buf):
        a = np.frombuffer(buf, np.uint8)
        space = a <= 32
        word = ~space
        edge = (np.flatnonzero(word[1:] != word[:-1]) + 1).astype(np.int32)
        starts = edge[word[edge]]
        ends = edge[space[edge]]
        if word[0]:
            starts = np.concatenate(([0], starts))
        if word[-1]:
            ends = np.concatenate((ends, [len(a)]))
        first = a[starts]
        keep = np.ones(len(starts), bool)
        # A vector or real value's identifier is the next word: not a change.
        vec = np.flatnonzero((first == 98) | (first == 66) | (first == 114) | (first == 82))
        keep[vec] = False
        keep[vec[vec + 1 < len(keep)] + 1] = False
        dollar = np.flatnonzero(first == 36)
        if len(dollar) or self._in_comment:
            self._skip_comments(buf, starts, ends, dollar, keep)
        is_time = (first == 35) & keep
        is_change = ((first == 48) | (first == 49)) & keep
        t_idx = np.flatnonzero(is_time)
        c_idx = np.flatnonzero(is_change)
        times = _decimal(a, starts[t_idx] + 1, ends[t_idx])
        sig = self._lookup(a, starts[c_idx], ends[c_idx], buf)
        mine = sig >= 0
        c_idx = c_idx[mine]
        last = np.searchsorted(t_idx, c_idx) - 1
        t_all = np.concatenate(([self._time], times))
        if len(times):
            self._time = int(times[-1])
        if not len(c_idx):
            return None
        return (t_all[last + 1], sig[mine].astype(np.int32),
                (first[c_idx] - 48).astype(np.int8))

    def _skip_comments(self, buf, starts, ends, dollar, keep):
        """$dumpvars/$dumpall/$dumpon/$dumpoff and $end only bracket value changes;
        whatever is inside $comment ... $end is dropped."""
        if self._in_comment:
            stop = [i for i in dollar if buf[starts[i]:ends[i]] == b"$end"]
            upto = stop[0] + 1 if stop else len(keep)
            keep[:upto] = False
            self._in_comment = not stop
            dollar = dollar[dollar >= upto]
        keep[dollar] = False
        open_at = None
        for i in dollar.tolist():
            word = buf[starts[i]:ends[i]]
            if open_at is None and word in (b"$comment", b"$var", b"$scope", b"$upscope"):
                open_at = i
            elif open_at is not None and word == b"$end":
                keep[open_at:i + 1] = False
                open_at = None
        if open_at is not None:
            keep[open_at:] = False
            self._in_comment = True

    def _lookup(self, a, starts, ends, buf):
        """Signal index of each change word's identifier, -1 for signals not wanted."""
        sig = np.full(len(starts), -1, np.int64)
        length = ends - starts - 1
        for n, table in self._by_len.items():
            sel = np.flatnonzero(length == n)
            if not len(sel):
                continue
            code = np.zeros(len(sel), np.uint64)
            for j in range(n):
                code |= a[starts[sel] + 1 + j].astype(np.uint64) << np.uint64(8 * j)
            keys = np.array(sorted(table), np.uint64)
            vals = np.array([table[k] for k in sorted(table)], np.int64)
            at = np.minimum(np.searchsorted(keys, code), len(keys) - 1)
            hit = keys[at] == code
            sig[sel[hit]] = vals[at[hit]]
        for i in np.flatnonzero(length > 8).tolist() if self._long_ids else ():
            sig[i] = self._long_ids.get(buf[starts[i] + 1:ends[i]].decode("ascii", "replace"), -1)
        return sig


def _id_code(ident):
    code = 0
    for j, b in enumerate(ident.encode("ascii")):
        code |= b << (8 * j)
    return code


def _decimal(a, starts, ends):
    """Unsigned decimal numbers a[starts:ends] -> int64, vectorised."""
    if not len(starts):
        return np.zeros(0, np.int64)
    width = int((ends - starts).max())
    if width > 18:
        raise TraceError("time stamp too long: %d digits" % width)
    value = np.zeros(len(starts), np.int64)
    last = len(a) - 1
    for j in range(width):  # one digit column at a time keeps memory at a few vectors
        at = starts + j
        more = at < ends
        digit = a[np.minimum(at, last)].astype(np.int64) - 48
        if ((digit[more] < 0) | (digit[more] > 9)).any():
            raise TraceError("malformed time stamp in the VCD")
        value = np.where(more, value * 10 + digit, value)
    return value


def _parse_header(header, path):
    text = header.decode("ascii", "replace")
    words = text.split()
    timescale_s = None
    vars_ = []
    i = 0
    while i < len(words):
        w = words[i]
        if w == "$timescale":
            j = words.index("$end", i)
            spec = "".join(words[i + 1:j])
            digits = spec.rstrip("abcdefghijklmnopqrstuvwxyz")
            unit = spec[len(digits):]
            if unit not in _UNITS_S or digits not in ("1", "10", "100"):
                raise TraceError("%s: unreadable $timescale %r" % (path, spec))
            timescale_s = int(digits) * _UNITS_S[unit]
            i = j
        elif w == "$var":
            j = words.index("$end", i)
            parts = words[i + 1:j]
            if len(parts) >= 4 and parts[1] == "1":
                vars_.append((parts[2], parts[3]))
            i = j
        i += 1
    if timescale_s is None:
        timescale_s = 1e-9  # the VCD standard's default is 1 ns... but say nothing else
    if not vars_:
        raise TraceError("%s declares no 1-bit signals" % path)
    return timescale_s, vars_


def sigrok_to_vcd(sr_path, vcd_path):
    """A sigrok session file -> VCD, with sigrok-cli."""
    try:
        proc = subprocess.run(["sigrok-cli", "-i", str(sr_path), "-O", "vcd", "-o", str(vcd_path)],
                              capture_output=True, text=True)
    except FileNotFoundError:
        raise TraceError("reading .sr captures needs sigrok-cli (apt-get install sigrok-cli)")
    if proc.returncode != 0 or not os.path.exists(vcd_path):
        raise TraceError("sigrok-cli could not read %s: %s" % (sr_path, proc.stderr.strip()))


# --- Checking ------------------------------------------------------------------------

class _Axis:
    """Streaming state of one axis or drive: edges carry over between chunks."""

    def __init__(self, name, forward_level):
        self.name = name
        self.forward_level = forward_level
        self.step_level = -1
        self.dir_level = -1
        self.dir_change = None  # time of the last DIR edge
        self.last_edge = None  # time of the last STEP edge
        self.net = 0
        self.rises = 0
        self.recent = np.zeros(0, np.int64)  # last RATE_RUN rising times
        self.min_high = self.min_low = self.min_setup = self.min_run = None
        self.at_high = self.at_low = self.at_setup = self.at_run = None


def _track_min(ax, field, values, times):
    if len(values):
        k = int(np.argmin(values))
        old = getattr(ax, "min_" + field)
        if old is None or values[k] < old:
            setattr(ax, "min_" + field, int(values[k]))
            setattr(ax, "at_" + field, int(times[k]))


class Checker:
    def __init__(self, signals, settings, expected, window, mix_tolerance, unit_us):
        self.signals = signals
        index = {n: i for i, n in enumerate(signals)}
        inverted = settings.get("invert_dir", ())
        self.drives = ["e%d" % d for d in range(settings["drives"])]
        self.axes = {}
        self.sig = {}
        for name in list(AXES) + self.drives:
            if name + "_step" in index:
                self.axes[name] = _Axis(name, 0 if name in inverted else 1)
                self.sig[name] = (index[name + "_step"], index.get(name + "_dir", -1))
        # What the G-code moves must be in the trace, STEP and DIR (without DIR no step
        # can be counted); what it never moves may be left out of a capture.
        self.missing = [name + kind for name in list(AXES) + self.drives
                        if name in expected["moved"] for kind in ("_step", "_dir")
                        if name + kind not in index]
        self.walk = None if any(n.rsplit("_", 1)[0] in self.drives for n in self.missing) \
            else _MoveWalk(expected["moves"], settings["drives"], window, mix_tolerance, unit_us)
        # With pressure advance the drives run ahead of the moves by design: they are
        # followed with X Y Z instead, block by block.
        self.advance = None
        if expected.get("advance") and self.walk is not None and not self.missing:
            self.advance = _AdvanceWalk(expected["advance"], settings["drives"], unit_us)
            self.walk = None
        # Only a print with arcs pays for following X Y Z position by position.
        self.path = None
        if expected.get("arcs") and not any(n[0] in "xyz" for n in self.missing):
            self.path = _ArcPath(expected["arcs"], expected["axis_blocks"])

    def feed(self, times, sig, vals):
        e_events = []
        xyz_events = []
        for name, ax in self.axes.items():
            step, dirs = self.sig[name]
            sel = np.flatnonzero((sig == step) | (sig == dirs))
            if not len(sel):
                continue
            t, s, v = times[sel], sig[sel], vals[sel]
            is_dir = s == dirs
            # Only real edges: the first value, and repeats of the level, are not.
            dir0 = ax.dir_level
            prev = np.empty_like(v)
            for mask, attr in ((is_dir, "dir_level"), (~is_dir, "step_level")):
                idx = np.flatnonzero(mask)
                if len(idx):
                    prev[idx[0]] = getattr(ax, attr)
                    prev[idx[1:]] = v[idx[:-1]]
                    setattr(ax, attr, int(v[idx[-1]]))
            edge = (prev != v) & (prev >= 0)
            # DIR level and last DIR edge time in force at every record.
            last_dir = np.maximum.accumulate(np.where(is_dir, np.arange(len(s)), -1))
            dir_level = np.where(last_dir >= 0, v[np.maximum(last_dir, 0)], dir0)
            dir_edge_at = np.where(is_dir & edge, np.arange(len(s)), -1)
            last_dir_edge = np.maximum.accumulate(dir_edge_at)
            dir_edge_time = np.where(last_dir_edge >= 0, t[np.maximum(last_dir_edge, 0)],
                                     -1 if ax.dir_change is None else ax.dir_change)
            if (dir_edge_at >= 0).any():
                ax.dir_change = int(t[dir_edge_at[dir_edge_at >= 0][-1]])
            step_edge = ~is_dir & edge
            te, ve = t[step_edge], v[step_edge]
            if len(te):
                prev_t = np.concatenate(([ax.last_edge if ax.last_edge is not None else -1], te[:-1]))
                width = te - prev_t
                ok = prev_t >= 0
                _track_min(ax, "high", width[ok & (ve == 0)], te[ok & (ve == 0)])
                _track_min(ax, "low", width[ok & (ve == 1)], te[ok & (ve == 1)])
                ax.last_edge = int(te[-1])
            rise = step_edge & (v == 1)
            rt = t[rise]
            if not len(rt):
                continue
            sign = np.where(dir_level[rise] == ax.forward_level, 1, -1)
            ax.net += int(sign.sum())
            ax.rises += len(rt)
            setup_t = dir_edge_time[rise]
            has = setup_t >= 0
            _track_min(ax, "setup", (rt - setup_t)[has], rt[has])
            run = np.concatenate((ax.recent, rt))
            if len(run) > RATE_RUN:
                _track_min(ax, "run", run[RATE_RUN:] - run[:-RATE_RUN], run[RATE_RUN:])
            ax.recent = run[-RATE_RUN:]
            if (self.walk or self.advance) and name in self.drives:
                e_events.append((sel[rise], np.full(len(rt), self.drives.index(name)), sign, rt))
            if (self.path or self.advance) and name in AXES:
                xyz_events.append((sel[rise], np.full(len(rt), AXES.index(name)), sign, rt))
        if self.advance and (xyz_events or e_events):
            # X Y Z as 0 1 2, the drives from 3, in the order of the records.
            both = xyz_events + [(e[0], e[1] + 3, e[2], e[3]) for e in e_events]
            order = np.argsort(np.concatenate([e[0] for e in both]), kind="stable")
            self.advance.feed(np.concatenate([e[1] for e in both])[order].tolist(),
                              np.concatenate([e[2] for e in both])[order].tolist(),
                              np.concatenate([e[3] for e in both])[order].tolist())
        if self.path and xyz_events:
            order = np.argsort(np.concatenate([e[0] for e in xyz_events]), kind="stable")
            self.path.feed(np.concatenate([e[3] for e in xyz_events])[order],
                           np.concatenate([e[1] for e in xyz_events])[order],
                           np.concatenate([e[2] for e in xyz_events])[order])
        if self.walk and e_events:
            order_in_chunk = np.concatenate([e[0] for e in e_events])
            order = np.argsort(order_in_chunk, kind="stable")
            self.walk.feed(np.concatenate([e[1] for e in e_events])[order].tolist(),
                           np.concatenate([e[2] for e in e_events])[order].tolist(),
                           np.concatenate([e[3] for e in e_events])[order].tolist())


ADV_MOST_STEPS = 1024  # stepper._ADV_MOST_STEPS: the most advance the firmware takes


class _AdvanceWalk:
    """With pressure advance (M900): follows X Y Z's steps through the planner's blocks
    (the model's, each with its K) and looks at the drives where each ends.

    Pressure advance's own physics: the drives push the filament the G-code asks
    for plus K times its speed, so at the end of a block that moves X Y Z the drives
    are ahead of the G-code's filament by K times the block's filament per lead-axis
    step times the lead axis's speed there, which the trace itself gives (its last
    step's interval). An E-only block (a retraction, a priming) and the last block end
    with every drive exactly at the G-code's filament: the advance is given back
    before it. Times in the trace's units, messages in us (unit_us each)."""

    # Within this of K times the speed, plus STEP_SLACK steps for the rounding of the
    # advance, the share and the speed taken from one step's interval. The advance is
    # at most what the firmware's follower takes (stepper._ADV_MOST_STEPS).
    TOLERANCE = 0.15
    STEP_SLACK = 3
    # A block shorter than this many lead-axis steps is not looked at: its filament per
    # step, which sets its advance, is a step or two's rounding (the firmware takes it
    # from the block's whole steps as well), and the advance can't follow the jump in a
    # few steps.
    SHORTEST_STEPS = 16

    def __init__(self, blocks, drives, unit_us):
        self.blocks = blocks
        self.drives = drives
        self.unit_us = unit_us
        self.pos = [0] * drives
        self.target = [0] * drives
        self.before = [0] * drives  # the target before the current block
        self.i = -1
        self.left = [0, 0, 0]
        self.sign = [1, 1, 1]
        self.lead = -1
        self.lead_t = [None, None]  # the lead axis's last two steps' times
        self.error = None
        self.ends = 0  # block ends looked at
        self.worst = 0.0  # worst |measured - expected| over its tolerance
        self.worst_at = None
        self.most_steps = 0  # the largest advance seen, steps
        # The filament the advance may run into after each block: the drives never
        # push past the G-code's own filament (so that each ends exactly where it
        # would without), and past a retraction, homing or a block without advance
        # it is not theirs to push. Blocks without filament are passed over.
        e = []
        total = 0
        for _, k, dx, dy, dz, targets in blocks:
            step = sum(targets) - total if targets is not None else 0
            total += step
            e.append(step if k > 0 and step >= 0 else -1)
        self.room = [0] * len(blocks)
        for i in range(len(blocks) - 2, -1, -1):
            self.room[i] = 0 if e[i + 1] < 0 else e[i + 1] + self.room[i + 1]
        self._next()

    def _next(self):
        self.i += 1
        if self.i >= len(self.blocks):
            return
        line, k, dx, dy, dz, targets = self.blocks[self.i]
        self.before = self.target
        if targets is not None:
            self.target = list(targets)
        d = (dx, dy, dz)
        self.left = [abs(v) for v in d]
        self.sign = [1 if v >= 0 else -1 for v in d]
        self.lead = max(range(3), key=lambda a: self.left[a]) if any(d) else -1
        self.lead_t = [None, None]
        if self.lead < 0 and self.pos == self.target:
            self._next()  # an E-only block the drives have done already

    def _fail(self, text, t):
        if self.error is None:
            self.error = "%s at %s" % (text, _at(t, self.unit_us))

    def feed(self, kinds, signs, times):
        blocks = self.blocks
        for kind, s, t in zip(kinds, signs, times):
            if self.error:
                return
            if kind >= 3:
                self.pos[kind - 3] += s
                if self.i < len(blocks) and self.lead < 0 and self.pos == self.target:
                    self._next()
                continue
            if self.i >= len(blocks):
                self._fail("%s stepped after the last block" % AXES[kind], t)
                continue
            line = blocks[self.i][0]
            if self.lead < 0:
                self._fail("%s stepped before the drives reached the filament of the E move "
                           "of G-code line %d (drives at %s, target %s)"
                           % (AXES[kind], line, self.pos, self.target), t)
                continue
            if self.left[kind] == 0 or s != self.sign[kind]:
                self._fail("%s stepped %s, outside the block of G-code line %d"
                           % (AXES[kind], "forward" if s > 0 else "back", line), t)
                continue
            self.left[kind] -= 1
            if kind == self.lead:
                self.lead_t = [self.lead_t[1], t]
            if not any(self.left):
                self._block_end(t)
                self._next()

    def _block_end(self, t):
        line, k, dx, dy, dz, _ = self.blocks[self.i]
        e_steps = sum(self.target) - sum(self.before)
        n = max(abs(dx), abs(dy), abs(dz), abs(e_steps))
        t0, t1 = self.lead_t
        if t0 is None or n > max(abs(dx), abs(dy), abs(dz)) or n < self.SHORTEST_STEPS:
            return  # no speed to read, E leads, or too short to tell
        after = self.blocks[self.i + 1] if self.i + 1 < len(self.blocks) else None
        if after is None or not any(after[2:5]):
            return  # X Y Z stop here: the advance goes back with the E-only block's check
        speed = 1e6 / ((t1 - t0) * self.unit_us)  # lead-axis steps/s
        want = min(k * max(e_steps, 0) / n * speed, self.room[self.i], ADV_MOST_STEPS)
        got = sum(self.pos) - sum(self.target)
        room = self.TOLERANCE * want + self.STEP_SLACK
        self.ends += 1
        self.most_steps = max(self.most_steps, got)
        if abs(got - want) / room > self.worst:
            self.worst = abs(got - want) / room
            self.worst_at = (t, line, want, got)

    def finished(self):
        return self.error is None and self.i >= len(self.blocks) and self.pos == self.target


class _MoveWalk:
    """Follows the drive steps through the G-code's E moves, one step at a time, and
    checks the mix in windows of `window` steps within each stretch of one mix. Times
    come in the trace's units; messages give them in us (unit_us each)."""

    def __init__(self, moves, drives, window, tolerance, unit_us):
        self.moves = moves
        self.unit_us = unit_us
        self.drives = drives
        self.window = window
        self.tolerance = tolerance
        self.m = -1
        self.pos = [0] * drives
        self.target = [0] * drives
        self.left = 0
        self.error = None
        self.windows = 0
        self.worst = 0.0
        self.worst_at = None
        self.bad_windows = 0
        self.steps = 0
        self._counts = [0] * drives
        self._n = 0
        self._shares = None
        self._next_move()

    def _next_move(self):
        while self.left == 0 and self.m + 1 < len(self.moves):
            self.m += 1
            line, weights, target = self.moves[self.m]
            self.target = list(target)
            self.left = sum(abs(target[d] - self.pos[d]) for d in range(self.drives))
            # A replayed retraction (retract_policy 2) runs the steps of earlier blocks
            # backwards, so no one mix holds within it: it has no weights, and no windows.
            shares = None if weights is None else [w / sum(weights) for w in weights]
            if shares != self._shares or shares is None:
                self._shares = shares
                self._counts = [0] * self.drives
                self._n = 0

    def feed(self, drives, signs, times):
        if self.error:
            return
        pos, target = self.pos, self.target
        counts = self._counts
        for d, s, t in zip(drives, signs, times):
            want = target[d] - pos[d]
            if self.left == 0 or want == 0 or (want > 0) != (s > 0):
                where = ("after the last E move" if self.left == 0 else
                         "in the E move of G-code line %d" % self.moves[self.m][0])
                self.error = "e%d stepped %s at %s %s (drives at %s, move target %s)" % (
                    d, "forward" if s > 0 else "back", _at(t, self.unit_us), where, pos, target)
                return
            pos[d] += s
            self.left -= 1
            self.steps += 1
            if self._shares is not None:
                counts[d] += s
                self._n += 1
                if self._n == self.window:
                    self._check_window(t)
            if self.left == 0:
                self._next_move()
                target = self.target
                counts = self._counts

    def _check_window(self, t):
        net = sum(self._counts)
        for d in range(self.drives):
            off = abs(self._counts[d] - self._shares[d] * net)
            if off > self.worst:
                self.worst, self.worst_at = off, (t, d)
        if max(abs(self._counts[d] - self._shares[d] * net) for d in range(self.drives)) \
                > self.tolerance:
            self.bad_windows += 1
        self.windows += 1
        self._counts[:] = [0] * self.drives
        self._n = 0

    def finished(self):
        return self.error is None and self.left == 0 and self.m + 1 >= len(self.moves)


class _ArcPath:
    """Follows the X Y Z steps over every G2/G3 and checks that they keep to the arc,
    with this checker's own geometry (the model's centre, radius and sweep; nothing of
    the firmware's).

    Which steps belong to which arc: the model lists every block that steps an axis,
    with its G-code line, so the n-th step of X falls in a known line, and so for Y
    and Z. After each moment of the trace (all its edges at one time), each axis's
    count of steps says which lines it can be in (inside one, or between one and the
    next that moves it); the position is in the line all three agree on. A position
    they cannot agree on fits no line of the G-code: an axis stepped more, or less,
    than the lines before it ask.

    Over an arc, every position must lie within `tolerance` of the circle: the sagitta
    r (1 - cos(theta / 2)) of one segment (theta = sweep / segments) plus one step of
    each of the plane's axes, i.e. their diagonal (half a step where a segment's end is
    rounded to a step, half for the step loop taking one axis's step before the
    other's). Its angle from the centre, unwrapped from the start the arc's way round,
    must not fall behind the start, run past the end or go back by more than that
    tolerance seen from the centre, and must reach the end; the third axis (a helix)
    must stay within one segment's share and a step of where the angle puts it. Arcs
    whose tolerance is over half their radius (a few steps across) get the distance
    check only: their angles say nothing."""

    STEP_SLACK = 1.0

    def __init__(self, arcs, axis_blocks):
        self.arcs = arcs
        blocks = np.array(axis_blocks, np.int64).reshape(-1, 4)
        # A line's blocks count as one: the firmware works out an arc's segment ends in
        # its own arithmetic, which may put one a step from the model's, but its ends,
        # and a line's, are exact.
        first = np.flatnonzero(np.append(True, blocks[1:, 0] != blocks[:-1, 0])) \
            if len(blocks) else np.zeros(0, np.int64)
        travel = np.add.reduceat(np.abs(blocks[:, 1:]), first, axis=0) if len(first) \
            else np.zeros((0, 3), np.int64)
        self.far = len(first) + 1  # past every line
        arc_of_line = {arc["line"]: k for k, arc in enumerate(arcs)}
        self.block_arc = np.array([arc_of_line.get(int(line), -1) for line in
                                   blocks[first, 0]] + [-1, -1], np.int64)
        self.line_of = np.append(blocks[first, 0], [0, 0])  # [-1]: before any line
        # Per axis: the lines that step it, and its step count at the end of each.
        self.index, self.ends = [], []
        for i in range(3):
            moving = np.flatnonzero(travel[:, i])
            self.index.append(moving)
            self.ends.append(np.cumsum(travel[moving, i]))
        self.count = np.zeros(3, np.int64)  # rising STEP edges so far
        self.pos = np.zeros(3, np.int64)  # net steps so far
        self.pending = None  # the edges at the last time of a chunk, which may go on
        self.stray = 0
        self.stray_at = None
        self.stray_after = 0  # the line the steps last fitted before the first stray
        self.last_line = 0
        k = len(arcs)
        g = {name: np.array([arc[name] for arc in arcs], np.float64)
             for name in ("radius_mm", "start_angle", "sweep", "segments", "start_c_mm",
                          "along_mm")}
        self.axes = np.array([arc["axes"] for arc in arcs], np.int64).reshape(k, 3)
        self.centre = np.array([arc["centre_mm"] for arc in arcs], np.float64).reshape(k, 2)
        self.spm = np.array([[arc["steps_per_mm"][a] for a in arc["axes"]] for arc in arcs],
                            np.float64).reshape(k, 3)
        self.shift = np.array([[arc["step_shift"][a] for a in arc["axes"]] for arc in arcs],
                              np.float64).reshape(k, 3)
        self.radius = g["radius_mm"]
        self.start_angle = g["start_angle"]
        self.way = np.where(g["sweep"] < 0, -1.0, 1.0)
        self.total = np.abs(g["sweep"])
        self.start_c = g["start_c_mm"]
        self.along = g["along_mm"]
        theta = self.total / g["segments"]
        self.tolerance = (self.radius * (1 - np.cos(theta / 2)) + self.STEP_SLACK
                          * np.hypot(1 / self.spm[:, 0], 1 / self.spm[:, 1]) + 1e-6)
        self.c_tolerance = np.abs(self.along) / g["segments"] + self.STEP_SLACK / self.spm[:, 2]
        self.turn_tolerance = self.tolerance / self.radius
        self.angles_count = self.tolerance <= self.radius / 2
        # What each arc's positions did: the worst distance off (as a share of the
        # tolerance), where; the unwrapped angle so far, the furthest and the last.
        self.worst = np.zeros(k)
        self.worst_t = np.zeros(k, np.int64)
        self.worst_mm = np.zeros((k, 2))
        self.seen = np.zeros(k, bool)
        self.last_raw = np.zeros(k)
        self.progress = np.zeros(k)
        self.reached = np.full(k, -np.inf)
        # The first position that went the wrong way (or off the helix): time, angle, Z.
        self.fault_t = np.full(k, -1, np.int64)
        self.fault_turn = np.zeros(k)
        self.fault_c = np.zeros(k)

    def feed(self, times, axis, sign):
        """The X Y Z rising STEP edges of a chunk in trace order: times, axis (0 1 2),
        sign (+1 forward, -1 back)."""
        if self.pending is not None:
            times = np.concatenate((self.pending[0], times))
            axis = np.concatenate((self.pending[1], axis))
            sign = np.concatenate((self.pending[2], sign))
        if not len(times):
            return
        cut = int(np.searchsorted(times, times[-1]))  # the last moment may go on
        self.pending = (times[cut:], axis[cut:], sign[cut:])
        if cut:
            self._walk(times[:cut], axis[:cut], sign[:cut])

    def finish(self):
        if self.pending is not None and len(self.pending[0]):
            self._walk(*self.pending)
        self.pending = None

    def _walk(self, times, axis, sign):
        one = (axis[:, None] == np.arange(3)).astype(np.int64)
        count = self.count + np.cumsum(one, axis=0)
        pos = self.pos + np.cumsum(one * sign[:, None].astype(np.int64), axis=0)
        self.count, self.pos = count[-1].copy(), pos[-1].copy()
        moment = np.flatnonzero(np.append(times[1:] != times[:-1], True))
        times, count, pos = times[moment], count[moment], pos[moment]
        lo = np.full(len(times), -1, np.int64)
        hi = np.full(len(times), self.far, np.int64)
        for i in range(3):
            if not len(self.index[i]):
                continue
            a_lo, a_hi = self._blocks_of(count[:, i], self.index[i], self.ends[i])
            lo = np.maximum(lo, a_lo)
            hi = np.minimum(hi, a_hi)
        stray = lo > hi
        fits = np.flatnonzero(~stray)
        if stray.any():
            if self.stray_at is None:
                bad = int(np.argmax(stray))
                self.stray_at = int(times[bad])
                self.stray_after = int(self.line_of[lo[fits[fits < bad][-1]]]) \
                    if (fits < bad).any() else self.last_line
            self.stray += int(stray.sum())
        if len(fits):
            self.last_line = int(self.line_of[lo[fits[-1]]])
        arc = np.where(stray, -1, self.block_arc[np.clip(lo, -1, self.far)])
        arc = np.where(arc < 0, np.where(stray, -1, self.block_arc[np.clip(hi, -1, self.far)]), arc)
        on = np.flatnonzero(arc >= 0)
        if len(on):
            self._check(times[on], pos[on], arc[on])

    def _blocks_of(self, k, index, ends):
        """The lines an axis with k steps done can be in: (lo, hi), the first and last."""
        j = np.searchsorted(ends, k)
        jj = np.minimum(j, len(ends) - 1)
        inside = (j < len(ends)) & (ends[jj] > k) & (k > 0)
        at_end = (j < len(ends)) & (ends[jj] == k)
        after = np.append(index[1:], self.far)
        lo = np.where(k == 0, -1, np.where(inside | at_end, index[jj], self.far))
        hi = np.where(k == 0, index[0], np.where(inside, index[jj],
                                                 np.where(at_end, after[jj], -1)))
        return lo, hi

    def _check(self, times, pos, arc):
        rows = np.arange(len(arc))
        ax = self.axes[arc]
        mm = (pos[rows[:, None], ax] + self.shift[arc]) / self.spm[arc]
        da = mm[:, 0] - self.centre[arc, 0]
        db = mm[:, 1] - self.centre[arc, 1]
        off = np.abs(np.hypot(da, db) - self.radius[arc]) / self.tolerance[arc]
        # Runs of one arc; an arc's positions are one run (a chunk may cut it in two).
        first = np.flatnonzero(np.append(True, arc[1:] != arc[:-1]))
        last = np.append(first[1:], len(arc)) - 1
        run = np.cumsum(np.isin(rows, first)) - 1
        k = arc[first]
        # The angle gone the arc's way, unwrapped position by position from the start
        # (or from its last position in the chunk before).
        raw = np.arctan2(db, da)
        prev = np.append(0.0, raw[:-1])
        prev[first] = np.where(self.seen[k], self.last_raw[k], self.start_angle[k])
        turn = _wrap(self.way[arc] * (raw - prev))
        total = np.cumsum(turn)
        base = np.where(self.seen[k], self.progress[k], 0.0) - (total - turn)[first]
        progress = total + base[run]
        lift = run * 1e5  # more than any sweep: keeps the running maximum within a run
        furthest = np.maximum(np.maximum.accumulate(progress + lift) - lift,
                              self.reached[arc])
        share = np.clip(progress / np.maximum(self.total[arc], 1e-12), 0, 1)
        c_off = np.abs(mm[:, 2] - (self.start_c[arc] + self.along[arc] * share))
        # The worst distance off in each run, and where.
        worst = np.maximum.reduceat(off, first)
        at = _first_where(off == worst[run], run, len(first))
        better = worst > self.worst[k]
        self.worst[k[better]] = worst[better]
        self.worst_t[k[better]] = times[at[better]]
        self.worst_mm[k[better]] = mm[at[better], :2]
        # Going the other way, back, past either end, or the third axis off.
        tol = self.turn_tolerance[arc]
        wrong = self.angles_count[arc] & ((furthest - progress > tol) | (progress < -tol)
                                          | (progress > self.total[arc] + tol))
        wrong |= c_off > self.c_tolerance[arc]
        at = _first_where(wrong, run, len(first))
        new = (at >= 0) & (self.fault_t[k] < 0)
        self.fault_t[k[new]] = times[at[new]]
        self.fault_turn[k[new]] = progress[at[new]]
        self.fault_c[k[new]] = c_off[at[new]]
        self.seen[k] = True
        self.last_raw[k] = raw[last]
        self.progress[k] = progress[last]
        self.reached[k] = furthest[last]

    def failures(self, unit_us):
        """A message for every arc the steps left, in order."""
        out = []
        for k in np.flatnonzero((self.worst > 1) | (self.fault_t >= 0) | (
                self.seen & self.angles_count
                & (self.reached < self.total - self.turn_tolerance))).tolist():
            line = self.arcs[k]["line"]
            names = "".join("XYZ"[a] for a in self.arcs[k]["axes"][:2])
            if self.worst[k] > 1:
                out.append("%s at (%.3f, %.3f) mm, %s, is %.3f mm off the arc of G-code "
                           "line %d (tolerance %.3f mm)" % (
                               names, self.worst_mm[k][0], self.worst_mm[k][1],
                               _at(self.worst_t[k], unit_us),
                               self.worst[k] * self.tolerance[k], line, self.tolerance[k]))
            elif self.fault_t[k] >= 0 and self.fault_c[k] > self.c_tolerance[k]:
                out.append("the arc of G-code line %d left its helix: %s %.3f mm off, %s" % (
                    line, "XYZ"[self.arcs[k]["axes"][2]], self.fault_c[k],
                    _at(self.fault_t[k], unit_us)))
            elif self.fault_t[k] >= 0:
                out.append("the arc of G-code line %d went another way round: at %.1f of "
                           "its %.1f degrees, %s" % (
                               line, math.degrees(self.fault_turn[k]),
                               math.degrees(self.total[k]), _at(self.fault_t[k], unit_us)))
            else:
                out.append("the arc of G-code line %d stopped at %.1f of its %.1f degrees"
                           % (line, math.degrees(self.reached[k]), math.degrees(self.total[k])))
        return out


def _first_where(mask, run, runs):
    """Per run, the index of the first True of mask in it, or -1."""
    at = np.full(runs, -1, np.int64)
    hits = np.flatnonzero(mask)
    found, first = np.unique(run[hits], return_index=True)
    at[found] = hits[first]
    return at


def _wrap(angle):
    """An angle in radians to [-pi, pi)."""
    return (angle + math.pi) % (2 * math.pi) - math.pi


def check(trace_path, gcode_path, board="sim", mapping=None, step_pulse_us=None,
          dir_setup_us=None, rate_margin=0.02, window=100, mix_tolerance=2.0,
          chunk_bytes=CHUNK_BYTES, settings=None, config=None):
    """Check a trace (VCD or sigrok .sr) against a G-code file. settings: board
    settings to override ({key: value}, as `mixstep serve --set`), e.g. retract_policy
    or transition_l1_mm; config: the configuration file the printer started with
    (saved by M500), under them. Returns the report: {"ok": bool, "checks": [{name, expected,
    measured, ok, detail}], ...}. Raises TraceError for input that cannot be read."""
    pins = paths.load_board(board)["PINS"]
    overrides = settings or {}
    settings = board_settings(board, overrides, config)
    expected = expected_from_gcode(gcode_path, settings)
    names = [n for n in pins if n.endswith(("_step", "_dir"))]
    tmp = None
    path = str(trace_path)
    if path.endswith(".sr"):
        tmp = tempfile.TemporaryDirectory(prefix="mixstep-trace-")
        vcd_path = os.path.join(tmp.name, "capture.vcd")
        sigrok_to_vcd(path, vcd_path)
        path = vcd_path
    wall0 = time.perf_counter()
    try:
        reader = VcdReader(path, names, mapping, chunk_bytes)
        checker = Checker(reader.signals, settings, expected, window, mix_tolerance,
                          reader.timescale_s * 1e6)
        for times, sig, vals in reader.chunks():
            checker.feed(times, sig, vals)
        if checker.path:
            checker.path.finish()
        reader.close()
    finally:
        if tmp:
            tmp.cleanup()
    wall = time.perf_counter() - wall0
    unit_us = reader.timescale_s * 1e6
    pulse_us = settings.get("step_pulse_us", 0) if step_pulse_us is None else step_pulse_us
    setup_us = settings.get("dir_setup_us", 0) if dir_setup_us is None else dir_setup_us
    checks = _report_checks(checker, settings, expected, unit_us, pulse_us, setup_us,
                            rate_margin, window, mix_tolerance)
    return {
        "ok": all(c["ok"] is not False for c in checks),
        "trace": str(trace_path),
        "gcode": str(gcode_path),
        "board": board,
        "config": str(config) if config else None,
        "settings": {k: overrides[k] for k in sorted(overrides)},
        "signals": reader.signals,
        "timescale_us": unit_us,
        "missing_signals": checker.missing,
        "unmodelled": expected["unmodelled"],
        "refused_lines": len(expected["refused"]),
        "checks": checks,
        "input": {"bytes": reader.bytes_read, "lines": reader.lines,
                  "seconds": round(wall, 3)},
    }


def _report_checks(ck, settings, expected, unit_us, pulse_us, setup_us, rate_margin,
                   window, mix_tolerance):
    checks = []

    def add(name, want, got, ok, detail=""):
        checks.append({"name": name, "expected": want, "measured": got, "ok": ok,
                       "detail": detail})

    for name, want in expected["steps"].items():
        ax = ck.axes.get(name)
        absent = [n for n in ck.missing if n.rsplit("_", 1)[0] == name]
        if absent:
            add("steps_" + name, want, None, False, "the G-code moves %s, but %s %s not in "
                "the trace" % (name, " and ".join(absent), "are" if len(absent) > 1 else "is"))
        elif ax is None:
            add("steps_" + name, want, None, None, "not in the trace (the G-code does not "
                "move it)")
        else:
            add("steps_" + name, want, ax.net, ax.net == want,
                "%d rising edges" % ax.rises)
    walk = ck.walk
    if walk is None and ck.advance is None:
        add("moves", len(expected["moves"]), None, None, "not checked: a drive that moves "
            "is not in the trace")
    elif walk is not None:
        done = walk.m + 1 if walk.finished() else walk.m
        add("moves", len(expected["moves"]), done, walk.finished(),
            walk.error or ("" if walk.finished() else "the trace ends inside the E move of "
                           "G-code line %d" % walk.moves[walk.m][0]))
        add("mix", "<= %g steps off" % mix_tolerance, round(walk.worst, 3),
            walk.bad_windows == 0,
            "%d windows of %d drive steps, %d over; worst %s" % (
                walk.windows, window, walk.bad_windows,
                "e%d at %s" % (walk.worst_at[1], _at(walk.worst_at[0], unit_us))
                if walk.worst_at else "-"))

    adv = ck.advance
    if adv is not None:
        done = min(adv.i, len(adv.blocks))
        add("moves", len(expected["moves"]), None, adv.finished(),
            adv.error or ("%d blocks followed with X Y Z, every E move ended exactly "
                          "where the G-code puts it" % done if adv.finished() else
                          "the trace ends in the block of G-code line %d (drives at %s, "
                          "target %s)" % (adv.blocks[min(adv.i, len(adv.blocks) - 1)][0],
                                          adv.pos, adv.target)))
        detail = "%d block ends, the most %d steps ahead" % (adv.ends, adv.most_steps)
        if adv.worst_at:
            t, line, want, got = adv.worst_at
            detail += "; worst %d steps where K v is %.1f, at %s (G-code line %d)" % (
                got, want, _at(t, unit_us), line)
        add("advance", "within %d%% + %d steps of K v" % (100 * adv.TOLERANCE,
                                                        adv.STEP_SLACK),
            "%.0f%% of that" % (100 * adv.worst), adv.worst <= 1, detail)
        add("mix", "<= %g steps off" % mix_tolerance, None, None,
            "not checked with pressure advance: the drives step back and forth")

    path = ck.path
    if path is not None:
        failures = path.failures(unit_us)
        if path.stray:
            failures.insert(0, "%d moments of X Y Z steps fit no line of the G-code, the "
                            "first at %s, after G-code line %d" % (
                                path.stray, _at(path.stray_at, unit_us), path.stray_after))
        add("arc_path", "%d arcs within a segment's sagitta + %g steps"
            % (len(path.arcs), _ArcPath.STEP_SLACK), len(failures), not failures,
            "; ".join(failures[:3]) + ("; ..." if len(failures) > 3 else "") if failures
            else "worst %.0f%% of its tolerance" % (100 * path.worst.max() if len(path.arcs)
                                                    else 0))
    elif expected.get("arcs"):
        add("arc_path", "%d arcs" % len(expected["arcs"]), None, None,
            "not checked: an axis that moves is not in the trace")

    def worst(field):
        best = None
        for ax in ck.axes.values():
            v = getattr(ax, "min_" + field)
            if v is not None and (best is None or v < best[0]):
                best = (v, ax.name, getattr(ax, "at_" + field))
        return best

    for field, name, limit in (("high", "pulse_high_us", pulse_us), ("low", "step_low_us", pulse_us),
                               ("setup", "dir_setup_us", setup_us)):
        w = worst(field)
        if w is None:
            add(name, ">= %g" % limit, None, None, "no edges measured")
        else:
            us = w[0] * unit_us
            add(name, ">= %g" % limit, round(us, 6), us >= limit - 1e-9,
                "%s at %s" % (w[1], _at(w[2], unit_us)))
    tick_us = settings.get("tick_us", 0)
    for name, ax in ck.axes.items():
        if ax.min_run is None:
            continue
        i = min(list(AXES).index(name) if name in AXES else 3, 3)
        limit = settings["max_feed_mm_s"][i] * settings["steps_per_mm"][i] * (1 + rate_margin)
        rate = RATE_RUN / ((ax.min_run * unit_us + 2 * tick_us) * 1e-6)
        add("rate_" + name, "<= %.0f steps/s" % limit, round(rate, 1), rate <= limit,
            "fastest %d steps at %s" % (RATE_RUN, _at(ax.at_run, unit_us)))
    return checks


def _at(time_units, unit_us):
    """A trace time for messages, in us whatever the timescale (so a capture at 1 ns
    and one at 1 us of the same steps read alike), exact to the nanosecond."""
    return "t=%s us" % ("%.3f" % (time_units * unit_us)).rstrip("0").rstrip(".")


def format_report(report):
    lines = ["trace %s against %s (board %s)" % (report["trace"], report["gcode"], report["board"])]
    for c in report["checks"]:
        status = {True: "pass", False: "FAIL", None: "skip"}[c["ok"]]
        lines.append("  %-4s %-15s expected %-22s measured %-12s %s" % (
            status, c["name"], c["expected"], c["measured"], c["detail"]))
    for cmd, line in sorted(report["unmodelled"].items()):
        lines.append("  note: %s (first at line %d) is not modelled; counts may differ"
                     % (cmd, line))
    if report.get("refused_lines"):
        lines.append("  note: %d lines the firmware refuses (bad words, checksums, limits) "
                     "are not run" % report["refused_lines"])
    if report["missing_signals"]:
        lines.append("FAILED: the G-code moves what the trace does not show: %s missing"
                     % ", ".join(report["missing_signals"]))
    else:
        lines.append("OK: the trace does what the G-code asks" if report["ok"] else
                     "FAILED: the trace disagrees with the G-code")
    return "\n".join(lines)


def parse_map(text):
    """'x_step=D0,x_dir=D1' -> {'x_step': 'D0', 'x_dir': 'D1'}."""
    mapping = {}
    for item in (text or "").split(","):
        if item.strip():
            name, sep, channel = item.partition("=")
            if not sep:
                raise TraceError("--map wants name=channel, got %r" % item)
            mapping[name.strip()] = channel.strip()
    return mapping


def add_parser(sub):
    p = sub.add_parser("check", help="check a trace (VCD or sigrok .sr) against G-code")
    p.add_argument("trace", help="VCD file, or sigrok .sr capture")
    p.add_argument("--gcode", required=True, help="the G-code the trace should show")
    p.add_argument("--board", default="sim", help="board whose pins and settings apply")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="a board setting the printer ran with, as `mixstep serve --set`, "
                        "e.g. retract_policy=2 or transition_l1_mm=1.5 (repeatable); "
                        "over --config")
    p.add_argument("--config", metavar="FILE",
                   help="the configuration the printer started with, as M500 saved it "
                        "(a board's /mixstep.cfg; `mixstep serve` and `sim`: "
                        "out/printer/mixstep.cfg by default)")
    p.add_argument("--json", metavar="OUT", help="write the report as JSON here ('-': stdout)")
    p.add_argument("--map", metavar="NAME=CHANNEL,...",
                   help="VCD names of signals, e.g. x_step=D0,x_dir=D1")
    p.add_argument("--step-pulse-us", type=float, help="minimum STEP high/low time "
                   "(default: the board's step_pulse_us)")
    p.add_argument("--dir-setup-us", type=float, help="minimum DIR-to-STEP time "
                   "(default: the board's dir_setup_us)")
    p.add_argument("--rate-margin", type=float, default=0.02,
                   help="allowed fraction over the axis's maximum step rate")
    p.add_argument("--window", type=int, default=100, help="drive steps per mix window")
    p.add_argument("--mix-tolerance", type=float, default=2.0,
                   help="allowed steps off a drive's share in a mix window")
    p.set_defaults(run=_run)


def _run(args):
    overrides = {}
    for item in args.set:
        key, sep, value = item.partition("=")
        if not sep or not key:
            print("mixstep trace check: --set wants KEY=VALUE, got %r" % item, file=sys.stderr)
            return 2
        overrides[key] = value
    try:
        report = check(args.trace, args.gcode, args.board, parse_map(args.map),
                       args.step_pulse_us, args.dir_setup_us, args.rate_margin, args.window,
                       args.mix_tolerance, settings=overrides, config=args.config)
    except TraceError as e:
        print("mixstep trace check: %s" % e, file=sys.stderr)
        return 2
    except OSError as e:
        print("mixstep trace check: %s" % e, file=sys.stderr)
        return 2
    text = json.dumps(report, indent=2) + "\n"
    if args.json == "-":
        sys.stdout.write(text)
    else:
        print(format_report(report))
        if args.json:
            with open(args.json, "w") as f:
                f.write(text)
    return 0 if report["ok"] else 1
