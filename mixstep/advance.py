"""`mixstep advance`: move every tool change earlier by the purge amount.

A mixing hot end still holds the old mix when a tool change reaches it: what comes out
of the nozzle changes only after some millimetres of filament (the purge amount of mixing-extruder practice,
or Ovenbird's L0 = L1 + L2/2 with delay L1 and transition L2). Moving each
`T<n>` that much extrusion earlier puts the colour boundary where the slicer drew it,
without a wipe tower.

What counts as extrusion
    Only positive E on printing moves, in mm of filament: G0/G1/G2/G3 moves that move
    X, Y or Z, whatever came before them. Not counted: travel; retraction (negative E);
    E-only moves (unretraction, priming); anything between PrusaSlicer's `;WIPE_START`
    and `;WIPE_END` (its wipes retract). This is the firmware's rule for its own
    transitions (firmware/mixfw/transition.py), so a file advanced here and the same
    file printed with transitions change colour at the same filament: a retraction
    that straddles a tool change (T0 retracts, T1 unretracts) moves no change, as the
    filament it pulls back is pushed out again before anything prints.

Where a change goes
    A change found after S mm of printing extrusion, purging P mm, goes to S - P: into
    the printing move that crosses that point, which is split there exactly (X, Y, Z
    and E interpolated, along the arc for G2/G3 with the same centre, E and Z linear in
    the angle). The first half carries the line's own F if it had one, the second half
    none: the T line in between does not change the modal feed, so both halves run at
    the line's feed rate. When S - P falls exactly at the end of a printing move, the
    change goes right after that move.

    Changes are never reordered: a change is never placed before an earlier one. With
    one purge amount, closely spaced changes (closer than P) all move by P and keep
    their spacing (measured from the previous change's *original* place, they would
    bunch up). With a purge matrix, a change whose pair needs more than the gap to the
    previous change is held just behind the previous one, with a warning; so is a
    change near the start of the print, where less than P mm was extruded before it
    (behind the initial selection), as the firmware's transition reaches back over
    every move queued since, a retraction or priming among them.
    The first `T` before any printing is the initial selection and stays where it is.
    A `T` that selects the tool already in use moves with the same purge as the change
    before it, so it can never re-select a stale tool.

Conventions handled
    The file is read by `mixstep.gcodeio`, which keeps the modal state as the firmware
    does: M82/M83 and G90/G91 (G90/G91 set E too), `G92` (with or without axes), `G28`,
    F-only lines, comments, CR/LF endings. PrusaSlicer (`T<n>` then `G92 E0`;
    `;WIPE_START`/`;WIPE_END`), Slic3r 1.3 (`G92 E0` around the change, wipes as
    retracting moves) and Cura (`;LAYER:n`, absolute E, a switch retraction of 16 mm
    before `T<n>`, paid back E-only when the tool returns) need nothing special beyond
    these rules. A split line is written with one space between words, whatever the
    spacing or case it was read with.

Output
    Every line that is not moved or split comes out byte for byte. A moved `T` line is
    the original line, moved. New numbers are written with 4 decimals for X Y Z I J and
    5 for E (an error below 5e-6 mm of filament).

Memory
    The file is streamed. A line can be written once no later change can land before
    it, i.e. once it lies more than the largest purge amount of extrusion behind the
    line being read. So memory is bounded by the lines within one purge length of
    extrusion (plus the non-printing lines among them), not by the file. Should a
    stretch without extrusion exceed `max_buffer_lines` lines, the oldest lines are
    written anyway and a change that would have needed them advances less, with a
    warning.

Purge matrix file (`--purge-matrix FILE`)
    One rule per line, `#` or `;` starts a comment::

        default 2.5        # any pair not listed
        0 1 2.0            # from T0 to T1: 2.0 mm
        T1 T0 3.0          # the T is optional
        * 2 4.0            # from any tool to T2
        2 * 1.5            # from T2 to any tool

    An exact pair wins over `from *`, which wins over `* to`, which wins over
    `default`. A pair that matches no rule is an error.
"""
import json
import math
import sys
from collections import deque

from mixstep import gcodeio
from mixstep.outfile import refuse_input, replacing

_SNAP_MM = 5e-6     # a split closer than this to a move's end is not worth a new line
_DEFAULT_MAX_BUFFER_LINES = 200000


class PurgeMatrix:
    """Purge amount per (from tool, to tool) pair, read from the text format above."""

    def __init__(self, text):
        self.pairs = {}
        self.default = None
        for n, raw in enumerate(text.splitlines(), 1):
            line = raw.split("#")[0].split(";")[0].strip()
            if not line:
                continue
            words = line.split()
            try:
                if words[0].lower() == "default" and len(words) == 2:
                    self.default = self._mm(words[1])
                elif len(words) == 3:
                    self.pairs[(self._tool(words[0]), self._tool(words[1]))] = self._mm(words[2])
                else:
                    raise ValueError("expected 'FROM TO MM' or 'default MM'")
            except ValueError as err:
                raise ValueError("purge matrix line %d (%r): %s" % (n, raw.strip(), err))
        values = list(self.pairs.values()) + ([self.default] if self.default is not None else [])
        if not values:
            raise ValueError("purge matrix has no rules")
        self.max_mm = max(values)

    @staticmethod
    def _tool(word):
        if word == "*":
            return "*"
        t = int(word[1:] if word[:1] in "Tt" else word)
        if t < 0:
            raise ValueError("tool %d is negative" % t)
        return t

    @staticmethod
    def _mm(word):
        v = float(word)
        if not (v >= 0 and math.isfinite(v)):
            raise ValueError("purge %r mm must be a finite number >= 0" % word)
        return v

    @classmethod
    def from_file(cls, path):
        with open(path) as f:
            return cls(f.read())

    def __call__(self, from_tool, to_tool):
        for key in ((from_tool, to_tool), (from_tool, "*"), ("*", to_tool)):
            if key in self.pairs:
                return self.pairs[key]
        if self.default is None:
            raise ValueError("purge matrix has no rule for T%s -> T%s and no default"
                             % (from_tool, to_tool))
        return self.default


def l0_mm(l1_mm, l2_mm):
    """Ovenbird's advancement length: the delay plus half the transition."""
    if l1_mm < 0 or l2_mm < 0:
        raise ValueError("lengths must be >= 0 mm, got L1 %g, L2 %g" % (l1_mm, l2_mm))
    return l1_mm + l2_mm / 2.0


class _Change:
    """A T line in the buffer, and its report record."""
    __slots__ = ("text", "rec")

    def __init__(self, text, rec):
        self.text = text
        self.rec = rec


def _fmt(v, places):
    s = "%.*f" % (places, v)
    if "." in s:
        s = s.rstrip("0").rstrip(".")
    if s in ("-0", ""):
        s = "0"
    return s


def _split_code(line):
    """(code, rest) where rest is the comment and line ending, kept verbatim."""
    semi = line.find(";")
    if semi < 0:
        code = line.rstrip("\r\n")
    else:
        code = line[:semi]
    rest = line[len(code):]
    stripped = code.rstrip()
    return stripped, code[len(stripped):] + rest


def _split_move(ent, t_mm):
    """Split a buffered printing move at printing extrusion t_mm.

    Returns (first_text, point, e_first, second_entry) or None when it can't be split
    (an arc with P turns)."""
    s_end, line, s_start, start, code, words, flags, lineno = ent
    rel_xyz, rel_e = flags & 1, flags & 2
    if "P" in words and code in gcodeio.ARCS:
        return None
    _, rest = _split_code(line)
    nl = "\r\n" if line.endswith("\r\n") else "\n"
    x0, y0, z0, e0 = start
    (x1, y1, z1, _), de = gcodeio.move_end(start, words, rel_xyz, rel_e)
    e_first = round(t_mm - s_start, 5)
    if not rel_e:   # the E word written is rounded: measure the split from it
        e_first = round(e0 + e_first, 5) - e0
    f = e_first / de
    arc = code in gcodeio.ARCS
    if arc:
        cx, cy, r0, a0, sweep = gcodeio.arc(start, (x1, y1), words, code == "G2")
        a_mid = a0 + f * sweep
        xm, ym = cx + r0 * math.cos(a_mid), cy + r0 * math.sin(a_mid)
    else:
        xm, ym = x0 + f * (x1 - x0), y0 + f * (y1 - y0)
    zm = z0 + f * (z1 - z0)
    xm, ym, zm = round(xm, 4), round(ym, 4), round(zm, 4)

    def axis(letter, v_mid, v0, v1, first):
        if rel_xyz:
            return _fmt(v_mid - v0 if first else v1 - v_mid, 4)
        return _fmt(v_mid, 4) if first else words[letter]

    first = [code]
    second = {}
    mids = {"X": (xm, x0, x1), "Y": (ym, y0, y1), "Z": (zm, z0, z1)}
    for letter in ("X", "Y", "Z"):
        if letter in words or (arc and letter != "Z"):
            first.append(letter + axis(letter, *mids[letter], True))
    if arc:
        if "R" in words:
            first.append("I" + _fmt(cx - x0, 4))
            first.append("J" + _fmt(cy - y0, 4))
        else:
            first.extend(k + words[k] for k in ("I", "J") if k in words)
    first.append("E" + _fmt(e_first if rel_e else e0 + e_first, 5))
    if "F" in words:
        first.append("F" + words["F"])
    for letter, value in words.items():
        if letter in "XYZ":
            second[letter] = axis(letter, *mids[letter], False)
        elif letter == "E":
            second["E"] = _fmt(de - e_first, 5) if rel_e else value
        elif letter not in "IJRF":
            second[letter] = value
    if arc:
        if "X" not in words:
            second["X"] = _fmt(x1 if not rel_xyz else x1 - xm, 4)
        if "Y" not in words:
            second["Y"] = _fmt(y1 if not rel_xyz else y1 - ym, 4)
        second["I"] = _fmt(cx - xm, 4)
        second["J"] = _fmt(cy - ym, 4)
    s_mid = s_start + e_first
    second_text = " ".join([code] + [k + v for k, v in second.items()]) + rest
    second_ent = (s_end, second_text, s_mid, (xm, ym, zm, e0 + e_first), code, second,
                  flags, lineno)
    return " ".join(first) + nl, (xm, ym, zm), s_mid, second_ent


class _Advancer:
    def __init__(self, write, purge_for, max_purge_mm, max_buffer_lines, on_record=None):
        self.write = write
        # on_record(kind, record): changes as they are written, and warnings, handed
        # over instead of kept, so memory stays bounded however long the file.
        self.on_record = on_record
        self.purge_for = purge_for
        self.max_purge_mm = max_purge_mm
        self.max_buffer_lines = max_buffer_lines
        self.buf = deque()
        self.out_lines = 0
        self.forced_flush = False
        self.max_buffered = 0
        self.changes = []
        self.warnings = []

    def flush_to(self, limit_s):
        buf = self.buf
        write = self.write
        n = self.out_lines
        while buf and buf[0][0] < limit_s:
            p = buf.popleft()[1]
            n += 1
            if p.__class__ is str:
                write(p)
            else:
                self._write_change(p, n)
        self.out_lines = n

    def _write_change(self, change, out_line):
        change.rec["out_line"] = out_line
        self.write(change.text)
        if self.on_record and "placed" in change.rec:
            self.on_record("change", change.rec)

    def _warn(self, warning):
        if self.on_record:
            self.on_record("warning", warning)
        else:
            self.warnings.append(warning)

    def flush_all(self):
        self.flush_to(math.inf)

    def force_flush(self):
        """Keep memory bounded through long stretches without extrusion."""
        buf = self.buf
        while len(buf) > self.max_buffer_lines:
            self.forced_flush = True
            self.flush_to(buf[0][0] + 1e-12)
            if len(buf) > self.max_buffer_lines:   # many lines at the same extrusion
                p = buf.popleft()[1]
                self.out_lines += 1
                if p.__class__ is str:
                    self.write(p)
                else:
                    self._write_change(p, self.out_lines)

    def place(self, text, lineno, s_mm, from_tool, to_tool, purge_mm):
        """Put a T line purge_mm of printing extrusion before s_mm (see the module doc)."""
        if not text.endswith("\n"):
            text += "\n"
        buf = self.buf
        t = s_mm - purge_mm
        rec = {"line": lineno, "text": text.rstrip("\r\n"), "from": from_tool,
               "to": to_tool, "purge_mm": purge_mm}
        change = _Change(text, rec)
        cand = None
        stop = "front"
        i = len(buf) - 1
        if purge_mm > 0:
            while i >= 0:
                ent = buf[i]
                if len(ent) == 8:    # a printing move
                    if ent[0] < t - _SNAP_MM:
                        stop = None
                        break
                    cand = i
                elif ent[1].__class__ is _Change:
                    stop = "initial" if "initial" in ent[1].rec else ent[1].rec["line"]
                    break
                i -= 1
        split = None
        if stop not in (None, "front") and (cand is None or buf[cand][2] >= t - _SNAP_MM):
            # Too little printing extrusion since the previous change: right behind it,
            # as far back as the firmware's transition reaches (over every move queued
            # since, retractions included).
            new_s = buf[i][0]
            buf.insert(i + 1, (new_s, change))
            how = "after the change at line %s" % buf[i][1].rec["line"]
        elif cand is None:
            new_s = s_mm
            buf.append((new_s, change))
            how = "in place"
        else:
            ent = buf[cand]
            if ent[0] <= t + _SNAP_MM:
                new_s = ent[0]
                buf.insert(cand + 1, (new_s, change))
                how = "after line %d" % ent[7]
            elif ent[2] >= t - _SNAP_MM:
                new_s = ent[2]
                buf.insert(cand, (new_s, change))
                how = "before line %d" % ent[7]
            else:
                split = _split_move(ent, t)
                if split is None:   # an arc with P turns: go after it
                    new_s = ent[0]
                    buf.insert(cand + 1, (new_s, change))
                    how = "after line %d (arc with P not split)" % ent[7]
                else:
                    first_text, point, new_s, second = split
                    buf[cand] = second
                    buf.insert(cand, (new_s, change))
                    buf.insert(cand, (new_s, first_text))
                    how = "splits line %d" % ent[7]
                    rec["split_line"] = ent[7]
                    rec["split_point"] = list(point)
        rec["placed"] = how
        rec["s_mm"] = round(s_mm, 6)
        rec["new_s_mm"] = round(new_s, 6)
        rec["advanced_mm"] = round(s_mm - new_s, 6)
        if not self.on_record:
            self.changes.append(rec)
        short = purge_mm - (s_mm - new_s)
        if short > 1e-4:
            if isinstance(stop, int):
                why = "held behind the change at line %d, which is closer than the purge" % stop
            elif self.forced_flush:
                why = "the earlier lines were already written (max_buffer_lines)"
            else:
                why = "not enough printing extrusion before it"
            self._warn({"line": lineno, "message": "%s advanced %.5f of %.5f mm: %s"
                        % (rec["text"], s_mm - new_s, purge_mm, why)})
            rec["short_mm"] = round(short, 6)
        return rec


def advance(lines_in, write, purge_for, max_purge_mm=None,
            max_buffer_lines=_DEFAULT_MAX_BUFFER_LINES, on_record=None):
    """Stream G-code lines from lines_in to write(), every tool change moved earlier.

    purge_for is a number (mm) or a callable (from_tool, to_tool) -> mm; a callable
    needs max_purge_mm or a max_mm attribute (PurgeMatrix has one), which bounds the
    lines held back. Returns the report: changes (each with its input line, where it
    went, mm advanced), warnings, lines in and out, the most lines held at once. With
    on_record(kind, record), kind "change" or "warning", each is handed over as it is
    made instead, and the report's lists stay empty: memory is then bounded by the
    lines held back alone, whatever the file's length."""
    if not callable(purge_for):
        constant = float(purge_for)
        if not (constant >= 0 and math.isfinite(constant)):
            raise ValueError("purge must be a finite number >= 0, not %r" % purge_for)
        purge_for = lambda a, b: constant  # noqa: E731
        max_purge_mm = constant
    if max_purge_mm is None:
        max_purge_mm = getattr(purge_for, "max_mm", None)
    if max_purge_mm is None:
        raise ValueError("a purge function needs max_purge_mm")
    adv = _Advancer(write, purge_for, max_purge_mm, max_buffer_lines, on_record)
    buf = adv.buf
    append = buf.append
    flush_to = adv.flush_to
    reader = gcodeio.Reader(lines_in)
    s = 0.0                     # printing extrusion so far, mm
    tool = None                 # the input's tool (the slicer's view)
    last_purge = None
    n = 0
    limit = -math.inf
    cap = max_buffer_lines
    for n, line, code, words, start, _, de, printing, _, error in reader.tuples():
        if de > 0 and printing and not reader.wipe:
            s0 = s
            s += de
            append((s, line, s0, start, code, words,
                    (1 if reader.rel_xyz else 0) | (2 if reader.rel_e else 0), n))
            limit = s - max_purge_mm - 2 * _SNAP_MM
            if buf[0][0] < limit:
                flush_to(limit)
            continue
        if not de and code[:1] == "T" and code[1:].isdigit():
            new_tool = int(code[1:])
            if tool is None and s == 0.0:
                tool = new_tool
                append((s, _Change(line, {"line": n, "initial": True})))
                continue
            from_tool = 0 if tool is None else tool
            if new_tool == from_tool and last_purge is not None:
                purge = last_purge
            else:
                purge = float(purge_for(from_tool, new_tool))
            if purge > max_purge_mm + 1e-9:
                raise ValueError("purge %g mm for T%d -> T%d exceeds max_purge_mm %g"
                                 % (purge, from_tool, new_tool, max_purge_mm))
            last_purge = purge
            adv.place(line, n, s, from_tool, new_tool, purge)
            tool = new_tool
            if len(buf) > adv.max_buffered:
                adv.max_buffered = len(buf)
            continue
        elif error is not None:
            adv._warn({"line": n, "message": "could not read: " + line.strip()})
        append((s, line))
        if len(buf) > cap:
            adv.force_flush()
            if len(buf) > adv.max_buffered:
                adv.max_buffered = len(buf)
        elif (n & 1023) == 0 and len(buf) > adv.max_buffered:
            adv.max_buffered = len(buf)
    if len(buf) > adv.max_buffered:
        adv.max_buffered = len(buf)
    adv.flush_all()
    return {"lines_in": n, "lines_out": adv.out_lines, "extrusion_mm": round(s, 6),
            "max_purge_mm": max_purge_mm, "max_buffered_lines": adv.max_buffered,
            "changes": adv.changes, "warnings": adv.warnings}


def advance_file(in_path, out_path, purge_for, max_purge_mm=None,
                 max_buffer_lines=_DEFAULT_MAX_BUFFER_LINES, on_record=None):
    """advance() from one file to another; lines are kept byte for byte. The output
    is written whole or not at all, and never over the input."""
    refuse_input(out_path, in_path)
    with open(in_path, newline="", encoding="utf-8", errors="surrogateescape") as fin, \
            replacing(out_path, "w", newline="", encoding="utf-8", errors="surrogateescape",
                      buffering=1 << 20) as fout:
        return advance(fin, fout.write, purge_for, max_purge_mm, max_buffer_lines, on_record)


def add_parser(sub):
    """Register `mixstep advance` on the command's subparsers."""
    p = sub.add_parser("advance", help="move every tool change earlier by the purge amount")
    p.set_defaults(run=main)
    p.add_argument("gcode", help="input G-code")
    p.add_argument("-o", "--output", required=True, help="write the advanced G-code here")
    g = p.add_mutually_exclusive_group(required=True)
    g.add_argument("--purge-mm", type=float, help="purge amount, mm of filament")
    g.add_argument("--l1-mm", type=float, help="delay length L1 (with --l2-mm): purge L1 + L2/2")
    g.add_argument("--purge-matrix", metavar="FILE",
                   help="purge amount per tool pair (format: pydoc mixstep.advance)")
    p.add_argument("--l2-mm", type=float, help="transition length L2 (with --l1-mm)")
    p.add_argument("--report", metavar="FILE",
                   help="write the report here as JSON lines: each change and warning, then "
                        "a summary ('-': stdout)")
    p.add_argument("--max-buffer-lines", type=int, default=_DEFAULT_MAX_BUFFER_LINES,
                   help="most lines held back at once (default %(default)s)")


def main(args):
    if args.l1_mm is not None:
        if args.l2_mm is None:
            print("mixstep advance: --l1-mm needs --l2-mm", file=sys.stderr)
            return 2
        purge = l0_mm(args.l1_mm, args.l2_mm)
    elif args.l2_mm is not None:
        print("mixstep advance: --l2-mm needs --l1-mm", file=sys.stderr)
        return 2
    elif args.purge_matrix:
        purge = PurgeMatrix.from_file(args.purge_matrix)
    else:
        purge = args.purge_mm
    # Changes and warnings are printed as they are made, and the JSON report (one
    # record per line, then a summary line) is written as it goes: the command's
    # memory does not grow with the file.
    refuse_input(args.report, args.gcode, args.output, what="report")
    report_file = None
    if args.report == "-":
        report_file = sys.stdout
    elif args.report:
        report_file = open(args.report, "w")

    def on_record(kind, rec):
        if kind == "change":
            print("line %d %s: %s, advanced %.5f mm (purge %.5f), output line %d" % (
                rec["line"], rec["text"], rec["placed"], rec["advanced_mm"], rec["purge_mm"],
                rec.get("out_line", 0)), file=sys.stderr)
        else:
            print("warning: line %d: %s" % (rec["line"], rec["message"]), file=sys.stderr)
        if report_file:
            report_file.write(json.dumps(dict(rec, kind=kind)) + "\n")

    try:
        summary = advance_file(args.gcode, args.output, purge,
                               max_buffer_lines=args.max_buffer_lines, on_record=on_record)
    except ValueError as err:
        print("mixstep advance: %s" % err, file=sys.stderr)
        return 2
    finally:
        if report_file and report_file is not sys.stdout:
            report_file.close()
    if report_file:
        summary = {k: v for k, v in summary.items() if k not in ("changes", "warnings")}
        line = json.dumps(dict(summary, kind="summary")) + "\n"
        if report_file is sys.stdout:
            sys.stdout.write(line)
        else:
            with open(args.report, "a") as f:
                f.write(line)
    return 0
