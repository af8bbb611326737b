# The planner's look-ahead and its records, in viper on integers. It runs for every
# G-code line, and on the chips every float operation allocates: its garbage would take
# a collection every few dozen lines.
#
# Speeds are kept squared, as V2 = (mm/s)**2 * 64 (_V2_SCALE), below 2**29 (about
# 2,900 mm/s): then the passes only add and compare (v**2 = v0**2 + 2 a s), a sum of
# three stays below 2**31, and the 32-bit chips and the 64-bit unix port give the same
# integers. A record's rates come from V2 by an exact integer square root.
from mixfw import stepper as st
from mixfw.compat import MASK30, micropython  # noqa: F401 (room in the globals: see compat)
from mixfw.ramp import isqrt_limbs, product

_V2_SCALE = const(64)
_V2_MAX = const(0x1FFFFFFF)

# Words per slot in the planner's lk array.
L_GAIN = const(0)  # the V2 a block gains over its length: 2 a mm
L_MAX_ENTRY = const(1)  # junction limit
L_NOMINAL = const(2)
_L_BACK = const(3)  # the fastest entry that can still stop by the end of the queue
L_ENTRY = const(4)
L_EXIT = const(5)  # the exit baked into the slot's record
L_K2 = const(6)  # rate = isqrt(V2 * K2) << K_SHIFT (>> -K_SHIFT): see plan_words
L_K_SHIFT = const(7)  # plus SHIFT_BIAS: a 64-bit build's viper reads words unsigned
L_RATE_NOM = const(8)  # the nominal speed's rate
L_FLOOR = const(9)  # the slowest rate: reached from rest within half a step
L_ACC = const(10)
L_DWELL = const(11)
L_WORDS = const(12)  # plan_words clears each word by name
SHIFT_BIAS = st.SHIFT_BIAS  # the step loop's: it reads K_SHIFT from a record too

# stepper.py's layout: the step loop's words and its records' (copies, as viper folds
# only this module's constants).
_SHIFT_BIAS = const(64)
_S_TAIL = const(1)
_S_ACTIVE = const(2)
_S_QUEUE = const(26)
_BLOCK_BASE = const(123)
_B_WORDS = const(24)
_B_FLAGS = const(7)
_B_RATE_INIT = const(8)
_B_RATE_NOM = const(9)
_B_RATE_FINAL = const(10)
_B_ACCEL = const(11)
_B_ACCEL_UNTIL = const(12)
_B_DECEL_AFTER = const(13)
_B_RATE_DECEL = const(22)
_F_SCHEDULE = const(2048)
_F_RATES = const(4096)
_V2_AT_NOMINAL = const(0x20000000)


# A block's planning data comes in as float32 in an array('f'), whose bits viper reads
# as integers (mantissa, exponent): no float operation, so nothing allocated.
F_MM = const(0)  # its length
_F_ACCEL = const(1)  # mm/s**2
_F_NOMINAL = const(2)  # mm/s
_F_NOMINAL2 = const(3)  # its square
F_TICK_ONE = const(4)  # the step loop's tick in s, times ONE (its rate of a step a tick)
_F_ACCEL_TICK = const(5)  # _F_ACCEL times the tick in s: the speed gained a tick
F_WORDS = const(6)
# Scratch words of the planning io array, after ramp.py's (its IO_WORDS).
_W_M = const(16)  # F_WORDS mantissas (with the hidden bit; 0 for 0)
_W_E = const(22)  # and their exponent fields: x = m * 2**(field - _BIAS)
_BIAS = const(150)  # float32's exponent bias and its 23 fraction bits
# The latest nominal speed's V2 and the float32 bits of the square it came from: most
# lines keep the feed rate of the line before.
_W_N2_BITS = const(28)
_W_N2_V2 = const(29)
# plan_words and recalculate take io as its address over 4 (as ramp's helpers take
# theirs). Then their inputs, which the planner stores (a viper call's argument and
# ptr32() of an array cost the chip far more than a store: see ramp.py): where lk, the
# floats and the step loop's words are, as byte offsets from io's own plus _AT_BIAS
# (see ramp.array_offsets), then the block's slot, its n, the junction's entry_v2 and
# the rate_cap (see plan_words). planner.py keeps copies of these words.
_W_AT_LK = const(30)
_W_AT_F = const(31)
_W_AT_MEM = const(32)
_W_SLOT = const(33)
_W_N = const(34)
_W_ENTRY_V2 = const(35)
_W_RATE_CAP = const(36)
W_WORDS = const(37)
# ramp.py's: the io words product() and isqrt_limbs() read, and product()'s modes
# (copies).
_AT_BIAS = const(0x20000000)
_IO_HI = const(8)
_IO_LO = const(9)
_IO_A = const(11)
_IO_B = const(12)
_IO_C = const(13)
_IO_S = const(14)
_IO_HOW = const(15)
_P_TRUNC = const(1)
_P_ROUND = const(2)
_P_TOP = const(3)
_MASK30 = const(0x3FFFFFFF)  # compat.MASK30


@micropython.viper
def plan_words(w4: int):
    """A new block's words in lk (its slot's) from its floats (F_*), n, its lead-axis
    steps (0 for a dwell), and entry_v2, the junction's limit (V2, see
    geometry.junction), each in the io array w's words (_W_*). Speeds become V2 within
    the range kept; what the block adds to v**2 over its length is 2 a s; mm/s becomes
    the step loop's rate with k = TICK_ONE n / mm, and mm/s**2 its rate change per
    tick, k a TICK_S.

    k is the one conversion of a speed to a rate, made here: RATE_NOM is the nominal
    speed times k, and K2 and K_SHIFT are k as stepper.schedule takes it for a V2's
    rate, k sqrt(V2 / 64), worked out as the block starts (host_tests/test_layouts.py
    checks that the two agree).

    rate_cap (0: none) is the fastest rate the lead axis may step at (the step pulse's
    high and low time): a nominal rate above it becomes it, and the nominal V2 the
    V2 whose rate it is. In integers here, as the rate is: the same limit in mm/s
    would be a speed worked out in floats for every fast line (each float operation
    allocates on the chips)."""
    w = ptr32(w4 << 2)
    base = int(w) - _AT_BIAS  # the arrays' offsets are from here
    lk = ptr32(base + w[_W_AT_LK])
    f = ptr32(base + w[_W_AT_F])
    at = w[_W_SLOT] * L_WORDS
    n = w[_W_N]
    entry_v2 = w[_W_ENTRY_V2]
    rate_cap = w[_W_RATE_CAP]
    # A local: a call of a module's function looks it up by name first, about 1 us
    # on the chip, and a line makes five or six products.
    prod = product
    # Every word: those worked out below, then the rest (a loop turn costs the chip
    # about as much as a store).
    lk[at + L_GAIN] = 0
    lk[at + L_MAX_ENTRY] = 0
    lk[at + L_NOMINAL] = 0
    lk[at + L_K2] = 0
    lk[at + L_K_SHIFT] = 0
    lk[at + L_RATE_NOM] = 0
    lk[at + L_FLOOR] = 0
    lk[at + L_ACC] = 0
    lk[at + _L_BACK] = 0
    lk[at + L_ENTRY] = 0
    lk[at + L_EXIT] = 0
    lk[at + L_DWELL] = 0
    if n <= 0:
        lk[at + L_DWELL] = 1
        return
    for i in range(F_WORDS):
        bits = f[i]
        ex = (bits >> 23) & 0xFF
        if ex:
            w[_W_M + i] = (bits & 0x7FFFFF) | 0x800000
        else:
            w[_W_M + i] = 0
        w[_W_E + i] = ex
    m_mm = w[_W_M + F_MM]
    e_mm = w[_W_E + F_MM] - _BIAS
    m_a = w[_W_M + _F_ACCEL]
    e_a = w[_W_E + _F_ACCEL] - _BIAS
    # GAIN = 2 _V2_SCALE a mm (_V2_SCALE = 2**6)
    w[_IO_A] = m_a
    w[_IO_B] = m_mm
    w[_IO_C] = 1
    w[_IO_S] = e_a + e_mm + 7
    w[_IO_HOW] = _P_ROUND
    x = int(prod(w4))
    lk[at + L_GAIN] = x if x < _V2_MAX else _V2_MAX
    bits = f[_F_NOMINAL2]
    if bits != w[_W_N2_BITS]:
        w[_IO_A] = w[_W_M + _F_NOMINAL2]
        w[_IO_B] = 1
        w[_IO_S] = w[_W_E + _F_NOMINAL2] - _BIAS + 6
        x = int(prod(w4))  # C and HOW as for GAIN
        w[_W_N2_V2] = x if x < _V2_MAX else _V2_MAX
        w[_W_N2_BITS] = bits
    x = w[_W_N2_V2]
    lk[at + L_NOMINAL] = x
    lk[at + L_MAX_ENTRY] = entry_v2 if entry_v2 < x else x
    # k = TICK_ONE n / mm as km 2**ke, km of 26 bits: n taken to 29 bits and TICK_ONE's
    # mantissa to 30 first, so the quotient has 33 bits or more.
    ns = 28  # 29 - bits(n), at least 0: halving the bits searched, five turns
    a = n
    b = 16
    while b:
        if a >> b:
            a = a >> b
            ns -= b
        b = b >> 1
    if ns < 0:
        ns = 0
    w[_IO_A] = w[_W_M + F_TICK_ONE] << 6
    w[_IO_B] = n << ns
    w[_IO_C] = m_mm
    w[_IO_S] = 26
    w[_IO_HOW] = _P_TOP
    ke = int(prod(w4))
    ke += w[_W_E + F_TICK_ONE] - _BIAS - 6 - ns - e_mm
    km = w[_IO_LO]
    # RATE_NOM = nominal k, truncated.
    w[_IO_A] = w[_W_M + _F_NOMINAL]
    w[_IO_B] = km
    w[_IO_C] = 1
    w[_IO_S] = w[_W_E + _F_NOMINAL] - _BIAS + ke
    w[_IO_HOW] = _P_TRUNC
    r_nom = int(prod(w4))
    # acc = k a TICK_S, the rate change per tick, as km * m_at 2**s (a TICK_S comes
    # in as one float, worked out where the acceleration changes: a product less a
    # line): ACC rounded, at least 1.
    m_at = w[_W_M + _F_ACCEL_TICK]
    s = ke + w[_W_E + _F_ACCEL_TICK] - _BIAS
    w[_IO_A] = km
    w[_IO_B] = m_at
    w[_IO_S] = s
    w[_IO_HOW] = _P_ROUND
    acc = int(prod(w4))  # C as for RATE_NOM
    lk[at + L_ACC] = acc if acc > 1 else 1
    # FLOOR, the slowest rate a block may fall to: reached from rest within half a
    # step, so a block that ends at a stop still finishes. sqrt(acc ONE), ONE = 2**28:
    # the root of acc taken to 54 bits, or 55 for an even exponent, truncated.
    w[_IO_S] = 54
    w[_IO_HOW] = _P_TOP
    t = int(prod(w4)) + s + 28  # A B C as for ACC
    if t & 1:
        hi = w[_IO_HI]
        lo = w[_IO_LO]
        w[_IO_HI] = (hi << 1) | (lo >> 29)
        w[_IO_LO] = (lo << 1) & _MASK30
        t -= 1
    floor = int(isqrt_limbs(w4))
    t = t >> 1
    if t >= 0:
        floor = _MASK30 if t > 30 or floor > (_MASK30 >> t) else floor << t
    else:
        floor = floor >> (0 - t) if t > -31 else 0
    lk[at + L_FLOOR] = floor
    # rate = k sqrt(V2 / _V2_SCALE) = isqrt(V2 * K2) scaled by 2**K_SHIFT, with K2 in
    # [2**24, 2**26): V2 * K2 stays below 2**55, and the root keeps 15 bits or more.
    # k**2 / 2**6 = km**2 2**(2 ke - 6) = K2 4**K_SHIFT with K2 = km**2 >> 26: the
    # square in two limbs, in ramp.product's form (for a square: 2 a b in the middle),
    # written out (a call costs the chip about 6 us; km has 26 bits, so the high limb
    # has 22 and nothing is capped).
    a = km >> 15
    b = km & 0x7FFF
    x = 2 * a * b
    lo = ((x & 0x7FFF) << 15) + b * b
    k2 = ((a * a + (x >> 15) + (lo >> 30)) << 4) | ((lo & _MASK30) >> 26)
    lk[at + L_K2] = k2
    shift = ke + 10
    lk[at + L_K_SHIFT] = shift + _SHIFT_BIAS
    if rate_cap > 0 and r_nom > rate_cap:
        r_nom = rate_cap
        # The cap's V2, (cap / 2**K_SHIFT)**2 / K2 truncated: its rate by the root
        # above is the cap or just below.
        a = 0
        if shift >= 0:
            a = rate_cap >> shift
        elif shift > -30 and (rate_cap >> (30 + shift)) == 0:
            a = rate_cap << (0 - shift)
        if a:  # else the cap's V2 is past any V2 kept
            w[_IO_A] = a
            w[_IO_B] = a
            w[_IO_C] = k2
            w[_IO_S] = 0
            w[_IO_HOW] = _P_TRUNC
            x = int(prod(w4))
            if x < lk[at + L_NOMINAL]:
                lk[at + L_NOMINAL] = x
                if x < lk[at + L_MAX_ENTRY]:
                    lk[at + L_MAX_ENTRY] = x
    lk[at + L_RATE_NOM] = r_nom if r_nom > floor else floor


@micropython.viper
def recalculate(w4: int, hooks):
    """Bring the look-ahead up to date after the slot plan_words planned (`newest`, in
    the io array w) was queued (it stops at its end)
    and rewrite the records of the blocks not yet started whose entry or exit changed.
    hooks: (irq_off, irq_on, NVIC mask words: see planner.Planner).

    BACK of a slot, the fastest it may enter and still stop by the end of the queue,
    only grows as blocks are queued. The backward pass stops at the first block whose
    BACK stays the same (Grbl's and Marlin's optimal marker): the plan before it stands,
    and the forward pass starts there. A record is written here, not in a function of
    its own: on curves a line rewrites a dozen, and the call with its arrays' lookups
    would cost the chip about 14 us a record."""
    w = ptr32(w4 << 2)
    base = int(w) - _AT_BIAS
    lk = ptr32(base + w[_W_AT_LK])
    mem = ptr32(base + w[_W_AT_MEM])
    newest = w[_W_SLOT]
    q = mem[_S_QUEUE]
    tail = mem[_S_TAIL]
    first = tail
    if mem[_S_ACTIVE]:
        first = tail + 1
        if first >= q:
            first = 0
    # Backward pass.
    # A slot's words through a pointer of their own (rec): an index into lk costs
    # viper an addition and a shift at every use.
    k = newest
    rec = ptr32(int(lk) + 4 * k * L_WORDS)
    e = rec[L_GAIN]
    if rec[L_MAX_ENTRY] <= e:
        e = rec[L_MAX_ENTRY]
    rec[_L_BACK] = e
    while k != first:
        j = k - 1
        if j < 0:
            j = q - 1
        rec = ptr32(int(lk) + 4 * j * L_WORDS)
        e = e + rec[L_GAIN]
        if rec[L_MAX_ENTRY] <= e:
            e = rec[L_MAX_ENTRY]
        k = j
        if e == rec[_L_BACK]:
            break
        rec[_L_BACK] = e
    # Forward pass from block k, whose entry stands, then records.
    rec = ptr32(int(lk) + 4 * k * L_WORDS)
    if k == first:
        # The block before the first one is running or has run: the first one enters
        # at most at the exit baked into that record, also between blocks (tail
        # advanced, not yet started), where more look-ahead would otherwise raise it
        # above the speed the step loop left at. After a stop, MAX_ENTRY is 0 anyway.
        v0 = rec[_L_BACK]
        p = k - 1
        if p < 0:
            p = q - 1
        handed_over = lk[p * L_WORDS + L_EXIT]
        if handed_over < v0:
            v0 = handed_over
    else:
        v0 = rec[L_ENTRY]
    mask = ptr32(hooks[2])
    bit = mask[2]
    while True:
        rec = ptr32(int(lk) + 4 * k * L_WORDS)
        nk = k + 1
        if nk >= q:
            nk = 0
        if k == newest:
            v1 = 0
        else:
            v1 = lk[nk * L_WORDS + _L_BACK]
            reach = v0 + rec[L_GAIN]
            if v1 > reach:
                v1 = reach
        # A record is a function of its entry and exit: rewrite changed ones (a dwell
        # has none).
        changed = 0
        if k == newest or v0 != rec[L_ENTRY] or v1 != rec[L_EXIT]:
            rec[L_ENTRY] = v0
            changed = 1 - rec[L_DWELL]
        if changed:
            # The rates of V2 v0 and v1 are the step loop's to work out, once, as the
            # block starts (stepper.schedule, F_RATES): the record gets the two V2s
            # (V2_AT_NOMINAL where the nominal rate is theirs) and what a rate comes
            # from. On curves, whose queue is shorter than the braking distance, a
            # line rewrites a dozen records, and their roots here would cost the chip
            # about 0.3 ms a line.
            nominal = rec[L_NOMINAL]
            c0 = v0 if v0 < nominal else _V2_AT_NOMINAL
            c1 = v1 if v1 < nominal else _V2_AT_NOMINAL
            blk = ptr32(int(mem) + 4 * (_BLOCK_BASE + k * _B_WORDS))
            # The step loop must not start the block half written: its interrupt held
            # back, in the NVIC where one IRQ runs it (ISER reads which are enabled),
            # else all.
            was = 0
            state = hooks  # any object, until irq_off's state
            if bit:
                was = ptr32(mask[1])[0] & bit
                ptr32(mask[0])[0] = bit
            else:
                state = hooks[0]()
            if not (k == mem[_S_TAIL] and mem[_S_ACTIVE]):  # else too late to change
                blk[_B_RATE_INIT] = c0
                blk[_B_RATE_NOM] = rec[L_RATE_NOM]
                blk[_B_RATE_FINAL] = c1
                blk[_B_ACCEL] = rec[L_ACC]
                # Until the schedule is worked out, its words hold the rates' K2,
                # K_SHIFT (biased, as here) and FLOOR.
                blk[_B_ACCEL_UNTIL] = rec[L_K2]
                blk[_B_DECEL_AFTER] = rec[L_K_SHIFT]
                blk[_B_RATE_DECEL] = rec[L_FLOOR]
                blk[_B_FLAGS] |= _F_SCHEDULE | _F_RATES
                rec[L_EXIT] = v1
            if bit:
                if was:
                    ptr32(mask[1])[0] = bit
            else:
                hooks[1](state)
        if k == newest:
            break
        # The step loop may have started block k meanwhile: then the next block enters
        # at most at the exit it was given before.
        v0 = v1
        if v1 > rec[L_EXIT]:
            v0 = rec[L_EXIT]
        k = nk
