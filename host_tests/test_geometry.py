"""A move's lengths and its junction with the move before (mixfw/geometry.py), in
integers on the unix port: worked examples against the geometry done exactly in
CPython, and random moves against double precision. The same integers on the 32-bit
build (CI's second pass) show no intermediate overflows a machine word."""
import json
import math
import struct

from mixfw import geometry as ge

V2_MAX = (1 << 29) - 1  # the look-ahead's V2 range, (mm/s)**2 * 64


def _f32(x):
    return struct.unpack("<f", struct.pack("<f", x))[0]


def _bits(x):
    return struct.unpack("<I", struct.pack("<f", x))[0]


def move(x=0, y=0, z=0, e=0, join=True, e_nm=False):
    """A move as the planner hands it over: X Y Z E in steps (E in nm with e_nm),
    signed; join: it follows a move it may join at speed."""
    d = [abs(x), abs(y), abs(z), abs(e)]
    flags = sum(1 << i for i, v in enumerate((x, y, z, e)) if v < 0)
    flags |= (ge.FL_E_NM if e_nm else 0) | (ge.FL_JOIN if join else 0)
    return d, flags


def run_moves(mp, steps_per_mm, accel_jd, moves):
    """Each move through lengths() and junction() in turn: for each, its length along
    the path (F_MM) as a float, G_LEN, G_DIST, the junction's V2 and what lengths()
    returned."""
    gf = [_bits(1.0 / s) for s in steps_per_mm] + [_bits(1e-6), _bits(accel_jd)]
    got = mp.script_json("geometry_moves", stdin=json.dumps([[gf, moves]]).encode())
    return [{"mm": struct.unpack("<f", struct.pack("<I", bits[0]))[0], "len": length,
             "dist": dist, "v2": v2, "returned": returned}
            for bits, length, dist, v2, returned in got]


def deviation_v2(accel_jd, before, after):
    """The junction deviation model from its geometry: the arc tangent to both moves
    that passes the corner at the deviation has radius R = deviation * sin(t / 2) /
    (1 - sin(t / 2)), t the angle between the moves at the corner (pi straight on, 0
    a reversal), and the speed on it v**2 = acceleration * R; as the look-ahead's V2."""
    cos_turn = (sum(a * b for a, b in zip(before, after))
                / (math.hypot(*before) * math.hypot(*after)))
    t = math.pi - math.acos(max(-1.0, min(1.0, cos_turn)))
    s = math.sin(t / 2)
    return min(V2_MAX, 64 * accel_jd * s / (1 - s)) if s < 1 else V2_MAX


def assert_v2(got, want, cos_turn):
    # The cosine is good to a few parts in 2**28: the more of the speed the straighter
    # (or the more reversed) the junction.
    assert abs(got - want) <= 1 + want * (1e-6 + 2 ** -24 / (1 - abs(cos_turn))), (got, want)


# --- worked examples --------------------------------------------------------------

# 128 steps/mm: a step is 2**-7 mm, so every component is a whole number of the
# move's unit and the lengths below are exact.
EXACT = (128.0, 128.0, 128.0, 128.0)


def test_a_moves_length_is_its_euclidean_length_along_x_y_z(mp):
    """3-4-5 and 2-3-6-7 moves, of either sign, a single step and a move of E alone:
    the length along the path (what its speed is along) is exact; with E beside X Y
    (5 mm and 12 mm of filament) G_LEN takes E in and G_DIST does not: 13 to 5."""
    moves = [move(3 * 128, 4 * 128), move(-2 * 128, 3 * 128, -6 * 128), move(1),
             move(e=-320), move(3 * 128, 4 * 128, e=12 * 128)]
    got = run_moves(mp, EXACT, 50.0, moves)
    assert [g["mm"] for g in got] == [5.0, 7.0, 1 / 128, 2.5, 5.0]
    with_e = got[4]
    assert with_e["len"] * 5 == with_e["dist"] * 13
    assert got[0]["len"] == got[0]["dist"]  # no E: the same length


def test_lengths_returns_the_length_as_float32_bits_halved_which_order_as_lengths(mp):
    """What lengths() returns: F_MM's float32 bits halved, so that a comparison of two
    moves' lengths needs no float."""
    mm = [0.3, 1.0, 2.5, 7.0, 40.0, 250.0]
    steps_per_mm = (80.0, 100.0, 400.0, 415.0)
    got = run_moves(mp, steps_per_mm, 50.0, [move(round(v * 80.0), join=False) for v in mm])
    assert [g["returned"] for g in got] == [_bits(g["mm"]) >> 1 for g in got]
    assert sorted(g["returned"] for g in got) == [g["returned"] for g in got]
    for want, g in zip(mm, got):
        assert abs(g["mm"] - want) <= want * 2 ** -22


def test_e_in_nanometres_is_read_at_its_own_scale(mp):
    """A move of E alone given in nanometres (FL_E_NM, GF_E_NM mm per nm) is as long
    as the same filament in steps."""
    got = run_moves(mp, (80.0, 80.0, 400.0, 415.0), 50.0,
                    [move(e=2500000, e_nm=True), move(e=-2500000, e_nm=True),
                     move(e=415 * 3)])
    assert abs(got[0]["mm"] - 2.5) <= 2.5 * 2 ** -22
    assert got[1]["mm"] == got[0]["mm"]
    assert abs(got[2]["mm"] - 3.0) <= 3.0 * 2 ** -22


def test_junction_speeds_follow_the_junction_deviation_model(mp):
    """Straight on: no limit; a reversal: a stop; a right angle, 45 degrees and a
    sharp turn: the model's speed. A move that may not be joined (no FL_JOIN) is a
    stop, and still the move before for the next one."""
    accel_jd = 1000.0 * 0.05  # acceleration (mm/s**2) times junction deviation (mm)
    path = [(10, 0), (10, 0), (0, 10), (10, 10), (-10, -10), (-10, 20), (10, 0), (0, -10)]
    joins = [False, True, True, True, True, True, False, True]
    moves = [move(x * 128, y * 128, join=j) for (x, y), j in zip(path, joins)]
    got = [g["v2"] for g in run_moves(mp, EXACT, accel_jd, moves)]
    assert got[0] == 0 and got[6] == 0  # not joined
    assert got[1] == V2_MAX  # straight on
    assert got[4] == 0  # back the way it came
    right_angle = 64 * accel_jd * math.sqrt(0.5) / (1 - math.sqrt(0.5))
    assert_v2(got[2], right_angle, 0.0)
    assert_v2(got[7], right_angle, 0.0)  # at right angles to the unjoined X move
    for k in (3, 5):
        before, after = path[k - 1], path[k]
        cos_turn = (sum(a * b for a, b in zip(before, after))
                    / (math.hypot(*before) * math.hypot(*after)))
        assert_v2(got[k], deviation_v2(accel_jd, before, after), cos_turn)
    assert got[5] < got[2] < got[3]  # the sharper the turn, the slower


def test_the_junctions_angle_is_in_millimetres_not_steps(mp):
    """X at 80 steps/mm, Y at 100: 10 mm along X, then 10 mm along each is a 45 degree
    turn (800 and 1000 steps would be 51)."""
    accel_jd = _f32(1500.0 * 0.02)
    got = run_moves(mp, (80.0, 100.0, 400.0, 415.0), accel_jd,
                    [move(800, join=False), move(800, 1000)])
    assert_v2(got[1]["v2"], deviation_v2(accel_jd, (1, 0), (1, 1)), math.sqrt(0.5))


def test_junction_speed_squared_goes_as_acceleration_times_deviation_up_to_its_range(mp):
    """V2 at a right angle for accel * deviation from 0.01 to 4000 mm**2/s**2, and
    beyond the look-ahead's range, where it is held at its top."""
    moves = [move(1280, join=False), move(0, 1280)]
    ratio = math.sqrt(0.5) / (1 - math.sqrt(0.5))
    for accel_jd in (0.01, 1.0, 50.0, 4000.0):
        aj = _f32(accel_jd)
        assert_v2(run_moves(mp, EXACT, aj, moves)[1]["v2"], 64 * aj * ratio, 0.0)
    assert run_moves(mp, EXACT, 1e9, moves)[1]["v2"] == V2_MAX


# --- random moves against double precision ----------------------------------------


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
    from array import array
    runs = _geometry_cases()
    given = []  # the floats as bits: a 32-bit build reads a float's text its own way
    for spm, accel_jd, moves in runs:
        gf = array("f", bytes(4 * ge.GF_WORDS))
        for i in range(4):
            gf[ge.GF_SCALE + i] = 1.0 / spm[i]
        gf[ge.GF_E_NM] = 1e-6
        gf[ge.GF_ACCEL_JD] = accel_jd
        given.append((list(array("I", bytes(gf))), moves))
    got = iter(mp.script_json("geometry_moves", stdin=json.dumps(given).encode()))
    checked = 0
    for spm, accel_jd, moves in runs:
        scale = [_f32(1.0 / s) for s in spm] + [_f32(1e-6)]
        aj = _f32(accel_jd)
        prev = None
        for d, flags in moves:
            bits, _, _, v2, _ = next(got)
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

