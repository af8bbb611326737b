# Each drive's exact filament, for the planner: every E move's share per drive counted
# in integers (nanometres and a remainder), so that a drive's target step is an exact
# rounding of its whole filament and never drifts over a print; each drive's steps/mm
# as a fixed-point fraction; and the record of the latest extrusion that
# retract_policy 2 replays.
#
# The state lives on the Planner object (init() makes it) and these functions take
# the planner: the planner's viper code reads the same arrays and words for every G1
# line, and one object keeps each of them a single lookup on the chips. Only this
# module writes them.
from array import array
from mixfw.mixer import MAX_DRIVES, gcd
from mixfw.ramp import product
from mixfw.stepper import schedule_counts

# The planner's words this module's viper code reads (planner.py owns them; a copy
# each, which host_tests/test_layouts.py checks): its drives, and the places of its
# counts, drives' steps, targets and io arrays, as byte offsets from its words plus
# ramp's _AT_BIAS.
_S_DRIVES = const(5)
_AT_COUNTS = const(15)
_AT_DRIVE_STEPS = const(20)
_AT_TARGETS = const(22)
_AT_IO = const(23)
_S_E = const(24)
# ramp.py's: product()'s words in the limbs' scratch, its mode P_LIMBS, the bias.
_IO_LO = const(9)
_IO_REM = const(10)
_IO_A = const(11)
_IO_B = const(12)
_IO_C = const(13)
_IO_HOW = const(15)
_P_LIMBS = const(0)
_AT_BIAS = const(0x20000000)
_MASK30 = const(0x3FFFFFFF)  # compat.MASK30
_MAX_PERIOD = const(20000)  # planner.MAX_PERIOD: most E steps in one block

# A drive's filament past its base (rebase), in nm: the base moves up once it
# passes _NM_HIGH, leaving _NM_KEEP to _NM_KEEP + q, and back down below _NM_LOW. A
# move's filament is far below _NM_LOW (max_extrude_mm).
_NM_LOW = const(0x8000000)
_NM_KEEP = const(0x10000000)
_NM_HIGH = const(0x30000000)

# Filament is counted in integers, never summed in floats: a chip's 32-bit float
# would drift by steps over a print. E in nanometres, and steps/mm in millionths, so a
# drive's target step is an exact integer rounding (integers beyond 2**30 become big
# ints on the chips: fine in the main loop).
NM_PER_MM = const(1000000)
SPM_SCALE = const(1000000)
# How much of the latest extrusion retract_policy 2 remembers: enough blocks for the
# longest retraction the options allow, within a bounded memory.
_REPLAY_NM = const(50 * NM_PER_MM)
_REPLAY_BLOCKS = const(64)


def round_steps(v):
    """The one rounding rule to whole steps: half away from zero."""
    return int(v + 0.5) if v >= 0 else -int(0.5 - v)


def div_round(a, b):
    """a / b for integers (b > 0), rounded as round_steps does: half away from zero."""
    q = (2 * (a if a >= 0 else -a) + b) // (2 * b)
    return q if a >= 0 else -q


def nm_from_mm(mm):
    """A length from the settings (floats) in the integer unit E is counted in."""
    return round_steps(mm * NM_PER_MM)


def spm_fixed(steps_per_mm):
    """Steps/mm as an integer count of 1/SPM_SCALE steps/mm."""
    return round_steps(steps_per_mm * SPM_SCALE)


def steps_per_nm(steps_per_mm):
    """Steps per nanometre as a reduced fraction (p, q) of the fixed steps/mm: 80
    steps/mm is 1/12500. scaled_round(nm, p, q) is then a position's step."""
    p = spm_fixed(steps_per_mm)
    q = NM_PER_MM * SPM_SCALE
    g = gcd(q, p)
    return p // g, q // g


def scaled_round(x, p, q):
    """div_round(x * p, q) (q > 0, p >= 0) without the product x * p, which is a big
    int on the chips (31-bit small ints) for a position in nanometres: split as
    x = h q + l, only l p (below q p) is multiplied. The same integer either way."""
    a = x if x >= 0 else -x
    r = (a // q) * p + (2 * (a % q) * p + q) // (2 * q)
    return r if x >= 0 else -r


def spm_digits(steps_per_mm, out, at):
    """Steps/mm as spm_fixed in three 15-bit digits, lowest first (below 2**37: the
    options' largest steps/mm is 100,000), into out[at:at + 3], for
    cmd_motion.xyz_targets."""
    s = spm_fixed(steps_per_mm)
    for k in range(3):
        out[at + k] = (s >> (15 * k)) & 0x7FFF


# plan_e_words' words, the planner's from _S_E on (resync writes them): per
# drive, at _E_STRIDE * i, its weight, the largest e_nm its share keeps in a machine
# word, its steps per nm p / q (and q times the weights' total), the base's steps, the
# filament's bounds (see rebase), its filament and remainder as the planner's drive_nm and
# drive_rem hold them, and how its step is worked out (_E_HOW: 0 in Python, 1 in
# machine words, 2 in limbs); then the weights' total, whether the words are the
# planner's state (_E_SYNCED), and whether every drive with a share fits them
# (_E_FITS).
_E_W = const(0)
_E_LIM = const(1)
_E_P = const(2)
_E_Q = const(3)
_E_QT = const(4)
_E_BASE = const(5)
_E_LOW = const(6)
_E_HIGH = const(7)
_E_NM = const(8)
_E_REM = const(9)
_E_HOW = const(10)
_E_STRIDE = const(11)
_E_TOTAL = const(66)
_E_SYNCED = const(67)
_E_FITS = const(68)


@micropython.viper
def plan_e_words(words_buf, e_nm: int, drive_nm, drive_rem) -> int:
    """Each drive's steps from where it is to its target step, into the counts; then,
    where the words hold the planner's state (_E_SYNCED) and every drive with a share
    fits them, the move's e_nm of filament planned as plan_e does, exactly:
    each such drive's filament and remainder (in its words, and in the planner's lists
    drive_nm and drive_rem), its target and its count (a travel, e_nm 0, changes none).
    Returns 1 if it did that, 0 if plan_e must (nothing planned then). The planner's arrays from the
    places its words keep (Planner._abs_steps).

    One viper call: native code, as plan_e, pays a runtime call for every attribute,
    subscript or operation on objects."""
    words = ptr32(words_buf)
    at = int(words) - _AT_BIAS
    t = ptr32(at + words[_AT_TARGETS])
    s = ptr32(at + words[_AT_DRIVE_STEPS])
    c = ptr32(at + words[_AT_COUNTS])
    drives = words[_S_DRIVES]
    for i in range(drives):
        c[i] = t[i] - s[i]
    e = ptr32(int(words) + 4 * _S_E)
    if e[_E_SYNCED] == 0:
        return 0
    if e_nm == 0:
        return 1  # a travel: the plan stands
    total = e[_E_TOTAL]
    io = ptr32(at + words[_AT_IO])
    # Twice over the drives with a share: every one checked first (one that does not
    # fit leaves all to plan_e), then each planned. The filament and its low bound
    # are kept 2**30 up in their words, as a 64-bit port's ptr32 would read a negative
    # word zero-extended.
    planning = 0
    while planning < 2:
        for i in range(drives):
            d = ptr32(int(e) + 4 * _E_STRIDE * i)
            w = d[_E_W]
            if w == 0:
                continue
            num = e_nm * w + d[_E_REM]
            if num >= 0:
                k = num // total
            else:
                k = 0 - ((total - 1 - num) // total)
            nm = d[_E_NM] - _MASK30 - 1 + k
            if planning == 0:
                lim = d[_E_LIM]
                if (d[_E_HOW] == 0 or e_nm >= lim or e_nm <= 0 - lim
                        or nm < d[_E_LOW] - _MASK30 - 1 or nm >= d[_E_HIGH]):
                    return 0  # beyond the words, or the base moves (rebase)
                continue
            rem = num - k * total
            # scaled_round(nm * total + rem, p, q * total): nm = h q + l, so the
            # filament in 1/total nm is h qt + low, low below qt, and its step
            # h p + low p / qt rounded half away from zero (as the sign).
            p = d[_E_P]
            q = d[_E_Q]
            qt = d[_E_QT]
            m = nm if nm >= 0 else 0 - nm
            h = m // q
            low = (m - h * q) * total
            if nm >= 0:
                low += rem
            else:
                low -= rem
                if low < 0:
                    h -= 1
                    low += qt
            if d[_E_HOW] == 1:  # 2 qt p below 2**30
                r = (2 * low * p + qt) // (2 * qt)
            else:  # low p // qt and its remainder in limbs: qt below 2**28, p 2**29
                io[_IO_A] = low
                io[_IO_B] = p
                io[_IO_C] = qt
                io[_IO_HOW] = _P_LIMBS
                product(int(io) >> 2)  # its address over 4
                r = io[_IO_LO]
                if 2 * io[_IO_REM] >= qt:
                    r += 1
            r += h * p
            if nm < 0:
                r = 0 - r
            target = d[_E_BASE] + r
            d[_E_NM] = nm + _MASK30 + 1
            d[_E_REM] = rem
            drive_nm[i] = nm
            drive_rem[i] = rem
            t[i] = target
            c[i] = target - s[i]
        planning += 1
    return 1


def init(planner, drive_steps_per_mm):
    """The planner's filament state, from each drive's steps/mm."""
    planner.drive_steps_per_mm = list(drive_steps_per_mm)
    set_spm_fixed(planner)
    # Each drive's exact filament is drive_nm[i] + drive_rem[i] / rem_total nm: the
    # part of a share below a nanometre is carried, not dropped; drive_targets[i] is
    # its step there, where targets_known. plan_e changes them in place, and only for
    # the drives with a share in the move (copying every drive's plan for each line
    # would be most of its time on the chips): a move is refused, if at all, before
    # its filament is planned.
    planner.drive_nm = [0] * planner.drives
    planner.drive_rem = [0] * planner.drives
    planner.rem_total = 1
    planner.drive_targets = array("i", bytes(4 * planner.drives))
    planner.targets_known = False
    # The latest weights plan_e took, and their total.
    planner._shares = (None, 1)
    # For retract_policy 2: the latest extrusion as stretches [start, end) of block
    # schedules (weights, start, end), newest last, and what retractions took back
    # from it, taken-first first. See replay_counts.
    planner.keep_extrusion = False
    planner.extruded = []
    planner.retracted = []


def set_drive_steps(planner, drive_steps_per_mm):
    """New steps/mm per drive (M92 E, M930), once the moves have run (the planner's
    set_drive_steps waits for them): each drive stays where it is, counted in the new
    unit."""
    planner.drive_steps_per_mm = list(drive_steps_per_mm)
    set_spm_fixed(planner)
    drive_pos_from_steps(planner)
    resync(planner)


def set_spm_fixed(planner):
    planner._spm_fixed = [spm_fixed(v) for v in planner.drive_steps_per_mm]
    # Per drive: [p, q, base steps, low, high, base nm], p/q its steps per nm (see
    # rebase for the rest): low and high 0 until the drive's first plan sets them.
    planner._per_nm = [list(steps_per_nm(v)) + [0, 0, 0, 0]
                  for v in planner.drive_steps_per_mm]
    # The longest extrusion that goes in one block (see add_move), worked out here
    # once: a big-int product per move costs the chips more than the rest of it.
    limit = NM_PER_MM * SPM_SCALE * (_MAX_PERIOD - 2 * MAX_DRIVES)
    planner._one_piece_nm = -(-limit // max(planner._spm_fixed))


def nm_of_steps(planner, i, steps):
    pq = planner._per_nm[i]
    return scaled_round(steps, pq[1], pq[0])


def drive_pos_from_steps(planner):
    for i in range(planner.drives):
        pq = planner._per_nm[i]
        pq[2] = pq[5] = 0  # no base: the whole filament in drive_nm first
        planner.drive_nm[i] = rebase(planner, i, nm_of_steps(planner, i, planner.drive_steps[i]))
        planner.drive_rem[i] = 0
    planner.rem_total = 1
    planner.targets_known = False
    planner._abs_steps[_S_E + _E_SYNCED] = 0


def rebase(planner, i, x):
    """Drive i's filament is its base plus x nm (drive_nm) plus the remainder; its
    target step is the base's steps plus that of the rest. The base is a whole
    number of q nm (p/q: its steps per nm), so its steps are exact, and it takes
    all but _NM_KEEP to _NM_KEEP + q of the filament once it passes _NM_HIGH: a
    print's metres of filament would be big ints on the chips, which every line's
    arithmetic then allocates. Returns the nm past the new base: at least _NM_LOW
    while there is a base, so that the rest's rounding (half away from zero) is
    the whole filament's. Called where x leaves low..high (words 3 and 4)."""
    pq = planner._per_nm[i]
    p, q, base_nm = pq[0], pq[1], pq[5]
    movable = q <= _NM_HIGH - _NM_KEEP
    k = 0
    if movable:
        if base_nm + x < _NM_KEEP:
            k = -(base_nm // q)  # the whole base back
        else:
            k = (x - _NM_KEEP) // q
    pq[2] += k * p
    pq[5] = base_nm = base_nm + k * q
    pq[3] = _NM_LOW if base_nm else -_MASK30 - 1
    pq[4] = _NM_HIGH if movable else _MASK30
    return x - k * q


def plan_e(planner, e_nm, weights=None):
    """The drives' exact filament and target steps after an E move of e_nm
    nanometres shared by the weights, in place; the move's steps per drive in
    planner._counts. Mostly in one viper call (plan_e_words: add_move makes it
    first); else here, in integers of any size."""
    w = weights or planner.tool_mix
    shares = planner._shares
    words = planner._abs_steps
    if w is not shares[0]:  # mostly the same weights (a tuple) as the move before
        shares = planner._shares = (w, sum(w))
        # The words are the old weights': worked out again below (resync), once.
        words[_S_E + _E_SYNCED] = 0
        words[_S_E + _E_FITS] = 1
    # Every drive's steps to its target first: a drive with no share in the move
    # stays where it is, and so does its target step, where it is known.
    if plan_e_words(words, e_nm, planner.drive_nm, planner.drive_rem):
        return
    total = shares[1]
    targets = planner.drive_targets
    now_steps = planner.drive_steps
    counts = planner._counts
    now_total = planner.rem_total
    rescale = now_total != total
    every = not planner.targets_known
    if not (every or rescale or e_nm):
        if not words[_S_E + _E_SYNCED] and words[_S_E + _E_FITS]:
            resync(planner)
        return
    per_nm = planner._per_nm
    drive_nm = planner.drive_nm
    drive_rem = planner.drive_rem
    for i in range(planner.drives):
        rem = drive_rem[i]
        if rescale and rem:
            rem = div_round(rem * total, now_total)  # below a nanometre either way
            drive_rem[i] = rem
        if (w[i] and e_nm) or every:
            num = e_nm * w[i] + rem
            nm = drive_nm[i] + num // total
            rem = num % total
            pq = per_nm[i]
            if not pq[3] <= nm < pq[4]:
                nm = rebase(planner, i, nm)
            # (nm + rem / total) * p / q, rounded, past the base's steps: with no
            # remainder (every one-drive tool) all in small ints.
            if rem:
                target = scaled_round(nm * total + rem, pq[0], pq[1] * total) + pq[2]
            else:
                target = scaled_round(nm, pq[0], pq[1]) + pq[2]
            drive_nm[i] = nm
            drive_rem[i] = rem
            targets[i] = target
            counts[i] = target - now_steps[i]
    if rescale:
        planner.rem_total = total
    if every:
        planner.targets_known = True
    if words[_S_E + _E_FITS]:
        resync(planner)


def resync(planner):
    """plan_e_words' words from the plan's state: each drive's weight, p / q and
    how its step is worked out, and whether every drive with a share fits the words
    (_E_FITS); its filament, remainder, base and bounds; and whether the words are
    the planner's state (_E_SYNCED): while the targets are known, the remainders
    count in the weights' total, and every drive with a share fits. After any
    change plan_e does not make in them (the weights, the steps per mm, a rebase)."""
    e = planner._abs_steps
    w, total = planner._shares[0], planner._shares[1]
    fits = bool(w)
    for i in range(planner.drives):
        d = _S_E + _E_STRIDE * i
        wi = w[i] if w else 0
        e[d + _E_W] = wi
        e[d + _E_HOW] = 0
        if not wi:
            continue
        pq = planner._per_nm[i]
        p, qt = pq[0], pq[1] * total
        how = 0
        if p < 0x20000000 and qt < 0x10000000:
            how = 1 if 2 * qt * p < 0x40000000 else 2
            e[d + _E_LIM] = (_MASK30 - total) // wi
            e[d + _E_P] = p
            e[d + _E_Q] = pq[1]
            e[d + _E_QT] = qt
            nm = planner.drive_nm[i]
            if -_MASK30 < nm < _MASK30 and pq[2] < _MASK30:
                e[d + _E_NM] = nm + _MASK30 + 1  # see plan_e_words
                e[d + _E_REM] = planner.drive_rem[i]
                e[d + _E_BASE] = pq[2]
                e[d + _E_LOW] = max(pq[3], -_MASK30) + _MASK30 + 1
                e[d + _E_HIGH] = min(pq[4], _MASK30)
            else:
                how = 0
        if not how:
            fits = False
        e[d + _E_HOW] = how
    e[_S_E + _E_TOTAL] = total
    e[_S_E + _E_FITS] = 1 if fits else 0
    e[_S_E + _E_SYNCED] = 1 if (fits and planner.targets_known and
                                planner.rem_total == total) else 0


def replay_counts(planner, e_nm):
    """Per-drive steps of a retraction (e_nm < 0) that takes back exactly the drive
    steps of the latest e_nm of extrusion, newest first, or of an unretraction that
    pushes back exactly what retractions took, oldest first. What the record does
    not cover follows the active mix. Plans as plan_e does."""
    planner._abs_steps[_S_E + _E_SYNCED] = 0  # drive_nm changes here
    back = e_nm < 0
    take = planner.extruded if back else planner.retracted
    give = planner.retracted if back else planner.extruded
    need_nm = e_nm if e_nm >= 0 else -e_nm
    counts = [0] * planner.drives
    while take and need_nm > 0:
        w, start, end, part, nm = take[-1]
        if nm > need_nm:
            k = div_round(need_nm * (end - start), nm)
            if k == 0:
                break
            # A part of the stretch: its newest steps go back first, and come
            # forward again oldest first.
            cut = end - k if back else start + k
            first = stretch(planner, w, start, cut)
            second = stretch(planner, w, cut, end)
            take[-1] = first if back else second
            mine = second if back else first
            give.append(mine)
            part, nm = mine[3], mine[4]
        else:
            give.append(take.pop())
        for i in range(planner.drives):
            counts[i] += part[i]
        need_nm -= nm
    # The drives' exact positions move by the replayed steps, and the rest by the
    # mix. The replayed steps are exact: they are the targets, not a rounding of the
    # new positions (which a half step could tip the other way).
    sign = -1 if back else 1
    for i in range(planner.drives):
        planner.drive_nm[i] += sign * nm_of_steps(planner, i, counts[i])
        planner.drive_targets[i] = planner.drive_steps[i] + sign * counts[i]
    planner.targets_known = True
    plan_e(planner, sign * need_nm if need_nm > 0 else 0)


def stretch(planner, weights, start, end, counts=None):
    """A record of steps [start, end) of a block's schedule, with its per-drive
    steps and its filament in nm."""
    if counts is None:
        a = schedule_counts(weights, start)
        b = schedule_counts(weights, end)
        counts = [b[i] - a[i] for i in range(len(weights))]
    nm = 0
    for i in range(planner.drives):
        nm += nm_of_steps(planner, i, counts[i])
    return (weights, start, end, counts, nm)


def remember_extrusion(planner, weights, counts):
    """Keep the latest extrusion for retract_policy 2: at most _REPLAY_BLOCKS blocks,
    and no more than _REPLAY_NM beyond what the newest of them hold."""
    ext = planner.extruded
    ext.append(stretch(planner, weights, 0, sum(counts), counts))
    planner.retracted = []
    total = 0
    for kept in ext:
        total += kept[4]
    while len(ext) > _REPLAY_BLOCKS or (len(ext) > 1 and total - ext[0][4] >= _REPLAY_NM):
        total -= ext.pop(0)[4]
