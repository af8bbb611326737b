"""What a G-code file asks of the steppers, worked out without the firmware's code.

`mixstep trace check` compares a trace with this model, so the model must not share
code with the firmware it checks: a bug in the firmware's parser, mixer or rounding
would otherwise be copied into the check meant to catch it. Nothing here imports
`mixfw`. The model follows the firmware's *specification* (docs/G-Codes.md's
section, "How the mixer picks a drive" and the options' meaning), in exact arithmetic:

- Lengths. An axis or E word is read as an exact decimal (at most 9 significant
  digits, as the firmware reads numbers) and rounded to the nanometre, half away from
  zero: the firmware's unit of position. Steps/mm are taken to a millionth, half away
  from zero. Everything after that is a `Fraction`: no float ever decides a step.
- Drives. Each drive's filament is the exact sum of its shares (E times weight over
  the sum of weights) of every E move, and its planned step is that times its
  steps/mm, rounded half away from zero. This is first principles: the step nearest
  the exact filament; a tie (exactly half a step) goes away from zero, the rule the
  firmware states. A move less than a step on every axis plans no block; its shares
  count toward the next move (the position is exact, so nothing is lost).
- Mixes are integer weights as the firmware states them: whole numbers up to 10000
  in total stay as given (1:2:3 is exactly 1/6, 2/6, 3/6), anything else is scaled
  to 0.01 % steps (a total of 10000, largest remainder first, ties to the lower
  drive, and a drive asked for keeps at least 1); the common divisor is taken out.
- Retraction (retract_policy): 0 follows the mix (drives go back along their exact
  shares, so an unretraction restores every drive exactly); 1 moves every drive
  equally (weights 1:1:...); 2 replays the newest steps of the latest extrusion blocks
  (at most 64 blocks, up to 50 mm), the order within a block being the mixing
  document's error diffusion (highest error first, ties to the lower drive; see
  docs/Mixing.md), and the unretraction pushes
  exactly those steps back; what the record does not cover follows the mix.
- Transitions (transition_l1_mm, transition_l2_mm, transition_pairs): a mix change
  applies L0 = L1 + L2/2 of printing extrusion (E > 0 on a move of X, Y or Z) earlier,
  splitting the crossing move at the nanometre; moves wait for L0 of printing after
  them, and a wait for the moves (M400, G4, G28, M92 ...) releases them.
- Gradients (M166, M169) set the mix of each extruding move from its middle: mid-Z
  of the move, or the printing filament since M169 plus half the move's.
- Flow (M221 S, per virtual tool): a G0-G3 move's filament is its E times the active
  tool's percentage, to the nanometre rounded down, what falls below one carried to
  the next such move; G10/G11 are not scaled.
- Pressure advance (M900 K [T], per virtual tool): every block keeps the K in force as
  it is planned, for the trace check's own reading of what the drives then do.
- Cancelled objects (M486): while the current object is cancelled, a move that
  extrudes (G0-G3 with E, G10, G11) steps nothing and its position is taken; travel
  runs. The filament it would have retracted is followed (a retraction adds to it,
  extrusion takes from it down to 0), and when the skip ends (another object, S-1, U)
  an E move where the axes are makes the filament retracted what it would have been.

Where the firmware departs from its specification, this model keeps to the
specification, and the tests say which is right and why (host_tests/test_trace_check.py):
a settings change mid-print (M204, M201, M203, M205, M92) keeps every drive's exact
filament here (the firmware rounds it to whole steps each time), and a retract_policy 1
retraction keeps its equal mix when a transition reaches back over it (the firmware
gives it the new tool's mix), and an exact tie in a mix's remainders goes to the lower
drive as the rule says (the firmware sorts the remainders with MicroPython's sort,
which is not stable, and in floats: 5:2:1:0.5:0.25:2 gives e5 the 0.01 % the rule
gives e1), and moves wait for L0 of printing extrusion after them counted anew
(the firmware keeps a running total that a split whose last part moves no axis leaves
too high, so it releases moves early and later transitions fall short). Two
approximations of the firmware's are not copied
either: it rounds a drive's position to the nanometre after a replayed retraction and
when a mix's total changes; this model stays exact. They differ by under a nanometre,
so only a position within that of exactly half a step could round the other way.

The input side mirrors what the firmware refuses (and so does not run): bad
checksums and line numbers, lines over line_buffer_bytes, bytes that are not
printable ASCII, malformed words, unknown tools, moves beyond the soft limits or
max_extrude_mm, all-zero mixes.
"""
import math
import re
from array import array
from fractions import Fraction

NM_PER_MM = 10 ** 6
SPM_SCALE = 10 ** 6
MAX_DRIVES = 6
WEIGHT_SCALE = 10000
MAX_BLOCK_E_STEPS = 20000 - 2 * MAX_DRIVES  # a block's E steps (planner.MAX_PERIOD), less rounding
REPLAY_BLOCKS = 64
REPLAY_NM = 50 * NM_PER_MM
_MARLIN_LETTERS = "ABCDHI"
# G2/G3 (docs/G-Codes.md): how far R may fall short of half the chord, or an I J K
# centre's radius to the end differ from its radius to the start; and how near a
# whole number a segment count counts as that number.
ARC_SLACK_NM = 10000
ARC_SLACK = 0.001
_MAX_DIGITS = 9

# Commands whose arguments are text, not words (the firmware reads them whole).
RAW_COMMANDS = {"M23", "M28", "M30", "M32", "M117", "M118", "M567", "M168", "M169",
                "M925", "M926", "M486"}
# Commands that wait for the queued moves (so moves held for a transition go to the
# planner first, and a later mix change cannot reach back over them).
SYNC_COMMANDS = {"M400", "G28", "M92", "M201", "M203", "M204", "M205", "M930", "M167",
                 "M18", "M84"}
# Known but not modelled: what they do to the steps cannot be told from the G-code
# alone (a queue dropped at some moment, a file on the printer's flash) or they change
# options this model reads only at the start.
UNMODELLED = {"M112", "M410", "M999", "M23", "M24", "M32", "M926", "M930", "M501", "M502",
              "M7100", "M7101", "M7102"}

# Settings the firmware has a default for, so a board may leave them out.
OPTION_DEFAULTS = {
    "soft_limits": True,
    "max_extrude_mm": 200.0,
    "retract_policy": 0,
    "retract_mm": 2.0,
    "transition_l1_mm": 0.0,
    "transition_l2_mm": 0.0,
    "transition_pairs": (),
    "virtual_tools": 16,
    "line_buffer_bytes": 96,
    "travel_mm": (250.0, 250.0, 200.0),
    "min_arc_segment_mm": 0.1,
    "max_arc_segment_mm": 1.0,
    "min_circle_segments": 72,
}


class Refused(ValueError):
    """The firmware answers this line with an error and does not run it."""


def round_half_away(x):
    """The rounding rule to whole units: the nearest, half away from zero."""
    if not isinstance(x, Fraction):
        x = Fraction(x)
    return div_round(x.numerator, x.denominator)


def div_round(a, b):
    """a / b for integers (b > 0), rounded half away from zero."""
    q = (2 * (a if a >= 0 else -a) + b) // (2 * b)
    return q if a >= 0 else -q


def nm(mm):
    """A length in mm (exact) -> whole nanometres."""
    return round_half_away(Fraction(mm) * NM_PER_MM)


def fixed_spm(steps_per_mm):
    """Steps/mm to a millionth, as an exact fraction."""
    return Fraction(round_half_away(Fraction(str(steps_per_mm)) * SPM_SCALE), SPM_SCALE)


# --- reading G-code ------------------------------------------------------------------

class Line:
    """One line as the firmware would run it: its command ("G1", "T2", "" for none),
    its words {letter: Fraction or None} and, for raw commands, the text after it."""

    def __init__(self, command, words, text, line_number):
        self.command = command
        self.words = words
        self.text = text
        self.line_number = line_number
        self.decimals = {}  # letter -> decimals written: "S1.0" is no whole number

    def has(self, ch):
        return ch in self.words

    def value(self, ch, default=None):
        """The word's number; a letter given without a number is refused unless a
        default is given (as the firmware does)."""
        if ch not in self.words:
            return default
        v = self.words[ch]
        if v is None:
            if default is None:
                raise Refused("parameter %s needs a number" % ch)
            return default
        return v

    def int(self, ch, default=None, lo=None, hi=None):
        v = self.value(ch, default)
        if v is None:
            return None
        if self.decimals.get(ch) or Fraction(v).denominator != 1:
            raise Refused("parameter %s must be a whole number" % ch)
        v = int(v)
        if (lo is not None and v < lo) or (hi is not None and v > hi):
            raise Refused("%s%d out of range" % (ch, v))
        return v


def _number(text, i):
    """An optional signed decimal at text[i:]: (value or None, decimals, next index).
    At most 9 significant digits are kept; more before the point is refused."""
    n = len(text)
    while i < n and text[i] == " ":
        i += 1
    neg = False
    if i < n and text[i] in "+-":
        neg = text[i] == "-"
        i += 1
        signed = True
    else:
        signed = False
    mant = decimals = digits = 0
    seen_digit = seen_dot = False
    while i < n:
        c = text[i]
        if "0" <= c <= "9":
            seen_digit = True
            if digits < _MAX_DIGITS:
                if mant or c != "0" or seen_dot:
                    digits += 1
                mant = mant * 10 + ord(c) - 48
                if seen_dot:
                    decimals += 1
            elif not seen_dot:
                raise Refused("number too long")
        elif c == "." and not seen_dot:
            seen_dot = True
        else:
            break
        i += 1
    if i < n and not (text[i] in " \t\r\n;(*" or "A" <= text[i] <= "Z"):
        raise Refused("malformed number")
    if (signed or seen_dot) and not seen_digit:
        raise Refused("malformed number")
    if not seen_digit:
        return None, (0, False), i
    v = Fraction(-mant if neg else mant, 10 ** decimals)
    return v, (decimals, neg), i


def parse_words(text):
    """A line's text (no ';' comment) -> Line, or Refused (a command the firmware does
    not know is not run either, so the model need not tell the two apart)."""
    words = {}
    decimals = {}
    command = ""
    line_number = None
    first = True
    i, n = 0, len(text)
    while i < n:
        c = text[i]
        if c in " \t\r\n":
            i += 1
            continue
        if c in ";*":
            break
        if c == "(":
            end = text.find(")", i)
            if end < 0:
                raise Refused("unclosed ( comment")
            i = end + 1
            continue
        if not (c.isascii() and c.isalpha()):
            raise Refused("unexpected character %r" % c)
        letter = c.upper()
        v, dec, i = _number(text, i + 1)
        if first:
            if letter == "N" and line_number is None:
                if v is None or dec[0]:
                    raise Refused("malformed line number")
                line_number = int(v)
                continue
            if letter in "GMT":
                if v is None:
                    raise Refused("%s needs a number" % letter)
                if dec[0] or dec[1]:
                    raise Refused("unsupported command")
                command = "%s%d" % (letter, v)
                first = False
                if command in RAW_COMMANDS:
                    rest = text[i:]
                    for stop in ";*":
                        rest = rest.split(stop, 1)[0]
                    return Line(command, {}, rest.strip(), line_number)
                continue
            raise Refused("line must start with G, M or T")
        if letter in words:
            raise Refused("parameter %s given twice" % letter)
        words[letter] = v
        if v is not None:
            decimals[letter] = dec[0]
    line = Line(command, words, "", line_number)
    line.decimals = decimals
    return line


class Intake:
    """The firmware's line protocol, as a host's line stream reaches it: `;` comments
    are not stored, a stored line with a control byte, or longer than
    line_buffer_bytes unless it is a message (M117/M118 with no line number, cut at the
    last whole UTF-8 character), is refused; other bytes are kept, text is UTF-8 and
    they are refused in words; `N<n> ... *<checksum>` lines are checked (XOR of
    the bytes before `*`; the number must follow the last; a repeat is not run
    again), and M110 sets the number."""

    def __init__(self, line_bytes):
        self.line_bytes = line_bytes
        self.last_n = 0

    def line(self, raw):
        """raw bytes of one line (no newline) -> Line to run, None when not run (a
        repeat, or nothing on it), or Refused."""
        stored = raw.split(b";", 1)[0].replace(b"\r", b"")
        if any((c < 32 and c != 9) or c == 127 for c in stored[:self.line_bytes + 1]):
            raise Refused("control byte")
        if len(stored) > self.line_bytes:
            if not _MESSAGE.match(stored):
                raise Refused("line too long")
            cut = self.line_bytes
            while cut > 0 and stored[cut] & 0xC0 == 0x80:  # back to a character's start
                cut -= 1
            stored = stored[:cut]
        try:
            text = stored.decode()
        except UnicodeError:
            raise Refused("text is not UTF-8")
        star = text.find("*")
        if star >= 0:
            cs = 0
            for c in stored[:star]:
                cs ^= c
            digits = text[star + 1:].strip()
            if not digits.isdigit() or int(digits) != cs:
                raise Refused("checksum mismatch")
        body = text if star < 0 else text[:star]
        # The number and checksum are checked before the words: a line that arrived
        # intact uses up its number even if its words are bad.
        numbered = _LINE_NUMBER.match(body)
        if numbered and not _M110.match(body):
            if star < 0:
                raise Refused("no checksum with line number")
            if not numbered.group(1):
                raise Refused("malformed line number")
            number = int(numbered.group(1))
            if number <= self.last_n:
                return None  # a repeat of a line already run
            if number != self.last_n + 1:
                raise Refused("line number is not last + 1")
            self.last_n = number
        elif star >= 0 and not numbered:
            raise Refused("checksum without line number")
        line = parse_words(body)
        if line.command == "M110":
            default = line.line_number if line.line_number is not None else self.last_n
            self.last_n = line.int("N", default, lo=-1)
        return line


_LINE_NUMBER = re.compile(r"[ \t]*[Nn][ \t]*(-?[0-9]+)?")
_MESSAGE = re.compile(rb"[ \t]*[Mm]11[78][ \t]")
_M110 = re.compile(r"[ \t]*[Nn][ \t]*-?[0-9]*[ \t]*[Mm][ \t]*110(?![0-9])")


def _decimal_list(text, sep=":"):
    """'1:2.5:0' -> [Fraction, ...]; anything float() would not take plainly is
    refused (the firmware's float() refuses the same, or turns inf/nan into a refused
    mix)."""
    out = []
    for w in text.split(sep):
        try:
            v = Fraction(w.strip())
        except (ValueError, ZeroDivisionError):
            raise Refused("malformed number %r" % w)
        if "/" in w:
            raise Refused("malformed number %r" % w)
        out.append(v)
    return out


# --- mixes ---------------------------------------------------------------------------

def mix_weights(values, drives):
    """Non-negative numbers -> integer weights (a tuple of `drives`), as the firmware
    specifies: whole numbers totalling at most 10000 stay, others go to 0.01 % steps
    by largest remainder (ties to the lower drive); every drive asked for keeps at
    least 1; the common divisor is taken out. All-zero is refused."""
    if len(values) > drives:
        raise Refused("mix has %d weights but only %d drives" % (len(values), drives))
    vals = [Fraction(v) for v in values] + [Fraction(0)] * (drives - len(values))
    if any(v < 0 for v in vals):
        raise Refused("negative weight")
    total = sum(vals)
    if total <= 0:
        raise Refused("all-zero mix")
    if total <= WEIGHT_SCALE and all(v.denominator == 1 for v in vals):
        ints = [int(v) for v in vals]
    else:
        exact = [v * WEIGHT_SCALE / total for v in vals]
        ints = [int(x) for x in exact]  # floor: all are >= 0
        short = WEIGHT_SCALE - sum(ints)
        by_remainder = sorted(range(drives), key=lambda i: (-(exact[i] - ints[i]), i))
        for i in by_remainder[:short]:
            ints[i] += 1
        ints = [max(w, 1) if v > 0 else w for w, v in zip(ints, vals)]
    g = math.gcd(*ints)
    return tuple(w // g for w in ints)


def default_mixes(drives, count):
    """T<n> prints with drive n alone below the drive count, and every drive equally
    above (docs/Mixing.md)."""
    return [tuple(int(i == t) for i in range(drives)) if t < drives else (1,) * drives
            for t in range(count)]


class Gradient:
    """A mix that moves linearly between stops (position_mm, tool weights), held
    beyond the ends; along "Z" or "E"; alias: the tool it applies to, or None."""

    def __init__(self, stops, along, alias, drives):
        if len(stops) < 2:
            raise Refused("a gradient needs 2 stops")
        for (a, _), (b, _) in zip(stops, stops[1:]):
            if not b > a:
                raise Refused("gradient stops must increase")
        self.stops = [(Fraction(p), [Fraction(w, sum(m)) for w in m]) for p, m in stops]
        self.along = along
        self.alias = alias
        self.drives = drives

    def weights_at(self, pos_mm):
        stops = self.stops
        if pos_mm <= stops[0][0]:
            shares = stops[0][1]
        elif pos_mm >= stops[-1][0]:
            shares = stops[-1][1]
        else:
            k = 0
            while stops[k + 1][0] < pos_mm:
                k += 1
            (a, sa), (b, sb) = stops[k], stops[k + 1]
            f = (pos_mm - a) / (b - a)
            shares = [(1 - f) * x + f * y for x, y in zip(sa, sb)]
        return mix_weights(shares, self.drives)


# --- the mixer, from the mixing document's error diffusion ------------------------------

_period_cache = {}


def mixer_picks(weights, steps):
    """The drive of each of `steps` E steps from a fresh start, by the mixing
    document's rule: every drive's error starts at its weight; each step goes to the
    drive with the highest error (ties to the lowest drive), which loses the sum of
    the weights; then every error gains its weight. A drive of weight 0 never steps."""
    total = sum(weights)
    errors = list(weights)
    picks = []
    for _ in range(steps):
        best = max((i for i, w in enumerate(weights) if w), key=lambda i: (errors[i], -i))
        picks.append(best)
        errors[best] -= total
        errors = [e + w for e, w in zip(errors, weights)]
    return picks


def schedule_counts(weights, steps):
    """Per-drive steps the mixer gives in `steps` steps of a block with these integer
    weights, from the block's start: a period is sum(w) steps, and it repeats."""
    weights = tuple(weights)
    period = sum(weights)
    order = _period_cache.get(weights)
    if order is None:
        order = mixer_picks(weights, period)
        if len(_period_cache) < 256:
            _period_cache[weights] = order
    full, part = divmod(steps, period)
    counts = [full * w for w in weights]
    for i in order[:part]:
        counts[i] += 1
    return counts


# --- the machine ---------------------------------------------------------------------

class Planner:
    """The drive side: each drive's exact filament and planned steps, blocks in order,
    and for retract_policy 2 the latest extrusion's steps."""

    def __init__(self, drives, drive_spm, keep_extrusion, out):
        self.drives = drives
        self.spm = list(drive_spm)
        self.drive_mm = [Fraction(0)] * drives
        self.steps = [0] * drives
        self.tool_mix = (1,) + (0,) * (drives - 1)
        self.keep_extrusion = keep_extrusion
        self.extruded = []  # stretches (weights, start, end, counts, nm), newest last
        self.retracted = []
        self.out = out  # fn(line, weights, drive targets, xyz start, xyz target) per block

    def set_mix(self, weights, tool=None):
        self.tool_mix = tuple(weights)

    def set_drive_spm(self, spm):
        """New steps/mm: every drive stays at its steps, counted in the new unit."""
        self.spm = list(spm)
        self.drive_mm = [Fraction(s) / m for s, m in zip(self.steps, self.spm)]

    def _one_piece_nm(self):
        # The longest extrusion whose steps fit one block of the mixer's exact range.
        limit = Fraction(NM_PER_MM * MAX_BLOCK_E_STEPS) / max(self.spm)
        return -((-limit.numerator) // limit.denominator)

    def add_move(self, start_xyz, target_xyz, e_nm, line, mix=None, replay=False):
        """A move of X Y Z (steps) with e_nm of filament; a long extrusion goes in
        equal pieces along the line, each a block."""
        one = self._one_piece_nm()
        if -one < e_nm < one:
            return self._add_block(start_xyz, target_xyz, e_nm, line, mix, replay)
        pieces = _pieces(e_nm, self.spm)
        prev = start_xyz
        for k in range(1, pieces + 1):
            point = [start_xyz[i] + div_round((target_xyz[i] - start_xyz[i]) * k, pieces)
                     for i in range(3)]
            piece = e_nm * k // pieces - e_nm * (k - 1) // pieces
            self._add_block(prev, point, piece, line, mix, replay)
            prev = point

    def _plan(self, e_nm, weights):
        total = sum(weights)
        drive_mm = list(self.drive_mm)
        targets = list(self.steps)
        for i in range(self.drives):
            if weights[i] and e_nm:  # a drive with no share stays, and so does its step
                drive_mm[i] += Fraction(e_nm * weights[i], NM_PER_MM * total)
                targets[i] = round_half_away(drive_mm[i] * self.spm[i])
        return drive_mm, targets

    def _add_block(self, start, target, e_nm, line, mix, replay):
        weights = mix or self.tool_mix
        if replay and e_nm:
            drive_mm, targets, weights = self._replay(e_nm)
        else:
            drive_mm, targets = self._plan(e_nm, weights)
        counts = [targets[i] - self.steps[i] for i in range(self.drives)]
        e_steps = sum(counts)
        self.drive_mm = drive_mm
        if not e_steps and list(start) == list(target):
            return  # less than a step: it counts toward the next move
        if e_steps:
            if e_steps > 0 and self.keep_extrusion and not replay:
                self._remember(counts)
            self.steps = targets
            if weights is not None:
                # The mix in steps: a drive geared finer takes more steps for its share.
                weights = tuple(float(w * m) for w, m in zip(weights, self.spm))
            self.out(line, weights, tuple(targets), start, target)
        else:
            self.out(line, None, None, start, target)

    def _length_nm(self, counts):
        return sum(nm(Fraction(c) / self.spm[i]) for i, c in enumerate(counts))

    def _stretch(self, weights, start, end):
        a = schedule_counts(weights, start)
        b = schedule_counts(weights, end)
        counts = [y - x for x, y in zip(a, b)]
        return (weights, start, end, counts, self._length_nm(counts))

    def _remember(self, counts):
        g = math.gcd(*counts)
        weights = tuple(abs(c) // g for c in counts)
        self.extruded.append((weights, 0, sum(counts), list(counts), self._length_nm(counts)))
        self.retracted = []
        total = sum(s[4] for s in self.extruded)
        while len(self.extruded) > REPLAY_BLOCKS or (
                len(self.extruded) > 1 and total - self.extruded[0][4] >= REPLAY_NM):
            total -= self.extruded.pop(0)[4]

    def _replay(self, e_nm):
        """A retraction takes back the newest steps of the latest extrusion; an
        unretraction gives back what retractions took, in the order they were made.
        What the record does not cover follows the active mix."""
        back = e_nm < 0
        take = self.extruded if back else self.retracted
        give = self.retracted if back else self.extruded
        need = -e_nm if back else e_nm
        counts = [0] * self.drives
        while take and need > 0:
            w, start, end, part, length = take[-1]
            if length > need:
                k = round_half_away(Fraction(need * (end - start), length))
                if k == 0:
                    break
                cut = end - k if back else start + k
                first, second = self._stretch(w, start, cut), self._stretch(w, cut, end)
                take[-1] = first if back else second
                mine = second if back else first
                give.append(mine)
                part, length = mine[3], mine[4]
            else:
                give.append(take.pop())
            counts = [c + p for c, p in zip(counts, part)]
            need -= length
        sign = -1 if back else 1
        self.drive_mm = [self.drive_mm[i] + sign * Fraction(counts[i]) / self.spm[i]
                         for i in range(self.drives)]
        replayed = [self.steps[i] + sign * counts[i] for i in range(self.drives)]
        if need > 0:
            drive_mm, targets = self._plan(sign * need, self.tool_mix)
            # Drives the mix moves go to their exact rounding; the replayed steps are
            # exact for the rest.
            targets = [targets[i] if self.tool_mix[i] else replayed[i]
                       for i in range(self.drives)]
        else:
            drive_mm, targets = self.drive_mm, replayed
        # No one mix: the steps are earlier blocks' (the check's windows skip it).
        return drive_mm, targets, None


def _pieces(e_nm, spm):
    return abs(e_nm) * max(spm) // (NM_PER_MM * MAX_BLOCK_E_STEPS) + 1


class Transitions:
    """Moves wait here until L0 of printing extrusion follows them; a mix change
    reaches back over the last L0 (the tool pair's own, if it has one), splitting the
    move that crosses that point at the nanometre."""

    def __init__(self, planner, l0_nm, pair_l0_nm):
        self.planner = planner
        self.default_l0_nm = l0_nm
        self.pair_l0_nm = pair_l0_nm
        self.l0_nm = max([l0_nm] + list(pair_l0_nm.values()))
        self.tool = -1
        self.pending = []  # [start, target, e_nm, line, mix, replay, mix is its own]
        self.tool_mix = planner.tool_mix

    @staticmethod
    def _printing(move):
        return move[2] if move[2] > 0 and move[0] != move[1] else 0

    def add_move(self, start, target, e_nm, line, mix=None, replay=False):
        # A move with a mix of its own (retract_policy 1) keeps it: a transition moves
        # colour changes of printing extrusion, and the policy says how drives retract.
        self.pending.append([list(start), list(target), e_nm, line, mix or self.tool_mix,
                             replay, mix is not None])
        waiting = sum(self._printing(m) for m in self.pending)
        while self.pending and waiting - self._printing(self.pending[0]) >= self.l0_nm:
            waiting -= self._printing(self.pending[0])
            self._release()

    def _release(self):
        start, target, e_nm, line, mix, replay, _ = self.pending.pop(0)
        self.planner.set_mix(mix)
        self.planner.add_move(start, target, e_nm, line, replay=replay)

    def flush(self):
        while self.pending:
            self._release()

    def set_mix(self, weights, tool=None):
        self.tool_mix = tuple(weights)
        t = -1 if tool is None else tool
        need = self.pair_l0_nm.get((self.tool, t), self.default_l0_nm)
        if tool is not None:
            self.tool = tool
        k = len(self.pending)
        while k > 0 and need > 0:
            move = self.pending[k - 1]
            e = self._printing(move)
            if e > need:
                self._split(k - 1, need)
                break
            need -= e
            k -= 1
        for move in self.pending[k:]:
            if not move[6]:
                move[4] = self.tool_mix

    def _split(self, index, tail_nm):
        start, target, e, line, mix, replay, own = self.pending[index]
        mid = [start[i] + div_round((target[i] - start[i]) * (e - tail_nm), e)
               for i in range(3)]
        self.pending[index] = [start, mid, e - tail_nm, line, mix, replay, own]
        self.pending.insert(index + 1, [mid, list(target), tail_nm, line, mix, replay, own])


class Machine:
    """The command side: modal state, positions in nanometres, tools and gradients,
    retraction; it hands moves to the transitions (if any) and the planner."""

    def __init__(self, settings):
        s = dict(OPTION_DEFAULTS)
        s.update(settings)
        self.settings = s
        self.drives = drives = s["drives"]
        self.spm = [fixed_spm(v) for v in s["steps_per_mm"][:3]]
        drive_spm = s.get("drive_steps_per_mm") or (s["steps_per_mm"][3],) * drives
        self.travel_nm = [nm(Fraction(str(t))) for t in s["travel_mm"]]
        self.soft_limits = bool(s["soft_limits"])
        self.max_extrude_nm = nm(Fraction(str(s["max_extrude_mm"])))
        self.policy = int(s["retract_policy"])
        self.retract_nm = nm(Fraction(str(s["retract_mm"])))
        self.pos_nm = [0, 0, 0]
        self.offset_nm = [0, 0, 0]
        self.axis_steps = [0, 0, 0]  # planned machine steps
        self.axis_net = [0, 0, 0]  # steps the trace shows: moves only, not M92
        self.e_nm = 0
        self.absolute = self.absolute_e = True
        self.retracted_nm = 0
        self.fw_retracted = False
        self.blocks = []  # (line, weights, drive targets) of every block that steps E
        self.plane = 0  # G17, G18, G19
        self.arcs = []  # every arc's geometry in machine mm (see arc)
        # line, then X Y Z steps, of every block that steps an axis (homing too), in the
        # order the trace steps them: the trace check follows the arcs' steps by them.
        self.axis_blocks = array("q")
        self.step_shift = [0, 0, 0]  # planned machine steps less the trace's, since M92
        self.moved = set()
        self.line = 0
        self.planner = Planner(drives, [fixed_spm(v) for v in drive_spm], self.policy == 2,
                               self._block)
        l0 = lambda l1, l2: nm(Fraction(str(l1)) + Fraction(str(l2)) / 2)
        pairs = {(int(a), int(b)): l0(l1, l2) for a, b, l1, l2 in s["transition_pairs"]
                 if int(a) != int(b)}
        default_l0 = l0(s["transition_l1_mm"], s["transition_l2_mm"])
        self.transitions = None
        self.queue = self.planner
        if max([default_l0] + list(pairs.values())) > 0:
            self.transitions = self.queue = Transitions(self.planner, default_l0, pairs)
        count = int(s["virtual_tools"])
        given = s.get("tool_mixes")
        self.mixes = [tuple(m) for m in given] if given else default_mixes(drives, count)
        self.collector = [Fraction(0)] * drives
        self.palette = None
        self.gradient = None
        self.gradient_on = False
        self.extruded_nm = 0
        self.flow = [100] * len(self.mixes)  # M221, per tool
        # M900, per tool; every block with the K in force as it is planned, once one is
        # set (see expected's "advance").
        self.advance_k = [float(k) for k in s.get("tool_advance_k") or ()] or \
            [0.0] * len(self.mixes)
        self.k = 0.0
        self.advance_blocks = []
        self.advance_used = False
        self.flow_carry = 0
        self.unprimed_nm = 0  # filament retracted, not pushed back
        # M486: the objects cancelled, the current one, and while it is cancelled, the
        # filament that would be retracted now (None: not skipping).
        self.cancelled = set()
        self.current_object = -1
        self.skip_unprimed_nm = None
        self.active = 0
        self.mix = None
        self._activate(0)

    # --- the planner's side -------------------------------------------------------
    def _block(self, line, weights, targets, start, target):
        self.advance_blocks.append((line, self.k, target[0] - start[0], target[1] - start[1],
                                    target[2] - start[2],
                                    None if targets is None else tuple(targets)))
        if list(target) != list(start):
            self.axis_blocks.extend((line, target[0] - start[0], target[1] - start[1],
                                     target[2] - start[2]))
        for i in range(3):
            if target[i] != start[i]:
                self.axis_net[i] += target[i] - start[i]
                self.moved.add("xyz"[i])
        if targets is not None:
            prev = self.blocks[-1][2] if self.blocks else (0,) * self.drives
            self.moved.update("e%d" % d for d in range(self.drives) if targets[d] != prev[d])
            self.blocks.append((line, weights, targets))

    def synchronize(self):
        if self.transitions:
            self.transitions.flush()

    def _set_mix(self, weights, tool=None):
        self.queue.set_mix(weights, tool)

    # --- mixing -------------------------------------------------------------------
    def _check_tool(self, tool):
        if not 0 <= tool < len(self.mixes):
            raise Refused("tool T%d out of range" % tool)
        return tool

    def _activate(self, tool):
        self.active = tool
        self.k = self.advance_k[tool]
        self.advance_used = self.advance_used or self.k > 0
        if self.mixes[tool] != self.mix:
            self.mix = self.mixes[tool]
            self._set_mix(self.mix, tool)

    def _store(self, tool, values):
        self.mixes[tool] = mix_weights(values, self.drives)
        if tool == self.active:
            self._activate(tool)

    def _before_extrude(self, z_mm, e_nm):
        g = self.gradient
        if g is None or not self.gradient_on or (g.alias is not None and g.alias != self.active):
            return
        if g.along == "Z":
            pos = z_mm
        else:
            pos = Fraction(self.extruded_nm + max(e_nm, 0) // 2, NM_PER_MM)
            if e_nm > 0:
                self.extruded_nm += e_nm
        mix = g.weights_at(pos)
        if mix != self.mix:
            self.mix = mix
            self._set_mix(mix)

    def _after_gradient_change(self):
        if not self.gradient_on:
            self.mix = None
            self._activate(self.active)

    def _palette_rows(self):
        if self.palette is not None:
            return self.palette
        return [[Fraction(int(i == k)) for i in range(self.drives)] for k in range(self.drives)]

    # --- motion -------------------------------------------------------------------
    def _steps(self, pos_nm):
        # nm times steps/mm in millionths: an exact integer over 10**12.
        return [div_round((pos_nm[i] + self.offset_nm[i]) * self.spm[i].numerator,
                          NM_PER_MM * self.spm[i].denominator) for i in range(3)]

    def _printing_e(self, e_nm, xyz):
        """A G0-G3 move's filament after M221 and M486: 0 while skipping."""
        pct = self.flow[self.active]
        if self.skip_unprimed_nm is not None:
            e = e_nm * pct // 100
            self.skip_unprimed_nm = (self.skip_unprimed_nm - e if e < 0
                                     else max(0, self.skip_unprimed_nm - e))
            return 0
        if pct != 100:
            total = e_nm * pct + self.flow_carry
            self.flow_carry = total % 100
            return total // 100
        return e_nm

    def _skip(self, on):
        if on and self.skip_unprimed_nm is None:
            self.skip_unprimed_nm = self.unprimed_nm
        elif not on and self.skip_unprimed_nm is not None:
            e = self.unprimed_nm - self.skip_unprimed_nm
            self.skip_unprimed_nm = None
            if e:
                self._queue(list(self.axis_steps), False, e)

    def m486(self, ln):
        words = {}
        for word in ln.text.split():
            letter = word[0].upper()
            if letter == "A":
                break
            words[letter] = int(word[1:]) if word[1:] else None
        if "T" in words:
            self.cancelled = set()
            self.current_object = -1
            self._skip(False)
        if "S" in words:
            self.current_object = words["S"]
            self._skip(words["S"] in self.cancelled)
        if "P" in words:
            self.cancelled.add(words["P"])
        if "U" in words:
            self.cancelled.discard(words["U"])
        if "C" in words:
            if self.current_object < 0:
                raise Refused("M486 C with no current object")
            self.cancelled.add(self.current_object)
        self._skip(self.current_object in self.cancelled)

    def m900(self, ln):
        tool = self._check_tool(ln.int("T", self.active))
        if ln.has("K"):
            k = float(ln.value("K"))
            if not 0 <= k <= 10:
                raise Refused("M900 K out of range")
            self.advance_k[tool] = k
            if tool == self.active:
                self._activate(tool)

    def m221(self, ln):
        tool = self._check_tool(ln.int("T", self.active))
        if ln.has("S"):
            self.flow[tool] = ln.int("S", lo=1, hi=999)

    def _queue(self, target_steps, xyz, e_nm):
        if e_nm and not -self.max_extrude_nm <= e_nm <= self.max_extrude_nm:
            raise Refused("extrusion over max_extrude_mm")
        if e_nm < 0:
            self.unprimed_nm -= e_nm
        else:
            self.unprimed_nm = max(0, self.unprimed_nm - e_nm)
        start = list(self.axis_steps)
        q = self.queue
        if not xyz and self.policy == 1 and (e_nm < 0 or self.retracted_nm > 0):
            q.add_move(start, target_steps, e_nm, self.line, mix=(1,) * self.drives)
            self.retracted_nm = max(0, self.retracted_nm - e_nm)
        elif self.policy == 2 and (e_nm < 0 or (not xyz and self.retracted_nm > 0)):
            q.add_move(start, target_steps, e_nm, self.line, replay=True)
            self.retracted_nm = max(0, self.retracted_nm - e_nm)
        else:
            if self.policy == 2 and e_nm > 0:
                self.retracted_nm = 0
            q.add_move(start, target_steps, e_nm, self.line)
        self.axis_steps = list(target_steps)

    def _end(self, ln):
        """A move's X Y Z target (nm), the bits of the axes it names, and its E target
        (nm), as G90/G91 and M82/M83 read them."""
        target = list(self.pos_nm)
        moved = 0
        for i, ch in enumerate("XYZ"):
            if ln.has(ch):
                v = nm(ln.value(ch))
                target[i] = v if self.absolute else target[i] + v
                moved |= 1 << i
        target_e = self.e_nm
        if ln.has("E"):
            v = nm(ln.value("E"))
            target_e = v if self.absolute_e else target_e + v
        return target, moved, target_e

    def g1(self, ln):
        if ln.has("F") and ln.value("F", -1) <= 0:
            raise Refused("feed rate must be > 0")
        target, moved, target_e = self._end(ln)
        if not moved and not ln.has("E"):
            return
        if self.soft_limits:
            for i in range(3):
                at = target[i] + self.offset_nm[i]
                if (moved >> i) & 1 and not -1 <= at <= self.travel_nm[i] + 1:
                    raise Refused("outside the soft limits")
        steps = self._steps(target)
        e_nm = target_e - self.e_nm
        xyz = steps != self.axis_steps
        if e_nm:
            self._before_extrude(Fraction(self.pos_nm[2] + target[2], 2 * NM_PER_MM), e_nm)
            e_nm = self._printing_e(e_nm, xyz)
            xyz = xyz and self.skip_unprimed_nm is None
        if xyz or e_nm:
            self._queue(steps, xyz, e_nm)
        self.e_nm = target_e
        self.pos_nm = target

    def arc(self, ln):
        """G2/G3 in the plane of G17/G18/G19, in this model's own geometry: the centre
        from I J K (or R), each segment's end on the circle through the start at
        angle start + i * sweep / n (float64, rounded to the nanometre), the third axis
        and E split as floor(total * i / n) in integers, the last segment exactly at
        the end. n follows the firmware's stated rule (docs/G-Codes.md): segments of
        at most max_arc_segment_mm and at least min_circle_segments a turn, none under
        min_arc_segment_mm."""
        if ln.has("F") and ln.value("F", -1) <= 0:
            raise Refused("feed rate must be > 0")
        a, b, c = ((0, 1, 2), (2, 0, 1), (1, 2, 0))[self.plane]
        if ln.has("IJK"[c]):
            raise Refused("centre letter of the wrong plane")
        centred = ln.has("IJK"[a]) or ln.has("IJK"[b])
        if ln.has("R") == centred:
            raise Refused("an arc needs R or I J K, not both or neither")
        turns = ln.int("P", 0, lo=0, hi=1000)
        target, moved, target_e = self._end(ln)
        e_nm = target_e - self.e_nm
        if e_nm and not -self.max_extrude_nm <= e_nm <= self.max_extrude_nm:
            raise Refused("extrusion over max_extrude_mm")
        start = self.pos_nm
        dx, dy = target[a] - start[a], target[b] - start[b]
        cw = ln.command == "G2"
        if ln.has("R"):
            r = float(ln.value("R"))
            chord = math.hypot(dx, dy)
            if not chord or abs(r) * NM_PER_MM < chord / 2 - ARC_SLACK_NM:
                raise Refused("R cannot reach the end")
            h = max((r * NM_PER_MM) ** 2 - chord * chord / 4, 0.0) ** 0.5 / chord
            if cw != (r < 0):
                h = -h
            ox, oy = round(dx / 2 - h * dy), round(dy / 2 + h * dx)
        else:
            ox, oy = nm(ln.value("IJK"[a], Fraction(0))), nm(ln.value("IJK"[b], Fraction(0)))
        radius = math.hypot(ox, oy)
        if not radius or abs(math.hypot(dx - ox, dy - oy) - radius) > ARC_SLACK_NM:
            raise Refused("arc radius zero, or the end off the circle")
        start_angle = math.atan2(-oy, -ox)
        sweep = math.atan2(dy - oy, dx - ox) - start_angle
        full = 2 * math.pi
        if cw:
            sweep = -((-sweep) % full or (full if not (dx or dy) else 0)) - turns * full
        else:
            sweep = (sweep % full or (full if not (dx or dy) else 0)) + turns * full
        along = target[c] - start[c]
        length_mm = math.hypot(radius * sweep, along) / NM_PER_MM
        s = self.settings
        n = max(math.ceil(length_mm / s["max_arc_segment_mm"] - ARC_SLACK),
                math.ceil(abs(sweep) / full * s["min_circle_segments"] - ARC_SLACK), 1)
        n = max(1, min(n, int(length_mm / s["min_arc_segment_mm"] + ARC_SLACK)))
        centre = (start[a] + ox, start[b] + oy)
        points = []
        for i in range(1, n):
            point = list(start)
            angle = start_angle + sweep * i / n
            point[a] = round(centre[0] + radius * math.cos(angle))
            point[b] = round(centre[1] + radius * math.sin(angle))
            point[c] = start[c] + along * i // n
            points.append(point)
        points.append(target)
        if self.soft_limits:
            for point in points:
                for i in range(3):
                    if not -1 <= point[i] + self.offset_nm[i] <= self.travel_nm[i] + 1:
                        raise Refused("outside the soft limits")
        self.arcs.append(self._arc_record((a, b, c), centre, radius, start_angle, sweep, n,
                                          start[c], along))
        e_done = 0
        for i, point in enumerate(points, 1):
            e = e_nm * i // n - e_done
            steps = self._steps(point)
            xyz = steps != self.axis_steps
            e_done += e
            if e:
                self._before_extrude(Fraction(self.pos_nm[2] + point[2], 2 * NM_PER_MM), e)
                e = self._printing_e(e, xyz)
                xyz = xyz and self.skip_unprimed_nm is None
            if xyz or e:
                self._queue(steps, xyz, e)
            self.pos_nm = point
        self.e_nm = target_e
        self.pos_nm = list(target)

    def _arc_record(self, axes, centre_nm, radius_nm, start_angle, sweep, segments,
                    start_c_nm, along_nm):
        """An arc as the trace check follows it, in machine mm (G92's offset in): the
        plane's axes a b and the third c, the centre in a b, the radius, the start's
        angle and the sweep (radians, counter-clockwise in a b positive), the segment
        count, the third axis's start and travel, and for each axis its steps/mm and
        the steps the trace is short of the planned ones (step_shift, after M92)."""
        a, b, c = axes
        off = self.offset_nm
        return {"line": self.line, "axes": axes,
                "centre_mm": ((centre_nm[0] + off[a]) / NM_PER_MM,
                              (centre_nm[1] + off[b]) / NM_PER_MM),
                "radius_mm": radius_nm / NM_PER_MM, "start_angle": start_angle,
                "sweep": sweep, "segments": segments,
                "start_c_mm": (start_c_nm + off[c]) / NM_PER_MM, "along_mm": along_nm / NM_PER_MM,
                "steps_per_mm": tuple(float(v) for v in self.spm),
                "step_shift": tuple(self.step_shift)}

    def _fw_retract(self, e_nm):
        if self.skip_unprimed_nm is None:
            self._queue(list(self.axis_steps), False, e_nm)
        elif e_nm < 0:
            self.skip_unprimed_nm -= e_nm
        else:
            self.skip_unprimed_nm = max(0, self.skip_unprimed_nm - e_nm)

    def g10(self, ln):
        if not self.fw_retracted:
            self._fw_retract(-self.retract_nm)
            self.fw_retracted = True

    def g11(self, ln):
        if self.fw_retracted:
            self._fw_retract(self.retract_nm)
            self.fw_retracted = False

    def g28(self, ln):
        axes = [i for i in range(3) if ln.has("XYZ"[i])] or [0, 1, 2]
        for i in axes:
            self.synchronize()
            # The axis runs to its min endstop, which the trace's start is at: back by
            # the steps the trace counts, which an M92 since leaves apart from the
            # planned ones.
            if self.axis_net[i]:
                self.moved.add("xyz"[i])
                back = [0, 0, 0]
                back[i] = -self.axis_net[i]
                self.axis_blocks.extend([self.line] + back)
                self.advance_blocks.append((self.line, 0.0, back[0], back[1], back[2], None))
            self.axis_net[i] = self.axis_steps[i] = self.step_shift[i] = 0
            self.pos_nm[i] = self.offset_nm[i] = 0

    def g92(self, ln):
        named = [i for i in range(4) if ln.has("XYZE"[i])] or range(4)
        for i in named:
            v = nm(ln.value("XYZE"[i], Fraction(0)))
            if i == 3:
                self.e_nm = v
            else:
                self.offset_nm[i] += self.pos_nm[i] - v
                self.pos_nm[i] = v

    def m92(self, ln):
        values = {ch: ln.value(ch) for ch in "XYZE" if ln.has(ch)}
        if not values:
            return
        for v in values.values():
            if not Fraction(1, 1000) <= v <= 100000:
                raise Refused("steps/mm out of range")
        self.synchronize()
        for i, ch in enumerate("XYZ"):
            if ch in values:
                self.spm[i] = fixed_spm(values[ch])
        # The axes stay where they are in mm: their steps are counted anew, unmoved.
        was = self.axis_steps
        self.axis_steps = self._steps(self.pos_nm)
        self.step_shift = [self.step_shift[i] + self.axis_steps[i] - was[i] for i in range(3)]
        if "E" in values:
            self.planner.set_drive_spm([fixed_spm(values["E"])] * self.drives)

    def m163(self, ln):
        for ch in "SP":
            if ln.value(ch, None) is None:
                raise Refused("missing parameter %s" % ch)
        drive = ln.int("S", lo=0, hi=self.drives - 1)
        weight = ln.value("P")
        if weight < 0:
            raise Refused("weight must be >= 0")
        self.collector[drive] = weight

    def m164(self, ln):
        tool = self._check_tool(ln.int("S", self.active))
        ln.int("P", 0, lo=0, hi=1)
        self._store(tool, self.collector)

    def m165(self, ln):
        if ln.has("R"):
            return
        weights = [Fraction(0)] * self.drives
        given = False
        for i in range(self.drives):
            ch = _MARLIN_LETTERS[i]
            if ln.has(ch):
                weights[i] = ln.value(ch)
                given = True
        if not given:
            raise Refused("M165 needs weights")
        self._store(self.active, weights)

    def m567(self, ln):
        tool = weights = None
        for word in ln.text.split():
            letter, value = word[0].upper(), word[1:]
            if letter == "P":
                if not value.lstrip("+-").isdigit():
                    raise Refused("malformed tool")
                tool = int(value)
            elif letter == "E":
                weights = _decimal_list(value)
            elif letter == "U":
                amounts = _decimal_list(value)
                rows = self._palette_rows()
                if len(amounts) > len(rows) or any(u < 0 for u in amounts):
                    raise Refused("bad mixture amounts")
                weights = [sum(u * row[i] for u, row in zip(amounts, rows))
                           for i in range(self.drives)]
            else:
                raise Refused("M567 takes P, E or U")
        if tool is None or weights is None:
            raise Refused("M567 needs P and E or U")
        self._store(self._check_tool(tool), weights)

    def m168(self, ln):
        if not ln.text.strip():
            self.palette = None
            return
        rows = []
        for row in ln.text.strip().split(","):
            w = mix_weights(_decimal_list(row), self.drives)
            rows.append([Fraction(x, sum(w)) for x in w])
        self.palette = rows

    def m166(self, ln):
        if not ln.words:
            return
        if any(ln.has(ch) for ch in "AZIJ"):
            for ch in "AZIJ":
                if ln.value(ch, None) is None:
                    raise Refused("missing parameter %s" % ch)
            stops = [(ln.value("A"), self.mixes[self._check_tool(ln.int("I"))]),
                     (ln.value("Z"), self.mixes[self._check_tool(ln.int("J"))])]
            alias = self._check_tool(ln.int("T")) if ln.has("T") else None
            self.gradient = Gradient(stops, "Z", alias, self.drives)
            self.gradient_on = True
        if ln.has("S"):
            if self.gradient is None:
                raise Refused("no gradient set")
            self.gradient_on = ln.int("S", lo=0, hi=1) == 1
        self._after_gradient_change()

    def m169(self, ln):
        words = ln.text.split()
        if not words:
            self.gradient = None
            self.gradient_on = False
            self._after_gradient_change()
            return
        alias = along = stops = None
        for word in words:
            letter, value = word[0].upper(), word[1:]
            if letter == "T":
                if not value.lstrip("+-").isdigit():
                    raise Refused("malformed tool")
                alias = self._check_tool(int(value))
            elif letter in "ZE":
                along, stops = letter, []
                for stop in value.split(","):
                    parts = stop.split(":")
                    if len(parts) != 2 or not parts[1].lstrip("+-").isdigit():
                        raise Refused("malformed stop list")
                    stops.append((_decimal_list(parts[0])[0],
                                  self.mixes[self._check_tool(int(parts[1]))]))
            else:
                raise Refused("M169 takes T and Z or E stops")
        if stops is None:
            raise Refused("M169 needs stops")
        self.gradient = Gradient(stops, along, alias, self.drives)
        self.gradient_on = True
        self.extruded_nm = 0
        self._after_gradient_change()

    def tool(self, ln):
        tool = self._check_tool(int(ln.command[1:]))
        if tool != self.active:
            self._activate(tool)

    def run(self, ln):
        cmd = ln.command
        if cmd in ("G0", "G1"):
            self.g1(ln)
        elif cmd in ("G2", "G3"):
            self.arc(ln)
        elif cmd in ("G17", "G18", "G19"):
            self.plane = int(cmd[1:]) - 17
        elif cmd[:1] == "T":
            self.tool(ln)
        elif cmd in ("G90", "G91"):
            self.absolute = self.absolute_e = cmd == "G90"
        elif cmd in ("M82", "M83"):
            self.absolute_e = cmd == "M82"
        elif cmd == "G4":
            if ln.value("S", Fraction(0)) + ln.value("P", Fraction(0)) / 1000 > 0:
                self.synchronize()
        elif cmd == "M211" and ln.has("S"):
            self.soft_limits = ln.int("S", lo=0, hi=1) == 1
        else:
            handler = _HANDLERS.get(cmd)
            if handler:
                if cmd in SYNC_COMMANDS and cmd != "M92":
                    self.synchronize()
                handler(self, ln)
            elif cmd in SYNC_COMMANDS:
                self.synchronize()

    def finish(self):
        self.synchronize()
        steps = {a: self.axis_net[i] for i, a in enumerate("xyz")}
        steps.update({"e%d" % d: self.planner.steps[d] for d in range(self.drives)})
        return steps


_HANDLERS = {"G10": Machine.g10, "G11": Machine.g11, "G28": Machine.g28,
             "G92": Machine.g92, "M92": Machine.m92, "M163": Machine.m163,
             "M164": Machine.m164, "M165": Machine.m165, "M567": Machine.m567,
             "M168": Machine.m168, "M166": Machine.m166, "M169": Machine.m169,
             "M221": Machine.m221, "M486": Machine.m486,
             "M900": Machine.m900}


def expected(gcode_path, settings):
    """Run a G-code file through the model. Returns {"steps": {axis: net steps the
    trace must show}, "moves": [(line, weights, drive targets)] for every block that
    steps a drive (weights: its mix in steps, each drive's weight times its steps/mm;
    None for a replayed retraction), "moved": {axes and drives
    some block steps}, "unmodelled":
    {command: first line}, "refused": [(line, reason)], "arcs": [every arc's geometry,
    see Machine._arc_record], "axis_blocks": array('q') of line, X, Y, Z steps of every
    block that steps an axis, in order}."""
    m = Machine(settings)
    intake = Intake(int(m.settings["line_buffer_bytes"]))
    unmodelled = {}
    refused = []
    uploading = False  # M28 ... M29: lines go to a file on the printer, not run
    with open(gcode_path, "rb") as f:
        for number, raw in enumerate(f, 1):
            m.line = number
            raw = raw.rstrip(b"\r\n")
            try:
                ln = intake.line(raw)
                if ln is None or not ln.command:
                    continue
                if uploading:
                    uploading = ln.command != "M29"
                    continue
                if ln.command == "M28":
                    uploading = True
                    continue
                if ln.command in UNMODELLED:
                    unmodelled.setdefault(ln.command, number)
                m.run(ln)
            except Refused as e:
                refused.append((number, str(e)))
    steps = m.finish()
    return {"steps": steps, "moves": m.blocks, "moved": m.moved, "unmodelled": unmodelled,
            "refused": refused, "arcs": m.arcs, "axis_blocks": m.axis_blocks,
            "advance": m.advance_blocks if m.advance_used else None}
