"""ramp.py on the unix port: a record's step schedule (ramp_ticks, through
ramp.ramp_into) and the helpers on two 30-bit limbs it and the look-ahead work with
(isqrt_limbs, div_limbs, product), each against Python's exact integers. CPython runs
the same viper code as plain Python: the same answers on the 64-bit port and on the
32-bit build (CI's second pass) show no intermediate overflows a machine word."""
import json

# --- the schedule of a record in integers (ramp.ramp_into) -------------------------

RAMP_CASES = """
import sys, json
from mixfw.planner import ramp_ticks
print(json.dumps([list(ramp_ticks(*c)) for c in json.loads(sys.stdin.read())]))
"""


def _ramp_cases():
    """Records as the planner writes them (rates from the floor it allows up to half a
    step per tick, entry and exit reachable in n steps), with the extremes of n and acc."""
    import random
    from math import isqrt
    one = 1 << 28
    rnd = random.Random(13)
    cases = []
    while len(cases) < 1500:
        acc = rnd.choice([1, 3, 7, 50, 161, 500, 5000, 20000, 100000, 1 << 20])
        floor = isqrt(acc * one)
        r_nom = rnd.randint(floor, one // 2)
        r0 = min(rnd.randint(floor, one // 2), r_nom) if rnd.random() < 0.7 else r_nom
        r1 = min(rnd.randint(floor, one // 2), r_nom) if rnd.random() < 0.7 else r_nom
        n = rnd.choice([1, 2, 5, 30, 300, 5000, 10 ** 6, 10 ** 8, (1 << 30) - 1])
        if abs(r0 * r0 - r1 * r1) <= 2 * acc * n * one:
            cases.append((n, r0, r_nom, r1, acc))
    # Short blocks whose ramps meet below the nominal rate, with entry and exit close
    # enough to be reached: the peak's sum of squares in limbs. The first one, found by
    # test_step_timing on the 32-bit build, overflowed a 32-bit word there.
    cases.append((3, 566139, 1010775, 957027, 501))
    while len(cases) < 2000:
        acc = rnd.choice([1, 7, 161, 501, 5000, 20000])
        n = rnd.choice([1, 2, 3, 5, 30])
        r0 = rnd.randint(isqrt(acc * one), one // 4)
        reach = 2 * acc * n * one
        r1 = isqrt(max(r0 * r0 + rnd.randint(-reach, reach), acc * one))
        if abs(r0 * r0 - r1 * r1) <= reach:
            cases.append((n, r0, one // 2, r1, acc))
    # Either side of where the ramps just fill the block, which ramp_into decides
    # without dividing: the least r_nom whose ramps' steps, truncated, pass n << 28.
    while len(cases) < 2400:
        acc = rnd.choice([1, 7, 161, 501, 5000, 20000, 100000, 1 << 20])
        n = rnd.choice([1, 2, 3, 5, 30, 300, 5000, 10 ** 6])
        r0 = rnd.randint(isqrt(acc * one), one // 4)
        r1 = rnd.randint(isqrt(acc * one), one // 4)
        # (2 r**2 - r0**2 - r1**2) // (2 acc) > n one, for the least such r.
        least = isqrt(((n * one + 1) * 2 * acc + r0 * r0 + r1 * r1 - 1) // 2)
        while (2 * least * least - r0 * r0 - r1 * r1) // (2 * acc) <= n * one:
            least += 1
        for r_nom in (least - 1, least):
            if (max(r0, r1) <= r_nom <= one // 2
                    and abs(r0 * r0 - r1 * r1) <= 2 * acc * n * one):
                cases.append((n, r0, r_nom, r1, acc))
    return cases


def _exact_schedule(n, r0, r_nom, r1, acc):
    """The trapezoid's corners from their definition, in exact fractions: accelerate at
    acc from r0 to r_nom or to the peak where the ramps meet, cruise, decelerate to r1
    over the n steps (times ONE); ACCEL_UNTIL and DECEL_AFTER are the ticks holding the
    two corners, RATE_DECEL the mean rate of the tick after the second."""
    from fractions import Fraction as F
    from math import ceil
    one = 1 << 28
    dist = F(n * one)
    up = F(r_nom * r_nom - r0 * r0, 2 * acc)
    down = F(r_nom * r_nom - r1 * r1, 2 * acc)
    vn = F(r_nom)
    if up + down > dist:
        peak2 = acc * dist + F(r0 * r0 + r1 * r1, 2)
        vn = F(int(float(peak2) ** 0.5))  # to a rate unit: the plan's floor
        up, down = F(vn * vn - r0 * r0, 2 * acc), F(vn * vn - r1 * r1, 2 * acc)
        cruise = 0
    else:
        cruise = (dist - up - down) / vn
    accel_s = (vn - r0) / acc
    decel_s = accel_s + cruise
    decel_after = max(1, ceil(decel_s))
    return ceil(accel_s), decel_after, max(r1, vn - acc * (decel_after + F(1, 2) - decel_s))


def test_the_schedule_is_the_same_integers_on_every_build_and_the_exact_trapezoid(mp):
    """CPython runs ramp.py's viper code as plain Python with unbounded integers: the
    same answers on the unix port (64-bit words) and, in CI's second pass, on the 32-bit
    build show no intermediate overflows a machine word. And against the exact corners:
    within a tick, and the decelerating rate within one tick's change."""
    from mixfw.planner import ramp_ticks
    cases = _ramp_cases()
    on_host = [list(ramp_ticks(*c)) for c in cases]
    assert mp.json(RAMP_CASES, stdin=json.dumps(cases).encode()) == on_host
    for case, (until, after, r_decel) in zip(cases, on_host):
        if after >= 0x3FFFFFFF:
            continue  # over 2**30 ticks (15 hours at 50 us): the end is never reached
        e_until, e_after, e_decel = _exact_schedule(*case)
        acc = case[4]
        assert abs(until - e_until) <= 1 and abs(after - e_after) <= 1, case
        assert abs(r_decel - e_decel) <= acc + 1, case


# --- the square root of two limbs (ramp.isqrt_limbs) --------------------------------


def test_the_root_of_two_limbs_is_the_integer_square_root(mp):
    """Every bit length up to the 56 bits a root below 2**28 allows, both limbs'
    edges, and squares and their neighbours, where the last digit's correction and
    Newton's end are decided."""
    import random
    from math import isqrt
    rnd = random.Random(21)
    values = [0, 1, 2, 3, 4, (1 << 30) - 1, 1 << 30, (1 << 30) + 1, (1 << 56) - 1,
              ((1 << 28) - 1) ** 2, 5 << 30]
    for bits in range(1, 57):
        values += [rnd.getrandbits(bits) | (1 << (bits - 1)) for _ in range(40)]
    for bits in range(1, 29):
        for _ in range(20):
            r = rnd.getrandbits(bits) | (1 << (bits - 1))
            values += [v for v in (r * r - 1, r * r, r * r + 2 * r) if v < 1 << 56]
    got = mp.script_json("ramp_limbs", "isqrt", stdin=json.dumps(values).encode())
    assert got == [isqrt(v) for v in values]


# --- long division of two limbs (ramp.div_limbs) -----------------------------------


def test_two_limbs_over_a_word_give_the_exact_quotient_and_remainder(mp):
    """Every divisor's bit length up to 29 bits, against every dividend's up to 60:
    where a digit's estimate from the divisor's top bits is furthest off (a divisor
    just above a power of two, a dividend of all ones) and where it is exact."""
    import random
    rnd = random.Random(29)
    pairs = []
    for cb in range(1, 30):
        divisors = [1 << (cb - 1), (1 << cb) - 1, (1 << (cb - 1)) + 1]
        divisors += [rnd.getrandbits(cb) | (1 << (cb - 1)) for _ in range(6)]
        for c in divisors:
            for vb in (0, 1, cb, 30, 31, 45, 59, 60):
                pairs.append([rnd.getrandbits(vb) if vb else 0, c])
            pairs.append([(1 << 60) - 1, c])
            pairs.append([c * ((1 << 30) - 1) + c - 1, c])
    got = mp.script_json("ramp_limbs", "div", stdin=json.dumps(pairs).encode())
    assert got == [[(v // c) >> 30, (v // c) & 0x3FFFFFFF, v % c] for v, c in pairs]


# --- a * b // c scaled (ramp.product) ----------------------------------------------


def _product_model(a, b, c, s, how):
    """ramp.product as its docstring and P_* say, in Python's integers: [returned,
    hi, lo], with hi and lo only where the mode leaves them."""
    cap = (1 << 30) - 1
    v = a * b // c if c > 1 else a * b
    if how == 0:  # P_LIMBS
        return [0, v >> 30, v & cap]
    if how == 3:  # P_TOP: v to s bits, truncated, and t with v = (hi, lo) 2**t
        u = s - v.bit_length()
        x = v << u if u >= 0 else v >> -u
        return [-u, x >> 30, x & cap]
    if how == 2:  # P_ROUND
        s += 1
    x = v << s if s >= 0 else v >> -s
    if x >> 31:
        return [cap, None, None]
    if how == 2:
        x = (x >> 1) + (x & 1)
    return [min(x, cap), None, None]


def test_a_product_over_a_divisor_scaled_is_exact_in_every_mode(mp):
    """Each mode (P_LIMBS, P_TRUNC, P_ROUND, P_TOP) for products of every size below
    2**60, no divisor and divisors up to 2**29, and scales on both sides of where the
    result passes 2**31 and is capped."""
    import random
    rnd = random.Random(60)
    cases = []
    for how in range(4):
        for _ in range(400):
            a = rnd.getrandbits(rnd.randint(0, 30))
            b = rnd.getrandbits(rnd.randint(0, 30))
            c = rnd.choice([1, 1, rnd.getrandbits(rnd.randint(1, 29)) | 1])
            bits = (a * b // c).bit_length()
            if how == 3:
                s = rnd.randint(1, 30)
            else:
                s = rnd.randint(-bits - 2, 33 - bits) if bits else rnd.randint(-5, 5)
            cases.append([a, b, c, s, how])
        cases += [[0, 5, 1, 3, how], [1, 1, 1, 30, how], [1 << 29, 2, 1, 0, how],
                  [(1 << 30) - 1, (1 << 30) - 1, 1, -29, how]]
    got = mp.script_json("ramp_limbs", "product", stdin=json.dumps(cases).encode())
    for case, (x, hi, lo) in zip(cases, got):
        want = _product_model(*case)
        assert [x, hi if want[1] is not None else None,
                lo if want[2] is not None else None] == want, case
