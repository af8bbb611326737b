"""The planner's look-ahead, on the unix port: blocks planned against a full ring, with
one block taken by the step loop at every wait (as bench/plan_rate.py does)."""
import json

from mixstep import paths

LOOK_AHEAD = """
import sys
import simmachine
sys.modules["machine"] = simmachine
import board
from mixfw import assemble
from mixfw import lookahead, stepper as st
from mixfw import planner as planner_module

simmachine.attach_world(board.PINS, ["x", "y", "z"] + ["e%%d" %% i for i in range(6)])
printer = assemble.build(files_root=None)
pl = printer.planner
mem = printer.mem
q = pl.queue
errors = []
last_exit = [0]
counts = {"blocks": 0, "checked": 0}
lk = pl.lk
W = lookahead.L_WORDS

def field(slot, word):
    return lk[slot * W + word]

def take_one():
    # The step loop runs the tail block: it enters at its planned entry, which must be
    # no faster than the block before it left.
    t = mem[st.S_TAIL]
    if t != mem[st.S_HEAD]:
        if field(t, lookahead.L_ENTRY) > last_exit[0]:
            errors.append("block %%d enters at V2 %%d after an exit at %%d"
                          %% (counts["blocks"], field(t, lookahead.L_ENTRY), last_exit[0]))
        last_exit[0] = field(t, lookahead.L_EXIT)
        counts["blocks"] += 1
        mem[st.S_TAIL] = t + 1 if t + 1 < q else 0
    mem[st.S_ACTIVE] = 0
    mem[st.S_HOME_STOP] = 7  # homing: every endstop is hit at once

pl.idle = take_one
recalculate = planner_module._recalculate

def checked_recalculate(w4, hooks):
    # The incremental look-ahead must plan what a full pass over the queue plans: in
    # V2 (speed squared), v**2 = v0**2 + 2 a s exactly, within each junction's limit.
    recalculate(w4, hooks)
    # The slot planned, in the planner's io array (see lookahead's _W_SLOT).
    newest = planner_module._RAMP_IO[lookahead.W_WORDS - 4]
    first = mem[st.S_TAIL]
    slots = []
    k = first
    while True:
        slots.append(k)
        if k == newest:
            break
        k = k + 1 if k + 1 < q else 0
    back = {}
    e = 0
    for k in reversed(slots):
        e = min(field(k, lookahead.L_MAX_ENTRY), e + field(k, lookahead.L_GAIN))
        back[k] = e
    v = min(back[first], field(first - 1 if first > 0 else q - 1, lookahead.L_EXIT))
    for i, k in enumerate(slots):
        v1 = 0 if k == newest else min(back[slots[i + 1]], v + field(k, lookahead.L_GAIN))
        got = (field(k, lookahead.L_ENTRY), field(k, lookahead.L_EXIT))
        if got != (v, v1):
            errors.append("slot %%d planned %%r, a full pass gives %%r" %% (k, got, (v, v1)))
        v = v1
    counts["checked"] += 1

planner_module._recalculate = checked_recalculate
run = printer.run_line
parse = printer.parser.parse
run(parse(b"M302 P1", 7))
n = 0
for text in open(%r, "rb"):
    text = text.rstrip()
    if text[:4] in (b"M109", b"M190", b"M116"):
        continue
    run(parse(text, len(text)))
    n += 1
    if n >= 3000:
        break
pl.synchronize()
print(json.dumps({"errors": errors[:5], "blocks": counts["blocks"], "checked": counts["checked"]}))
"""


def test_look_ahead_is_a_full_pass_and_speed_is_continuous_where_blocks_meet(mp):
    got = mp.json("import json\n" + LOOK_AHEAD % str(paths.EXAMPLE_GCODE), heap="4M")
    assert got["errors"] == []
    assert got["blocks"] > 2500 and got["checked"] == got["blocks"]


# --- the schedule of a record in integers (mixfw/ramp.py) --------------------------

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


# --- a block's planning words from its floats, in integers (lookahead.plan_words) ---

PLAN_WORDS = """
import sys, json
from array import array
from uctypes import addressof
from mixfw import lookahead as la
from mixfw.ramp import array_offsets
lk = array("i", bytes(4 * la.L_WORDS))
W = la.W_WORDS
w = array("i", bytes(4 * W))
out = []
for bits, n, entry_v2 in json.loads(sys.stdin.read()):
    f = array("f", bytes(array("I", bits)))
    # The io array's last seven words: where lk and the floats are (and the step
    # loop's words, which only recalculate reads), the slot, n, entry_v2, no rate cap.
    array_offsets(w, W - 7, (lk, f))
    w[W - 4] = 0
    w[W - 3] = n
    w[W - 2] = entry_v2
    w[W - 1] = 0
    la.plan_words(addressof(w) >> 2)  # the array as its address over 4
    out.append(list(lk))
print(json.dumps(out))
"""


def _f32(x):
    import struct
    return struct.unpack("<f", struct.pack("<f", x))[0]


def _plan_word_cases():
    """Blocks over the ranges the options allow (the planner's floats as float32, the
    chips' floats), with the extremes: a nanometre move, a metre, the slowest and the
    fastest tick, a junction that is a stop or no limit at all (the look-ahead's V2, from
    geometry.junction)."""
    import random
    import struct
    rnd = random.Random(7)
    cases = []
    while len(cases) < 1500:
        mm = rnd.choice([1e-6, 0.001, 0.05, 0.2, 1.0, 30.0, 1000.0]) * rnd.uniform(0.5, 2)
        accel = rnd.choice([0.1, 10.0, 500.0, 3000.0, 1e6]) * rnd.uniform(0.5, 1)
        nominal = rnd.choice([0.01, 1.0, 25.0, 150.0, 10000.0]) * rnd.uniform(0.5, 1)
        entry_v2 = rnd.choice([0, (1 << 29) - 1, int(64 * nominal * nominal * rnd.random())])
        tick_s = rnd.choice([5, 10, 20, 50, 1000]) * 1e-6
        n = rnd.choice([1, 3, 16, 800, 10 ** 5, (1 << 30) - 2])
        floats = [mm, accel, nominal, nominal * nominal, tick_s * (1 << 28), accel * tick_s]
        bits = [struct.unpack("<I", struct.pack("<f", x))[0] for x in floats]
        cases.append((bits, n, min(entry_v2, (1 << 29) - 1)))
    return cases


def _exact_plan_words(bits, n, entry_v2):
    """The words from their definitions (planner.py, lookahead.py), in exact fractions of
    the float32 values: GAIN, MAX_ENTRY, NOMINAL, ACC rounded, RATE_NOM and FLOOR
    truncated, each within the range kept; K2 and K_SHIFT as the exact k**2 / 64."""
    import struct
    from fractions import Fraction as F
    from math import isqrt
    cap, v2_max = (1 << 30) - 1, (1 << 29) - 1
    mm, accel, nominal, nominal2, tick_one, accel_tick = (
        F(struct.unpack("<f", struct.pack("<I", b))[0]) for b in bits)
    k = tick_one * n / mm
    acc = k * accel_tick
    floor = min(cap, isqrt(int(acc * (1 << 28))))
    nominal_v2 = min(v2_max, round(64 * nominal2))
    return {"gain": min(v2_max, round(128 * accel * mm)),
            "max_entry": min(entry_v2, nominal_v2), "nominal": nominal_v2,
            "acc": max(1, min(cap, round(acc))), "floor": floor,
            "rate_nom": max(floor, min(cap, int(nominal * k))), "k2_64": k * k / 64}


def test_a_blocks_words_are_the_same_integers_on_every_build_and_the_exact_ones(mp):
    """plan_words reads the planner's floats as float32 bits and works in integers, on
    the unix port and (CI's second pass) the 32-bit build. Against the exact values:
    the V2 words within one, the rates within a part in 2**22 (the float32 inputs have
    24 bits), and K2 * 4**K_SHIFT, the rate's scale, likewise."""
    from mixfw import lookahead as la
    cases = _plan_word_cases()
    words = mp.json(PLAN_WORDS, stdin=json.dumps(cases).encode())
    assert len(words) == len(cases)
    for (bits, n, entry_v2), got in zip(cases, words):
        want = _exact_plan_words(bits, n, entry_v2)
        assert abs(got[la.L_GAIN] - want["gain"]) <= 1, (bits, n)
        assert abs(got[la.L_MAX_ENTRY] - want["max_entry"]) <= 1, (bits, n)
        assert abs(got[la.L_NOMINAL] - want["nominal"]) <= 1, (bits, n)
        for word, key in ((la.L_ACC, "acc"), (la.L_FLOOR, "floor"),
                          (la.L_RATE_NOM, "rate_nom")):
            assert abs(got[word] - want[key]) <= 1 + want[key] / 2 ** 22, (key, bits, n)
        shift = got[la.L_K_SHIFT] - la.SHIFT_BIAS
        scale = got[la.L_K2] * (4 ** shift if shift >= 0 else 1 / 4 ** -shift)
        assert abs(scale / want["k2_64"] - 1) < 2 ** -21, (bits, n)
        assert 1 << 24 <= got[la.L_K2] < 1 << 26
        assert got[la.L_DWELL] == 0


# --- positions to steps without big ints (planner.scaled_round) --------------------

SCALED_CASES = """
import sys, json
from mixfw.planner import scaled_round, steps_per_nm, div_round, spm_fixed, NM_PER_MM, SPM_SCALE
out = []
for spm, x in json.loads(sys.stdin.read()):
    p, q = steps_per_nm(spm)
    # Position to step (p/q) and step to position (q/p), against the product itself.
    out.append([scaled_round(x, p, q), div_round(x * spm_fixed(spm), NM_PER_MM * SPM_SCALE),
                scaled_round(x, q, p), div_round(x * NM_PER_MM * SPM_SCALE, spm_fixed(spm))])
print(json.dumps(out))
"""


def test_positions_become_the_same_steps_as_by_the_full_product(mp):
    """A position in nm to steps (and steps back to nm) by the reduced fraction, split so
    the chips keep it in small ints, is the rounding of the full product, halves away
    from zero included, for steps/mm the options allow and positions either side of 0."""
    import random
    rnd = random.Random(7)
    cases = []
    for spm in (80.0, 100.0, 400.0, 415.0, 93.42, 0.5, 2560.0, 837.123456, 3200.0):
        for x in (0, 1, -1, 6250, -6250, 12500, 2 ** 29, -(2 ** 30), 10 ** 11):
            cases.append([spm, x])
        cases += [[spm, rnd.randint(-10 ** 12, 10 ** 12)] for _ in range(40)]
    got = mp.json(SCALED_CASES, stdin=json.dumps(cases).encode())
    for case, (a, b, c, d) in zip(cases, got):
        assert a == b and c == d, case


SIM_PLANNER = """
import sys, json
import simmachine
sys.modules["machine"] = simmachine
import board
from mixfw import assemble, planner
simmachine.attach_world(board.PINS, ["x", "y", "z"] + ["e%d" % i for i in range(6)])
printer = assemble.build(files_root=None)
pl = printer.planner
whole = planner._drive_targets
python = lambda words, e_nm, nm, rem: whole(words, 0, nm, rem) and 0  # counts only
fast = [0]


def viper(words, e_nm, nm, rem):
    done = whole(words, e_nm, nm, rem)
    fast[0] += done
    return done
"""

BLOCK_WEIGHTS = SIM_PLANNER + """
from uctypes import addressof
out = []
for counts in json.loads(sys.stdin.read()):
    # The planner's six drives: counts of fewer drives with 0 for the rest.
    n = len(counts)
    for i in range(pl.drives):
        pl._counts[i] = counts[i] if i < n else 0
        pl._weights[i] = 7
        pl._given[i] = 7
    fits = planner.block_weights(addressof(pl._abs_steps) >> 2)  # its address over 4
    out.append([fits, list(pl._given)[:n], list(pl._weights)[:n]])
print(json.dumps(out))
"""


def test_block_weights_are_the_steps_over_their_gcd(mp):
    """The mixer weights of a block (planner.block_weights, viper): each drive's
    steps, of either sign, over their gcd, so one period of the schedule is the whole
    block; 0 (and the weights untouched) where that period is longer than the
    mixer's integers take, as for counts a 64-bit port reads zero-extended."""
    import math
    import random
    from mixfw.planner import MAX_PERIOD
    rnd = random.Random(25)
    cases = [[0] * 6, [5], [-5, 0, 0], [12, -18, 30], [MAX_PERIOD, 0], [MAX_PERIOD + 1, 0],
             [10001, 10000], [-20000, 1], [3, 0, 0, 0, 0, -3]]
    for _ in range(400):
        n = rnd.randint(1, 6)
        scale = rnd.choice([1, 7, 120])
        cases.append([rnd.choice([-1, 1]) * scale * rnd.randint(0, 40) *
                      rnd.choice([0, 1, 1]) for _ in range(n)])
        cases.append([rnd.randint(-30000, 30000) for _ in range(n)])
    got = mp.json(BLOCK_WEIGHTS, stdin=json.dumps(cases).encode())
    for counts, (fits, steps, weights) in zip(cases, got):
        want = [abs(c) for c in counts]
        assert steps == want, counts
        g = 0
        for c in want:
            g = math.gcd(g, c)
        if g and sum(want) // g > MAX_PERIOD:
            assert (fits, weights) == (0, [7] * len(counts)), counts
        else:
            assert fits == 1, counts
            assert weights == [c // g if g else 0 for c in want], counts


# X's step at each position, by xyz_targets with no word named (X stays where it is:
# at the position), and by scaled_round.
STEPS_OF_NM = """
import sys, json
from array import array
from mixfw.cmd_motion import xyz_targets, SPM_WORDS
from mixfw.planner import array_offsets, spm_digits, scaled_round, steps_per_nm
nm = array("i", bytes(12))
zeros = array("i", bytes(12))
steps = array("i", bytes(4 * 5))
out = []
for s, xs in json.loads(sys.stdin.read()):
    spm = array("i", bytes(4 * SPM_WORDS))  # and no step kept
    spm_digits(s, spm, 0)
    # Its last five words: where the line's words, the offsets, the steps and the
    # travel are (no word named here: only the offsets and the steps are read).
    array_offsets(spm, SPM_WORDS - 3, (zeros, steps))
    p, q = steps_per_nm(s)
    got = []
    for x in xs:
        nm[0] = x
        xyz_targets(spm, 0, nm, array("i", bytes(12)), None)
        got.append(steps[0])
    out.append([got, [scaled_round(x, p, q) for x in xs]])
print(json.dumps(out))
"""


def test_positions_become_the_same_steps_in_small_ints(mp):
    """X Y Z's positions to steps in viper (cmd_motion.xyz_targets, 15-bit digits and
    30-bit limbs): the integer scaled_round gives, halves away from zero included, over
    the options' whole range of steps/mm and positions within +-2**30 nm, on both
    builds."""
    import random
    from mixfw.planner import scaled_round, steps_per_nm
    rnd = random.Random(17)
    top = 2 ** 30 - 1
    cases = []
    for spm in (80.0, 100.0, 400.0, 415.0, 93.42, 93.71234, 0.001, 100000.0, 2560.0,
                837.123456) + tuple(rnd.uniform(0.001, 100000.0) for _ in range(20)):
        p, q = steps_per_nm(spm)
        xs = [0, 1, -1, top, -top, 6250, -6250, 12500, -12500]
        # Halves: positions whose step is exactly half way, where the fraction allows.
        xs += [(2 * k + 1) * q // (2 * p) for k in range(3) if (2 * k + 1) * q % (2 * p) == 0]
        xs += [rnd.randint(-top, top) for _ in range(60)]
        cases.append([spm, [x for x in xs if abs(x) <= top]])
    got = mp.json(STEPS_OF_NM, stdin=json.dumps(cases).encode())
    for (spm, xs), (steps, by_fraction) in zip(cases, got):
        # Against scaled_round on the same build: a 32-bit build's steps/mm in
        # millionths may round differently from a 64-bit one's (100,000 steps/mm is
        # 99,999.997952 in float32).
        assert steps == by_fraction, spm
        p, q = steps_per_nm(spm)
        if spm in (80.0, 100.0, 400.0, 415.0, 2560.0):  # and the 64-bit answer where
            # float32 holds the steps/mm in millionths exactly
            assert steps == [scaled_round(x, p, q) for x in xs], spm


# --- a G1 line's X Y Z words to nanometres (cmd_motion.xyz_targets) -----------------

XYZ_CASES = """
import sys, json
from mixfw.gcode import Parser
from mixfw.cmd_motion import xyz_targets, MOVE_BITS, SPM_WORDS
from mixfw.planner import array_offsets, spm_digits
from array import array
p = Parser()
spm = array("i", bytes(4 * SPM_WORDS))
for i, s in enumerate((80.0, 93.71234, 400.0)):
    spm_digits(s, spm, 3 * i)
steps = array("i", bytes(4 * 5))
out = []
for text, pos, relative, travel, at in json.loads(sys.stdin.read()):
    b = text.encode()
    line = p.parse(b, len(b))
    target = array("i", bytes(12))
    off = array("i", bytes(12))
    travel_nm = array("i", travel) if travel else off
    # spm's last five words: where the line's words, the offsets, the steps and the
    # travel are.
    array_offsets(spm, SPM_WORDS - 5, (line.mant, line.decimals, off, steps, travel_nm))
    # The word before them: the modes, relative (1) and soft limits (2).
    spm[SPM_WORDS - 6] = (1 if relative else 0) | (2 if travel else 0)
    got = xyz_targets(spm, line.present & MOVE_BITS, array("i", pos), target, at)
    out.append([got, list(target), list(steps)])
print(json.dumps(out))
"""


def _nm_of_word(word):
    """A word's exact nanometres, further decimals rounded half away from zero."""
    from decimal import ROUND_HALF_UP, Decimal
    return int((Decimal(word) * 10 ** 6).quantize(Decimal(1), rounding=ROUND_HALF_UP))


def test_xyz_words_become_the_exact_nanometres_or_a_clear_refusal(mp):
    """X Y Z words (up to the parser's 9 digits, and 9 decimals) to nanometres in one
    viper call, absolute and relative, with the 64-bit build's unsigned words read right:
    the exact value rounded half away from zero, as Line.fixed_at gives it; beyond
    +-2**30 nm (1,073 mm) the axis is named, as with soft limits outside 0..travel.
    An E word within that range comes back in nanometres too (beyond it, Python reads
    it), and the axes whose steps differ from the queue's position are flagged."""
    import random
    rnd = random.Random(11)
    nm_max = 2 ** 30 - 1
    cases = []
    for _ in range(1500):
        words = []
        for letter in "XYZE":
            if rnd.random() < 0.6:
                digits = rnd.randint(1, 9)
                mant = rnd.randint(0, 10 ** digits - 1)
                dec = rnd.randint(0, min(digits, 9))
                text = str(mant).rjust(dec + 1, "0")
                text = text[:len(text) - dec] + ("." + text[len(text) - dec:] if dec else "")
                words.append(letter + rnd.choice(["", "-"]) + text)
        pos = [rnd.randint(-nm_max, nm_max) // rnd.choice([1, 1000]) for _ in range(3)]
        travel = rnd.choice([None, [250 * 10 ** 6] * 3])
        at = rnd.choice([None, [rnd.randint(-5, 5) for _ in range(3)]])
        cases.append(["G1 " + " ".join(words), pos, rnd.random() < 0.5, travel, at])
        if rnd.random() < 0.3:  # again: the steps of the same positions, as it keeps them
            cases.append(cases[-1])
    got = mp.json(XYZ_CASES, stdin=json.dumps(cases).encode())
    from mixfw.planner import scaled_round, steps_per_nm
    fractions = [steps_per_nm(s) for s in (80.0, 93.71234, 400.0)]
    e_read = 0
    for (text, pos, relative, travel, at), (verdict, target, steps) in zip(cases, got):
        named = {w[0]: _nm_of_word(w[1:]) for w in text.split()[1:]}
        want = 0
        for a, letter in enumerate("XYZ"):
            if letter not in named:
                assert target[a] == pos[a], text
                continue
            value = named[letter] + (pos[a] if relative else 0)
            if abs(named[letter]) > nm_max or abs(value) > nm_max:
                want = -1 - a
                break
            assert target[a] == value, (text, pos, relative)
            if travel and not -1 <= value <= travel[a] + 1:
                want = -4 - a
                break
            want |= 1 << a
        if want >= 0:
            if "E" in named and abs(named["E"]) <= nm_max:
                want |= 8
                assert steps[4] == named["E"], text
                e_read += 1
            for a in range(3):
                if at and steps[a] != at[a]:
                    want |= 16 << a
        assert verdict == want, (text, pos, relative, travel, at)
        if verdict >= 0:  # each axis's step at its position (no offsets here)
            assert steps[:3] == [scaled_round(target[a], *fractions[a]) for a in range(3)]
    assert e_read > 150


# --- A block's nominal speed: the step rate's limit, Marlin's SLOWDOWN (M205 B) ----

# For each line that queued a block: the blocks waiting before it, its nominal V2 and
# its nominal rate.
G1_OTHER_PARSER = """
import sys, json
import simmachine
sys.modules["machine"] = simmachine
import board
from mixfw import assemble
from mixfw.gcode import Parser
simmachine.attach_world(board.PINS, ["x", "y", "z"] + ["e%d" % i for i in range(6)])
printer = assemble.build(files_root=None)
out = []
for text in (b"G1 X10 Y5 F3000", b"G1 X12"):
    printer.run_line(printer.parser.parse(text, len(text)))
    out.append(list(printer.motion.pos_nm))
other = Parser()
for text in (b"G1 X20 Y7", b"G1 Y9"):
    printer.motion.g1(other.parse(text, len(text)))
    out.append(list(printer.motion.pos_nm))
text = b"G1 X3"
printer.run_line(printer.parser.parse(text, len(text)))
out.append(list(printer.motion.pos_nm))
print(json.dumps(out))
"""


def test_g1_reads_the_words_of_the_line_it_is_given(mp):
    """xyz_targets finds the parsed line's words by their places (Motion.line): a line
    of another parser is read as its own, and the printer's own parser's after it."""
    mm = 1000000
    assert mp.json(G1_OTHER_PARSER) == [
        [10 * mm, 5 * mm, 0], [12 * mm, 5 * mm, 0], [20 * mm, 7 * mm, 0],
        [20 * mm, 9 * mm, 0], [3 * mm, 9 * mm, 0]]


PLANS = """
import sys, json
import simmachine
sys.modules["machine"] = simmachine
import board
from mixfw import assemble, lookahead
from mixfw import stepper as st

simmachine.attach_world(board.PINS, ["x", "y", "z"] + ["e%d" % i for i in range(6)])
printer = assemble.build(files_root=None)
pl = printer.planner
mem = printer.mem
run = printer.run_line
parse = printer.parser.parse
plans = []
from mixfw.planner import waiting_blocks

def take_one():
    # The step loop takes a block only when the planner waits for room: so the queue
    # fills up from empty, one more block waiting with each line.
    t = mem[st.S_TAIL]
    if t != mem[st.S_HEAD]:
        mem[st.S_TAIL] = t + 1 if t + 1 < pl.queue else 0
    mem[st.S_ACTIVE] = 0

pl.idle = take_one
for text in json.loads(sys.stdin.read()):
    waiting = waiting_blocks(mem)
    head = mem[st.S_HEAD]
    run(parse(text.encode(), len(text)))
    if mem[st.S_HEAD] != head:
        at = head * lookahead.L_WORDS
        plans.append([waiting, pl.lk[at + lookahead.L_NOMINAL],
                      pl.lk[at + lookahead.L_RATE_NOM], pl.lk[at + lookahead.L_ACC]])
print(json.dumps(plans))
"""


def test_the_lead_axis_never_steps_faster_than_the_step_pulse_allows(mp):
    """A STEP pin is high for a pulse and low as long (on the simulated board one 20 us
    tick each: 25,000 steps/s). At 400 steps/mm that is 62.5 mm/s along X, and 88.4
    mm/s on a diagonal, whose lead axis moves 1/sqrt(2) of the path: a move asked
    faster keeps its lead axis at that rate (half a step a tick), and its V2 is that
    speed's; a slower one keeps its own."""
    lines = ["M302 P1", "G92 X0 Y0 Z0", "G90", "M92 X400 Y400", "G1 X10 F6000",
             "G1 X20 Y10 F6000", "G1 X30 Y10 F3000"]
    got = [plan[:3] for plan in mp.json(PLANS, stdin=json.dumps(lines).encode())]
    cap = (1 << 28) // 2
    (_, x_v2, x_rate), (_, d_v2, d_rate), (_, slow_v2, slow_rate) = got
    assert x_rate == d_rate == cap
    assert abs(x_v2 - 62.5 ** 2 * 64) <= 62.5 ** 2 * 64 * 1e-4
    assert abs(d_v2 - 2 * 62.5 ** 2 * 64) <= 2 * 62.5 ** 2 * 64 * 1e-4
    assert slow_v2 == round(50.0 ** 2 * 64) and slow_rate < cap


def test_a_move_keeps_each_axis_within_its_limits_by_its_share(mp):
    """An axis's max feed (M203) binds on a move by the axis's share of the path: along
    X at 50 mm/s, on a diagonal at 50 / (1/sqrt(2)) = 70.7; Z at its own 10 mm/s; a move
    asked slower keeps its speed. The limits change between moves at one F, and each
    move sees the ones in force; a move within them after one slowed by them, at the
    same F and limits, has its F again."""
    lines = ["M302 P1", "G92 X0 Y0 Z0", "G90", "G1 X10 F6000", "M203 X50", "G1 X20",
             "G1 X30 Y10", "G1 X40 Y10 F600", "G1 Z1 F6000", "G1 Y20", "M203 X250",
             "G1 X50 Y10"]
    v2 = [plan[1] for plan in mp.json(PLANS, stdin=json.dumps(lines).encode())]
    first, x_only, diagonal, slow, z_only, y_after, again = v2
    assert first == y_after == again == round(100.0 ** 2 * 64)
    assert abs(x_only - 50.0 ** 2 * 64) <= 2
    assert abs(diagonal - 2 * 50.0 ** 2 * 64) <= 4
    assert slow == round(10.0 ** 2 * 64)
    assert abs(z_only - 10.0 ** 2 * 64) <= 2


def test_a_feed_rate_taken_again_plans_as_it_did_the_first_time(mp):
    """A print's retractions, travels and extrusions take turns at a few feed rates, and
    the planner keeps the floats of the latest eight (Planner._base_floats' memo): a move at a
    feed rate it planned before, kept or long gone from the memo, along X and as a
    retraction of E alone (its own acceleration), plans as the first move at it did."""
    feeds = [600, 1200, 1800, 2400, 3000]  # within E's own limit too
    lines = ["M302 P1", "G92 X0 Y0 Z0 E0", "G90", "M82", "M205 B0"]
    x = 0
    for f in feeds + feeds[::-1] + feeds[1:3] * 3:
        x += 5
        lines += ["G1 X%d F%d" % (x, f), "G1 E%d F%d" % (x % 2, f)]
    plans = mp.json(PLANS, stdin=json.dumps(lines).encode())
    assert len(plans) == len(lines) - 5
    first = {}
    for text, (_, v2, rate, acc) in zip(lines[5:], plans):
        move, f = text.split(" F")
        kind = "E" if " E" in move else "X"
        first.setdefault((kind, f), (v2, rate, acc))
        assert (v2, rate, acc) == first[(kind, f)], text
        # The first moves' own: the feed rate's V2, and each kind its acceleration.
        assert abs(v2 - (int(f) / 60.0) ** 2 * 64) <= 1, text
    assert len(first) == 10
    # Each kind its own acceleration, though X planned every feed rate first: the rate
    # change a tick goes as the acceleration times the lead axis's steps/mm.
    from mixfw.defaults import SETTINGS
    accs = {kind: {acc for (k, _), (_, _, acc) in first.items() if k == kind}
            for kind in "XE"}
    assert len(accs["X"]) == len(accs["E"]) == 1
    spm = SETTINGS["steps_per_mm"]
    want = (SETTINGS["retract_acceleration_mm_s2"] * spm[3]
            / (SETTINGS["acceleration_mm_s2"] * spm[0]))
    assert abs(accs["E"].pop() / accs["X"].pop() / want - 1) < 0.02


def test_short_moves_slow_down_while_the_queue_is_under_half_full(mp):
    """As Marlin's SLOWDOWN: with 2 to 7 of the 16 blocks waiting, a move shorter than
    min_segment_time_us (20 ms) takes t + 2 (20 ms - t) / waiting; fewer or more
    waiting, or a longer move, keep the asked speed; M205 B0 turns it off. The
    acceleration stays what it is: every move along X has the same rate change a
    tick."""
    feed = 150.0  # mm/s: 0.3 mm takes 2 ms
    moves = ["G1 X%.1f F9000" % (10 + 0.3 * (i + 1)) for i in range(12)]
    lines = ["M302 P1", "G92 X0 Y0 Z0", "G90", "G1 X10 F9000", "M400"] + moves + [
        "M400", "G1 X14 F9000", "G1 X14.3", "G1 X100", "M400", "M205 B0"] + [
        "G1 X%.1f F9000" % (100 + 0.3 * (i + 1)) for i in range(12)]
    plans = mp.json(PLANS, stdin=json.dumps(lines).encode())
    assert len({plan[3] for plan in plans}) == 1
    got = [plan[:2] for plan in plans]
    nominal = round(feed * feed * 64)
    short = got[1:13]  # after the first move
    assert [w for w, _ in short] == list(range(12))
    for waiting, v2 in short:
        if 2 <= waiting < 8:
            t = 0.3 / feed
            slowed = 0.3 / (t + 2 * (0.02 - t) / waiting)
            assert abs(v2 - slowed * slowed * 64) <= 2, (waiting, v2)
        else:
            assert v2 == nominal, (waiting, v2)
    assert got[15] == [2, nominal]  # 86 mm: far longer than 20 ms
    assert [v2 for _, v2 in got[16:]] == [nominal] * 12  # M205 B0


# --- the square root of two limbs (ramp.isqrt_limbs) --------------------------------

ISQRT = """
import sys, json
from array import array
from uctypes import addressof
from mixfw import ramp
w = array("i", bytes(4 * ramp.IO_WORDS))
w4 = addressof(w) >> 2  # the helpers take the array as its address over 4
out = []
for v in json.loads(sys.stdin.read()):
    w[ramp.IO_HI] = v >> 30
    w[ramp.IO_LO] = v & 0x3FFFFFFF
    out.append(ramp.isqrt_limbs(w4))
print(json.dumps(out))
"""


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
    assert mp.json(ISQRT, stdin=json.dumps(values).encode()) == [isqrt(v) for v in values]


# --- long division of two limbs (ramp.div_limbs) -----------------------------------

DIV = """
import sys, json
from array import array
from uctypes import addressof
from mixfw import ramp
w = array("i", bytes(4 * ramp.IO_WORDS))
w4 = addressof(w) >> 2  # the helpers take the array as its address over 4
out = []
for v, c in json.loads(sys.stdin.read()):
    w[ramp.IO_HI] = v >> 30
    w[ramp.IO_LO] = v & 0x3FFFFFFF
    ramp.div_limbs(w4, c)
    out.append([w[ramp.IO_HI], w[ramp.IO_LO], w[ramp.IO_HI + 2]])
print(json.dumps(out))
"""


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
    got = mp.json(DIV, stdin=json.dumps(pairs).encode())
    assert got == [[(v // c) >> 30, (v // c) & 0x3FFFFFFF, v % c] for v, c in pairs]


# --- a * b // c scaled (ramp.product) ----------------------------------------------

PRODUCT = """
import sys, json
from array import array
from uctypes import addressof
from mixfw import ramp
w = array("i", bytes(4 * ramp.IO_WORDS))
w4 = addressof(w) >> 2  # the helpers take the array as its address over 4
out = []
for a, b, c, s, how in json.loads(sys.stdin.read()):
    for k, v in enumerate((a, b, c, s, how)):  # product()'s operands: w's last five
        w[ramp.IO_WORDS - 5 + k] = v
    x = ramp.product(w4)
    out.append([x, w[ramp.IO_HI], w[ramp.IO_LO]])
print(json.dumps(out))
"""


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
    got = mp.json(PRODUCT, stdin=json.dumps(cases).encode())
    for case, (x, hi, lo) in zip(cases, got):
        want = _product_model(*case)
        assert [x, hi if want[1] is not None else None,
                lo if want[2] is not None else None] == want, case


# --- metres of filament: each drive's base (Planner._rebase) ------------------------

LONG_PRINT = """
import sys, json
import simmachine
sys.modules["machine"] = simmachine
import board
from mixfw import assemble
from plan_only import retire_all
simmachine.attach_world(board.PINS, ["x", "y", "z"] + ["e%d" % i for i in range(6)])
printer = assemble.build(files_root=None)
pl = printer.planner
pl.idle = retire_all(printer.mem, pl.queue)
if sys.stdin.read() == "no base":
    for pq in pl._per_nm:  # a drive's filament never leaves low..high: no base
        pq[3] = -(1 << 62)
        pq[4] = 1 << 62
lines = [b"M302 P1", b"M83", b"M567 P6 E0.1:0.15:0.2:0.25:0.12:0.18"]
for turn in range(9):
    # a metre on one drive, then a mix over all six with a remainder, then a
    # retraction past the base's low edge and back
    lines += [b"T%d" % (turn % 3)] + [b"G1 E150.0003 F6000"] * 6
    lines += [b"T6", b"G1 X%d E47.123457 F3000" % (turn % 2), b"G1 E-160.5", b"G1 E160.5"]
out = []
for raw in lines:
    printer.run_line(printer.parser.parse(raw, len(raw)))
    out.append(list(pl.drive_steps))
print(json.dumps({"steps": out, "rem": pl.drive_rem,
                  "nm": [pq[5] + nm for pq, nm in zip(pl._per_nm, pl.drive_nm)],
                  "bases": [pq[5] for pq in pl._per_nm]}))
"""


def test_metres_of_filament_give_each_drive_the_same_steps_with_a_base_as_without(mp):
    """Each drive's filament in nm passes the chips' small ints within a metre or so; the
    planner keeps a base of whole steps under it. Single-drive and mixed extrusion with
    remainders, retractions past the base's low edge: every drive's step after every
    line, and its exact filament, are those worked out with no base."""
    based = mp.json(LONG_PRINT, stdin=b"")
    plain = mp.json(LONG_PRINT, stdin=b"no base")
    assert all(b > 0 for b in based.pop("bases")[:3])
    assert not any(plain.pop("bases"))
    assert based == plain
    assert max(plain["nm"]) > 2 << 30


# --- a move refused leaves the drives' filament as it was --------------------------

REFUSED = """
import sys, json
import simmachine
sys.modules["machine"] = simmachine
import board
from mixfw import assemble
from mixfw.planner import PlanError
simmachine.attach_world(board.PINS, ["x", "y", "z"] + ["e%d" % i for i in range(6)])
printer = assemble.build(files_root=None)
pl = printer.planner
weights = tuple([1, 2, 4] + [0] * (pl.drives - 3))[:pl.drives]
pl.set_mix(1, weights)
refused = []
pl.add_move([800, 0, 0, 0], 30.0, e_nm=1234567)
if sys.stdin.read() == "refuse":
    # Beyond a 32-bit word, and beyond it by as little as a 32-bit word would keep.
    for far in (1 << 31, (1 << 32) + 5, -(1 << 40)):
        try:
            pl.add_move([far, 0, 0, 0], 30.0, e_nm=2345678)
        except PlanError as e:
            refused.append(str(e))
pl.add_move([1600, 400, 0, 0], 30.0, e_nm=7654321)
print(json.dumps({"refused": refused, "drive_steps": list(pl.drive_steps),
                  "drive_nm": pl.drive_nm, "drive_rem": pl.drive_rem,
                  "position": pl.position_steps}))
"""


def test_a_move_refused_changes_neither_the_position_nor_the_drives_filament(mp):
    """The planner works out a move's filament in place (mixfw/planner.py): a move it
    refuses must do so before, or the next move's drive steps would carry its share."""
    plain = mp.json(REFUSED, stdin=b"")
    with_refusal = mp.json(REFUSED, stdin=b"refuse")
    assert len(with_refusal.pop("refused")) == 3
    plain.pop("refused")
    assert with_refusal == plain
    assert plain["drive_steps"][:3] != [0, 0, 0]


TARGET_WORDS = SIM_PLANNER + """
from plan_only import retire_all
pl.idle = retire_all(printer.mem, pl.queue)
out = []
# Each case: where X is, and a target X beyond +-(2**30 - 1) steps but a few steps away,
# written into the planner's own array (as g1 writes it) or given as a list.
for start, end in ((2 ** 30 - 10, 2 ** 30 + 5), (-(2 ** 30) + 10, -(2 ** 30)),
                   (2 ** 30 - 10, 2 ** 30 - 4)):
    for as_words in (1, 0):
        pl.set_position_steps([start, 0, 0, 0])
        target = pl.target_steps if as_words else [0, 0, 0]
        target[0] = end
        target[1] = target[2] = 0
        try:
            pl.add_move(target, 10.0)
            got = "planned"
        except planner.PlanError as e:
            got = str(e)[:13]
        out.append([got, pl.position_steps[0] == (end if got == "planned" else start)])
print(json.dumps(out))
"""


def test_targets_beyond_the_chips_small_ints_are_refused_as_words_as_in_lists(mp):
    """add_move reads X Y Z's targets from the planner's target_steps as words, in
    viper: a target past +-(2**30 - 1) steps is refused there as a list's is in Python
    (move too long), the position kept, even a few steps from where the axis is."""
    got = mp.json(TARGET_WORDS, stdin=b"")
    assert got == [["move too long", True]] * 4 + [["planned", True]] * 2


# --- each drive's plan in one viper call (planner._drive_targets) ------------------

# A printer on the simulated board; whole, its _drive_targets, and as viper and python
# two that count the lines it planned (fast), or plan none (every plan _plan_e's own).

DRIVE_TARGETS = SIM_PLANNER + """
from plan_only import retire_all
pl.idle = retire_all(printer.mem, pl.queue)
planner._drive_targets = python if sys.stdin.read() == "python" else viper
# Steps per mm whose p / q fit the words in machine words, in limbs, or not at all
# (a calibrated drive's 93.71234: _plan_e plans every mix it has a share in).
pl.set_drive_steps([415.0, 80.0, 400.5, 93.71234, 415.0, 2000.0][:pl.drives])
seed = [12345]


def rand(n):
    seed[0] = (seed[0] * 1103515245 + 12345) & 0x7FFFFFFF
    return seed[0] % n


mixes = [(1, 0, 0, 0, 0, 0), (0, 0, 0, 0, 1, 0), (3, 7, 0, 0, 0, 0),
         (10, 15, 20, 25, 12, 18), (373, 0, 627, 0, 0, 0), (1, 0, 0, 0, 0, 9999),
         (0, 1, 0, 1, 0, 0), (2, 0, 0, 0, 5, 0)]
out = []
x = 0
for n in range(800):
    if n % 25 == 0:
        pl.set_mix(n, mixes[rand(len(mixes))][:pl.drives])
    # Back past zero filament first, then metres forward: each drive's base moves.
    e_nm = rand(900000) - 200000 if rand(4) else rand(60000000) - 8000000
    if n < 150:
        e_nm = -e_nm
    x = 800 - x
    pl.add_move([x, 0, 0, 0], 30.0, e_nm=e_nm)
    out.append(list(pl.drive_steps))
print(json.dumps({"steps": out, "targets": list(pl.drive_targets), "nm": pl.drive_nm,
                  "rem": pl.drive_rem, "bases": [pq[5] for pq in pl._per_nm],
                  "fast": fast[0]}))
"""


def test_each_drives_plan_in_one_viper_call_is_the_plan_in_python_exactly(mp):
    """Most lines' filament is planned in _drive_targets (viper, machine words and
    limbs), else in _plan_e (Python's integers of any size): over mixes whose totals
    and drives' steps per mm fit the words in machine words, in limbs or not at all,
    extrusion and retraction past zero filament, and moves long enough to move a
    drive's base, every drive's steps after every move, its target and its exact
    filament are those planned in Python alone."""
    both = mp.json(DRIVE_TARGETS, stdin=b"")
    python = mp.json(DRIVE_TARGETS, stdin=b"python")
    assert python.pop("fast") == 0
    assert both.pop("fast") > 400
    assert max(both["bases"]) > 0
    assert both == python


DRIVE_TARGET_EDGES = SIM_PLANNER + """
out = []
for spm, w, nm_f, rem_f, e_nm in json.loads(sys.stdin.read()):
    pl.set_drive_steps([spm] * pl.drives)
    w = tuple(w + [0] * (pl.drives - len(w)))
    total = sum(w)
    got = []
    for plan in (viper, python):
        planner._drive_targets = plan
        pl._shares = (w, total)  # the planner's weights, as after a move with them
        for i in range(pl.drives):
            # The filament before the move that leaves drive 0 at nm_f + rem_f / total.
            rem = (rem_f - e_nm * w[i]) % total if i == 0 else 0
            k = (e_nm * w[i] + rem - (rem_f if i == 0 else 0)) // total
            pl.drive_nm[i] = (nm_f if i == 0 else 12345) - k
            pl.drive_rem[i] = rem
        pl.targets_known = True
        pl.rem_total = total
        pl.resync()  # the words from that state
        pl._plan_e(e_nm, w)
        got.append([pl.drive_nm[0], pl.drive_rem[0], list(pl.drive_targets)])
    out.append(got)
planner._drive_targets = whole
print(json.dumps([fast[0], out]))
"""


def _edge_cases():
    """Filament that leaves drive 0 where _drive_targets' arithmetic turns: exactly
    half a step (rounded away from zero), and a negative filament whose remainder
    borrows a whole q; with mixes whose steps fit machine words, limbs or neither."""
    import random
    from fractions import Fraction
    rnd = random.Random(36)
    cases = []
    for spm in (415.0, 80.0, 400.5, 2000.0, 93.71234):
        pq = Fraction(round(spm * 10 ** 6), 10 ** 12)
        p, q = pq.numerator, pq.denominator
        for w in ([1], [1, 1], [3, 7], [10, 15, 20, 25, 12, 18], [373, 0, 627], [1, 9999]):
            total = sum(w)
            qt = q * total
            for _ in range(12):
                e_nm = rnd.choice([rnd.randint(-900000, 900000), rnd.randint(-30000000, 30000000)])
                rem = rnd.randrange(total)
                cases.append([spm, w, rnd.randint(-(1 << 29), 1 << 29), rem, e_nm])
                # a borrow: negative filament, a whole number of q below zero, remainder
                cases.append([spm, w, -q * rnd.randint(1, (1 << 28) // q + 1),
                              rnd.randrange(1, total) if total > 1 else 0, e_nm])
            # exactly half a step: 2 low p = qt (2 j + 1), low below qt
            for j in range(3000):
                if (qt * (2 * j + 1)) % (2 * p) == 0 and qt * (2 * j + 1) // (2 * p) < qt:
                    low = qt * (2 * j + 1) // (2 * p)
                    h = rnd.randint(0, (1 << 28) // q)
                    cases.append([spm, w, h * q + low // total, low % total, 0])
                    cases[-1][4] = rnd.randint(-900000, 900000)
                    if low % total == 0 or total == 1:  # as the negative of the same
                        cases.append([spm, w, -(h * q + low // total), 0, cases[-1][4]])
                    break
    return cases


def test_each_drives_plan_in_one_viper_call_is_exact_where_its_arithmetic_turns(mp):
    """_drive_targets' step for filament at exactly half a step, and for negative
    filament whose remainder borrows a whole q, in machine words and in limbs, is
    _plan_e's in Python; and so are its filament and remainder."""
    cases = _edge_cases()
    fast, got = mp.json(DRIVE_TARGET_EDGES, stdin=json.dumps(cases).encode())
    assert len(got) == len(cases) > 300
    assert fast > len(cases) // 2
    for case, (viper, python) in zip(cases, got):
        assert viper == python, case
        assert viper[:2] == case[2:4], case


# --- a move's lengths and junction in integers (mixfw/geometry.py) -------------------

GEOMETRY = """
from array import array
from uctypes import addressof
from mixfw import geometry as ge
from mixfw.ramp import array_offsets


def run_geometry(runs):
    # Each run: the geometry floats as bits, and its moves: (G_D words, flags).
    g = array("i", bytes(4 * ge.G_WORDS))
    f = array("f", bytes(4))
    out = []
    for gf_bits, moves in runs:
        gf = array("f", bytes(array("I", gf_bits)))
        # g's last three words: where gf and f are, then the move's flags.
        array_offsets(g, ge.G_WORDS - 3, (gf, f))
        for d, flags in moves:
            for i in range(4):
                g[ge.G_D + i] = d[i]
            g[ge.G_WORDS - 1] = flags
            ge.lengths(addressof(g) >> 2)  # the array as its address over 4
            v2 = ge.junction(addressof(g) >> 2)
            out.append([list(array("I", bytes(f))), g[ge.G_LEN], g[ge.G_DIST], v2])
    return out
"""


def _geometry_cases():
    """Runs of moves as the planner hands them over: X Y Z in steps, E in nanometres or
    steps, each sign, from a step to the longest move a block takes, at steps/mm the
    options allow; most join the move before."""
    import random
    rnd = random.Random(11)
    runs = []
    for _ in range(40):
        spm = [rnd.choice([5.0, 80.0, 100.0, 93.7, 400.0, 415.0, 2560.0]) for _ in range(4)]
        accel_jd = rnd.choice([0.01, 1.0, 50.0, 3000.0]) * rnd.uniform(0.5, 1)
        moves = []
        while len(moves) < 60:
            d = [rnd.choice([0, 0, rnd.randint(1, 40), rnd.randint(1, 4000),
                             rnd.randint(1, (1 << 30) - 2)]) for _ in range(3)]
            e_nm = rnd.random() < 0.6
            d.append(rnd.choice([0, rnd.randint(1, 2000), rnd.randint(1, 5 * 10 ** 7)])
                     if e_nm else rnd.choice([0, rnd.randint(1, 20000)]))
            if not any(d):
                continue
            flags = sum(rnd.choice([0, 1]) << i for i in range(4))
            flags |= 16 if e_nm else 0
            flags |= 32 if moves and rnd.random() < 0.9 else 0
            moves.append((d, flags))
        runs.append((spm, accel_jd, moves))
    return runs


def test_a_moves_lengths_and_junction_are_the_same_integers_everywhere_and_near_exact(mp):
    """geometry.py works in integers, on the unix port and (CI's second pass) the 32-bit
    build. Against the lengths and the junction worked out from
    the float32 mm per unit in double precision: the length to 2**-23 and three of the
    move's units (2**-25 of its largest component), and the junction's V2 where it
    matters (below 300 mm/s) as far as the cosine's 28 bits allow."""
    import math
    import struct
    from array import array
    from mixfw import geometry as ge
    runs = _geometry_cases()
    given = []  # the floats as bits: a 32-bit build reads a float's text its own way
    for spm, accel_jd, moves in runs:
        gf = array("f", bytes(4 * ge.GF_WORDS))
        for i in range(4):
            gf[ge.GF_SCALE + i] = 1.0 / spm[i]
        gf[ge.GF_E_NM] = 1e-6
        gf[ge.GF_ACCEL_JD] = accel_jd
        given.append((list(array("I", bytes(gf))), moves))
    script = "import sys, json\n" + GEOMETRY + (
        "print(json.dumps(run_geometry(json.loads(sys.stdin.read()))))\n")
    got = iter(mp.json(script, stdin=json.dumps(given).encode()))
    checked = 0
    for spm, accel_jd, moves in runs:
        scale = [_f32(1.0 / s) for s in spm] + [_f32(1e-6)]
        aj = _f32(accel_jd)
        prev = None
        for d, flags in moves:
            bits, _, _, v2 = next(got)
            dist = struct.unpack("<f", struct.pack("<I", bits[0]))[0]
            e_scale = scale[4] if flags & 16 else scale[3]
            mm = [d[i] * scale[i] * (-1 if flags >> i & 1 else 1) for i in range(3)]
            mm.append(d[3] * e_scale * (-1 if flags >> 3 & 1 else 1))
            want = math.hypot(*mm[:3]) if any(d[:3]) else abs(mm[3])
            biggest = max(abs(x) for x in mm)
            assert abs(dist - want) <= want * 2 ** -23 + 3 * biggest * 2 ** -25, (d, flags)
            length = math.hypot(*mm)
            if flags & 32:
                dot = sum(a * b for a, b in zip(prev, mm)) / (math.hypot(*prev) * length)
                if dot > 0.999999:
                    want_v2 = (1 << 29) - 1
                elif dot < -0.999999:
                    want_v2 = 0
                else:
                    sin_half = math.sqrt(0.5 * (1 + dot))
                    want_v2 = min((1 << 29) - 1, 64 * aj * sin_half / (1 - sin_half))
                if want_v2 < 64 * 300 ** 2 and 1 - abs(dot) > 1e-5:
                    # The cosine is good to a few parts in 2**28, which is the more of
                    # the junction's speed the straighter (or the more reversed) it is.
                    tolerance = 1 + want_v2 * (1e-6 + 2 ** -24 / (1 - abs(dot)))
                    assert abs(v2 - want_v2) <= tolerance, (d, flags, dot)
                    checked += 1
            else:
                assert v2 == 0
            prev = mm
    assert checked > 1000
