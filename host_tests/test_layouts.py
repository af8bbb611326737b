"""One owner per fact in the firmware. Viper folds only a module's own constants, so a
module whose viper code reads another's words keeps a copy of each (`_NAME =
const(...)`), which the compiler strips: nothing on a chip checks them. Every copy is
checked here against its owner, and so are the rules of the layouts themselves (a
record's words in order, product()'s operands last). The constants are read from the
source; the owners' public ones also from the modules on the unix port.

Then the facts kept in one place with copies written out where a call would cost too
much: the small ints' limit (compat.MASK30), the two-limb product (ramp.product's
form), and the conversion of a speed to the step loop's rate (lookahead.plan_words
makes it, stepper.schedule applies it to a V2)."""
import ast
import functools
import json
import re
import struct
from fractions import Fraction
from math import isqrt

import pytest

from mixstep import paths

MIXFW = paths.FIRMWARE / "mixfw"
SOURCES = {p.stem: p for p in MIXFW.glob("*.py")}
SOURCES["plan_only"] = paths.BOARDS / "sim" / "plan_only.py"  # the planner's bench

# module: {owner: copies}. A copy _NAME equals the owner's NAME, or its _NAME where the
# owner keeps the name private.
COPIES = {
    "stepper": {
        "ramp": ["_IO_N", "_IO_R0", "_IO_RNOM", "_IO_R1", "_IO_ACC", "_IO_ACCEL_UNTIL",
                 "_IO_DECEL_AFTER", "_IO_RATE_DECEL", "_IO_HI", "_IO_LO"],
        "compat": ["_MASK30"],
        "mixer": ["_MIX_BIAS", "_RING_STEPS"],
    },
    "ramp": {"compat": ["_MASK30"]},
    "lookahead": {
        "stepper": ["_SHIFT_BIAS", "_S_TAIL", "_S_ACTIVE", "_S_QUEUE", "_BLOCK_BASE",
                    "_B_WORDS", "_B_FLAGS", "_B_RATE_INIT", "_B_RATE_NOM", "_B_RATE_FINAL",
                    "_B_ACCEL", "_B_ACCEL_UNTIL", "_B_DECEL_AFTER", "_B_RATE_DECEL",
                    "_F_SCHEDULE", "_F_RATES", "_V2_AT_NOMINAL"],
        "ramp": ["_AT_BIAS", "_IO_HI", "_IO_LO", "_IO_A", "_IO_B", "_IO_C", "_IO_S",
                 "_IO_HOW", "_P_TRUNC", "_P_ROUND", "_P_TOP"],
        "compat": ["_MASK30"],
    },
    "geometry": {
        "ramp": ["_AT_BIAS", "_IO_HI", "_IO_LO", "_IO_A", "_IO_B", "_IO_C", "_IO_S",
                 "_IO_HOW", "_P_ROUND"],
        "lookahead": ["_BIAS", "_V2_MAX"],
        "compat": ["_MASK30"],
    },
    "planner": {
        "stepper": ["_S_HEAD", "_S_TAIL", "_S_ACTIVE", "_S_QUEUE", "_R_PENDING",
                    "_BLOCK_BASE", "_B_WORDS", "_B_N", "_B_STEPS", "_B_DIR_SET",
                    "_B_DIR_CLR", "_B_FLAGS", "_B_DWELL", "_B_MIX", "_F_NEG", "_F_HOMING",
                    "_F_HOME_SHIFT", "_F_ADVANCE", "_B_ADV", "_S_ADV_OWED", "_S_ADV_NOW",
                    "_S_ADV_SLOT", "_S_ADV_FWD_SET", "_S_ADV_FWD_CLR", "_ADV_OFF",
                    "_ADV_BIAS"],
        "lookahead": ["_F_MM", "_F_ACCEL", "_F_NOMINAL", "_F_NOMINAL2", "_F_ACCEL_TICK",
                      "_L_WORDS", "_L_NOMINAL", "_W_AT_LK", "_W_AT_F", "_W_AT_MEM",
                      "_W_SLOT", "_W_N", "_W_ENTRY_V2", "_W_RATE_CAP"],
        "geometry": ["_G_D", "_G_C", "_G_DIST", "_G_AT_GF", "_G_FLAGS", "_GF_ACCEL_JD",
                     "_FL_E_NM", "_FL_JOIN"],
        "ramp": ["_IO_LO", "_IO_REM", "_IO_A", "_IO_B", "_IO_C", "_IO_HOW", "_P_LIMBS",
                 "_AT_BIAS"],
        "mixer": ["_MAX_DRIVES"],
        "compat": ["_MASK30"],
    },
    "filament": {
        "planner": ["_S_DRIVES", "_AT_COUNTS", "_AT_DRIVE_STEPS", "_AT_TARGETS", "_AT_IO",
                    "_S_E", "_MAX_PERIOD"],
        "ramp": ["_IO_LO", "_IO_REM", "_IO_A", "_IO_B", "_IO_C", "_IO_HOW", "_P_LIMBS",
                 "_AT_BIAS"],
        "compat": ["_MASK30"],
    },
    "piodma": {
        "stepper": ["_R_BATCHES", "_R_BUSY_BIT", "_R_CH", "_R_CHAIN_SHIFT", "_R_CH_SEG",
                    "_R_CTRL", "_R_FIRED", "_R_LATE", "_R_READY", "_R_RING_ADDR",
                    "_R_SEG_LV", "_R_SEG_N", "_R_SEG_SEQ", "_R_SEG_WORDS", "_R_W", "_R_SM",
                    "_S_LEVELS"],
    },
    "cmd_motion": {"ramp": ["_AT_BIAS"], "compat": ["_MASK30"]},
    "printer": {"intake": ["_RX_BYTES", "_COUNT", "_LEN"]},
    "plan_only": {
        "stepper": ["_S_HEAD", "_S_TAIL", "_S_ACTIVE", "_S_HOME_STOP", "_S_QUEUE",
                    "_BLOCK_BASE", "_B_WORDS"],
    },
}
# Private names that are their own module's facts, though another module owns the same
# name for another: (module, name, why).
NOT_COPIES = [
    ("planner", "_S_WORDS", "the planner's own words, not the step loop's"),
    ("stepper", "_S_WORDS", "the step loop's own words, not the planner's"),
    ("geometry", "_ONE", "the cosine's fixed point, not the step loop's rate"),
]


def _consts(path):
    """name: value of every `NAME = const(expr)` at the top level of a source file."""
    values = {}
    for node in ast.parse(path.read_text()).body:
        if (isinstance(node, ast.Assign) and len(node.targets) == 1
                and isinstance(node.targets[0], ast.Name)
                and isinstance(node.value, ast.Call)
                and getattr(node.value.func, "id", None) == "const"):
            expr = compile(ast.Expression(node.value.args[0]), str(path), "eval")
            values[node.targets[0].id] = eval(expr, {}, dict(values))
    return values


@functools.lru_cache(maxsize=None)
def consts(module):
    return _consts(SOURCES[module])


def owner_value(owner, copy):
    """The owner's value of the fact a copy _NAME names: its NAME, or its _NAME (not a
    copy itself)."""
    own = consts(owner)
    for name in (copy[1:], copy):
        if name in own:
            assert name not in sum(COPIES.get(owner, {}).values(), []), (
                "%s's %s is a copy, not the owner's" % (owner, name))
            return own[name]
    raise AssertionError("%s has no %s nor %s, which a copy names" % (owner, copy[1:], copy))


def test_every_copy_of_a_layout_is_its_owners_value():
    for module, owners in COPIES.items():
        mine = consts(module)
        for owner, copies in owners.items():
            for copy in copies:
                assert copy in mine, "%s has no copy %s of %s's" % (module, copy, owner)
                assert mine[copy] == owner_value(owner, copy), (
                    "%s.%s is %r, %s's is %r" % (module, copy, mine[copy], owner,
                                                  owner_value(owner, copy)))


def test_every_private_name_of_another_modules_fact_is_a_listed_copy():
    # A copy nobody listed would go unchecked: a private name that another module owns
    # (its NAME or _NAME, not as a copy itself) must be a listed copy, or a fact of its
    # own said so in NOT_COPIES.
    copies = {(m, c) for m, owners in COPIES.items() for cs in owners.values() for c in cs}
    owned = {}  # bare name: modules that own it
    for module in SOURCES:
        for name in consts(module):
            if (module, name) not in copies:
                owned.setdefault(name.lstrip("_"), set()).add(module)
    mine = {(m, n) for m, n, _ in NOT_COPIES}
    unlisted = []
    for module in SOURCES:
        for name in consts(module):
            if not name.startswith("_") or (module, name) in copies | mine:
                continue
            others = owned.get(name.lstrip("_"), set()) - {module}
            if others:
                unlisted.append("%s.%s (%s's)" % (module, name, ", ".join(sorted(others))))
    assert not unlisted, ("named as another module's: list each in COPIES, or in "
                          "NOT_COPIES if it is another fact: %s" % "; ".join(unlisted))
    for module, name, _ in NOT_COPIES:
        assert name in consts(module)


def _words(module, names):
    c = consts(module)
    return [c[n] for n in names]


def test_each_layout_keeps_its_rules():
    st, mixer, ramp = consts("stepper"), consts("mixer"), consts("ramp")
    la, geo, pl, motion = consts("lookahead"), consts("geometry"), consts("planner"), \
        consts("cmd_motion")
    fil = consts("filament")
    # ramp's io words: the record's, the limbs and the remainder, then product()'s five
    # operands last, every word once.
    io = sorted(v for n, v in ramp.items() if n.lstrip("_").startswith("IO_")
                and n != "IO_WORDS")
    assert io == list(range(ramp["IO_WORDS"]))
    assert _words("ramp", ["_IO_A", "_IO_B", "_IO_C", "_IO_S", "_IO_HOW"]) == list(
        range(ramp["IO_WORDS"] - 5, ramp["IO_WORDS"]))
    # The step loop's mixer section is mixer.py's, at MIX_BASE; a record's mix words
    # (id, then the weights) have the shape of its M_ID..M_W, so starting a block is one
    # copy; the forward pick is written out for six drives.
    assert st["_S_WORDS"] <= st["MIX_BASE"]
    assert st["MIX_BASE"] + mixer["M_WORDS"] <= st["MASK_BASE"]
    for m in ("M_W", "_M_SUM", "_M_Q", "_M_QMIN", "_M_AHEAD", "_M_E", "_M_RING",
              "_M_RING_MASK"):
        assert st["_MIX_" + m.lstrip("_")[2:]] == st["MIX_BASE"] + mixer[m], m
    # The mixer's ring: a power of 2 that fills whole words, and a divisor of the bias
    # its positions start at.
    ring = mixer["_RING_STEPS"]
    assert ring & (ring - 1) == 0 and ring % 4 == 0 and mixer["_MIX_BIAS"] % ring == 0
    assert (mixer["M_ID"], mixer["M_W"], mixer["MAX_DRIVES"]) == (0, 1, 6)
    assert st["B_MIX"] + 1 + mixer["MAX_DRIVES"] <= st["B_RATE_DECEL"] < st["B_WORDS"]
    # Every batch has a word more than the state machine's FIFO holds, and a refill
    # keeps the FIFO's words and the one before them.
    pio = consts("piodma")
    assert st["BATCH_MIN_WORDS"] == pio["_TAIL_WORDS"] == pio["_FIFO_WORDS"] + 1
    # lookahead's slot: every word named (plan_words clears each by name); its io array:
    # ramp's words, then its own in this order, the planner's inputs last.
    slot = [v for n, v in la.items() if n.lstrip("_").startswith("L_") and n != "L_WORDS"]
    assert sorted(slot) == list(range(la["L_WORDS"]))
    order = ["_W_M", "_W_E", "_W_N2_BITS", "_W_N2_V2", "_W_AT_LK", "_W_AT_F", "_W_AT_MEM",
             "_W_SLOT", "_W_N", "_W_ENTRY_V2", "_W_RATE_CAP", "W_WORDS"]
    widths = [la["F_WORDS"], la["F_WORDS"]] + [1] * (len(order) - 3)
    at = ramp["IO_WORDS"]
    for name, width in zip(order, widths + [None]):
        assert la[name] == at, name
        at += width or 0
    # geometry's array: ramp's io words first (its helpers' scratch); the flags last,
    # after the places of its floats and the planner's (array_offsets writes both).
    assert geo["G_D"] >= ramp["IO_WORDS"]
    assert geo["_G_AT_F"] == geo["_G_AT_GF"] + 1 and geo["_G_FLAGS"] == geo["G_WORDS"] - 1
    # geometry.lengths writes a move's length to the planner's first float.
    assert la["F_MM"] == 0
    # The planner's words: the places of the arrays array_offsets writes in one call
    # each, filament.plan_e_words' words between them.
    places = ["_AT_MEM", "_AT_LK", "_AT_COUNTS", "_AT_GEO", "_AT_DIR_SET", "_AT_DIR_CLR",
              "_AT_WEIGHTS", "_AT_DRIVE_STEPS", "_AT_GIVEN", "_AT_TARGETS", "_AT_IO"]
    assert _words("planner", places) == list(range(pl["_AT_MEM"], pl["_AT_MEM"] + 11))
    assert pl["_S_E"] == pl["_AT_IO"] + 1
    assert fil["_E_TOTAL"] == fil["_E_STRIDE"] * mixer["MAX_DRIVES"]
    assert pl["_S_E"] + fil["_E_FITS"] + 1 == pl["_AT_F"] and pl["_AT_XYZ"] == pl["_AT_F"] + 1
    assert pl["_AT_XYZ"] < pl["_S_JOINS"] < pl["_S_MEMO_NEXT"] < pl["_S_WORDS"]
    # cmd_motion's steps/mm words: the places of its five arrays last; 10**12 in limbs.
    assert _words("cmd_motion", ["_SPM_MANT", "_SPM_DEC", "_SPM_OFF", "_SPM_STEPS",
                                 "_SPM_TRAVEL"]) == list(range(motion["SPM_WORDS"] - 5,
                                                               motion["SPM_WORDS"]))
    assert ((motion["_E12_HI"] << 30) + motion["_E12_LO"] == fil["NM_PER_MM"] * fil["SPM_SCALE"]
            == motion["_FIVE6"] ** 2 << 12)


def test_the_letters_indexes_are_the_parsers():
    from mixfw.gcode import letter_index
    motion = consts("cmd_motion")
    assert motion["_AXIS_LETTERS"] == "XYZE"
    x = letter_index("X")
    assert [x, x + 1, x + 2] == [letter_index(a) for a in "XYZ"]
    assert (motion["_X_INDEX"], motion["_E_INDEX"], motion["_F_INDEX"]) == (
        x, letter_index("E"), letter_index("F"))


OWNERS_ON_THE_PORT = """
import json
from mixfw import (compat, mixer, ramp, stepper, lookahead, geometry, filament, planner,
                   piodma, cmd_motion)
names = json.loads(%r)
out = {}
for m in (compat, mixer, ramp, stepper, lookahead, geometry, filament, planner, piodma,
          cmd_motion):
    key = m.__name__.split(".")[-1]
    out[key] = {n: getattr(m, n, None) for n in names[key]}
print(json.dumps(out))
"""


def test_the_owners_public_values_are_what_the_firmware_imports(mp):
    # The source's reading of the constants, against the modules themselves.
    modules = ["compat", "mixer", "ramp", "stepper", "lookahead", "geometry", "filament",
               "planner", "piodma", "cmd_motion"]
    public = {m: sorted(n for n in consts(m) if not n.startswith("_")) for m in modules}
    got = mp.json(OWNERS_ON_THE_PORT % json.dumps(public))
    for m in modules:
        assert got[m] == {n: consts(m)[n] for n in public[m]}, m


# --- the chips' small-int limit, one name a module -------------------------------

def test_the_small_int_limit_is_named_once_a_module():
    assert consts("compat")["MASK30"] == (1 << 30) - 1
    for module, path in SOURCES.items():
        tree = ast.parse(path.read_text())
        named = set()
        for node in tree.body:
            if isinstance(node, ast.Assign) and isinstance(node.value, ast.Call):
                for arg in node.value.args:
                    if isinstance(arg, ast.Constant) and arg.value == (1 << 30) - 1:
                        named.add(id(arg))
                        assert node.targets[0].id == ("MASK30" if module == "compat"
                                                      else "_MASK30"), module
        bare = [node.lineno for node in ast.walk(tree) if isinstance(node, ast.Constant)
                and node.value == (1 << 30) - 1 and id(node) not in named]
        assert not bare, "%s: 2**30 - 1 written out on lines %s: use _MASK30" % (module,
                                                                                  bare)
        if "_MASK30" in consts(module):
            assert module in COPIES and "_MASK30" in COPIES[module].get("compat", ())


# --- the two-limb product: ramp.product's form, wherever it is written out ----------

_ID = r"[A-Za-z_]\w*"
# a * b in two 30-bit limbs from 15-bit digits; for a square, b's digits are a's and
# the middle term is doubled. The high limb may go on past the carry (a sum of them).
_SPLIT = r"(?P<a1>{i}) = (?P<a>.+) >> 15\n\s*(?P<a0>{i}) = (?P=a) & 0x7FFF\n\s*"
_PRODUCT = re.compile((
    _SPLIT + r"(?P<b1>{i}) = (?P<b>.+) >> 15\n\s*(?P<b0>{i}) = (?P=b) & 0x7FFF\n\s*"
    r"(?P<mid>{i}) = (?P=a1) \* (?P=b0) \+ (?P=a0) \* (?P=b1)\n\s*"
    r"(?P<lo>{i}) = \(\((?P=mid) & 0x7FFF\) << 15\) \+ (?P=a0) \* (?P=b0)\n"
    r"(?:.*\n)?.*(?P=a1) \* (?P=b1) \+ \((?P=mid) >> 15\) \+ \((?P=lo) >> 30\)"
).format(i=_ID))
_SQUARE = re.compile((
    _SPLIT + r"(?P<mid>{i}) = 2 \* (?P=a1) \* (?P=a0)\n\s*"
    r"(?P<lo>{i}) = \(\((?P=mid) & 0x7FFF\) << 15\) \+ (?P=a0) \* (?P=a0)\n"
    r"(?:.*\n)?.*(?P=a1) \* (?P=a1) \+ \((?P=mid) >> 15\) \+ \((?P=lo) >> 30\)"
).format(i=_ID))
# The line every such product has: the low limb's sum.
_LOW_LIMB = re.compile(r"= \(\(%s & 0x7FFF\) << 15\) \+ " % _ID)


def _function_source(module, name):
    text = SOURCES[module].read_text()
    return ast.get_source_segment(text, next(
        node for node in ast.parse(text).body
        if isinstance(node, ast.FunctionDef) and node.name == name))


def test_the_two_limb_product_is_written_out_in_ramp_products_form():
    found = 0
    for module, path in SOURCES.items():
        text = path.read_text()
        covered = set()
        for form in (_PRODUCT, _SQUARE):
            for m in form.finditer(text):
                covered.add(text.count("\n", 0, m.start("lo")))
        for m in _LOW_LIMB.finditer(text):
            line = text.count("\n", 0, m.start())
            assert line in covered, "%s:%d: a two-limb product not in ramp.product's form" % (
                path.name, line + 1)
            found += 1
    # ramp.product itself, ramp_into, stepper.schedule, geometry's three, plan_words'.
    assert found >= 7
    assert _PRODUCT.search(_function_source("ramp", "product"))


@pytest.mark.parametrize("square", [False, True])
def test_the_forms_arithmetic_is_the_exact_product(square):
    import random
    rnd = random.Random(5)
    # The reference, and the square plan_words writes out.
    m = (_SQUARE.search(_function_source("lookahead", "plan_words")) if square
         else _PRODUCT.search(_function_source("ramp", "product")))
    # Its lines up to the low limb, with their own names, then the high limb as the
    # form has it.
    names = {k: m.group(k) for k in ("a1", "a0", "mid", "lo")}
    code = "\n".join(line.strip() for line in m.group(0).splitlines()[:-1])
    hi_line = "hi = %(a1)s * %(b1)s + (%(mid)s >> 15) + (%(lo)s >> 30)" % dict(
        names, b1=names["a1"] if square else m.group("b1"))
    for _ in range(2000):
        a = rnd.choice([rnd.randrange(1 << 30), (1 << 30) - 1, rnd.randrange(1 << 15), 0])
        b = a if square else rnd.choice([rnd.randrange(1 << 30), (1 << 30) - 1, 1])
        env = {m.group("a"): a} if square else {m.group("a"): a, m.group("b"): b}
        exec(code + "\n" + hi_line, {}, env)
        assert (env["hi"], env[names["lo"]] & ((1 << 30) - 1)) == divmod(a * b, 1 << 30)


# --- a speed's rate: lookahead.plan_words makes k, stepper.schedule applies it -------

RATES = """
import sys, json
from array import array
from uctypes import addressof
from mixfw import lookahead as la, stepper as st
from mixfw.ramp import array_offsets
lk = array("i", bytes(4 * la.L_WORDS))
w = array("i", bytes(4 * la.W_WORDS))
mem = array("i", bytes(4 * st.mem_words(1)))
io = st.ramp_scratch()
b = st.BLOCK_BASE
out = []
for bits, n, v2s in json.loads(sys.stdin.read()):
    f = array("f", bytes(array("I", bits)))
    array_offsets(w, %(at_lk)d, (lk, f))
    w[%(slot)d] = 0
    w[%(n)d] = n
    w[%(entry)d] = 0
    w[%(cap)d] = %(rate_cap)d
    la.plan_words(addressof(w) >> 2)
    nominal = lk[la.L_NOMINAL]
    rates = []
    for i, v2 in enumerate(v2s):
        if v2 < 0:  # just below the nominal V2
            v2 = v2s[i] = max(0, nominal - 1)
        # The record as recalculate leaves it: two V2s (V2_AT_NOMINAL for the nominal
        # speed's), and what a rate comes from.
        mem[b + st.B_N] = n
        mem[b + st.B_RATE_INIT] = v2 if v2 < nominal else st.V2_AT_NOMINAL
        mem[b + st.B_RATE_NOM] = lk[la.L_RATE_NOM]
        mem[b + st.B_RATE_FINAL] = 0
        mem[b + st.B_ACCEL] = lk[la.L_ACC]
        mem[b + st.B_ACCEL_UNTIL] = lk[la.L_K2]
        mem[b + st.B_DECEL_AFTER] = lk[la.L_K_SHIFT]
        mem[b + st.B_RATE_DECEL] = lk[la.L_FLOOR]
        mem[b + st.B_FLAGS] = st.F_SCHEDULE | st.F_RATES
        st.schedule(mem, b, io)
        rates.append(mem[b + st.B_RATE_INIT])
    out.append([list(lk), v2s, rates])
print(json.dumps(out))
"""


def _f32_bits(x):
    return struct.unpack("<I", struct.pack("<f", x))[0]


def _f32(bits):
    return Fraction(struct.unpack("<f", struct.pack("<I", bits))[0])


def test_a_v2s_rate_is_the_speed_at_the_look_aheads_k(mp):
    """The one conversion of a speed to a rate is k (lookahead.plan_words): RATE_NOM is
    the nominal speed times k, and stepper.schedule works a V2's rate out as the block
    starts, from k as K2 and K_SHIFT. Over the ranges the options allow, each V2's rate
    is k sqrt(V2 / 64) within FLOOR and RATE_NOM, to the root's last bit; the nominal V2
    (V2_AT_NOMINAL) gives RATE_NOM itself, and a V2 just below it a rate just below."""
    import random
    la, st = consts("lookahead"), consts("stepper")
    rnd = random.Random(11)
    cases = []
    while len(cases) < 300:
        mm = rnd.choice([0.001, 0.2, 1.0, 30.0, 1000.0]) * rnd.uniform(0.5, 2)
        accel = rnd.choice([10.0, 500.0, 3000.0, 1e5]) * rnd.uniform(0.5, 1)
        nominal = rnd.choice([1.0, 25.0, 150.0, 1000.0]) * rnd.uniform(0.5, 1)
        tick_s = rnd.choice([5, 10, 20, 50, 1000]) * 1e-6
        n = rnd.choice([1, 16, 800, 10 ** 5, (1 << 30) - 2])
        floats = [mm, accel, nominal, nominal * nominal, tick_s * (1 << 28), accel * tick_s]
        bits = [_f32_bits(x) for x in floats]
        nominal_v2 = round(64 * _f32(bits[3]))
        # -1: just below the nominal V2, as plan_words makes it (the rate cap may
        # lower it).
        v2s = [0, 1, rnd.randrange(1, 1 << 29), rnd.randrange(1, max(2, nominal_v2)), -1]
        cases.append((bits, n, v2s))
    # The rate cap of the shortest step pulse, a tick (the planner's): the step loop's
    # rates stay below half a step a tick.
    words = {"at_lk": la["_W_AT_LK"], "slot": la["_W_SLOT"], "n": la["_W_N"],
             "entry": la["_W_ENTRY_V2"], "cap": la["_W_RATE_CAP"], "rate_cap": st["ONE"] // 2}
    got = mp.json(RATES % words, stdin=json.dumps(cases).encode())
    assert len(got) == len(cases)
    for (bits, n, _), (lk, v2s, rates) in zip(cases, got):
        k = _f32(bits[4]) * n / _f32(bits[0])
        r_nom, floor = lk[la["L_RATE_NOM"]], lk[la["L_FLOOR"]]
        shift = lk[la["L_K_SHIFT"]] - st["SHIFT_BIAS"]
        nominal_v2 = lk[la["L_NOMINAL"]]
        for v2, rate in zip(v2s, rates):
            if v2 >= nominal_v2:
                assert rate == r_nom
                continue
            # k sqrt(V2 / 64), in the exact fractions of the float32 inputs, to within
            # the root's truncation (a unit, scaled by 2**K_SHIFT) and K2's 26 bits.
            exact = k * Fraction(isqrt(v2 * 2 ** 80), 8 * 2 ** 40)
            want = min(max(exact, floor), r_nom)
            slack = (1 << max(shift, 0)) + 1 + want / 2 ** 20
            assert abs(rate - want) <= slack, (bits, n, v2, rate, float(want))
        # Just below the nominal V2, RATE_NOM's own speed to V2's rounding.
        if nominal_v2 > 1 << 20:
            near = rates[4]
            assert near <= r_nom and r_nom - near <= (1 << max(shift, 0)) + 1 + r_nom / 2 ** 19
