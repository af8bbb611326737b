# The planner: a ring of blocks with trapezoidal speed profiles and look-ahead
# junction speeds. It works in floats in the main loop and hands the step loop
# integer records (see stepper.py). Each block carries its own mix, so a mix or tool
# change reaches only moves queued after it.
#
# Pure logic: the hooks that touch the chip (waiting, masking the interrupt) are
# passed in by assemble.py, so host tools can plan on CPython too.
from array import array
from mixfw import geometry, heap, lookahead, ramp
from mixfw import filament
from mixfw.filament import (NM_PER_MM, SPM_SCALE, div_round, drive_pos_from_steps, plan_e,
                            plan_e_words, remember_extrusion, replay_counts, resync,
                            set_drive_steps)
from mixfw import stepper as st
from mixfw.mixer import MAX_DRIVES, normalize
from mixfw.ramp import array_offsets
from mixfw.stepper import schedule_counts

# The other modules' words the planner reads and writes, as this module's constants:
# viper and the compiler fold them, where each st.X is a lookup at run time. Each is a
# copy of its owner's, which host_tests/test_layouts.py checks.
# stepper.py's: the step loop's words and its records'.
_S_HEAD = const(0)
_S_TAIL = const(1)
_S_ACTIVE = const(2)
_S_QUEUE = const(26)
_R_PENDING = const(96)
_BLOCK_BASE = const(123)
_B_WORDS = const(24)
_B_N = const(0)
_B_STEPS = const(1)
_B_DIR_SET = const(5)
_B_DIR_CLR = const(6)
_B_FLAGS = const(7)
_B_DWELL = const(14)
_B_MIX = const(15)
_F_NEG = const(4)
_F_HOMING = const(2)
_F_HOME_SHIFT = const(8)
_F_ADVANCE = const(8192)
_B_ADV = const(23)
_S_ADV_OWED = const(115)
_S_ADV_NOW = const(116)
_S_ADV_SLOT = const(117)
_S_ADV_FWD_SET = const(121)
_S_ADV_FWD_CLR = const(122)
_ADV_OFF = const(0)
_ADV_BIAS = const(0x20000000)
# lookahead.py's: the floats, the slots, and the words of plan_words and recalculate
# in the io array they share with ramp.py's helpers (_RAMP_IO), which _plan_move
# stores.
_F_MM = const(0)
_F_ACCEL = const(1)
_F_NOMINAL = const(2)
_F_NOMINAL2 = const(3)
_F_ACCEL_TICK = const(5)
_L_WORDS = const(12)
_L_NOMINAL = const(2)
_W_AT_LK = const(30)
_W_AT_F = const(31)
_W_AT_MEM = const(32)
_W_SLOT = const(33)
_W_N = const(34)
_W_ENTRY_V2 = const(35)
_W_RATE_CAP = const(36)
# geometry.py's: the move's words, and where its floats and the planner's are, then
# the move's flags (_plan_move stores them).
_G_D = const(16)
_G_C = const(20)
_G_DIST = const(25)
_G_AT_GF = const(33)
_G_FLAGS = const(35)
_GF_ACCEL_JD = const(5)
_FL_E_NM = const(16)
_FL_JOIN = const(32)
# ramp.py's: product()'s words in the limbs' scratch (_RAMP_IO), its mode P_LIMBS,
# and array_offsets' bias.
_IO_LO = const(9)
_IO_REM = const(10)
_IO_A = const(11)
_IO_B = const(12)
_IO_C = const(13)
_IO_HOW = const(15)
_P_LIMBS = const(0)
_AT_BIAS = const(0x20000000)
_MAX_DRIVES = const(6)  # mixer.MAX_DRIVES
# compat.MASK30: the chips' largest small int, and the mask mix ids wrap at.
_MASK30 = const(0x3FFFFFFF)

_RING_IDLE = const(0x10000)  # see _ring_room

# Most E steps in one block, and so the longest period of its mix: its weights and
# the mixer's errors stay far below 2**30.
MAX_PERIOD = const(20000)


@micropython.viper
def _ring_room(mem_buf) -> int:
    """The slot for the next block (S_HEAD), plus _RING_IDLE if the step path has run
    out of work (no block queued or running, no steps still in the DMA ring); -1 while
    the ring is full: one slot stays free, so a full ring is not taken for an empty one.
    One viper call, where the queue's methods would be three calls and a dozen lookups."""
    m = ptr32(mem_buf)
    head = m[_S_HEAD]
    tail = m[_S_TAIL]
    count = head - tail
    if count < 0:
        count += m[_S_QUEUE]
    if count >= m[_S_QUEUE] - 1:
        return -1
    if count == 0 and m[_S_ACTIVE] == 0 and m[_R_PENDING] == 0:
        return head | _RING_IDLE
    return head


@micropython.viper
def waiting_blocks(mem_buf) -> int:
    """Blocks queued that the step loop has not started. A function, not a method:
    add_move asks for every short move, and a bytecode method looked up on the planner
    costs the chip about 30 us."""
    m = ptr32(mem_buf)
    count = m[_S_HEAD] - m[_S_TAIL]
    if count < 0:
        count += m[_S_QUEUE]
    if count and m[_S_ACTIVE]:
        return count - 1
    return count


# The planner's words (Planner._abs_steps): X Y Z E steps (_xyz_steps), then the
# largest of X Y Z's, the drives (_plan_move: len() is a call), the fastest rate the
# step loop may step at (see lookahead.plan_words), and _plan_move's words (below).
_S_N_XYZ = const(4)
_S_DRIVES = const(5)
_S_RATE_CAP = const(6)
# Where the arrays _plan_move, filament.plan_e_words and _xyz_steps work on are, as byte offsets
# from the planner's words plus _AT_BIAS (each non-negative, as a 64-bit port's ptr32
# reads a word zero-extended): ptr32() of an address costs nothing, of an array much
# more (see ramp.array_offsets). MicroPython never moves an object, and the planner
# holds them all.
_AT_MEM = const(13)
_AT_LK = const(14)
_AT_COUNTS = const(15)
_AT_GEO = const(16)
_AT_DIR_SET = const(17)
_AT_DIR_CLR = const(18)
_AT_WEIGHTS = const(19)
_AT_DRIVE_STEPS = const(20)
_AT_GIVEN = const(21)
_AT_TARGETS = const(22)
_AT_IO = const(23)
_S_E = const(24)  # filament.plan_e_words' words (its _E_*) from here
_AT_F = const(93)  # after them: the floats (lookahead's F_*)
_AT_XYZ = const(94)  # and Planner.target_steps
# 1 while the latest block is a move the next one may join at speed (geometry.junction
# has its direction); 0 after a stop, which _plan_move's homing moves are too.
_S_JOINS = const(95)
_S_MEMO_NEXT = const(96)  # where the memo's oldest entry starts (see _work_base_floats)
# X Y Z E: how much of the path an axis whose limits the speed is not within may take
# and still not bind, _SHARE_ONE over the factor the speed or acceleration is past them
# (see _shares): worked out on the first move at a speed where axes are past their
# limits and none binds, and kept while _S_SHARES_SET is 1.
_S_SHARES = const(97)
_S_SHARES_SET = const(101)
# Pressure advance: K times the step loop's ticks a second times 256 (0: off), and
# the drives' DIR pins, which blocks with advance leave to the step loop's follower.
_S_ADV_K = const(102)
_S_E_DIR_PINS = const(103)
_S_WORDS = const(104)


# _plan_move's answers besides 1 (queued) and 0 (shorter than a step: nothing to do),
# each with nothing queued, for add_move to do in Python and ask again.
_RING_WAIT = const(-1)  # the ring is full, or the step path idle (see _new_slot)
_FLOATS = const(-2)  # a limit binds, SLOWDOWN may, or the floats are another move's
_SCALE = const(-3)  # too many steps for the mixer's weights (see _scaled)
_EXTRUDED = const(2)  # queued, with filament forward
# What add_move has done of that (_plan_move's `how`).
_HOW_SLOT = const(1)
_HOW_FLOATS = const(2)
_HOW_SCALED = const(4)
_HOW_LENGTHS = const(8)  # the call before worked out the move's lengths
# and in the same word, the homing axes (X=1, Y=2, Z=4) and the ring's slot of _HOW_SLOT
_HOW_HOMING_SHIFT = const(5)
# Planner._queue_io's objects: the step loop's words, the planner's, the look-ahead's
# hooks, position_steps, drive_nm, drive_rem, _base_of, target_steps.
_Q_MEM = const(0)
_Q_WORDS = const(1)
_Q_HOOKS = const(2)
_Q_POS = const(3)
_Q_NM = const(4)
_Q_REM = const(5)
_Q_BASE = const(6)
_Q_TARGET = const(7)
_HOW_SLOT_SHIFT = const(8)
# Words of Planner._abs_steps past the drives and the rate cap.
_S_MIX_ID = const(7)  # the latest block's mix id
_S_WITHIN = const(8)  # the axes whose limits the speed is within (see _base_floats)
_S_MIN_BITS = const(9)  # SLOWDOWN's shortest length at that speed, as lengths' bits
_S_OVER = const(10)  # _plan_move's answer _FLOATS: the axes whose limits bind
_S_DIST_BITS = const(11)  # and the move's length, as lengths' bits
_S_F_BASE = const(12)  # which floats hold _base_floats' own: _F_BASE_ACCEL the
_F_BASE_ACCEL = const(2)  # acceleration's, _F_BASE_BOTH its speed's too
_F_BASE_BOTH = const(3)
_MEMO = const(8)  # pairs of speed and acceleration _base_floats keeps, each as
_MEMO_WORDS = const(7)  # speed, accel, its _S_WITHIN, _S_MIN_BITS and the floats
# _set_floats works out: _F_NOMINAL2, _F_ACCEL_TICK, _GF_ACCEL_JD
_SHARE_ONE = const(0x4000)  # _S_SHARES' fixed point


@micropython.viper
def block_weights(words4: int) -> int:
    """Mixer weights that make the step loop give each drive exactly abs(counts[i])
    steps in a block (one whole period of the schedule); a block runs every drive the
    same way: abs(counts) into steps, and the weights as the steps over their gcd.
    The arrays are the planner's, found from its words (words_buf: Planner._abs_steps):
    as its address over 4 (as ramp's helpers take theirs): its counts (_counts),
    weights (_weights) and steps (_given), arrays 'i' of a word
    a drive. Returns 0 if that period is longer than the mixer takes (nothing written
    to weights then: add_move scales them). In one viper call, where native code paid
    a runtime call for every item read or written, and a bytecode call for every
    gcd."""
    words = ptr32(words4 << 2)
    at = int(words) - _AT_BIAS
    c = ptr32(at + words[_AT_COUNTS])
    s = ptr32(at + words[_AT_GIVEN])
    w = ptr32(at + words[_AT_WEIGHTS])
    n = words[_S_DRIVES]
    g = 0
    total = 0
    for i in range(n):
        x = c[i]
        if x < 0 or x > _MASK30:  # negative: a 64-bit port's ptr32 reads it zero-extended
            x = (0 - x) & _MASK30
        s[i] = x
        total += x
        a = x
        while a:  # g = gcd(x, g)
            t = g % a
            g = a
            a = t
    if g and total // g > MAX_PERIOD:
        return 0
    for i in range(n):
        w[i] = s[i] // g if g else 0
    return 1


@micropython.viper
def _plan_move(io, e_nm: int, neg: int, how: int, pos) -> int:
    """The move _xyz_steps measured (neg: its answer) with e_nm of filament, whose
    drives' steps are planned (the planner's counts), from its lengths to its slot of the step
    loop's ring, where its speed is the one add_move set in floats (_base_floats) and
    nothing needs Python: else the answer says what add_move must do first (_FLOATS
    and the rest). how: _HOW_*, the homing axes << _HOW_HOMING_SHIFT and, with
    _HOW_SLOT, the ring's slot << _HOW_SLOT_SHIFT. pos: Planner.position_steps, whose
    X Y Z become the target's (Planner.target_steps). One call for the lengths, the
    axes' limits, SLOWDOWN's check, the junction, the block's weights and its words:
    as a call each, with native code on objects between them, they would cost 1 to 2
    us an attribute or an operation on the chips.

    Its arrays are found from the planner's words (_AT_*), and the functions it calls
    take theirs as addresses over 4: a subscript of an object costs the chip about
    1.5 us from viper, as much as a dozen operations on words, and ptr32() of an array
    is as dear (see ramp.array_offsets)."""
    mem_buf = io[_Q_MEM]
    words = ptr32(io[_Q_WORDS])
    at = int(words) - _AT_BIAS  # the arrays' offsets are from here (_AT_*)
    counts = ptr32(at + words[_AT_COUNTS])
    geo = ptr32(at + words[_AT_GEO])
    drives = words[_S_DRIVES]
    e_steps = 0
    for i in range(drives):
        c = counts[i]
        if c > _MASK30:  # negative: a 64-bit port's ptr32 reads it zero-extended
            c = 0 - ((0 - c) & _MASK30)
        e_steps += c
    moving = neg >> 4
    neg &= 7
    n = words[_S_N_XYZ]
    e_abs = e_steps
    if e_steps < 0:
        neg |= 8
        e_abs = 0 - e_steps
    if e_steps:
        moving |= 8
    words[3] = e_abs
    if e_abs > n:
        n = e_abs
    if n == 0:
        return 0  # less than a step: the filament counts toward the next move
    mem = ptr32(at + words[_AT_MEM])
    slot = how >> _HOW_SLOT_SHIFT
    if not (how & _HOW_SLOT):
        slot = int(_ring_room(mem_buf))
        if slot < 0 or slot & _RING_IDLE:
            return _RING_WAIT
    if e_nm:
        geo[_G_D + 3] = e_nm if e_nm >= 0 else 0 - e_nm
        geo_flags = neg & 7 | _FL_E_NM
        if e_nm < 0:
            geo_flags |= 8
    else:
        geo[_G_D + 3] = e_abs
        geo_flags = neg
    if how & _HOW_LENGTHS:
        dist_bits = words[_S_DIST_BITS]  # worked out by the call before, for this move
    else:
        geo[_G_FLAGS] = geo_flags
        dist_bits = int(_lengths(int(geo) >> 2))
        words[_S_DIST_BITS] = dist_bits
    if not (how & _HOW_FLOATS):
        # An axis's share of the path is at most 1 (always on X Y Z), so its limits
        # bind only when the move asks more than the limits themselves; E, at most an
        # eighth of the path (as when printing), binds only beyond eight times its
        # limits. Then, or where SLOWDOWN may slow the move, add_move works its speed
        # out in floats.
        within = words[_S_WITHIN]
        over = moving & ~within & 7
        if moving & 8:
            over |= 8
            c3 = geo[_G_C + 3]
            dist = geo[_G_DIST]
            if within & 8:
                if c3 <= dist:
                    over ^= 8
            elif within & 16:
                if (c3 << 3) <= dist:
                    over ^= 8
        if over and words[_S_SHARES_SET]:
            # Such an axis binds only if its share of the path, c / dist, is over its
            # _S_SHARES word / _SHARE_ONE (a spiral vase's Z on every line): tested on
            # the top bits, leaning to binding.
            dist = geo[_G_DIST] >> 11
            for i in range(4):
                if (over >> i) & 1 and ((geo[_G_C + i] >> 11) + 1) * _SHARE_ONE <= \
                        dist * words[_S_SHARES + i]:
                    over ^= 1 << i
        slow = 0
        if words[_S_MIN_BITS] > dist_bits:
            # Marlin's bounds: 2 to half the queue's blocks waiting.
            waiting = int(waiting_blocks(mem_buf))
            if 2 <= waiting and waiting < mem[_S_QUEUE] // 2:
                slow = 1
        if over or slow or words[_S_F_BASE] != _F_BASE_BOTH:
            words[_S_OVER] = over
            return _FLOATS
    mix_id = -1
    given = counts
    if e_steps:
        # Exact per-drive counts as the block's mix; a fresh id, so the step loop
        # starts its schedule anew and gives each drive exactly its count.
        given = ptr32(at + words[_AT_GIVEN])
        if not (how & _HOW_SCALED):
            if int(block_weights(int(words) >> 2)) == 0:
                return _SCALE
        if e_steps < 0:
            g = given
            for i in range(drives):
                g[i] = 0 - g[i]
        mix_id = (words[_S_MIX_ID] + 1) & _MASK30
        words[_S_MIX_ID] = mix_id
    # The junction's speed, from the deviation model (a stop if the queue ran empty),
    # as the look-ahead's V2.
    homing = (how >> _HOW_HOMING_SHIFT) & 7
    if words[_S_JOINS] and not homing:
        geo_flags |= _FL_JOIN
    geo[_G_FLAGS] = geo_flags
    entry_v2 = int(_junction(int(geo) >> 2))
    # The block's words, then its look-ahead words and the records it changes
    # (lookahead.plan_words, recalculate), S_HEAD past it, and the planner's position:
    # X Y Z from target, E plus e_steps, and the drives' plus given, each drive's steps.
    # Its record through a pointer of its own: an index into mem costs viper an
    # addition and a shift at every use.
    blk = ptr32(int(mem) + 4 * (_BLOCK_BASE + slot * _B_WORDS))
    blk[_B_N] = n
    for i in range(4):
        blk[_B_STEPS + i] = words[i]
    flags = neg * _F_NEG
    dir_set = ptr32(at + words[_AT_DIR_SET])[neg]
    dir_clr = ptr32(at + words[_AT_DIR_CLR])[neg]
    if homing:
        flags |= _F_HOMING | (homing << _F_HOME_SHIFT)
    elif words[_S_ADV_K] and e_steps >= 0:
        # The step loop's follower runs the drives (stepper._S_ADV_OWED); a printing
        # move's advance is K times its filament's speed: K E / n lead-axis rates,
        # E / n in 2**-15 (E <= n), in 15-bit limbs below 2**30.
        flags |= _F_ADVANCE
        pins = words[_S_E_DIR_PINS]
        dir_set &= 0 - 1 - pins
        dir_clr &= 0 - 1 - pins
        adv = 0
        if e_steps > 0 and (moving & 7):
            if e_abs < 0x8000:
                ratio = (e_abs << 15) // n
            else:
                ratio = e_abs // (n >> 15)
            k = words[_S_ADV_K]
            adv = (k >> 15) * ratio + (((k & 0x7FFF) * ratio) >> 15)
            if adv > 0xFFFFFF:
                adv = 0xFFFFFF
        blk[_B_ADV] = adv
    blk[_B_FLAGS] = flags
    blk[_B_DIR_SET] = dir_set
    blk[_B_DIR_CLR] = dir_clr
    blk[_B_DWELL] = 0
    if mix_id >= 0:
        blk[_B_MIX] = mix_id
        weights = ptr32(at + words[_AT_WEIGHTS])
        for i in range(_MAX_DRIVES):
            blk[_B_MIX + 1 + i] = weights[i] if i < drives else 0
    # No faster than the move before, the ring's slot before this one: its nominal V2.
    # (entry_v2 is 0 after a stop.)
    prev = slot - 1
    if prev < 0:
        prev = mem[_S_QUEUE] - 1
    prev_v2 = ptr32(at + words[_AT_LK])[prev * _L_WORDS + _L_NOMINAL]
    if prev_v2 < entry_v2:
        entry_v2 = prev_v2
    # lookahead's words for its two calls (the places from the io array's own
    # address: it is shared by every planner).
    w = ptr32(at + words[_AT_IO])
    w_at = int(w) - _AT_BIAS
    w[_W_AT_LK] = at + words[_AT_LK] - w_at
    w[_W_AT_F] = at + words[_AT_F] - w_at
    w[_W_AT_MEM] = at + words[_AT_MEM] - w_at
    w[_W_SLOT] = slot
    w[_W_N] = n
    w[_W_ENTRY_V2] = entry_v2
    w[_W_RATE_CAP] = words[_S_RATE_CAP]
    _plan_words(int(w) >> 2)
    _recalculate(int(w) >> 2, io[_Q_HOOKS])
    slot += 1  # committed: the step loop may start it
    if slot >= mem[_S_QUEUE]:
        slot = 0
    mem[_S_HEAD] = slot
    words[_S_JOINS] = 0 if homing else 1
    target = ptr32(at + words[_AT_XYZ])  # within +-_MASK30 (_xyz_steps)
    for i in range(3):
        t = target[i]
        if t > _MASK30:  # negative: a 64-bit port's ptr32 reads it zero-extended
            t = 0 - ((0 - t) & _MASK30)
        pos[i] = t
    pos[3] = int(pos[3]) + e_steps
    # given, an array 'i': a 64-bit port's ptr32 reads a negative count zero-extended,
    # and the sum's low 32 bits, all the word keeps, are the same.
    drive_steps = ptr32(at + words[_AT_DRIVE_STEPS])
    for i in range(drives):
        drive_steps[i] += given[i]
    if e_steps > 0:
        return _EXTRUDED
    return 1


@micropython.viper
def _xyz_steps(pos, steps_buf) -> int:
    """X Y Z's steps from pos to the target (absolute steps, in Planner.target_steps,
    found from the words' _AT_XYZ): their sizes into steps_buf (the planner's words:
    X Y Z) and geometry's D words (from _AT_GEO), the largest into
    steps_buf[_S_N_XYZ]. Returns the bits of the axes that run backwards, and those of
    the axes that move shifted left 4; or -1 for a target or a move of 2**30 steps or
    more, beyond the chips' small ints. One viper call, where the same arithmetic in
    native code would cost the chip about 0.1 ms a line."""
    steps = ptr32(steps_buf)
    at = int(steps) - _AT_BIAS
    geo = ptr32(at + steps[_AT_GEO])
    target = ptr32(at + steps[_AT_XYZ])
    neg = 0
    n = 0
    for i in range(3):
        # The word's top two bits (as a 64-bit port reads it zero-extended, or a 32-bit
        # one signed): 0 for 0 .. 2**30 - 1, 3 for -2**30 .. -1, else beyond.
        t = target[i]
        top = (t >> 30) & 3
        if top == 3:
            t = 0 - ((0 - t) & _MASK30)
            if t == 0:  # -2**30
                return -1
        elif top:
            return -1
        p = int(pos[i])
        # In halves first: the difference itself could pass a 32-bit word.
        h = (t >> 1) - (p >> 1)
        if h >= 0x20000000 or h <= -0x20000000:
            return -1
        d = t - p
        if d < 0:
            neg |= 1 << i
            d = 0 - d
        if d >= _MASK30:
            return -1
        if d:
            neg |= 16 << i
        steps[i] = d
        geo[_G_D + i] = d
        if d > n:
            n = d
    steps[_S_N_XYZ] = n
    return neg


@micropython.viper
def _half_bits(f_buf) -> int:
    """A positive float32's bits halved (a small int), as geometry.lengths returns a
    length's: they order as the floats do."""
    return (ptr32(f_buf)[0] >> 1) & _MASK30


def ramp_ticks(n, r0, r_nom, r1, acc, out=None, at=0):
    """The step loop's schedule (B_ACCEL_UNTIL, B_DECEL_AFTER, B_RATE_DECEL) for the
    trapezoid of a record (n lead steps, rates r0, r_nom, r1, acc per tick), by
    ramp.ramp_into, which says what it is. Returned as a tuple, or written to
    out[at:at + 3] (no tuple to allocate)."""
    io = _RAMP_IO
    io[ramp.IO_N] = n
    io[ramp.IO_R0] = r0
    io[ramp.IO_RNOM] = r_nom
    io[ramp.IO_R1] = r1
    io[ramp.IO_ACC] = acc
    ramp.ramp_into(io)
    if out is None:
        return io[ramp.IO_ACCEL_UNTIL], io[ramp.IO_DECEL_AFTER], io[ramp.IO_RATE_DECEL]
    out[at] = io[ramp.IO_ACCEL_UNTIL]
    out[at + 1] = io[ramp.IO_DECEL_AFTER]
    out[at + 2] = io[ramp.IO_RATE_DECEL]


# The limbs' scratch words: ramp.py's io, and lookahead.plan_words' words after them.
_RAMP_IO = array("i", bytes(4 * lookahead.W_WORDS))
_recalculate = lookahead.recalculate
_plan_words = lookahead.plan_words
_lengths = geometry.lengths
_junction = geometry.junction
product = ramp.product


class PlanError(ValueError):
    pass


def _share(feed_ratio, accel_ratio):
    """_SHARE_ONE over the factor by which a speed or acceleration is past an axis's
    limits (each ratio to its limit), at most _SHARE_ONE."""
    past = max(feed_ratio, accel_ratio)
    return _SHARE_ONE if past <= 1 else int(_SHARE_ONE / past)


def lk_words(queue_blocks):
    """The look-ahead's array for a queue: build() takes it early, as the step loop's."""
    return lookahead.L_WORDS * queue_blocks


def step_loop_bytes(settings):
    """What build() takes in big blocks for these settings (heap.reserve holds them
    while the modules load): the step loop's memory, the look-ahead's words and the DMA
    ring at most, and room to spare."""
    from mixfw import options
    trace = settings.get("trace_records", options.FIRMWARE_DEFAULTS["trace_records"])
    q = settings["queue_blocks"]
    words = st.mem_words(q, trace) + lk_words(q)
    if settings.get("step_backend") == "pio_dma":
        from mixfw import piodma
        words += piodma.ring_words(settings["tick_us"])
    return 4 * words + 2048


class Planner:
    def __init__(self, mem, settings, idle, irq_off, irq_on, lk=None, irq=None):
        """irq_off, irq_on: mask every interrupt and restore (machine.disable_irq,
        enable_irq). irq: where one IRQ alone runs the step loop (step_backend
        pio_dma), its (ICER, ISER, bit) in the NVIC, as piodma.Feed.irq has them: the
        look-ahead's record writes then mask that IRQ only."""
        self.mem = mem
        self.idle = idle
        self._irq_off = irq_off
        self._irq_on = irq_on
        q = settings["queue_blocks"]
        self.queue = q
        mem[st.S_QUEUE] = q
        # The move's geometry in integers (geometry.py), with its mm per unit.
        self._geo = array("i", bytes(4 * geometry.G_WORDS))
        self._geo_f = array("f", bytes(4 * geometry.GF_WORDS))
        self._geo_f[geometry.GF_E_NM] = 1.0 / NM_PER_MM
        # The speed and acceleration _base_floats worked out its words for (see
        # add_move): a list changed in place, as a tuple a new F would be garbage on
        # the chips.
        self._base_of = [None, None]
        # _base_floats' memo: _MEMO entries of _MEMO_WORDS, one list changed in place.
        self._memo = [None] * (_MEMO * _MEMO_WORDS)
        self.set_limits(settings)
        tick_us = settings["tick_us"]
        self.tick_s = tick_us * 1e-6
        self.set_steps_per_mm(settings["steps_per_mm"])
        self._min_mm_f = array("f", bytes(4))  # SLOWDOWN's length (see _min_bits)
        self.position_steps = [0, 0, 0, 0]
        # add_move's X Y Z targets as its viper code reads them: callers may write
        # theirs here and pass it (cmd_motion's g1 does); else add_move copies them in.
        # Two words more, which add_move never reads, for the callers' E.
        self.target_steps = array("i", bytes(4 * 5))
        # Per-slot planning data in integers, for the look-ahead (see lookahead.py).
        # A block's floats for lookahead.plan_words, with the tick's two.
        self._plan_f = array("f", bytes(4 * lookahead.F_WORDS))
        self._plan_f[lookahead.F_TICK_ONE] = self.tick_s * st.ONE
        self.lk = lk or heap.zeros(lk_words(q))
        # The last: irq, or a bit of 0 for irq_off and irq_on.
        self._hooks = (irq_off, irq_on, irq or array("i", bytes(12)))
        # X Y Z E, n (_xyz_steps), the drives (_plan_move: len() is a call), the
        # fastest rate the step loop may step at (see lookahead.plan_words), and
        # _plan_move's words (_S_MIX_ID on).
        self._abs_steps = array("i", bytes(4 * _S_WORDS))
        self.mix_id = 0
        self.tool_mix = (1,) + (0,) * (MAX_DRIVES - 1)  # the active tool's weights
        # E is planned per drive, from absolute positions so rounding never drifts:
        # each drive's exact filament (its share of every E move) -> its target step.
        self.drives = settings["drives"]
        self._abs_steps[_S_DRIVES] = self.drives
        # A STEP pin is high for pulse_ticks and low at least as long: at most a step in
        # 2 pulse_ticks, in the step loop's rate (ONE a step a tick).
        self._abs_steps[_S_RATE_CAP] = st.ONE // (2 * mem[st.S_PULSE_TICKS])
        # Each drive's exact filament (filament.py).
        filament.init(self, settings.get("drive_steps_per_mm") or
                      [self.steps_per_mm[3]] * self.drives)
        self._counts = array("i", bytes(4 * self.drives))  # the latest plan's steps per drive
        # The latest block's weights, from block_weights.
        self._weights = array("i", bytes(4 * self.drives))
        self._given = array("i", bytes(4 * self.drives))
        self.drive_steps = array("i", bytes(4 * self.drives))
        self.before_sync = []  # fn() each: moves held before the planner are handed over
        self.dir_invert_mask = 0  # DIR pins of motors wired the other way round: see
        self._dir_set = array("i", bytes(4 * 16))  # set_dir_invert, _dir_words
        self._dir_clr = array("i", bytes(4 * 16))
        self._dir_masks_seen = None
        # Times the step loop ran dry between two moves with no wait between them
        # (M122): the host or the planner did not keep up, and the axes stopped.
        self.underruns = 0
        # The objects add_move and _plan_move read for every line (_Q_*; each never
        # replaced), in one tuple: a subscript costs the chip about half what an
        # attribute does, and a viper call's arguments cost it each.
        self._queue_io = (mem, self._abs_steps, self._hooks, self.position_steps,
                          self.drive_nm, self.drive_rem, self._base_of, self.target_steps)
        array_offsets(self._abs_steps, _AT_MEM, (mem, self.lk, self._counts, self._geo,
                                            self._dir_set, self._dir_clr, self._weights,
                                            self.drive_steps, self._given,
                                            self.drive_targets, _RAMP_IO))
        array_offsets(self._abs_steps, _AT_F, (self._plan_f, self.target_steps))
        array_offsets(self._geo, _G_AT_GF, (self._geo_f, self._plan_f))
        resync(self)

    # --- queue state, shared with the step loop ---
    def busy(self):
        m = self.mem
        # R_PENDING: the DMA ring (step_backend pio_dma) still holds steps for the pins.
        return m[_S_HEAD] != m[_S_TAIL] or m[_S_ACTIVE] or m[st.R_PENDING]

    def synchronize(self):
        """Wait until every queued block has run (M400)."""
        for fn in self.before_sync:
            fn()
        while self.busy():
            self.idle()
        self._abs_steps[_S_JOINS] = 0

    def abort(self):
        """Drop every queued block at once (M112, faults). The step loop's counters
        then hold where the axes really are."""
        state = self._irq_off()
        m = self.mem
        m[st.S_TAIL] = m[st.S_HEAD]
        m[st.S_ACTIVE] = 0
        # Pressure advance's follower off, owing nothing: the step loop's counters
        # hold where the drives are.
        m[_S_ADV_SLOT] = _ADV_OFF
        m[_S_ADV_OWED] = _ADV_BIAS
        m[_S_ADV_NOW] = 0
        self._irq_on(state)
        # In place: Transitions holds this list (see set_position_steps).
        for i in range(4):
            self.position_steps[i] = m[st.S_POS + i]
        for i in range(self.drives):
            self.drive_steps[i] = m[st.S_DRIVE_POS + i]
        drive_pos_from_steps(self)
        self._abs_steps[_S_JOINS] = 0
        self.extruded = []
        self.retracted = []

    def set_steps_per_mm(self, steps_per_mm):
        """Steps/mm of X Y Z E (M92, M930), between moves."""
        self.steps_per_mm = list(steps_per_mm)
        for i in range(4):
            self._geo_f[geometry.GF_SCALE + i] = 1.0 / self.steps_per_mm[i]

    def set_limits(self, settings):
        """The axes' limits (M201, M203), the accelerations (M204), the junction
        deviation and the minimum segment time (M205), from settings' keys. Set here
        only: add_move works out its floats again for the next move.

        min_segment_time_us is Marlin's SLOWDOWN: while fewer than half the queue's
        blocks wait, a move shorter than this (in time) is slowed toward it, the more
        the fewer wait, so that the step path does not run dry between lines a host or
        the planner is slow to bring (a stop and a blob on every short curve segment).
        0: off."""
        self.max_feed_mm_s = settings["max_feed_mm_s"]
        self.max_accel_mm_s2 = settings["max_accel_mm_s2"]
        self.acceleration_mm_s2 = settings["acceleration_mm_s2"]
        self.retract_acceleration_mm_s2 = settings["retract_acceleration_mm_s2"]
        self.junction_deviation_mm = settings["junction_deviation_mm"]
        self.min_segment_s = settings["min_segment_time_us"] * 1e-6
        self._base_of[0] = None
        memo = self._memo
        for i in range(len(memo)):
            memo[i] = None

    def set_drive_steps(self, drive_steps_per_mm):
        """New steps/mm per drive (M92 E, M930), once the moves have run."""
        self.synchronize()
        set_drive_steps(self, drive_steps_per_mm)

    def set_mix(self, mix_id, weights, tool=-1):
        """The mix for E moves queued from now on (already normalised weights). The
        tool it belongs to matters only to Transitions in front of the planner."""
        self.mix_id = mix_id & _MASK30  # a small int on the chips, as _plan_move's
        self.tool_mix = tuple(weights)

    def set_position_steps(self, steps):
        """Redefine where the axes are (G92, homing) once the queue is empty."""
        self.synchronize()
        # In place: Transitions ends its queue at this list while no move waits.
        for i in range(4):
            self.position_steps[i] = steps[i]

    # --- adding blocks ---
    # The methods every G1 line runs with much to do are native code, as cmd_motion's:
    # faster than bytecode (bench/chip_rows.py profile times them), but about four
    # times its heap, so short ones such as this stay bytecode.
    def _new_slot(self, slot):
        """The slot for the next block, once the ring has room (one slot stays free, so
        a full ring is not taken for an empty one), from what _ring_room said."""
        m = self.mem
        while slot < 0:
            self.idle()
            slot = _ring_room(m)
        if slot & _RING_IDLE:
            words = self._abs_steps
            if words[_S_JOINS]:
                self.underruns += 1
            words[_S_JOINS] = 0
            slot ^= _RING_IDLE
        return slot

    def add_dwell(self, seconds):
        ticks = int(seconds / self.tick_s + 0.5)
        slot = self._new_slot(_ring_room(self.mem))
        b = _BLOCK_BASE + slot * _B_WORDS
        m = self.mem
        for i in range(st.B_WORDS):
            m[b + i] = 0
        m[b + st.B_FLAGS] = st.F_DWELL
        m[b + st.B_DWELL] = ticks
        w = _RAMP_IO
        array_offsets(w, _W_AT_LK, (self.lk, self._plan_f))
        w[_W_SLOT] = slot
        w[_W_N] = 0  # a dwell
        from uctypes import addressof
        _plan_words(addressof(w) >> 2)
        slot += 1
        m[_S_HEAD] = 0 if slot >= self.queue else slot
        self._abs_steps[_S_JOINS] = 0

    @micropython.native
    def add_move(self, target_steps, feed_mm_s, dir_masks=None, e_nm=0, mix=None,
                 replay=False, homing_axes=0):
        """Queue a straight move to absolute X Y Z step targets (target_steps[:3]) with
        e_nm (an integer) of filament shared by the drives in the active mix. Returns False if the
        move is shorter than one step on every axis (nothing to do). mix: (id, weights)
        for this move instead of the active one. replay: a retraction or unretraction
        that replays the latest extrusion exactly (retract_policy 2)."""
        # The mixer gives every drive exactly its count in a block of at most
        # MAX_PERIOD E steps (each drive's count rounds by up to a step: hence the
        # margin), so a longer extrusion, such as a purge, goes in equal pieces.
        piece_nm = self._one_piece_nm
        if e_nm >= piece_nm or e_nm <= -piece_nm:
            return self._add_pieces(target_steps, feed_mm_s, dir_masks, e_nm, mix, replay,
                                    homing_axes)
        # The methods it calls are taken from the class: self.method looks in the
        # instance's attributes first, and a miss in a map of sixty costs the emulated
        # Pico about 9 us.
        io = self._queue_io
        pos = io[_Q_POS]
        words = io[_Q_WORDS]
        target = io[_Q_TARGET]
        if target_steps is not target:
            # X Y Z's targets go into the planner's array, which viper reads as words:
            # checked first, as viper would take a big int's low bits for its value.
            for i in range(3):
                t = target_steps[i]
                if not -_MASK30 <= t <= _MASK30:
                    raise PlanError("move too long: from %s to %s steps"
                                    % (pos[:3], list(target_steps[:3])))
                target[i] = t
        # Bit i: axis i runs backwards; bit 4 + i: it moves. Before the filament is
        # planned: a move refused changes nothing. (E has at most MAX_PERIOD steps a
        # block: see add_move.)
        neg = _xyz_steps(pos, words)
        if neg < 0:
            raise PlanError("move too long: from %s to %s steps"
                            % (pos[:3], list(target_steps[:3])))
        # The speed and acceleration in floats, worked out again only when one of them
        # or a limit changes (a new F; M201, M203, M204, M205: set_limits): most lines
        # keep them, and a feed rate kept was checked as it came.
        accel = self.acceleration_mm_s2 if neg & 0x70 else self.retract_acceleration_mm_s2
        base = io[_Q_BASE]
        if feed_mm_s is not base[0] or accel is not base[1]:
            if feed_mm_s <= 0:
                raise PlanError("feed rate must be > 0")
            Planner._base_floats(self, feed_mm_s, accel)
        if replay and e_nm:
            replay_counts(self, e_nm)
        else:
            # Mostly the weights of the move before, whose plan fits plan_e_words'
            # words: the whole plan in one viper call, and plan_e, bytecode for the
            # heap native code would take, only where it does not.
            w = mix[1] if mix else self.tool_mix
            if w is not self._shares[0] or not plan_e_words(words, e_nm, io[_Q_NM], io[_Q_REM]):
                plan_e(self, e_nm, w)
        # The DIR pins to set and clear for each pattern of the axes' signs, worked out
        # once for these masks.
        if dir_masks is not self._dir_masks_seen:
            self._dir_words(dir_masks)
        # How _plan_move is to plan, the homing axes and the ring's slot in one word.
        how = homing_axes << _HOW_HOMING_SHIFT
        got = _plan_move(io, e_nm, neg, how, pos)
        while got < 0:
            # In Python, as add_move did all of it before: the ring's room, the speed
            # where a limit binds or SLOWDOWN slows the move, a mix too long.
            if got == _RING_WAIT:
                slot = Planner._new_slot(self, _ring_room(self.mem))
                how = (how & ((1 << _HOW_SLOT_SHIFT) - 1) | _HOW_SLOT
                       | slot << _HOW_SLOT_SHIFT)
            elif got == _FLOATS:
                Planner._limited_floats(self, feed_mm_s, accel)
                how |= _HOW_FLOATS | _HOW_LENGTHS
            else:
                self._scaled(self._given)
                how |= _HOW_SCALED | _HOW_LENGTHS
            got = _plan_move(io, e_nm, neg, how, pos)
        if got == 0:
            return False
        if got == _EXTRUDED and self.keep_extrusion and not replay:
            remember_extrusion(self, tuple(self._weights), list(self._given))
        return True

    # The bytecode functions below run on lines that change the feed rate or where a
    # limit binds. Each keeps its locals and stack within 11 words: MicroPython gives a
    # function with more its frame from the heap at each call, and on a fragmented heap
    # that search for a hole of several blocks can cost the chip hundreds of
    # microseconds a call (the line's floats take one block each: found at once).
    def _base_floats(self, speed, accel):
        """For add_move: what the move's speed and acceleration are within (the axes'
        limits, bit i, and bit 4 within eight times E's) and SLOWDOWN's shortest length
        at that speed, in the planner's words; and the speed and acceleration as the
        look-ahead and the junction take them, in floats.

        Mostly a pair worked out before, taken from the memo: a print's retractions,
        travels and extrusions take turns at a few of them, and working them out costs
        the chip about 0.2 ms (each float operation allocates)."""
        base = self._base_of
        base[0] = speed
        base[1] = accel
        memo = self._memo
        for at in range(0, _MEMO * _MEMO_WORDS, _MEMO_WORDS):
            if memo[at + 1] is accel and memo[at] == speed:
                break
        else:
            at = Planner._work_base_floats(self, speed, accel)
        Planner._memo_load(self, at)
        self._abs_steps[_S_F_BASE] = _F_BASE_BOTH

    def _memo_load(self, at):
        """The memo's entry at `at`: its words and floats into the planner's."""
        memo = self._memo
        words = self._abs_steps
        words[_S_WITHIN] = memo[at + 2]
        words[_S_MIN_BITS] = memo[at + 3]
        f = self._plan_f
        f[_F_ACCEL] = memo[at + 1]
        f[_F_NOMINAL] = memo[at]
        f[_F_NOMINAL2] = memo[at + 4]
        f[_F_ACCEL_TICK] = memo[at + 5]
        self._geo_f[_GF_ACCEL_JD] = memo[at + 6]
        words[_S_SHARES_SET] = 0  # another speed's

    def _work_base_floats(self, speed, accel):
        """_base_floats' words and floats for the pair, worked out into the memo's
        oldest entry; returns where it starts. Its pair goes in last: an entry left
        half done matches none."""
        words = self._abs_steps
        at = words[_S_MEMO_NEXT]
        words[_S_MEMO_NEXT] = (at + _MEMO_WORDS) % (_MEMO * _MEMO_WORDS)
        memo = self._memo
        memo[at + 1] = None
        memo[at + 2] = Planner._within(self, speed, accel)
        memo[at + 3] = Planner._min_bits(self, speed) if self.min_segment_s else 0
        Planner._set_floats(self, speed, accel)
        memo[at + 4] = self._plan_f[_F_NOMINAL2]
        memo[at + 5] = self._plan_f[_F_ACCEL_TICK]
        memo[at + 6] = self._geo_f[_GF_ACCEL_JD]
        memo[at] = speed
        memo[at + 1] = accel
        return at

    def _within(self, speed, accel):
        """The axes whose limits speed and accel are within (bit i), and bit 4 if
        within eight times E's."""
        max_feed = self.max_feed_mm_s
        max_accel = self.max_accel_mm_s2
        within = 0
        for i in range(4):
            if speed <= max_feed[i] and accel <= max_accel[i]:
                within |= 1 << i
        if speed <= 8 * max_feed[3] and accel <= 8 * max_accel[3]:
            within |= 16
        return within

    def _shares(self, speed, accel):
        """_S_SHARES' words of speed and accel, for X Y Z E: the axis binds only where
        its share of the path is over its word over _SHARE_ONE. In the words until the
        speed changes."""
        words = self._abs_steps
        feed = self.max_feed_mm_s
        most = self.max_accel_mm_s2
        words[_S_SHARES] = _share(speed / feed[0], accel / most[0])
        words[_S_SHARES + 1] = _share(speed / feed[1], accel / most[1])
        words[_S_SHARES + 2] = _share(speed / feed[2], accel / most[2])
        words[_S_SHARES + 3] = _share(speed / feed[3], accel / most[3])
        words[_S_SHARES_SET] = 1

    def _min_bits(self, speed):
        """SLOWDOWN's shortest length at speed, as geometry.lengths gives a length."""
        self._min_mm_f[0] = speed * self.min_segment_s
        return _half_bits(self._min_mm_f)

    def _limited_floats(self, speed, accel):
        """add_move's speed and acceleration where an axis's limits bind (_plan_move
        said which) or SLOWDOWN may slow the move, in floats; or, with neither, the
        floats of the speed and acceleration asked, where they hold another move's. On
        a print that SLOWDOWN slows every line comes here, and each float operation
        allocates on the chips: the acceleration's floats are kept where they stand."""
        limited = speed
        limited_accel = accel
        if self._abs_steps[_S_OVER]:
            limited = Planner._axis_limit(self, speed, self.max_feed_mm_s)
            limited_accel = Planner._axis_limit(self, accel, self.max_accel_mm_s2)
            if (limited is speed and limited_accel is accel
                    and not self._abs_steps[_S_SHARES_SET]):
                # Past their limits, and none bound: such an axis has a small share of
                # the path (a spiral vase's Z). How much it may take at this speed, so
                # that the next moves need no floats.
                Planner._shares(self, speed, accel)
        if self.min_segment_s:
            limited = Planner._slowdown(self, limited, limited is speed)
        if (limited is not speed and limited_accel is accel
                and self._abs_steps[_S_F_BASE] & _F_BASE_ACCEL):
            # SLOWDOWN alone, mostly: the acceleration's floats stand.
            self._plan_f[_F_NOMINAL] = limited
            self._plan_f[_F_NOMINAL2] = limited * limited
            self._abs_steps[_S_F_BASE] = _F_BASE_ACCEL
            return
        Planner._set_floats(self, limited, limited_accel)
        self._abs_steps[_S_F_BASE] = (_F_BASE_BOTH if limited is speed
                                      and limited_accel is accel else 0)

    def _axis_limit(self, value, limits):
        """value (a speed or an acceleration along the path), or lower where an axis
        _plan_move found over its limits binds: its limit over its share of the path.
        The same object where none binds."""
        inv = 1.0 / self._geo[_G_DIST]
        for i in range(4):
            if (self._abs_steps[_S_OVER] >> i) & 1:
                bound = limits[i] / (self._geo[_G_C + i] * inv)
                if bound < value:
                    value = bound
        return value

    def _slowdown(self, speed, asked):
        """speed, or slower where Marlin's SLOWDOWN (set_limits) slows the move, with
        its bounds: 2 to half the queue's blocks waiting, and 2 (min_s - t) / waiting
        added to the time t. asked: speed is the one asked (its length is in the
        words)."""
        if ((self._abs_steps[_S_MIN_BITS] if asked else Planner._min_bits(self, speed))
                <= self._abs_steps[_S_DIST_BITS]):
            return speed
        waiting = waiting_blocks(self.mem)
        if not 2 <= waiting < self.queue // 2:
            return speed
        dist = self._plan_f[_F_MM]
        t = dist / speed
        return dist / (t + 2 * (self.min_segment_s - t) / waiting)

    def _set_floats(self, speed, accel):
        """The look-ahead's floats (lookahead.plan_words) and the junction's."""
        f = self._plan_f
        f[_F_ACCEL] = accel
        f[_F_NOMINAL] = speed
        f[_F_NOMINAL2] = speed * speed
        f[_F_ACCEL_TICK] = accel * self.tick_s
        self._geo_f[_GF_ACCEL_JD] = accel * self.junction_deviation_mm

    def _add_pieces(self, target_steps, feed_mm_s, dir_masks, e_nm, mix, replay,
                    homing_axes):
        """add_move's extrusion too long for one block, in equal pieces. Apart from
        add_move: a comprehension's variables are heap cells, made at every call of the
        function that holds it, and add_move runs for every line."""
        pieces = (abs(e_nm) * max(self._spm_fixed)
                  // (NM_PER_MM * SPM_SCALE * (MAX_PERIOD - 2 * MAX_DRIVES))) + 1
        start = list(self.position_steps)  # which each piece changes in place
        # A copy: the targets may be in the planner's target_steps, which each piece's
        # add_move overwrites.
        end = list(target_steps[:3])
        added = False
        for k in range(1, pieces + 1):
            point = [start[i] + div_round((end[i] - start[i]) * k, pieces)
                     for i in range(3)]
            piece_nm = e_nm * k // pieces - e_nm * (k - 1) // pieces
            added = self.add_move(point, feed_mm_s, dir_masks, piece_nm, mix, replay,
                                  homing_axes) or added
        return added

    def _scaled(self, steps):
        """add_move's weights for steps too many for the mixer's integers: scaled, and
        the steps the schedule then gives, worked out with the mixer itself, into
        self._given (an array, as _plan_move reads it)."""
        scaled = normalize(steps, self.drives)
        got = schedule_counts(scaled, sum(steps))
        for i in range(self.drives):
            self._weights[i] = scaled[i]
            self._given[i] = got[i]
        return self._given

    def set_advance(self, value):
        """Pressure advance for the moves queued from now on: K (value), seconds of the
        filament's speed pushed ahead (Marlin's LIN_ADVANCE K); 0 turns it off."""
        k = int(value / self.tick_s * 256 + 0.5)
        if not 0 <= k < 1 << 28:
            raise PlanError("pressure advance K %s is beyond the step loop's %s"
                            % (value, ((1 << 28) - 1) * self.tick_s / 256))
        self._abs_steps[_S_ADV_K] = k

    def set_dir_invert(self, mask):
        """The DIR pins of motors wired the other way round, flipped in every block."""
        self.dir_invert_mask = mask
        self._dir_masks_seen = None  # the DIR words are worked out again

    def _dir_words(self, dir_masks):
        """The DIR pins a block sets and clears, for each of the 16 patterns of its X Y Z
        E signs (bit i: axis i runs backwards), with dir_masks per axis (None: no pins)
        and the motors wired the other way round (dir_invert_mask) flipped."""
        inv = self.dir_invert_mask
        for neg in range(16):
            dset = 0
            dclr = 0
            for i in range(4):
                mask = dir_masks[i] if dir_masks else 0
                if neg >> i & 1:
                    dclr |= mask
                else:
                    dset |= mask
            self._dir_set[neg] = (dset & ~inv) | (dclr & inv)
            self._dir_clr[neg] = (dclr & ~inv) | (dset & inv)
        self._dir_masks_seen = dir_masks
        pins = dir_masks[3] if dir_masks else 0
        self._abs_steps[_S_E_DIR_PINS] = pins
        self.mem[_S_ADV_FWD_SET] = pins & ~inv
        self.mem[_S_ADV_FWD_CLR] = pins & inv
