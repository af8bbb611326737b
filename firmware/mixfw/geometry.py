# A move's lengths and its junction with the move before, for the planner, in viper on
# integers. They run for every G1 line, and on the chips every float operation
# allocates: in floats they would take about 25 a line, and their garbage a collection
# every few dozen lines.
#
# A move's X Y Z E come in as whole steps (E also as nanometres), each with its mm per
# unit as a float32 (mantissa, exponent). Each becomes a component below 2**27 in a
# unit common to the move: 2**-k mm, with k chosen so that the largest has 25 to 27
# bits. Lengths are exact integer square roots of their sums of squares (two 30-bit
# limbs, ramp.py), and the junction's cosine is worked out to 28 bits. Every
# intermediate stays below 2**31, so the 32-bit chips and the 64-bit unix port give
# the same integers.
from mixfw.ramp import div_limbs, isqrt_limbs, product

# Words of the geometry array g (array 'i', G_WORDS): first ramp.py's io words, which
# product() and isqrt_limbs() use as scratch, then these.
G_D = const(16)  # the move: |X| |Y| |Z| steps, then |E| in steps or nm (see GF_E_NM)
_G_C = const(20)  # its components: |X| |Y| |Z| |E| in the move's unit
G_LEN = const(24)  # its length in X Y Z E, in that unit
G_DIST = const(25)  # its length in X Y Z, or |E| for a move of E alone
_G_SIGNS = const(26)  # bit i: component i is negative
_G_PREV_C = const(27)  # the move before's components, signs and length (4 + 2 words)
_G_PREV_SIGNS = const(31)
_G_PREV_LEN = const(32)
# lengths and junction take g as its address over 4 (as ramp's helpers take theirs).
# Then their inputs: where the geometry floats (below) and the
# planner's floats (lookahead.F_*) are, as byte offsets from g's own plus _AT_BIAS (see
# ramp.array_offsets: set once, as g is made), and the flags (FL_*), which the planner
# stores for each move (a viper call's argument and ptr32() of an array cost the chip
# far more than a store: see ramp.py). planner.py keeps copies of these words.
_G_AT_GF = const(33)
_G_AT_F = const(34)
_G_FLAGS = const(35)
G_WORDS = const(36)
# Words of the geometry floats (array 'f', GF_WORDS): mm per unit.
GF_SCALE = const(0)  # X Y Z E: mm per step
GF_E_NM = const(4)  # E: mm per nanometre
GF_ACCEL_JD = const(5)  # acceleration (mm/s**2) times junction deviation (mm)
GF_WORDS = const(6)
# flags of lengths(): bit i for a negative component i, then
FL_E_NM = const(16)  # E is in nanometres
FL_JOIN = const(32)  # the move follows one it may join at speed: work out the junction

# ramp.py's: the io words its helpers read, and product()'s modes (copies).
_AT_BIAS = const(0x20000000)
_IO_HI = const(8)
_IO_LO = const(9)
_IO_A = const(11)
_IO_B = const(12)
_IO_C = const(13)
_IO_S = const(14)
_IO_HOW = const(15)
_P_ROUND = const(2)
_MASK30 = const(0x3FFFFFFF)  # compat.MASK30
# lookahead.py's (copies): float32's exponent bias and its 23 fraction bits, and the
# V2 range.
_BIAS = const(150)
_V2_MAX = const(0x1FFFFFFF)
_ONE = const(0x10000000)  # the cosine's and the sine's fixed point: 2**28
# The moves are one line within this (1e-6 of ONE) either way: a straight junction, or
# a reversal to a stop.
_STRAIGHT = const(268)


@micropython.viper
def lengths(g4: int) -> int:
    """The move in g's G_D words -> its components (_G_C), its length (G_LEN) and the
    length its speed is along (G_DIST), which also goes into the planner's floats'
    first word (lookahead.F_MM) as float32 bits. g's flags: FL_* and the signs.
    Returns those bits halved (a small int), which order as the lengths do: a
    comparison without reading the float, which allocates on the chips."""
    g = ptr32(g4 << 2)
    base = int(g) - _AT_BIAS  # the arrays' offsets are from here
    gf = ptr32(base + g[_G_AT_GF])
    flags = g[_G_FLAGS]
    # The unit: 2**(top - 27) mm, top the highest bit any component can reach (a
    # product of a and a mantissa of 24 bits has bits(a) + 23 or + 24 bits).
    top = -1000
    for i in range(4):
        a = g[G_D + i]
        if a:
            nb = 1  # bits(a), halving the bits searched: five turns
            b = 16
            while b:
                if a >> b:
                    a = a >> b
                    nb += b
                b = b >> 1
            k = GF_SCALE + i
            if i == 3 and (flags & FL_E_NM):
                k = GF_E_NM
            t = nb + 24 + ((gf[k] >> 23) & 0xFF) - _BIAS
            if t > top:
                top = t
    for i in range(4):
        a = g[G_D + i]
        c = 0
        if a:
            k = GF_SCALE + i
            if i == 3 and (flags & FL_E_NM):
                k = GF_E_NM
            bits = gf[k]
            # a * mantissa (below 2**30 and 2**24) in two 30-bit limbs, in
            # ramp.product's form, then shifted right u bits: below 2**27 by the choice
            # of top. Written out, as the squares below: a call costs the chip several
            # microseconds, and this runs for every axis of every line.
            m = (bits & 0x7FFFFF) | 0x800000
            u = top - 27 - ((bits >> 23) & 0xFF) + _BIAS
            a1 = a >> 15
            a0 = a & 0x7FFF
            m1 = m >> 15
            m0 = m & 0x7FFF
            mid = a1 * m0 + a0 * m1
            lo = ((mid & 0x7FFF) << 15) + a0 * m0
            hi = a1 * m1 + (mid >> 15) + (lo >> 30)
            lo = lo & _MASK30
            if u <= 0:
                c = lo << (0 - u)  # the product itself below 2**27: hi is 0
            elif u >= 60:
                c = 0
            elif u >= 30:
                c = hi >> (u - 30)
            else:
                c = (hi << (30 - u)) | (lo >> u)
        g[_G_C + i] = c
    g[_G_SIGNS] = flags & 15
    # Sums of squares, in two limbs: X Y Z, then E. Each square c * c (c below 2**27)
    # in two 30-bit limbs, in ramp.product's form (for a square: 2 c1 c0 in the middle),
    # written out: a call costs the chip several microseconds, and this runs for every
    # line.
    hi = 0
    lo = 0
    dist = g[_G_C + 3]  # a move of E alone
    for i in range(4):
        if i == 3:
            if hi or lo:
                g[_IO_HI] = hi
                g[_IO_LO] = lo
                dist = int(isqrt_limbs(g4))
            if dist < 1:
                dist = 1  # X Y Z below the unit: still a length to divide by
            g[G_DIST] = dist
        c = g[_G_C + i]
        if c:
            c1 = c >> 15
            c0 = c & 0x7FFF
            mid = 2 * c1 * c0
            low = ((mid & 0x7FFF) << 15) + c0 * c0
            lo += low & _MASK30
            hi += c1 * c1 + (mid >> 15) + (low >> 30) + (lo >> 30)
            lo = lo & _MASK30
    g[_IO_HI] = hi
    g[_IO_LO] = lo
    g[G_LEN] = int(isqrt_limbs(g4))
    # G_DIST as a float32: 24 bits of it, and the unit's exponent.
    nb = 1  # bits(dist), dist >= 1
    a = dist
    b = 16
    while b:
        if a >> b:
            a = a >> b
            nb += b
        b = b >> 1
    if nb > 24:
        mant = dist >> (nb - 24)
    else:
        mant = dist << (24 - nb)
    f = ptr32(base + g[_G_AT_F])
    bits = ((top - 27 + nb - 24 + _BIAS) << 23) | (mant & 0x7FFFFF)
    f[0] = bits
    return (bits >> 1) & _MASK30


@micropython.viper
def junction(g4: int) -> int:
    """The fastest the move (its lengths() just worked out) may enter from the move
    before, as the look-ahead's V2 ((mm/s)**2 * 64, at most its range), by the
    junction deviation model; 0 without FL_JOIN. Then the move becomes the move before.

    The angle's cosine comes from the two moves' components over their lengths, each in
    its own move's unit, which cancels; sin(angle / 2) = sqrt((1 - cos) / 2) of the
    angle between the moves' directions, and the junction's speed**2 is
    accel * deviation * sin / (1 - sin)."""
    g = ptr32(g4 << 2)
    v2 = 0
    if g[_G_FLAGS] & FL_JOIN:
        # The dot product of the directions, in two limbs: the products of the same sign
        # summed, and the other sum taken off.
        sign = 0
        same_hi = 0
        same_lo = 0
        diff_hi = 0
        diff_lo = 0
        signs = g[_G_SIGNS] ^ g[_G_PREV_SIGNS]
        # Each product a * b (below 2**28 both) in two 30-bit limbs, in ramp.product's
        # form, written out as in lengths(): the components', then the lengths'.
        d_hi = 0
        d_lo = 0
        for i in range(5):
            if i < 4:
                a = g[_G_C + i]
                b = g[_G_PREV_C + i]
            else:
                a = g[G_LEN]
                b = g[_G_PREV_LEN]
            if a and b:
                a1 = a >> 15
                a0 = a & 0x7FFF
                b1 = b >> 15
                b0 = b & 0x7FFF
                mid = a1 * b0 + a0 * b1
                low = ((mid & 0x7FFF) << 15) + a0 * b0
                p_hi = a1 * b1 + (mid >> 15) + (low >> 30)
                p_lo = low & _MASK30
                if i == 4:
                    d_hi = p_hi
                    d_lo = p_lo
                elif (signs >> i) & 1:
                    diff_lo += p_lo
                    diff_hi += p_hi + (diff_lo >> 30)
                    diff_lo = diff_lo & _MASK30
                else:
                    same_lo += p_lo
                    same_hi += p_hi + (same_lo >> 30)
                    same_lo = same_lo & _MASK30
        if diff_hi > same_hi or (diff_hi == same_hi and diff_lo > same_lo):
            sign = 1
            hi = diff_hi - same_hi
            lo = diff_lo - same_lo
        else:
            hi = same_hi - diff_hi
            lo = same_lo - diff_lo
        if lo < 0:
            lo += _MASK30  # and 1: 2**30 is no small int on the chips
            lo += 1
            hi -= 1
        # Over the product of the lengths (below 2**56), both taken down to 29 bits of
        # it: the cosine to 28 bits, at most ONE.
        nb = 30  # 30 + bits(d_hi), halving the bits searched: five turns
        a = d_hi
        b = 16
        while b:
            if a >> b:
                a = a >> b
                nb += b
            b = b >> 1
        if a:
            nb += 1
        k = nb - 29  # both lengths have 25 bits or more: k > 20
        if k >= 30:
            den = d_hi >> (k - 30)
            num = hi >> (k - 30)
        else:
            den = (d_hi << (30 - k)) | (d_lo >> k)
            num = (hi << (30 - k)) | (lo >> k)
        cos = _ONE
        if num < den:
            # num * ONE // den, below ONE: num shifted into two limbs, one division.
            g[_IO_HI] = num >> 2
            g[_IO_LO] = (num & 3) << 28
            div_limbs(g4, den)
            cos = g[_IO_LO]
        if cos > _ONE - _STRAIGHT:
            if not sign:
                v2 = _V2_MAX  # straight on
        else:
            # sin**2 = (1 - cos) / 2 of the angle between the directions, where cos is
            # minus that of the moves' dot product; its root to 28 bits.
            if sign:
                h = (_ONE - cos) >> 1
            else:
                h = (_ONE + cos) >> 1
            g[_IO_HI] = h >> 2
            g[_IO_LO] = (h & 3) << 28
            s = int(isqrt_limbs(g4))
            bits = ptr32(int(g) - _AT_BIAS + g[_G_AT_GF])[GF_ACCEL_JD]
            ex = (bits >> 23) & 0xFF
            if ex:
                g[_IO_A] = (bits & 0x7FFFFF) | 0x800000
                g[_IO_B] = s
                g[_IO_C] = _ONE - s
                g[_IO_S] = ex - _BIAS + 6
                g[_IO_HOW] = _P_ROUND
                v2 = int(product(g4))
            if v2 > _V2_MAX:
                v2 = _V2_MAX
    for i in range(4):
        g[_G_PREV_C + i] = g[_G_C + i]
    g[_G_PREV_SIGNS] = g[_G_SIGNS]
    g[_G_PREV_LEN] = g[G_LEN]
    return v2
