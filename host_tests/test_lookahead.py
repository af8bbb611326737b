"""The planner's look-ahead (mixfw/lookahead.py) on the unix port: whole prints'
blocks planned against a full ring, each pass checked against a full one, and a
block's planning words (plan_words) against their exact values."""
import json

from mixstep import paths

# --- a whole print planned, each look-ahead pass checked ----------------------------


def test_look_ahead_is_a_full_pass_and_speed_is_continuous_where_blocks_meet(mp):
    """The example print's first 3000 lines, planned against a full ring with one
    block taken by the step loop at every wait (as bench/plan_rate.py does): each
    incremental pass plans what a full pass over the queue plans, and no block enters
    faster than the one before it left."""
    got = mp.script_json("lookahead_full_pass", paths.EXAMPLE_GCODE, heap="4M")
    assert got["errors"] == []
    assert got["blocks"] > 2500 and got["checked"] == got["blocks"]


# --- a block's planning words from its floats, in integers (lookahead.plan_words) ---


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
    words = mp.script_json("lookahead_plan_words", stdin=json.dumps(cases).encode())
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
