# Motion commands: G0/G1, G2/G3, G4, G17/G18/G19, G28, G90/G91, G92, G20/G21, M82/M83,
# M400, M17/M18/M84.
from math import atan2, pi, sqrt
# Handlers parse and check; the planner does the work.
from array import array
from mixfw.gcode import GcodeError, letter_index
from mixfw.filament import nm_from_mm, scaled_round, spm_digits, steps_per_nm, NM_PER_MM
from mixfw.ramp import array_offsets
from mixfw import stepper as st

_AXIS_LETTERS = const("XYZE")
_AXIS_INDEX = tuple(letter_index(ch) for ch in _AXIS_LETTERS)
# Constants, which the compiler folds: a module's global costs every line a lookup.
# gcode.letter_index's (copies):
_F_INDEX = const(5)  # letter_index("F")
_X_INDEX = const(23)  # letter_index("X"), then Y and Z
_E_INDEX = const(4)  # letter_index("E")
_NM_DECIMALS = const(6)  # axis words are read as exact nanometres
# compat.MASK30: a position's nanometres stay within +-_MASK30, the chips' small ints.
_MASK30 = const(0x3FFFFFFF)
_XYZ_BITS = const(7 << _X_INDEX)
# X Y Z E in a parsed line's masks: the words a G0/G1 moves by, which xyz_targets reads.
MOVE_BITS = const(_XYZ_BITS | 1 << _E_INDEX)
# xyz_targets's verdicts on a word, for axis a: -_BEYOND - a, -_OUTSIDE - a.
_BEYOND = const(1)
_OUTSIDE = const(4)
# and its bits otherwise, beside the axes named (bits 0 to 2).
_E_READ = const(8)
_AXIS_MOVED = const(16)
# Words of its steps/mm array after the digits (9): each axis's latest machine position
# and its step (2 words an axis), and a bit per axis whose pair holds.
_SPM_LAST = const(9)
_SPM_HELD = const(15)
# Then the modes it moves in (_MODE_*: G90/G91, M211 and the soft_limits option), as
# a word it reads rather than arguments (each costs the chip about 1 us a call: see
# ramp.py).
_SPM_MODES = const(16)
_MODE_RELATIVE = const(1)
_MODE_SOFT = const(2)
_MODE_SOFT_OPTION = const(4)  # the option as last applied: M211 holds until it changes
# Then where the arrays it reads are (ramp.array_offsets): the parsed line's
# mantissas and decimals, G92's offsets, the steps it works out, the soft limits'
# travel. ptr32() of an address costs nothing, of an array much more (see
# ramp.array_offsets).
_SPM_MANT = const(17)
_SPM_DEC = const(18)
_SPM_OFF = const(19)
_SPM_STEPS = const(20)
_SPM_TRAVEL = const(21)
SPM_WORDS = const(22)  # the places are its last five words
_AT_BIAS = const(0x20000000)  # ramp.py's (a copy): as array_offsets adds
# 10**12 (NM_PER_MM * SPM_SCALE) in 30-bit limbs, and 2 * 10**12 = 2**13 * (5**6)**2.
_E12_HI = const(931)
_E12_LO = const(346361856)
_FIVE6 = const(15625)
# retract_policy: retractions follow the mix and run it exactly backwards, or pull every
# drive equally (and push them back equally), or take back exactly the steps each drive
# made in the latest extrusion (and push exactly those back).
_RETRACT_FOLLOW_MIX = const(0)
_RETRACT_EQUAL = const(1)
_RETRACT_REPLAY = const(2)


# G2/G3. An arc's angles are binary: a full turn is 2**30, so they wrap by a mask.
_ARC_TURN = const(0x40000000)
# The modes word's bits 3-4: the plane (0: G17 XY, 1: G18 ZX, 2: G19 YZ).
_MODE_PLANE_SHIFT = const(3)
# letter_index of I, J, K, P, R
_I_INDEX = const(8)
_K_INDEX = const(10)
_P_INDEX = const(15)
_R_INDEX = const(17)
# An R that falls short of half the chord by this much still makes a half circle, and
# an I J K centre may be this much further from the end than from the start: what a
# slicer's 3 decimals lose. Beyond it the arc is refused.
_ARC_SLACK_NM = const(10000)
# Segments are figured in floats: a segment count within 0.001 of a
# whole number counts as that number, so a quarter circle in 72 a circle is 18 on
# every port.
# The CORDIC gain of _ARC_ITERATIONS turns, times 2**30.
_ARC_K30 = const(652032874)
_ARC_ITERATIONS = const(28)
# atan(2**-i) in binary angle (i = 0..27).
_ARC_ATAN = array("i", (
    134217728, 79233351, 41864727, 21251189, 10666833, 5338616, 2669960, 1335061,
    667541, 333772, 166886, 83443, 41722, 20861, 10430, 5215, 2608, 1304, 652, 326,
    163, 81, 41, 20, 10, 5, 3, 1))
# Words of Motion._arc: the segment's end X Y Z (nm), then the start's vector from the
# centre (pre-scaled by the CORDIC gain, then not), in units of 2**shift nm, the
# segment count, three counters (angle, the third axis, E: value, quotient, remainder
# over n, running remainder), the start's two plane coordinates and the third axis's
# start, and the three axes' indexes (plane first, second, third).
_ARC_KX = const(3)
_ARC_X0 = const(5)
_ARC_SHIFT = const(7)
_ARC_N = const(8)
_ARC_ACC = const(9)  # 3 counters of 4 words
_ARC_P0 = const(21)
_ARC_AXES = const(24)
_ARC_WORDS = const(27)


@micropython.viper
def _arc_point(pos_buf) -> int:
    """The next segment's end of the arc Motion._arc (pos_buf) describes, into its
    words 0 to 2 (X Y Z nm): the start's vector from the centre turned by the angle so
    far, added to the start; the third axis and E move on by their share. Every end is
    worked out anew from the start, not from the end before it, so nothing drifts; the
    counters are exact integers (angle = total * i // n). The turn is a quarter turn's
    multiple exactly, then CORDIC in integers within +-45 degrees: no float, so no heap.
    Returns the segment's E in nm."""
    arc = ptr32(pos_buf)
    atan = ptr32(_ARC_ATAN)
    n = arc[_ARC_N]
    e_was = 0
    for j in range(3):
        k = _ARC_ACC + 4 * j
        v = arc[k]
        if v > _MASK30:  # negative: a 64-bit port's ptr32 reads it zero-extended
            v = 0 - ((0 - v) & _MASK30)
        q = arc[k + 1]
        if q > _MASK30:
            q = 0 - ((0 - q) & _MASK30)
        if j == 2:
            e_was = v
        v += q
        rem = arc[k + 3] + arc[k + 2]
        if rem >= n:
            rem -= n
            v += 1
        if j == 0:
            v &= _ARC_TURN - 1
        arc[k] = v
        arc[k + 3] = rem
    angle = arc[_ARC_ACC]
    quarters = (angle + (_ARC_TURN >> 3)) >> 28
    a = angle - (quarters << 28)  # within +-1/8 turn
    x = arc[_ARC_KX]
    y = arc[_ARC_KX + 1]
    if x > _MASK30:
        x = 0 - ((0 - x) & _MASK30)
    if y > _MASK30:
        y = 0 - ((0 - y) & _MASK30)
    quarters &= 3
    if quarters == 1:
        t = x
        x = 0 - y
        y = t
    elif quarters == 2:
        x = 0 - x
        y = 0 - y
    elif quarters == 3:
        t = x
        x = y
        y = 0 - t
    for i in range(_ARC_ITERATIONS):
        dx = x >> i
        dy = y >> i
        if a >= 0:
            x -= dy
            y += dx
            a -= atan[i]
        else:
            x += dy
            y -= dx
            a += atan[i]
    shift = arc[_ARC_SHIFT]
    x0 = arc[_ARC_X0]
    y0 = arc[_ARC_X0 + 1]
    if x0 > _MASK30:
        x0 = 0 - ((0 - x0) & _MASK30)
    if y0 > _MASK30:
        y0 = 0 - ((0 - y0) & _MASK30)
    arc[arc[_ARC_AXES]] = arc[_ARC_P0] + ((x - x0) << shift)
    arc[arc[_ARC_AXES + 1]] = arc[_ARC_P0 + 1] + ((y - y0) << shift)
    arc[arc[_ARC_AXES + 2]] = arc[_ARC_P0 + 2] + arc[_ARC_ACC + 4]
    e = arc[_ARC_ACC + 8]
    if e > _MASK30:
        e = 0 - ((0 - e) & _MASK30)
    return e - e_was


@micropython.viper
def xyz_targets(spm_buf, named: int, pos_buf, target_buf, at) -> int:
    """The X Y Z a G0/G1 line names with a number (bits of letter indexes in named),
    from its parsed words (gcode.Line's mant and decimals), as exact nanometres into
    target: pos's where not named, added to pos's if relative (spm_buf's modes word). Further decimals round
    half away from zero, as Line.fixed_at. Then each axis's absolute step at its
    machine position (target + G92's offset) into the steps array, with the steps/mm
    filament.spm_digits put in spm_buf (SPM_WORDS: the step an axis had at the same
    position is taken again, as a line mostly leaves Z). An E word named goes, as
    nanometres, into the steps array's word 4 where it is within +-_MASK30. The line's
    words, the offsets, the steps and the soft limits' travel are the arrays whose
    places spm_buf holds (_SPM_MANT on: ramp.array_offsets).

    A step is div_round(nm * spm_fixed, NM_PER_MM * SPM_SCALE), the integer
    filament.scaled_round gives, in small ints where scaled_round's products pass them
    for most steps/mm: (2 |nm| spm + 10**12) in three 30-bit limbs, shifted right 13
    bits, then over 5**6 twice, each in three machine divisions. Written out here, as
    a call of its own would cost the chip about 5 us an axis.

    Returns bits: the axes named (X=1, Y=2, Z=4), _E_READ if the steps' word 4 holds
    E's word, and (_AXIS_MOVED << a) for each axis a whose step differs from at[a]
    (at: the queue's position, or None). Or, refused, -_BEYOND - a if axis a's word,
    target or machine position is beyond +-_MASK30 nanometres (1,073 mm, the chips'
    small ints), or with soft limits (the modes word; the travel: each axis's in nm)
    -_OUTSIDE - a if its machine position is outside 0..travel. pos, target, the
    offsets and the travel are arrays 'i' of X Y Z nanometres, read and written as
    words. In one viper call, where Line.fixed_at, the sums, the checks and
    scaled_round, per axis, would cost the chip about 0.15 ms a line."""
    spm = ptr32(spm_buf)
    base = int(spm) - _AT_BIAS  # the arrays' offsets are from here (_SPM_MANT on)
    mant = ptr32(base + spm[_SPM_MANT])
    dec = ptr8(base + spm[_SPM_DEC])
    steps = ptr32(base + spm[_SPM_STEPS])
    pos = ptr32(pos_buf)
    target = ptr32(target_buf)
    off = ptr32(base + spm[_SPM_OFF])
    relative = spm[_SPM_MODES] & _MODE_RELATIVE
    soft = spm[_SPM_MODES] & _MODE_SOFT
    travel = spm  # read only with soft limits on
    if soft:
        travel = ptr32(base + spm[_SPM_TRAVEL])
    moved = 0
    compare = 1 if at else 0
    for a in range(4):
        k = _X_INDEX + a
        if a == 3:
            k = _E_INDEX
        word = (named >> k) & 1
        if word:
            m = mant[k]
            if (m >> 30) & 1:  # |m| < 10**9: bit 30 is the sign, which a 64-bit build's
                m |= ~_MASK30  # viper leaves unextended
            neg = m < 0
            if neg:
                m = 0 - m
            d = dec[k]
            if d > 6:
                div = 10
                while d > 7:
                    div *= 10
                    d -= 1
                q = m // div
                if 2 * (m - q * div) >= div:
                    q += 1
                m = q
            else:
                while d < 6:
                    if m > _MASK30 // 10:
                        if a == 3:
                            return moved  # E: read in Python (big ints)
                        return 0 - _BEYOND - a
                    m *= 10
                    d += 1
            if neg:
                m = 0 - m
            if a == 3:
                steps[4] = m
                return moved | _E_READ
            if relative:
                p = pos[a]
                if p > _MASK30:  # negative: a 64-bit port's ptr32 reads it zero-extended
                    p = 0 - ((0 - p) & _MASK30)
                m += p
            if m > _MASK30 or m < 0 - _MASK30:
                return 0 - _BEYOND - a
            moved |= 1 << a
        elif a == 3:
            return moved
        else:
            m = pos[a]
            if m > _MASK30:
                m = 0 - ((0 - m) & _MASK30)
        target[a] = m
        o = off[a]
        if o > _MASK30:
            o = 0 - ((0 - o) & _MASK30)
        nm = m + o  # the machine's position
        if nm > _MASK30 or nm < 0 - _MASK30:
            return 0 - _BEYOND - a
        if word and soft and (nm < -1 or nm > travel[a] + 1):
            return 0 - _OUTSIDE - a
        last = _SPM_LAST + 2 * a
        if (spm[_SPM_HELD] >> a) & 1 and spm[last] == nm:
            s = spm[last + 1]
        else:
            # |nm| * spm in limbs (h2, h1, h0), from 15-bit digit products.
            x = nm if nm >= 0 else 0 - nm
            x1 = x >> 15
            x0 = x & 0x7FFF
            j = 3 * a
            d1 = x1 * spm[j] + x0 * spm[j + 1]
            d3 = x1 * spm[j + 2]
            h0 = x0 * spm[j] + ((d1 & 0x7FFF) << 15)
            h1 = x1 * spm[j + 1] + x0 * spm[j + 2] + (d1 >> 15) + (h0 >> 30)
            h0 &= _MASK30
            h2 = h1 >> 30
            h1 = (h1 & _MASK30) + ((d3 & 0x7FFF) << 15)
            h2 += (h1 >> 30) + (d3 >> 15)
            h1 &= _MASK30
            # times 2, plus 10**12
            h0 = h0 << 1
            h1 = (h1 << 1) + (h0 >> 30)
            h0 = (h0 & _MASK30) + _E12_LO
            h2 = (h2 << 1) + (h1 >> 30)
            h1 = (h1 & _MASK30) + _E12_HI + (h0 >> 30)
            h0 &= _MASK30
            h2 += h1 >> 30
            h1 &= _MASK30
            # >> 13, then // 5**6 twice (remainders below 2**14, 15-bit digits): below
            # 2**27
            hi = (h1 >> 13) | (h2 << 17)
            s = (h0 >> 13) | ((h1 & 0x1FFF) << 17)
            for _ in range(2):
                q = hi // _FIVE6
                r = hi - q * _FIVE6
                hi = q
                x = (r << 15) | (s >> 15)
                q = x // _FIVE6
                r = x - q * _FIVE6
                x = (r << 15) | (s & 0x7FFF)
                s = (q << 15) | (x // _FIVE6)
            if nm < 0:
                s = 0 - s
            spm[last] = nm
            spm[last + 1] = s
            spm[_SPM_HELD] |= 1 << a
        steps[a] = s
        if compare and s != int(at[a]):
            moved |= _AXIS_MOVED << a
    return moved


class Motion:
    """Modal state owned by the command side: logical position, G92 offsets, modes."""

    def __init__(self, planner, pins, settings, reply):
        self.reply = reply
        self.planner = planner
        self.queue = planner  # where moves go: the planner, or Transitions in front of it
        self.pins = pins
        self.feed = None  # step_backend pio_dma's Feed (assemble sets it)
        # Logical X Y Z as G-code sees it, and their G92 offsets (machine = logical +
        # offset), in integers (nanometres) as E is: relative moves add up over a whole
        # print, and a chip's 32-bit floats would drift.
        # Arrays, which xyz_targets reads as words (list items are a call each).
        self.pos_nm = array("i", bytes(12))
        self._spare_nm = array("i", bytes(12))  # g1's target, then pos_nm: see g1
        self.offset_nm = array("i", bytes(12))
        # X Y Z's steps/mm for xyz_targets (and the steps it keeps), and the steps it
        # works out, then E's, then an E word in nanometres (see xyz_targets).
        self._xyz_spm = array("i", bytes(4 * SPM_WORDS))
        # The planner's own: add_move reads the targets there as words.
        self._steps_out = planner.target_steps
        array_offsets(self._xyz_spm, _SPM_OFF, (self.offset_nm, self._steps_out))
        self.line = None  # the parsed line whose words xyz_targets reads: see g1
        self._set_steps_per_mm(planner.steps_per_mm)
        self.e_nm = 0  # logical E
        self.e_offset_nm = 0  # filament = logical E + offset (G92 E, G10/G11)
        self.absolute_e = True  # G90/G91 for X Y Z: in _xyz_spm's modes word
        # The speed moves run at: the last F word's (f_mm_s) times M220's percentage.
        self.f_mm_s = self.feed_mm_s = settings["default_feed_mm_s"]
        self.feed_pct = 100
        self.feed_pct_kept = 100  # M220 B keeps it, R brings it back
        # M221: the active tool's flow percentage (Mixing sets it), and what its moves'
        # filament carried below a nanometre: see flowed.
        self.flow_pct = 100
        self._flow_carry = 0
        # Filament retracted and not yet pushed back, whatever the policy; while an
        # object M486 cancelled is skipped, what it would be had the object printed.
        self.unprimed_nm = 0
        self.skipping = False
        self._skip_unprimed_nm = 0
        # Either of the two: a printing line reads one word to know it has neither.
        self.e_changed = False
        self._travel(settings["travel_mm"])
        self.homing_feed_mm_s = settings["homing_feed_mm_s"]
        self.drives = settings["drives"]
        self.dir_masks = pins.axis_dir_masks()
        self.enabled = 0  # bit per driver: X Y Z then drives
        self.homed = 0  # bit per axis homed since its driver was last off (G29 asks)
        self.before_home = []  # fn() each, as G28 starts (levelling turns off: mesh.py)
        self._drive_bits = ((1 << self.drives) - 1) << 3
        if settings.get("soft_limits", True):  # in _xyz_spm's modes word (see there)
            self._xyz_spm[_SPM_MODES] = _MODE_SOFT | _MODE_SOFT_OPTION
        # Longest E move accepted, as Marlin's PREVENT_LENGTHY_EXTRUDE.
        self.max_extrude_mm = settings.get("max_extrude_mm", 200.0)
        self._max_extrude_nm = nm_from_mm(self.max_extrude_mm)
        self.retracted_nm = 0  # retraction not yet undone (equal and replay policies)
        self.fw_retracted = False
        self._retraction_settings(settings)
        # G2/G3: the arc worked out per line (words _ARC_*), and its segments' limits.
        self._arc = array("i", bytes(4 * _ARC_WORDS))
        self._arc_settings(settings)
        # Called before a move that extrudes; each raises GcodeError to refuse it
        # (cold extrusion, ...). Once they have all passed, they are called again only
        # after recheck_guards(), which their owners call where a verdict may change (a
        # reading, a setting): a guard's call costs the chip 12 us a line and more.
        self.extrusion_guards = []
        self._guards_passed = False
        # Called as fn(z2_nm, e_nm) before a move that extrudes (gradients set the mix):
        # twice the middle Z of the move, and its filament.
        self.before_extrude = []

    def apply(self, settings):
        """Take changed settings (M930, M92, M201...): the queue drains first, and the
        axes stay where they are in millimetres."""
        p = self.planner
        p.synchronize()
        p.set_steps_per_mm(settings["steps_per_mm"])
        p.set_drive_steps(settings["drive_steps_per_mm"])
        p.set_limits(settings)
        self._set_steps_per_mm(p.steps_per_mm)
        p.set_position_steps(self.machine_steps())
        self._travel(settings["travel_mm"])
        self.homing_feed_mm_s = settings["homing_feed_mm_s"]
        # M211 holds until M211 or a restart, as Marlin's does: the option changes it
        # only when the option itself changes (any setting's change applies them all).
        on = settings.get("soft_limits", True)
        modes = self._xyz_spm[_SPM_MODES]
        if bool(on) != bool(modes & _MODE_SOFT_OPTION):
            self._xyz_spm[_SPM_MODES] = modes & (_MODE_RELATIVE | 3 << _MODE_PLANE_SHIFT) | (
                _MODE_SOFT | _MODE_SOFT_OPTION if on else 0)
        self.max_extrude_mm = settings.get("max_extrude_mm", 200.0)
        self._max_extrude_nm = nm_from_mm(self.max_extrude_mm)
        self._retraction_settings(settings)
        self._arc_settings(settings)

    def _arc_settings(self, settings):
        self._arc_mm = (settings.get("min_arc_segment_mm", 0.1),
                        settings.get("max_arc_segment_mm", 1.0),
                        settings.get("min_circle_segments", 72))

    def _set_steps_per_mm(self, steps_per_mm):
        self._xyz_per_nm = [steps_per_nm(s) for s in steps_per_mm[:3]]
        for i in range(3):
            spm_digits(steps_per_mm[i], self._xyz_spm, 3 * i)
        self._xyz_spm[_SPM_HELD] = 0  # the steps it held were of the steps/mm before

    def _travel(self, travel_mm):
        self.travel_mm = travel_mm
        # Positions stay within +-_MASK30: a longer travel is as good as that.
        self._travel_nm = array("i", [min(nm_from_mm(t), _MASK30) for t in travel_mm])
        array_offsets(self._xyz_spm, _SPM_TRAVEL, (self._travel_nm,))

    # A method, not a property: a class with a property makes every attribute stored on
    # its instances look for a setter first, about 11 us a store on the chip.
    def pos_mm(self):
        """The logical X Y Z E in mm, for reports."""
        n = self.pos_nm
        return (n[0] / NM_PER_MM, n[1] / NM_PER_MM, n[2] / NM_PER_MM, self.e_nm / NM_PER_MM)

    def _retraction_settings(self, settings):
        self.retract_policy = settings.get("retract_policy", _RETRACT_FOLLOW_MIX)
        self.planner.keep_extrusion = self.retract_policy == _RETRACT_REPLAY
        self.retract_mm = settings.get("retract_mm", 2.0)
        self.retract_nm = nm_from_mm(self.retract_mm)
        self.retract_feed_mm_s = settings.get("retract_feed_mm_s", 40.0)
        self.unretract_feed_mm_s = settings.get("unretract_feed_mm_s", 40.0)

    def resync(self):
        """After the queue was dropped: the logical X Y Z are where the axes are. E keeps
        its logical value; the drives' own positions were taken by the planner."""
        # The queue's: a levelling stage in front of the planner keeps the position
        # unlevelled (mesh.py).
        steps = self.queue.position_steps
        for i in range(3):
            # Back to the same steps when planned again: half a nanometre is far below
            # a step at any steps/mm the options allow.
            p, q = self._xyz_per_nm[i]
            self.pos_nm[i] = scaled_round(steps[i], q, p) \
                - self.offset_nm[i]

    def machine_steps(self):
        """X Y Z as absolute steps from the logical position; E as planned (drive steps).
        In the planner's target_steps: valid until the next call, G1 or move queued
        (the planner and Transitions copy what they keep)."""
        # No word named: the line's words are not read.
        verdict = xyz_targets(self._xyz_spm, 0, self.pos_nm, self._spare_nm, None)
        if verdict < 0:
            self._refuse_target(self.pos_nm, verdict)
        self._steps_out[3] = self.planner.position_steps[3]
        return self._steps_out

    def enable_for(self, axes_mask):
        want = axes_mask & 7
        if axes_mask & 8:
            want |= ((1 << self.drives) - 1) << 3
        if not want & ~self.enabled:
            return  # every move: mostly all are on already
        for i in range(3 + self.drives):
            if (want >> i) & 1 and not (self.enabled >> i) & 1:
                self.pins.set_enabled(i, True)
        self.enabled |= want

    def disable(self, axes_mask):
        self.planner.synchronize()
        want = axes_mask & 7
        if axes_mask & 8:
            want |= ((1 << self.drives) - 1) << 3
        for i in range(3 + self.drives):
            if (want >> i) & 1:
                self.pins.set_enabled(i, False)
        self.enabled &= ~want
        self.homed &= ~want  # a motor off may be moved by hand, as Marlin takes it

    # G0/G1 X Y Z E F: straight move. Example: G1 X10 Y5 E0.4 F1800
    # Native code, as the planner's methods a line runs (see planner.py).
    @micropython.native
    def g1(self, line):
        present = line.present
        if (present >> _F_INDEX) & 1:
            f = line.float_at(_F_INDEX, -1.0)
            if f <= 0:
                raise GcodeError("feed rate F must be > 0, got %s" % f)
            self.f_mm_s = f / 60.0
            self.feed_mm_s = self.f_mm_s if self.feed_pct == 100 else \
                self.f_mm_s * self.feed_pct / 100
        if not present & MOVE_BITS:
            return None
        # The target goes in an array made once, which then becomes pos_nm, and pos_nm
        # the spare: an array a line would be garbage on the chips. pos_nm stays as it was
        # when the line is refused.
        pos = self.pos_nm
        target = self._spare_nm
        valued = line.valued
        if present & ~valued & _XYZ_BITS:
            for k in _AXIS_INDEX:
                line.fixed_at(k, _NM_DECIMALS)  # raises for the word with no number
        spm = self._xyz_spm
        if line is not self.line:  # mostly the same parser's line as the line before
            self.line = line
            array_offsets(spm, _SPM_MANT, (line.mant, line.decimals))
        moved = xyz_targets(spm, valued & MOVE_BITS, pos, target, self.queue.position_steps)
        steps = self._steps_out
        if moved < 0:
            self._refuse_target(target, moved)
        e_was = self.e_nm
        target_e_nm = e_was
        if (present >> _E_INDEX) & 1:
            if moved & _E_READ:
                v = steps[4]
            else:  # beyond +-1,073 mm, or no number (which this refuses)
                v = line.fixed_at(_E_INDEX, _NM_DECIMALS)
            target_e_nm = v if self.absolute_e else target_e_nm + v
        e_nm = target_e_nm - e_was
        xyz = (moved >> 4) & 7
        if e_nm:
            for fn in self.before_extrude:
                fn(pos[2] + target[2], e_nm)
            if self.e_changed:
                if self.skipping:  # a cancelled object's: the move goes, E is counted
                    e_nm = xyz = skipped(self, e_nm, self.flow_pct)
                else:
                    e_nm = flowed(self, e_nm)
        if xyz or e_nm:
            _queue(self, steps, xyz, e_nm, self.feed_mm_s)
        self.e_nm = target_e_nm
        self.pos_nm = target
        self._spare_nm = pos
        return None

    # G2/G3 X Y Z E F I J K R P: an arc clockwise (G2) or counter-clockwise (G3), seen
    # from the plane's third axis, in the plane G17/G18/G19 chose, to the end X Y Z E
    # (read as G1's). The centre is I J K, its offset from the start in the plane's two
    # letters (G17: I J; G18: K I; G19: J K), or R the radius (negative: the longer
    # way round). The third axis (a helix) and E move in proportion along the arc; P
    # adds whole turns. Each segment goes the way of a G1 line.
    # Example: G2 X20 Y10 I5 J0 E0.8 F1800
    # Bytecode, unlike g1: native code would take the chips' heap about 7 kB more, and
    # an arc's segments are long enough (a few ms each) for its loop's cost.
    def g2(self, line):
        present = line.present
        if (present >> _F_INDEX) & 1:
            f = line.float_at(_F_INDEX, -1.0)
            if f <= 0:
                raise GcodeError("feed rate F must be > 0, got %s" % f)
            self.f_mm_s = f / 60.0
            self.feed_mm_s = self.f_mm_s if self.feed_pct == 100 else \
                self.f_mm_s * self.feed_pct / 100
        spm = self._xyz_spm
        plane = (spm[_SPM_MODES] >> _MODE_PLANE_SHIFT) & 3
        a = (0, 2, 1)[plane]  # the plane's first axis, its second, and the third
        b = (1, 0, 2)[plane]
        c = (2, 1, 0)[plane]
        if (present >> (_I_INDEX + c)) & 1:
            raise GcodeError("G%d in the %s%s plane takes %s%s or R, not %s"
                             % (line.number, _AXIS_LETTERS[a], _AXIS_LETTERS[b],
                                "IJK"[a], "IJK"[b], "IJK"[c]))
        centred = present & (1 << (_I_INDEX + a) | 1 << (_I_INDEX + b))
        if (present >> _R_INDEX) & 1:
            if centred:
                raise GcodeError("an arc takes R or a centre (I J K), not both")
        elif not centred:
            raise GcodeError("an arc needs its centre (I J K) or radius (R)")
        turns = line.int("P", 0)
        if not 0 <= turns <= 1000:
            raise GcodeError("P (extra turns) must be 0..1000, got %d" % turns)
        # The end, as G1 reads it: pos_nm stays as it was when the line is refused.
        pos = self.pos_nm
        target = self._spare_nm
        valued = line.valued
        if present & ~valued & _XYZ_BITS:
            for k in _AXIS_INDEX:
                line.fixed_at(k, _NM_DECIMALS)  # raises for the word with no number
        if line is not self.line:
            self.line = line
            array_offsets(spm, _SPM_MANT, (line.mant, line.decimals))
        moved = xyz_targets(spm, valued & MOVE_BITS, pos, target, None)
        steps = self._steps_out
        if moved < 0:
            self._refuse_target(target, moved)
        e_was = self.e_nm
        target_e_nm = e_was
        if (present >> _E_INDEX) & 1:
            if moved & _E_READ:
                v = steps[4]
            else:
                v = line.fixed_at(_E_INDEX, _NM_DECIMALS)
            target_e_nm = v if self.absolute_e else target_e_nm + v
        e_nm = target_e_nm - e_was
        if e_nm > self._max_extrude_nm or e_nm < -self._max_extrude_nm:
            raise GcodeError("extrusion of %.1f mm in one move is over max_extrude_mm %g"
                             % (abs(e_nm) / NM_PER_MM, self.max_extrude_mm))
        along = target[c] - pos[c]
        if along > _MASK30 or along < -_MASK30:
            self._refuse_target(target, -_BEYOND - c)
        # The end from the start in the plane, and the centre's offset from the start.
        dx = target[a] - pos[a]
        dy = target[b] - pos[b]
        cw = line.number == 2
        if (present >> _R_INDEX) & 1:
            r = line.float_at(_R_INDEX)
            r_nm = abs(r) * NM_PER_MM
            chord = sqrt(float(dx) * dx + float(dy) * dy)
            if not chord:
                raise GcodeError("an arc by R needs an end apart from its start; a full "
                                 "circle takes I J K")
            h = r_nm * r_nm - chord * chord / 4
            if r_nm < chord / 2 - _ARC_SLACK_NM:
                raise GcodeError("R%g cannot reach an end %.3f mm away"
                                 % (r, chord / NM_PER_MM))
            # Toward the centre from the chord's middle: left of the chord counter-
            # clockwise, right clockwise; a negative R swaps them (the longer way).
            h = (sqrt(h) if h > 0 else 0.0) / chord
            if cw != (r < 0):
                h = -h
            ox = dx / 2 - h * dy
            oy = dy / 2 + h * dx
            ox = int(ox + 0.5) if ox >= 0 else -int(0.5 - ox)
            oy = int(oy + 0.5) if oy >= 0 else -int(0.5 - oy)
        else:
            ox = line.fixed_at(_I_INDEX + a, _NM_DECIMALS, 0)
            oy = line.fixed_at(_I_INDEX + b, _NM_DECIMALS, 0)
        if not (ox or oy):
            raise GcodeError("arc radius is zero")
        r_nm = sqrt(float(ox) * ox + float(oy) * oy)
        r_end = sqrt(float(dx - ox) * (dx - ox) + float(dy - oy) * (dy - oy))
        if abs(r_end - r_nm) > _ARC_SLACK_NM:
            raise GcodeError("the arc's end is %.3f mm from its centre, its start %.3f mm"
                             % (r_end / NM_PER_MM, r_nm / NM_PER_MM))
        # The turn from start to end, in binary angle, the arc's way round; an end at
        # the start is a full turn.
        angle = int((atan2(dy - oy, dx - ox) - atan2(-oy, -ox)) / (2 * pi) * _ARC_TURN)
        if cw:
            angle = -(-angle % _ARC_TURN or (_ARC_TURN if not (dx or dy) else 0)) \
                - turns * _ARC_TURN
        else:
            angle = (angle % _ARC_TURN or (_ARC_TURN if not (dx or dy) else 0)) \
                + turns * _ARC_TURN
        # Segments: at most max_arc_segment_mm and at least min_circle_segments a turn,
        # but none under min_arc_segment_mm; at least one.
        least_mm, most_mm, per_turn = self._arc_mm
        turned = abs(angle) / _ARC_TURN
        length_mm = sqrt((2 * pi * r_nm * turned) ** 2 + float(along) * along) / NM_PER_MM
        x = length_mm / most_mm - 0.001
        n = int(x) + (x > int(x))
        x = turned * per_turn - 0.001
        n = max(n, int(x) + (x > int(x)), 1)
        n = max(1, min(n, int(length_mm / least_mm + 0.001)))
        arc = self._arc
        if n > 1:
            # The start's vector from the centre, in units of 2**shift nm below 2**29,
            # so that CORDIC's sums stay within the chips' words.
            shift = 0
            while r_nm >= 0x20000000:
                r_nm /= 2
                shift += 1
            x = -ox >> shift
            y = -oy >> shift
            arc[_ARC_KX] = (x * _ARC_K30 + 0x20000000) >> 30
            arc[_ARC_KX + 1] = (y * _ARC_K30 + 0x20000000) >> 30
            arc[_ARC_X0] = x
            arc[_ARC_X0 + 1] = y
            arc[_ARC_SHIFT] = shift
            arc[_ARC_N] = n
            k = _ARC_ACC
            for total in (angle, along, e_nm):
                arc[k + 1] = total // n
                arc[k + 2] = total % n
                k += 4
            k = _ARC_P0
            for i in (a, b, c):
                arc[k] = pos[i]
                arc[k + 3] = i
                k += 1
            # Every segment's end is checked (soft limits, range) before one is queued:
            # xyz_targets checks the soft limits of the axes a line names, so here
            # they are checked for all three.
            soft = spm[_SPM_MODES] & _MODE_SOFT
            off = self.offset_nm
            travel = self._travel_nm
            for k in range(2):
                for i in range(_ARC_ACC, _ARC_ACC + 12, 4):
                    arc[i] = 0
                    arc[i + 3] = 0
                if k:
                    break
                for i in range(n - 1):
                    _arc_point(arc)
                    v = xyz_targets(spm, 0, arc, arc, None)
                    if v < 0:
                        self._refuse_target(arc, v)
                    if soft:
                        for j in range(3):
                            v = arc[j] + off[j]
                            if v < -1 or v > travel[j] + 1:
                                self._refuse_target(arc, -_OUTSIDE - j)
        if e_nm and not self._guards_passed:
            for guard in self.extrusion_guards:
                guard()
            self._guards_passed = True
        z_nm = pos[2]
        e_sum = 0
        end = arc
        for i in range(n):
            if i < n - 1:
                e = _arc_point(arc)
            else:
                end = target  # the last segment ends exactly at the end
                e = e_nm - e_sum
            moved = xyz_targets(spm, 0, end, end, self.queue.position_steps)
            xyz = (moved >> 4) & 7
            e_sum += e
            if e:
                for fn in self.before_extrude:
                    fn(z_nm + end[2], e)
                if self.skipping:
                    e = xyz = skipped(self, e, self.flow_pct)
                elif self.flow_pct != 100:
                    e = flowed(self, e)
            if xyz or e:
                _queue(self, steps, xyz, e, self.feed_mm_s)
            z_nm = end[2]
        self.e_nm = target_e_nm
        self.pos_nm = target
        self._spare_nm = pos
        return None

    # M220 [S<percent>] [B] [R]: the speed of G0-G3 moves from now on, as a percentage of
    # their F (OctoPrint's feed rate slider); B keeps the percentage it had, R brings the
    # kept one back. No words: report, as Marlin's "FR:100%". Example: M220 S120
    def m220(self, line):
        if line.has("B"):
            self.feed_pct_kept = self.feed_pct
        pct = line.int("S", self.feed_pct, lo=1, hi=999)
        if line.has("R"):
            pct = self.feed_pct_kept
        if not line.present:
            self.reply("FR:%d%%" % pct)
        self.feed_pct = pct
        self.feed_mm_s = self.f_mm_s if pct == 100 else self.f_mm_s * pct / 100

    # G17 / G18 / G19: the plane of G2/G3 arcs: XY, ZX or YZ.
    def g17(self, line):
        spm = self._xyz_spm
        spm[_SPM_MODES] = spm[_SPM_MODES] & ~(3 << _MODE_PLANE_SHIFT) | \
            (line.number - 17) << _MODE_PLANE_SHIFT

    def recheck_guards(self):
        """The next extruding move calls the extrusion guards again."""
        self._guards_passed = False

    def _refuse_target(self, target, verdict):
        if verdict <= -_OUTSIDE:
            i = -_OUTSIDE - verdict
            raise GcodeError("move to %s%.3f is outside the soft limits 0..%g mm"
                             % (_AXIS_LETTERS[i], target[i] / NM_PER_MM, self.travel_mm[i]))
        raise GcodeError("%s beyond +-%d mm: positions are kept in 32-bit integers of "
                         "nanometres" % (_AXIS_LETTERS[-_BEYOND - verdict],
                                         _MASK30 // NM_PER_MM))

    # G10: firmware retraction by retract_mm at retract_feed_mm_s; the logical E stays.
    def g10(self, line):
        if self.fw_retracted:
            return
        self._fw_retract(-self.retract_nm, self.retract_feed_mm_s)
        self.fw_retracted = True

    # G11: undo G10.
    def g11(self, line):
        if not self.fw_retracted:
            return
        self._fw_retract(self.retract_nm, self.unretract_feed_mm_s)
        self.fw_retracted = False

    def skip(self, on):
        """M486: from now on the moves of a cancelled object are skipped (on), or not:
        travel runs, extrusion is counted and not fed. At the end the filament is
        retracted or pushed back to where the object's moves would have left it, so
        the next object starts as it would have."""
        if on and not self.skipping:
            self._skip_unprimed_nm = self.unprimed_nm
        elif not on and self.skipping:
            self.skipping = False
            e_nm = self.unprimed_nm - self._skip_unprimed_nm
            if e_nm:
                steps = self._steps_out
                at = self.queue.position_steps
                for i in range(4):  # the E move starts and ends where the axes are
                    steps[i] = at[i]
                _queue(self, steps, 0, e_nm, self.unretract_feed_mm_s if e_nm > 0
                       else self.retract_feed_mm_s)
        self.skipping = on
        self.set_flow(self.flow_pct)

    def set_flow(self, pct):
        """M221: the active tool's flow percentage."""
        self.flow_pct = pct
        self.e_changed = self.skipping or pct != 100

    def travel_to(self, target_nm, feed_mm_s):
        """A move the firmware makes of itself (M600's park and return) to the logical
        X Y Z target_nm (nanometres), with no filament; outside the soft limits it is
        refused, as G1's."""
        verdict = xyz_targets(self._xyz_spm, 0, target_nm, self._spare_nm, None)
        if verdict >= 0 and self._xyz_spm[_SPM_MODES] & _MODE_SOFT:
            for i in range(3):
                at = target_nm[i] + self.offset_nm[i]
                if at < -1 or at > self._travel_nm[i] + 1:
                    verdict = -_OUTSIDE - i
        if verdict < 0:
            self._refuse_target(target_nm, verdict)
        _queue(self, self._steps_out, 7, 0, feed_mm_s)
        for i in range(3):
            self.pos_nm[i] = target_nm[i]

    def feed_filament(self, e_nm, feed_mm_s, drive=-1):
        """Filament in (e_nm > 0) or out where the head stands, made by the firmware of
        itself (M600): the logical E stays. drive: that drive alone; -1: the mix."""
        self.e_offset_nm += e_nm
        steps = self.machine_steps()
        if drive < 0:
            _queue(self, steps, 0, e_nm, feed_mm_s)
            return
        for guard in self.extrusion_guards:
            guard()
        self.enable_for(8)
        q = self.queue
        q.add_move(steps, feed_mm_s, dir_masks=self.dir_masks, e_nm=e_nm,
                   mix=(q.mix_id, tuple(int(i == drive) for i in range(self.drives))))

    def _fw_retract(self, e_nm, feed_mm_s):
        self.e_offset_nm += e_nm  # the filament moves; the logical E does not
        if self.skipping:  # in a cancelled object: counted, as its moves' E
            skipped(self, e_nm, 100)
            return
        _queue(self, self.machine_steps(), 0, e_nm, feed_mm_s)

    # G4 P<ms> | S<s>: dwell after the queued moves. Example: G4 P500
    def g4(self, line):
        seconds = line.float("S", 0.0) + line.float("P", 0.0) / 1000.0
        if seconds < 0:
            raise GcodeError("dwell time must be >= 0")
        if seconds > 0:
            # Queued, so the dwell is exact in time; then waited for, as in Marlin.
            self.planner.synchronize()
            self.planner.add_dwell(seconds)
            self.planner.synchronize()
        return None

    # G28 [X] [Y] [Z]: home the named axes, or all, to their min endstops. Example: G28 X Y
    def g28(self, line):
        axes = [i for i in range(3) if line.has(_AXIS_LETTERS[i])] or [0, 1, 2]
        for fn in self.before_home:
            fn()
        planner = self.planner
        mem = planner.mem
        feed = self.feed
        for i in axes:
            planner.synchronize()
            self.enable_for(1 << i)
            target = list(planner.position_steps)
            reach_mm = 1.5 * self.travel_mm[i]
            target[i] -= int(reach_mm * planner.steps_per_mm[i] + 0.5)
            if feed:
                feed.watch_endstop(self.pins.endstop_pins[i], self.pins.endstop_level)
            try:
                planner.add_move(target, self.homing_feed_mm_s[i], homing_axes=1 << i,
                                 dir_masks=self.dir_masks)
                if feed:
                    self._home_on_feed(i)
                else:
                    planner.synchronize()
            finally:
                if feed:
                    feed.watch_endstop(None)
            if not (mem[st.S_HOME_STOP] >> i) & 1:
                raise GcodeError("homing %s failed: no endstop within %.0f mm"
                                 % (_AXIS_LETTERS[i], reach_mm))
            mem[st.S_POS + i] = 0
            steps = list(planner.position_steps)
            steps[i] = 0
            planner.set_position_steps(steps)
            self.pos_nm[i] = 0
            self.offset_nm[i] = 0
            self.homed |= 1 << i
        return None

    def _home_on_feed(self, axis):
        """step_backend pio_dma: the step loop runs batches ahead of the pins, so it
        sees the endstop late, but the state machine holds the pins from the word after
        the switch (watch_endstop): once the endstop reads triggered, every step the
        pins never got is taken back, as on a quick stop, and the axis is where the
        switch is, as with the timer."""
        planner = self.planner
        bit = 1 << axis
        endstops = self.pins.endstops
        while planner.busy():
            if endstops() & bit:
                self.feed.stop_and_take_back()
                planner.abort()
                self.resync()
                planner.mem[st.S_HOME_STOP] |= bit
                self.feed.resume()
                return
            planner.idle()

    # G90 / G91: absolute / relative coordinates (E follows, as in Marlin).
    def g90(self, line):
        self._xyz_spm[_SPM_MODES] &= ~_MODE_RELATIVE
        self.absolute_e = True

    def g91(self, line):
        self._xyz_spm[_SPM_MODES] |= _MODE_RELATIVE
        self.absolute_e = False

    # M82 / M83: absolute / relative E only.
    def m82(self, line):
        self.absolute_e = True

    def m83(self, line):
        self.absolute_e = False

    # G92 [X Y Z E]: say where the axes are now, without moving. Example: G92 E0
    def g92(self, line):
        named = [i for i in range(4) if line.has(_AXIS_LETTERS[i])] or range(4)
        values = [line.fixed_at(_AXIS_INDEX[i], _NM_DECIMALS, 0) for i in named]
        for i, v in zip(named, values):
            # X Y Z and their offsets stay within what xyz_targets takes.
            if i < 3 and not (-_MASK30 <= v <= _MASK30 and
                              -_MASK30 <= self.offset_nm[i] + self.pos_nm[i] - v <= _MASK30):
                self._refuse_target(self.pos_nm, -_BEYOND - i)
        for i, v in zip(named, values):
            if i == 3:
                self.e_offset_nm += self.e_nm - v
                self.e_nm = v
            else:
                self.offset_nm[i] += self.pos_nm[i] - v
                self.pos_nm[i] = v

    # G20: inches are refused; G21: millimetres, the only unit.
    def g20(self, line):
        raise GcodeError("G20 (inch units) is not supported; use G21 (mm)")

    def g21(self, line):
        pass

    # M400: wait for every queued move to finish.
    def m400(self, line):
        self.planner.synchronize()

    def _axes_named(self, line):
        mask = 0
        for i in range(4):
            if line.has(_AXIS_LETTERS[i]):
                mask |= 1 << i
        return mask or 15

    # M17 [X Y Z E]: enable stepper drivers.
    def m17(self, line):
        self.enable_for(self._axes_named(line))

    # M18 / M84 [X Y Z E]: disable drivers once the queued moves are done.
    def m18(self, line):
        if line.has("S"):
            raise GcodeError("M18/M84 S (idle timeout) is not supported")
        self.disable(self._axes_named(line))


    # M119: endstop states, in Marlin's form.
    def m119(self, line):
        hit = self.pins.endstops()
        self.reply("Reporting endstop status")
        for i in range(3):
            self.reply("%s_min: %s" % ("xyz"[i], "TRIGGERED" if (hit >> i) & 1 else "open"))

    # M211 [S0|S1]: soft limits off/on; no S reports.
    def m211(self, line):
        spm = self._xyz_spm
        if line.has("S"):
            on = _MODE_SOFT if line.int("S", lo=0, hi=1) else 0
            spm[_SPM_MODES] = spm[_SPM_MODES] & ~_MODE_SOFT | on
        self.reply("echo:Soft endstops: %s" % ("On" if spm[_SPM_MODES] & _MODE_SOFT else "Off"))


def skipped(self, e_nm, pct):
    """Motion self's e_nm of filament in a cancelled object, counted and not fed: how
    much would be retracted now (at pct, its flow percentage); returns 0."""
    if pct != 100:
        e_nm = e_nm * pct // 100
    if e_nm < 0:
        self._skip_unprimed_nm -= e_nm
    else:
        self._skip_unprimed_nm = max(0, self._skip_unprimed_nm - e_nm)
    return 0


def flowed(self, e_nm):
    """Motion self's e_nm of filament at its flow percentage, to the nanometre; what
    falls below one is carried to the next move, so the filament of many moves is
    their sum's at that percentage, not less by a rounding each."""
    pct = self.flow_pct
    # e_nm * pct in two parts: the product may pass the chips' 31-bit small ints.
    part = e_nm % 100 * pct + self._flow_carry
    self._flow_carry = part % 100
    return e_nm // 100 * pct + part // 100


@micropython.native
def _queue(self, steps, xyz, e_nm, feed_mm_s):
    """Motion self queues a move of X Y Z (axes in xyz) to steps, with e_nm of
    filament. A function of the module's, not a method: Motion._queue would cost a line
    the class's lookup too, about 2.5 us on the chip (a method looked up on self is
    first missed among the instance's attributes: about 9 us)."""
    if e_nm:
        most = self._max_extrude_nm
        if e_nm > most or e_nm < -most:
            raise GcodeError("extrusion of %.1f mm in one move is over max_extrude_mm %g"
                             % (abs(e_nm) / NM_PER_MM, self.max_extrude_mm))
        if not self._guards_passed:
            for guard in self.extrusion_guards:
                guard()
            self._guards_passed = True
    if e_nm < 0:
        self.unprimed_nm -= e_nm
    elif self.unprimed_nm:
        self.unprimed_nm = max(0, self.unprimed_nm - e_nm)
    # Mostly the move's drivers are on already. Not all of them may be: a print
    # that never moves Z leaves it off, and enable_for's bytecode call then costs
    # the chip 35 us a line.
    if (xyz | (self._drive_bits if e_nm else 0)) & ~self.enabled:
        self.enable_for(xyz | (8 if e_nm else 0))
    q = self.queue
    policy = self.retract_policy
    if not xyz and policy == _RETRACT_EQUAL and (e_nm < 0 or self.retracted_nm > 0):
        # A retraction, or the unretraction after it: every drive pulls equally, and
        # as drives are planned from absolute positions, pushes back exactly.
        q.add_move(steps, feed_mm_s, dir_masks=self.dir_masks, e_nm=e_nm,
                   mix=(q.mix_id, (1,) * self.drives))
        self.retracted_nm = max(0, self.retracted_nm - e_nm)
    elif policy == _RETRACT_REPLAY and (e_nm < 0 or (not xyz and self.retracted_nm > 0)):
        # Wipes (retraction while moving) count as retraction too.
        q.add_move(steps, feed_mm_s, dir_masks=self.dir_masks, e_nm=e_nm, replay=True)
        self.retracted_nm = max(0, self.retracted_nm - e_nm)
    else:
        if policy == _RETRACT_REPLAY and e_nm > 0:
            self.retracted_nm = 0  # as the planner forgets them on extrusion
        # Positional: a call with keywords costs the chip more.
        q.add_move(steps, feed_mm_s, self.dir_masks, e_nm)


def register(printer, motion):
    m = motion
    for letter, number, fn, guarded in (
        ("G", 0, m.g1, True),  # rapid move (same as G1)
        ("G", 1, m.g1, True),  # straight move X Y Z E F
        ("G", 2, m.g2, True),  # clockwise arc X Y Z E F I J K R P
        ("G", 3, m.g2, True),  # counter-clockwise arc
        ("G", 17, m.g17, False),  # arcs in the XY plane
        ("G", 18, m.g17, False),  # arcs in the ZX plane
        ("G", 19, m.g17, False),  # arcs in the YZ plane
        ("G", 4, m.g4, True),  # dwell P<ms> or S<s>
        ("G", 28, m.g28, True),  # home axes to min endstops
        ("G", 90, m.g90, False),  # absolute coordinates
        ("G", 91, m.g91, False),  # relative coordinates
        ("G", 92, m.g92, False),  # set position
        ("G", 20, m.g20, False),  # inch units (refused)
        ("G", 21, m.g21, False),  # millimetre units
        ("M", 82, m.m82, False),  # absolute E
        ("M", 83, m.m83, False),  # relative E
        ("M", 400, m.m400, False),  # wait for moves to finish
        ("M", 17, m.m17, True),  # enable drivers
        ("G", 10, m.g10, True),  # firmware retraction
        ("G", 11, m.g11, True),  # firmware unretraction
        ("M", 18, m.m18, False),  # disable drivers
        ("M", 84, m.m18, False),  # disable drivers
    ):
        printer.add_command(letter, number, fn, guarded)
    printer.add_command("M", 119, m.m119)  # endstop states
    printer.add_command("M", 211, m.m211)  # soft limits S0/S1
    printer.add_command("M", 220, m.m220)  # feed rate percentage S, B keeps, R restores
