"""The planner (mixfw/planner.py) on the unix port: positions to steps, a move's
filament shared among the drives, block weights, a G1 line's words, and the speeds it
plans. Its look-ahead, ramps and geometry have test files of their own
(test_lookahead.py, test_ramp.py, test_geometry.py)."""
import json

# --- positions to steps without big ints (filament.scaled_round) --------------------


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
    got = mp.script_json("planner_scaled_round", stdin=json.dumps(cases).encode())
    for case, (a, b, c, d) in zip(cases, got):
        assert a == b and c == d, case


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
    got = mp.script_json("planner_block_weights", stdin=json.dumps(cases).encode())
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


def test_positions_become_the_same_steps_in_small_ints(mp):
    """X Y Z's positions to steps in viper (cmd_motion.xyz_targets, 15-bit digits and
    30-bit limbs): the integer scaled_round gives, halves away from zero included, over
    the options' whole range of steps/mm and positions within +-2**30 nm, on both
    builds."""
    import random
    from mixfw.filament import scaled_round, steps_per_nm
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
    got = mp.script_json("planner_steps_of_nm", stdin=json.dumps(cases).encode())
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
    got = mp.script_json("planner_xyz_targets", stdin=json.dumps(cases).encode())
    from mixfw.filament import scaled_round, steps_per_nm
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


def run_plans(mp, lines):
    """The lines run on the simulated printer (upy/planner_plans.py): for each that
    queued a block, the blocks waiting before it, its nominal V2, its nominal rate and
    its acceleration."""
    return mp.script_json("planner_plans", stdin=json.dumps(lines).encode())


def test_g1_reads_the_words_of_the_line_it_is_given(mp):
    """xyz_targets finds the parsed line's words by their places (Motion.line): a line
    of another parser is read as its own, and the printer's own parser's after it."""
    mm = 1000000
    assert mp.script_json("planner_g1_other_parser") == [
        [10 * mm, 5 * mm, 0], [12 * mm, 5 * mm, 0], [20 * mm, 7 * mm, 0],
        [20 * mm, 9 * mm, 0], [3 * mm, 9 * mm, 0]]


def test_the_lead_axis_never_steps_faster_than_the_step_pulse_allows(mp):
    """A STEP pin is high for a pulse and low as long (on the simulated board one 20 us
    tick each: 25,000 steps/s). At 400 steps/mm that is 62.5 mm/s along X, and 88.4
    mm/s on a diagonal, whose lead axis moves 1/sqrt(2) of the path: a move asked
    faster keeps its lead axis at that rate (half a step a tick), and its V2 is that
    speed's; a slower one keeps its own."""
    lines = ["M302 P1", "G92 X0 Y0 Z0", "G90", "M92 X400 Y400", "G1 X10 F6000",
             "G1 X20 Y10 F6000", "G1 X30 Y10 F3000"]
    got = [plan[:3] for plan in run_plans(mp, lines)]
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
    v2 = [plan[1] for plan in run_plans(mp, lines)]
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
    plans = run_plans(mp, lines)
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
    plans = run_plans(mp, lines)
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


# --- metres of filament: each drive's base (filament.rebase) ------------------------


def test_metres_of_filament_give_each_drive_the_same_steps_with_a_base_as_without(mp):
    """Each drive's filament in nm passes the chips' small ints within a metre or so; the
    planner keeps a base of whole steps under it. Single-drive and mixed extrusion with
    remainders, retractions past the base's low edge: every drive's step after every
    line, and its exact filament, are those worked out with no base."""
    based = mp.script_json("planner_long_print", stdin=b"")
    plain = mp.script_json("planner_long_print", stdin=b"no base")
    assert all(b > 0 for b in based.pop("bases")[:3])
    assert not any(plain.pop("bases"))
    assert based == plain
    assert max(plain["nm"]) > 2 << 30


# --- a move refused leaves the drives' filament as it was --------------------------


def test_a_move_refused_changes_neither_the_position_nor_the_drives_filament(mp):
    """The planner works out a move's filament in place (mixfw/planner.py): a move it
    refuses must do so before, or the next move's drive steps would carry its share."""
    plain = mp.script_json("planner_refused", stdin=b"")
    with_refusal = mp.script_json("planner_refused", stdin=b"refuse")
    assert len(with_refusal.pop("refused")) == 3
    plain.pop("refused")
    assert with_refusal == plain
    assert plain["drive_steps"][:3] != [0, 0, 0]


def test_targets_beyond_the_chips_small_ints_are_refused_as_words_as_in_lists(mp):
    """add_move reads X Y Z's targets from the planner's target_steps as words, in
    viper: a target past +-(2**30 - 1) steps is refused there as a list's is in Python
    (move too long), the position kept, even a few steps from where the axis is."""
    got = mp.script_json("planner_target_words", stdin=b"")
    assert got == [["move too long", True]] * 4 + [["planned", True]] * 2


# --- each drive's plan in one viper call (filament.plan_e_words) ------------------


def test_each_drives_plan_in_one_viper_call_is_the_plan_in_python_exactly(mp):
    """Most lines' filament is planned in filament.plan_e_words (viper, machine words and
    limbs), else in filament.plan_e (Python's integers of any size): over mixes whose totals
    and drives' steps per mm fit the words in machine words, in limbs or not at all,
    extrusion and retraction past zero filament, and moves long enough to move a
    drive's base, every drive's steps after every move, its target and its exact
    filament are those planned in Python alone."""
    both = mp.script_json("planner_drive_targets", stdin=b"")
    python = mp.script_json("planner_drive_targets", stdin=b"python")
    assert python.pop("fast") == 0
    assert both.pop("fast") > 400
    assert max(both["bases"]) > 0
    assert both == python


def _edge_cases():
    """Filament that leaves drive 0 where plan_e_words' arithmetic turns: exactly
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
    """plan_e_words' step for filament at exactly half a step, and for negative
    filament whose remainder borrows a whole q, in machine words and in limbs, is
    plan_e's in Python; and so are its filament and remainder."""
    cases = _edge_cases()
    fast, got = mp.script_json("planner_drive_target_edges", stdin=json.dumps(cases).encode())
    assert len(got) == len(cases) > 300
    assert fast > len(cases) // 2
    for case, (viper, python) in zip(cases, got):
        assert viper == python, case
        assert viper[:2] == case[2:4], case

