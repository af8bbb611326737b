# The step loop's schedule for a block's trapezoid (ramp_into says what it is), in viper
# on integers: the step loop works it out as each block starts, and on the chips every
# float operation allocates.
#
# The squares of rates need about 56 bits, more than a chip's machine word, so they are
# kept as two 30-bit limbs (hi, lo) in words of the io array. Every intermediate stays
# below 2**31, so the 32-bit chips and the 64-bit unix port give the same results.
# Viper's cast (a pointer's address) here, and CPython's stand-in for it (see compat).
from mixfw.compat import int  # noqa: A004
from mixfw.compat import micropython  # noqa: F401 (room in the globals: see compat)

_MASK30 = const(0x3FFFFFFF)  # compat.MASK30: also the most ticks a schedule counts
# Fraction bits of the deceleration's start time, in ticks: enough that the rate the
# first decelerating tick gets is exact to a rate unit for any acceleration the step
# loop takes.
_FRAC = const(16)
_HALF = const(0x8000)
_ONE_FRAC = const(0x10000)

# The io array's words: the record's inputs, the schedule out, and scratch.
IO_N = const(0)
IO_R0 = const(1)
IO_RNOM = const(2)
IO_R1 = const(3)
IO_ACC = const(4)
IO_ACCEL_UNTIL = const(5)
IO_DECEL_AFTER = const(6)
IO_RATE_DECEL = const(7)
IO_HI = const(8)  # (hi, lo): two 30-bit limbs, for the helpers below
IO_LO = const(9)
_IO_REM = const(10)
# The last five: product()'s operands a, b, c, s and how (see there), which its callers
# store (a viper call's int argument costs the chip about 1 us, a store a few cycles).
# Private, as every name a module keeps is interned, and the chips hold interned names
# for good, in pools of which one more costs kB of heap (printer.py, answer): the
# modules that store them keep copies (host_tests/test_layouts.py checks them).
_IO_A = const(11)
_IO_B = const(12)
_IO_C = const(13)
_IO_S = const(14)
_IO_HOW = const(15)
IO_WORDS = const(16)
_AT_BIAS = const(0x20000000)  # see array_offsets


def array_offsets(words, at, arrays):
    """The arrays' places, as byte offsets from words' own plus 0x20000000 (_AT_BIAS),
    into words from `at` on: viper finds an array there as ptr32(int(words) -
    0x20000000 + words[k]), where ptr32() of the array itself costs the chip about
    1.4 us. MicroPython never moves an object: the places hold while whoever keeps
    words keeps the arrays too (the planner's _AT_* words; lookahead's and geometry's;
    cmd_motion's _SPM_MANT on, for xyz_targets)."""
    from uctypes import addressof
    base = addressof(words)
    for i, a in enumerate(arrays):
        words[at + i] = addressof(a) - base + _AT_BIAS


# The helpers below take their array as its address over 4 (w4: int(ptr32(w)) >> 2, a
# small int on every port, 32-bit ones included): ptr32() of an int costs nothing, of an
# array much more (see array_offsets). Their callers keep the array, so its place holds
# (MicroPython never moves an object).


@micropython.viper
def div_limbs(w4: int, c: int):
    """(hi, lo) //= c and REM = the remainder, for 0 < c < 2**29: hi by one machine
    division (the RP2040's divider), then lo in two digits of 15 bits. Each digit's
    quotient is estimated from c's top 15 bits, which is at most one below and two
    above it, and put right by the remainder. That remainder is below 2**31 either
    way, so a 32-bit chip's products may wrap on the way: it comes out exact. Digits
    as wide as would keep the partial remainder below 2**30 would take up to 30 loop
    turns for a large c."""
    w = ptr32(w4 << 2)
    hi = w[IO_HI]
    lo = w[IO_LO]
    qh = hi // c
    r = hi - qh * c
    # t = bits(c) - 15 (at least 0), found in five steps: ch = c >> t, c's top 15 bits
    x = c
    b = 1
    if x >= 0x10000:
        x = x >> 16
        b += 16
    if x >= 0x100:
        x = x >> 8
        b += 8
    if x >= 0x10:
        x = x >> 4
        b += 4
    if x >= 4:
        x = x >> 2
        b += 2
    if x >= 2:
        b += 1
    t = b - 15
    if t < 0:
        t = 0
    ch = c >> t
    ql = 0
    for k in range(2):
        d = lo >> 15
        if k:
            d = lo & 0x7FFF
        # r < c: (r << 15 | d) >> t below 2**30
        q = ((r << (15 - t)) | (d >> t)) // ch
        r = (r << 15) + d - q * c
        while r < 0:
            q -= 1
            r += c
        while r >= c:
            q += 1
            r -= c
        ql = (ql << 15) | q
    w[IO_HI] = qh
    w[IO_LO] = ql
    w[_IO_REM] = r


@micropython.viper
def isqrt_limbs(w4: int) -> int:
    """floor(sqrt((hi, lo))), for (hi, lo) below 2**56, by Zimmermann's Karatsuba
    square root on four 14-bit digits: the root of the top two digits by Newton's
    method (28 bits, in machine words), the rest with one division, where bit by bit
    would take 28 loop turns."""
    w = ptr32(w4 << 2)
    hi = w[IO_HI]
    lo = w[IO_LO]
    if not (hi or lo):
        return 0
    # Shifted left by an even 2 z bits, to have its top pair of bits at 54 and 55.
    x = lo
    top = 0
    if hi:
        x = hi
        top = 30
    # t: x's top bit, by halving the bits searched, made even
    t = 0
    if x >> 16:
        x = x >> 16
        t = 16
    if x >> 8:
        x = x >> 8
        t += 8
    if x >> 4:
        x = x >> 4
        t += 4
    if x >> 2:
        t += 2
    sh = 54 - top - t
    z = sh >> 1
    if sh >= 30:
        hi = lo << (sh - 30)
        lo = 0
    elif sh > 0:
        hi = (hi << sh) | (lo >> (30 - sh))
        lo = (lo << sh) & _MASK30
    a0 = lo & 0x3FFF
    a1 = (lo >> 14) & 0x3FFF
    top = (hi << 2) | (lo >> 28)  # the top two digits: below 2**28, at least 2**26
    # Their root by Newton's method, from above: (top / c + c) / 2 >= sqrt(top) for
    # any c, here about 2**13.25 or 2**13.75 for each half of top's range (within 1.5 %:
    # a turn fewer than one c for both).
    c = 13777
    if top < 0x8000000:
        c = 9742
    r = ((top // c + c) >> 1) + 1
    while True:
        y = (r + top // r) >> 1
        if y >= r:
            break
        r = y
    rem = top - r * r
    # The next digit by one division, and the last one's remainder to correct it.
    num = (rem << 14) | a1
    q = num // (r + r)
    u = num - q * (r + r)
    s = (r << 14) + q
    if (u << 14) + a0 - q * q < 0:
        s -= 1
    return s >> z


# What product() does with a * b // c.
P_LIMBS = const(0)  # leaves it in (hi, lo), and the division's remainder in REM
P_TRUNC = const(1)  # returns int(x * 2**s), at most 2**30 - 1 (_MASK30)
P_ROUND = const(2)  # returns round(x * 2**s), at most 2**30 - 1
P_TOP = const(3)  # leaves x to s bits in (hi, lo), truncated; returns t: x = (hi, lo) 2**t


@micropython.viper
def product(w4: int) -> int:
    """x = a * b // c, for 0 <= a, b < 2**30 and 0 < c < 2**29, in two limbs, then as
    `how` says (P_*), with a, b, c, s and how in w's last five words. One call, not
    one each for the product, its scaling and its bit length: a viper call costs the
    chip several microseconds.

    The product is the reference form of two 30-bit limbs from 15-bit digits, which
    the hot loops elsewhere write out where a call would cost too much (ramp_into,
    stepper.schedule, geometry, lookahead.plan_words); host_tests/test_layouts.py
    checks that they keep this form."""
    w = ptr32(w4 << 2)
    a = w[_IO_A]
    b = w[_IO_B]
    c = w[_IO_C]
    s = w[_IO_S]
    if s > _MASK30:  # negative: a 64-bit port's ptr32 reads it zero-extended
        s = 0 - ((0 - s) & _MASK30)
    how = w[_IO_HOW]
    a1 = a >> 15
    a0 = a & 0x7FFF
    b1 = b >> 15
    b0 = b & 0x7FFF
    mid = a1 * b0 + a0 * b1
    lo = ((mid & 0x7FFF) << 15) + a0 * b0
    hi = a1 * b1 + (mid >> 15) + (lo >> 30)
    lo = lo & _MASK30
    if c > 1:
        w[IO_HI] = hi
        w[IO_LO] = lo
        div_limbs(w4, c)
        hi = w[IO_HI]
        lo = w[IO_LO]
    else:
        w[_IO_REM] = 0
    if how == P_LIMBS:
        w[IO_HI] = hi
        w[IO_LO] = lo
        return 0
    if how != P_TOP:
        # x * 2**s, truncated (rounded: to s + 1 bits, then halved), is capped where
        # it reaches 2**31: the shift's overflow tells that, with no bit length.
        if how == P_ROUND:
            s += 1
        if s >= 0:
            if hi:
                if s or hi > 1:
                    return _MASK30
                x = (hi << 30) | lo
            elif lo:
                if s >= 31 or lo >> (31 - s):
                    return _MASK30
                x = lo << s
            else:
                return 0
        elif s > -30:
            if hi >> (1 - s):
                return _MASK30
            x = (hi << (30 + s)) | (lo >> (0 - s))
        elif s > -60:
            x = hi >> (-30 - s)
        else:
            return 0
        if how == P_ROUND:
            x = (x >> 1) + (x & 1)
        if x > _MASK30:
            return _MASK30
        return x
    # P_TOP: n, the bit length, by halving the bits searched
    x = hi
    n = 30
    if not x:
        x = lo
        n = 0
    if x >> 16:
        x = x >> 16
        n += 16
    if x >> 8:
        x = x >> 8
        n += 8
    if x >> 4:
        x = x >> 4
        n += 4
    if x >> 2:
        x = x >> 2
        n += 2
    if x >> 1:
        x = x >> 1
        n += 1
    if x:
        n += 1
    u = s - n
    # (hi, lo) <<= u, or >>= -u, truncating (a left shift stays below 2**60)
    if u >= 30:
        hi = lo << (u - 30)
        lo = 0
    elif u > 0:
        hi = (hi << u) | (lo >> (30 - u))
        lo = (lo << u) & _MASK30
    elif u <= -60:
        hi = 0
        lo = 0
    elif u <= -30:
        lo = hi >> (-30 - u)
        hi = 0
    elif u < 0:
        r = 0 - u
        lo = ((hi & ((1 << r) - 1)) << (30 - r)) | (lo >> r)
        hi = hi >> r
    w[IO_HI] = hi
    w[IO_LO] = lo
    return 0 - u


_FRAC_MAX = const(0x8000000)
# A cruise's high limb below this (2**14) leaves room for its FRAC bits in two limbs.
_CRUISE_ONE_DIV = const(0x4000)


@micropython.viper
def ramp_into(io_buf):
    """The step loop's schedule (ACCEL_UNTIL, DECEL_AFTER, RATE_DECEL) for the
    trapezoid of io's record (N, R0, RNOM, R1, ACC): n lead steps from rate r0 up to
    rnom (or the peak where the ramps meet) and down to r1 at acc per tick, all in the
    step loop's fixed point (stepper.ONE a step a tick).

    Tick i (from 1) moves by the speed's mean over it. The step loop starts at
    r0 + acc/2 and adds acc per tick until ACCEL_UNTIL, the tick holding the end of
    acceleration, where rnom clamps it; cruises; and at tick DECEL_AFTER, the one
    holding the start of deceleration, sets the rate for the tick after, the first
    wholly decelerating one (RATE_DECEL), which then falls by acc per tick. Only the
    two corner ticks then differ from the trapezoid, by less than acc each, so the
    position stays on the plan to well under a step, however slow the end of the
    block.

    Distances are in steps << 28 (the step loop's ONE), so n up to 2**30 steps fits
    the two limbs. In integers: on the chips every float operation allocates."""
    io = ptr32(io_buf)
    io4 = int(io) >> 2  # for the helpers above
    n = io[IO_N]
    r0 = io[IO_R0]
    vn = io[IO_RNOM]
    r1 = io[IO_R1]
    acc = io[IO_ACC]
    # The whole block: n << 28.
    all_hi = n >> 2
    all_lo = (n & 3) << 28
    # Steps (<< 28) to accelerate from r0 and to decelerate to r1, together:
    # (vn^2 - r0^2 + vn^2 - r1^2) / 2acc, each (vn - r)(vn + r) (below 2**28 and 2**29)
    # in two 30-bit limbs as product() makes them, and one division; and r0^2, r1^2,
    # for where the ramps meet. Written out: a call costs the chip several
    # microseconds, and the step loop runs this as each block starts.
    s_hi = 0
    s_lo = 0
    h0 = 0
    l0 = 0
    h1 = 0
    l1 = 0
    for k in range(4):
        r = r0 if k == 0 or k == 2 else r1
        if k < 2:
            if vn <= r:
                continue
            a = vn - r
            b = vn + r
        else:
            a = r
            b = r
        a1 = a >> 15
        a0 = a & 0x7FFF
        b1 = b >> 15
        b0 = b & 0x7FFF
        mid = a1 * b0 + a0 * b1
        lo = ((mid & 0x7FFF) << 15) + a0 * b0
        hi = a1 * b1 + (mid >> 15) + (lo >> 30)
        lo = lo & _MASK30
        if k < 2:
            s_hi += hi
            s_lo += lo
            s_hi += s_lo >> 30
            s_lo &= _MASK30
        elif k == 2:
            h0 = hi
            l0 = lo
        else:
            h1 = hi
            l1 = lo
    # Whether the ramps pass the whole block, (s / 2 acc, truncated) > n << 28, without
    # the division: s >= n acc 2**29 + 2 acc. They can only where n acc is below 2**28
    # (s is below 2**57, vn below 2**28); past 2**30 the block cruises. On curves most
    # blocks never reach their nominal rate, and the quotient is needed only for a
    # cruise. (The chip divides machine words in hardware.)
    peak = 0
    if acc < 0x10000000 and n <= _MASK30 // acc:
        nacc = n * acc
        t_lo = ((nacc & 1) << 29) + 2 * acc
        t_hi = (nacc >> 1) + (t_lo >> 30)
        t_lo &= _MASK30
        if s_hi > t_hi or (s_hi == t_hi and s_lo >= t_lo):
            peak = 1
    c_hi = 0
    c_lo = 0
    if not peak and (s_hi or s_lo):
        io[IO_HI] = s_hi
        io[IO_LO] = s_lo
        div_limbs(io4, 2 * acc)
        s_hi = io[IO_HI]
        s_lo = io[IO_LO]
    if peak:
        # The ramps meet below vn: peak^2 = acc n ONE + (r0^2 + r1^2) / 2, with no
        # cruise. Then peak < vn < 2**28, so acc * n < 2**26 here.
        p = acc * n
        # 2 acc n ONE = p << 29, added a limb at a time: l0 + l1 + 2**29 may pass
        # 2**31, a 32-bit chip's sign bit.
        lo = l0 + l1
        hi = h0 + h1 + (p >> 1) + (lo >> 30)
        lo = (lo & _MASK30) + ((p & 1) << 29)
        hi += lo >> 30
        lo &= _MASK30
        lo = (lo >> 1) | ((hi & 1) << 29)
        hi = hi >> 1
        if hi < h0 or (hi == h0 and lo < l0):
            hi = h0
            lo = l0
        if hi < h1 or (hi == h1 and lo < l1):
            hi = h1
            lo = l1
        io[IO_HI] = hi
        io[IO_LO] = lo
        vn = int(isqrt_limbs(io4))
    else:
        # Cruise: what the ramps leave.
        c_lo = all_lo - s_lo
        c_hi = all_hi - s_hi
        if c_lo < 0:
            c_lo = c_lo + _MASK30 + 1
            c_hi -= 1
    # Acceleration time in ticks: (vn - r0) / acc; cruise time: its steps / vn. Each
    # with FRAC fraction bits: (rem << FRAC) // c, in four digits of 4 bits in machine
    # words for c below 2**27 (below half a step a tick, the planner's cap, for vn),
    # where product() would take two limbs and a call more.
    a_int = (vn - r0) // acc
    a_rem = (vn - r0) - a_int * acc
    c_int = 0
    c_rem = -1  # none: no cruise, or its fraction is in frac already
    frac = 0
    if c_hi or c_lo:
        if c_hi < _CRUISE_ONE_DIV:
            # (cruise << FRAC) // vn in one division: its whole ticks and fraction
            # (a cruise below 65,536 steps, most of them).
            io[IO_HI] = (c_hi << _FRAC) | (c_lo >> (30 - _FRAC))
            io[IO_LO] = (c_lo << _FRAC) & _MASK30
            div_limbs(io4, vn)
            if io[IO_HI] >> (30 - _FRAC):  # 2**30 ticks or more: as below, no fraction
                c_int = _MASK30
            else:
                c_int = (io[IO_HI] << (30 - _FRAC)) | (io[IO_LO] >> _FRAC)
                frac = io[IO_LO] & (_ONE_FRAC - 1)
        else:
            io[IO_HI] = c_hi
            io[IO_LO] = c_lo
            div_limbs(io4, vn)
            if io[IO_HI]:
                c_int = _MASK30
            else:
                c_int = io[IO_LO]
                c_rem = io[_IO_REM]
    for k in range(2):
        x = a_rem
        c = acc
        if k == 1:
            if c_rem < 0:
                break
            x = c_rem
            c = vn
        if c < 0x8000:  # x < c: x << FRAC below 2**31, one division
            q = (x << _FRAC) // c
        elif c < _FRAC_MAX:
            q = 0
            for _ in range(4):
                x = x << 4
                d = x // c
                x -= d * c
                q = (q << 4) | d
        else:
            io[_IO_A] = x
            io[_IO_B] = _ONE_FRAC
            io[_IO_C] = c
            io[_IO_S] = 0
            io[_IO_HOW] = P_LIMBS
            product(io4)
            q = io[IO_LO]
        frac += q
    decel = a_int + c_int
    if frac >= _ONE_FRAC:
        frac -= _ONE_FRAC
        decel += 1
    if decel > _MASK30 or decel < 0:
        decel = _MASK30
    accel_until = a_int + (1 if a_rem else 0)
    decel_after = decel + (1 if frac else 0)
    if decel_after < 1:
        decel_after = 1
    # The first wholly decelerating tick's mean rate: vn - acc (DECEL_AFTER + 1/2 -
    # its start), rounded.
    late = (decel_after - decel) * _ONE_FRAC - frac + _HALF
    r_decel = r1
    if decel_after < _MASK30:
        # acc * late (late below 2**18) in two digits of late in machine words, as
        # the fractions above divide.
        if acc < 0x100000:
            fall = (acc * (late >> 8) + ((acc * (late & 0xFF) + _HALF) >> 8)) >> 8
        else:
            io[_IO_A] = acc
            io[_IO_B] = late
            io[_IO_C] = 1
            io[_IO_S] = 0
            io[_IO_HOW] = P_LIMBS
            product(io4)
            lo = io[IO_LO] + _HALF
            fall = (io[IO_HI] << 14) + (lo >> _FRAC)
        r_decel = vn - fall
        if r_decel < r1:
            r_decel = r1
    if accel_until > _MASK30:
        accel_until = _MASK30
    if decel_after > _MASK30:
        decel_after = _MASK30
    io[IO_ACCEL_UNTIL] = accel_until
    io[IO_DECEL_AFTER] = decel_after
    io[IO_RATE_DECEL] = r_decel
