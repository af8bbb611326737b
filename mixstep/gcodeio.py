"""Reading G-code on the host: one streaming reader that keeps the modal state.

Every host tool that reads G-code (advance, detool, preview, trace checks) reads it
through `Reader`, so the modal rules exist once and follow the firmware's (see docs/G-Codes.md,
"G-code"):

    from mixstep import gcodeio

    with open(path, newline="") as f:        # or open(path, "rb"): raw stays bytes
        reader = gcodeio.Reader(f)
        for ln in reader:
            if ln.code in gcodeio.MOVES and ln.printing:
                x0, y0, z0, e0 = ln.start
                x1, y1, z1, e1 = ln.end
                ... ln.de_mm, ln.tool, reader.layer, reader.feature, reader.wipe
            elif ln.code == "M163":
                drive, weight = int(ln.words["S"]), float(ln.words["P"])
            out.write(ln.raw)                 # the line exactly as read

It streams: constant memory, one `Line` per input line, in order. `reader.tuples()`
gives the same as plain tuples, for hot loops that unpack every line (advance).

`Line` (a named tuple, fields in this order)
    lineno    1 for the first line.
    raw       the line as read, str or bytes, line ending included: writing it back
              copies the line byte for byte.
    code      the command, upper case and without leading zeros: "G1", "M163", "T2",
              "G29.1"; "" for a line without one (blank, comment, unreadable). A leading
              `N<n>` line number and a `*<checksum>` are skipped.
    words     {letter: value text} of the command's other words, upper case letters,
              in the line's order: `G1 X10 E.5 F1800` gives {"X": "10", "E": ".5",
              "F": "1800"}; a bare letter gives "" (`G28 X`); M567's `E0.5:0.5` stays
              "0.5:0.5". Read only: lines without words share one empty mapping.
              Commands whose argument is text (M23, M28, M30, M32, M117, M118) have
              no words.
    start     (x, y, z, e) before the line and
    end       (x, y, z, e) after it: absolute (G91/M83 resolved), in the frame the
              G-code sees, i.e. after G92 offsets; the numbers an absolute-mode line
              would write. `end` is `start` (the same tuple) when the line moves
              nothing. The machine's own position is `end` plus `reader.offset`.
    de_mm     E delta of a move in mm of filament (G0-G3 only; 0.0 for other lines:
              `G92 E` sets E without feeding).
    printing  True for a move with positive E that moves X, Y or Z, and for every arc
              with positive E (a full circle starts and ends at the same point).
              Retractions, unretractions and E-only primes are not printing.
    tool      the active tool after the line (None before the first `T<n>`).
    error     None, or why the command could not be read (a move or G92 with a word
              that is not a number): the line then changes nothing and has no code.

Modal state, readable on the reader while iterating (as after the latest line):
    rel_xyz, rel_e   G91/G90 set both (as Marlin and this firmware do), M83/M82 only E.
    offset           (x, y, z, e) to add to a position to get the machine's: G92 moves
                     it, G28 zeroes it on the homed axes. offset[3] + end[3] is the
                     net filament fed since the start.
    tool             as Line.tool.
    feed_mm_min      the modal F (None before the first).
    layer            None before the first layer marker; PrusaSlicer's `;LAYER_CHANGE`
                     counts from 0, Cura's `;LAYER:n` sets n.
    feature          the text after the latest `;TYPE:` (PrusaSlicer "External
                     perimeter", Cura "WALL-OUTER"), None before one.
    wipe             True between PrusaSlicer's `;WIPE_START` and `;WIPE_END`.
Markers count only at the start of a line.

Other rules, as the firmware's: G92 with no axes zeroes all four; G28 with no axes homes
X, Y and Z to 0. Mixing commands (M163, M164, M165, M166, M167, M168, M169, M567) and
T are not interpreted beyond `tool`: they are there as codes and words.

Single lines: `parse(line)` gives (code, words) of one line without any state, and
`tool_of(code)` the tool a code selects, for tools that skip most lines unread (detool
looks only at lines with a T in them).

Moves: `move_end(start, words, rel_xyz, rel_e)` gives (end, de_mm) of a move's words
from a start, the reader's own rule, for tools that rewrite moves (advance's splits).
Arcs: `arc(start, end, words, clockwise)` gives the centre, radius, start angle and
signed sweep of a G2/G3 from I/J or R, as the tools that split or draw arcs need it.
"""
import math
import re
from collections import namedtuple
from functools import partial
from types import MappingProxyType

MOVES = frozenset(("G0", "G1", "G2", "G3"))
ARCS = frozenset(("G2", "G3"))
_TEXT_ARGUMENT = frozenset(("M23", "M28", "M30", "M32", "M117", "M118"))
_NO_WORDS = MappingProxyType({})

Line = namedtuple("Line", "lineno raw code words start end de_mm printing tool error")
_as_line = partial(tuple.__new__, Line)

# Slicers separate words with spaces: such moves are read with str.split, the rest
# (other commands, lower case, glued words, N/* framing) with this.
_NUMBER = r"[-+]?(?:\d+\.?\d*|\.\d+)"
_WORD = re.compile(r"([A-Za-z])\s*(%s(?::%s)*)?" % (_NUMBER, _NUMBER))
_FAST_MOVES = {"G0": "G0", "G1": "G1", "G2": "G2", "G3": "G3",
               "G00": "G0", "G01": "G1", "G02": "G2", "G03": "G3"}


def _tokens(body):
    """(code, words, leftover) of a command's text with the comment taken off."""
    star = body.find("*")
    if star >= 0:
        body = body[:star]
    pairs = _WORD.findall(body)
    if pairs and pairs[0][0] in "Nn":
        pairs = pairs[1:]
    if not pairs:
        return "", _NO_WORDS, body.strip()
    letter, value = pairs[0]
    letter = letter.upper()
    code = letter + (str(int(value)) if value.isdigit() else value)
    if code in _TEXT_ARGUMENT:
        return code, _NO_WORDS, ""
    words = {k.upper(): v for k, v in pairs[1:]}
    return code, words, _WORD.sub("", body).strip()


def parse(line):
    """(code, words) of one line, str or bytes, as Reader reads them, without state: for
    tools that need only a few lines' commands and skip the rest unread."""
    text = line.decode("latin-1") if line.__class__ is bytes else line
    code, words, _ = _tokens(text.split(";", 1)[0])
    return code, words


def tool_of(code):
    """The tool a `T<n>` code selects; None for any other code."""
    return int(code[1:]) if code[:1] == "T" and code[1:].isdigit() else None


class Reader:
    """Iterate to get one `Line` per input line (see the module doc)."""

    def __init__(self, lines):
        self.lines = lines
        self.rel_xyz = False
        self.rel_e = False
        self.offset = (0.0, 0.0, 0.0, 0.0)
        self.tool = None
        self.feed_mm_min = None
        self.layer = None
        self.feature = None
        self.wipe = False

    def __iter__(self):
        return map(_as_line, self.tuples())

    def tuples(self):
        """The same as iterating, as plain tuples in Line's field order: for hot loops
        that unpack every line (a named tuple costs advance about 15 %)."""
        fast = _FAST_MOVES
        no_words = _NO_WORDS
        pos = (0.0, 0.0, 0.0, 0.0)
        rel_xyz, rel_e, tool = self.rel_xyz, self.rel_e, self.tool
        n = 0
        for raw in self.lines:
            n += 1
            text = raw.decode("latin-1") if raw.__class__ is bytes else raw
            c = text[:1]
            if c == ";":
                if text[1:2] in "LTW":      # a marker can only start so
                    self._marker(text)
                yield (n, raw, "", no_words, pos, pos, 0.0, False, tool, None)
                continue
            semi = text.find(";")
            body = text if semi < 0 else text[:semi]
            parts = body.split()
            code = fast.get(parts[0]) if parts else None
            if code is not None:
                # The common case, a move written as slicers write it: move_end inlined,
                # since this runs for nearly every line of a print.
                x0, y0, z0, e0 = pos
                x, y, z, e = pos
                de = 0.0
                feed = None
                words = {}
                try:
                    for w in parts[1:]:
                        k = w[0]
                        v = w[1:]
                        words[k] = v
                        if k == "X":
                            x = x0 + float(v) if rel_xyz else float(v)
                        elif k == "Y":
                            y = y0 + float(v) if rel_xyz else float(v)
                        elif k == "E":
                            if rel_e:
                                de = float(v)
                                e = e0 + de
                            else:
                                e = float(v)
                                de = e - e0
                        elif k == "Z":
                            z = z0 + float(v) if rel_xyz else float(v)
                        elif k == "F":
                            feed = float(v)
                        elif k.islower():
                            raise ValueError(k)
                except ValueError:
                    code = None     # glued words or a bad number: read it the slow way
                else:
                    if feed is not None:
                        self.feed_mm_min = feed
                    end = (x, y, z, e)
                    printing = de > 0 and (x != x0 or y != y0 or z != z0 or code == "G2"
                                           or code == "G3")
                    yield (n, raw, code, words, pos, end, de, printing, tool, None)
                    pos = end
                    continue
            code, words, leftover = _tokens(body) if parts else ("", no_words, "")
            start = pos
            de = 0.0
            printing = False
            error = None
            try:
                if code in MOVES:
                    if leftover:
                        raise ValueError("not a word: %r" % leftover)
                    pos, de = self._move(pos, words)
                    printing = de > 0 and (pos[0] != start[0] or pos[1] != start[1]
                                           or pos[2] != start[2] or code in ARCS)
                elif code == "G92":
                    pos = self._set_position(pos, words)
                elif code == "G28":
                    pos = self._home(pos, words)
                elif code == "G90" or code == "G91":
                    rel_xyz = rel_e = self.rel_xyz = self.rel_e = code == "G91"
                elif code == "M82" or code == "M83":
                    rel_e = self.rel_e = code == "M83"
                elif tool_of(code) is not None:
                    tool = self.tool = tool_of(code)
            except ValueError as err:
                pos = start
                code, words, de, error = "", no_words, 0.0, str(err)
            yield (n, raw, code, words, start, pos, de, printing, tool, error)

    def _move(self, pos, words):
        end, de = move_end(pos, words, self.rel_xyz, self.rel_e)
        if "F" in words:
            self.feed_mm_min = float(words["F"])     # after move_end: a bad line sets nothing
        return end, de

    def _set_position(self, pos, words):
        """G92: the named axes (all four if none) take the given values (0 if bare)."""
        named = [i for i, a in enumerate("XYZE") if a in words] or range(4)
        new = list(pos)
        offset = list(self.offset)
        for i in named:
            v = words.get("XYZE"[i]) or "0"
            new[i] = float(v)
            offset[i] += pos[i] - new[i]
        self.offset = tuple(offset)
        return tuple(new)

    def _home(self, pos, words):
        """G28: the named axes (X, Y and Z if none) go to 0, their offsets too."""
        named = [i for i, a in enumerate("XYZ") if a in words] or range(3)
        new = list(pos)
        offset = list(self.offset)
        for i in named:
            new[i] = offset[i] = 0.0
        self.offset = tuple(offset)
        return tuple(new)

    def _marker(self, text):
        if text.startswith(";TYPE:"):
            self.feature = text[6:].strip()
        elif text.startswith(";LAYER_CHANGE"):
            self.layer = 0 if self.layer is None else self.layer + 1
        elif text.startswith(";LAYER:"):
            try:
                self.layer = int(text[7:].strip())
            except ValueError:
                pass
        elif text.startswith(";WIPE_START"):
            self.wipe = True
        elif text.startswith(";WIPE_END"):
            self.wipe = False


def move_end(start, words, rel_xyz, rel_e):
    """(end, de_mm) of a G0-G3 with these words from start (x, y, z, e)."""
    x, y, z, e = start
    if "X" in words:
        x = x + float(words["X"]) if rel_xyz else float(words["X"])
    if "Y" in words:
        y = y + float(words["Y"]) if rel_xyz else float(words["Y"])
    if "Z" in words:
        z = z + float(words["Z"]) if rel_xyz else float(words["Z"])
    de = 0.0
    if "E" in words:
        if rel_e:
            de = float(words["E"])
            e = e + de
        else:
            v = float(words["E"])
            de = v - e
            e = v
    return (x, y, z, e), de


def arc(start, end, words, clockwise):
    """(cx, cy, radius, a0, sweep) of a G2/G3 from start to end (x, y, ...): centre
    from I/J (relative to the start) or R (Marlin's rule: R < 0 takes the long way),
    radius and angle a0 at the start, and the signed sweep in radians (negative for
    G2); a move ending where it starts is a full circle."""
    x0, y0, x1, y1 = start[0], start[1], end[0], end[1]
    if "I" in words or "J" in words:
        cx = x0 + float(words.get("I") or 0.0)
        cy = y0 + float(words.get("J") or 0.0)
    else:
        r = float(words["R"])
        dx, dy = x1 - x0, y1 - y0
        d = math.hypot(dx, dy)
        if d == 0:
            raise ValueError("R arc with the same start and end")
        h = math.sqrt(max(r * r - d * d / 4.0, 0.0))
        s = -1.0 if (clockwise != (r < 0)) else 1.0
        cx, cy = (x0 + x1) / 2.0 + s * h * (-dy / d), (y0 + y1) / 2.0 + s * h * (dx / d)
    ax, ay = x0 - cx, y0 - cy
    bx, by = x1 - cx, y1 - cy
    sweep = math.atan2(ax * by - ay * bx, ax * bx + ay * by)
    if sweep < 0:
        sweep += 2 * math.pi
    if clockwise:
        sweep -= 2 * math.pi
    if abs(x1 - x0) < 1e-9 and abs(y1 - y0) < 1e-9:
        sweep = -2 * math.pi if clockwise else 2 * math.pi
    return cx, cy, math.hypot(ax, ay), math.atan2(ay, ax), sweep
