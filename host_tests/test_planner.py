"""The planner's look-ahead, on the unix port: blocks planned against a full ring, with
one block taken by the step loop at every wait (as bench/plan_rate.py does)."""
from mixstep import paths

LOOK_AHEAD = """
import sys
from math import sqrt
import simmachine
sys.modules["machine"] = simmachine
import board, main
from mixfw import stepper as st

simmachine.attach_world(board.PINS, ["x", "y", "z"] + ["e%%d" %% i for i in range(6)])
printer = main.build(files_root=None)
pl = printer.planner
mem = printer.mem
q = pl.queue
errors = []
last_exit = [0.0]
counts = {"blocks": 0, "checked": 0}

def take_one():
    # The step loop runs the tail block: it enters at its planned entry, which must be
    # no faster than the block before it left.
    t = mem[st.S_TAIL]
    if t != mem[st.S_HEAD]:
        if pl.entry[t] > last_exit[0]:
            errors.append("block %%d enters at %%r after an exit at %%r"
                          %% (counts["blocks"], pl.entry[t], last_exit[0]))
        last_exit[0] = pl.exit[t]
        counts["blocks"] += 1
        mem[st.S_TAIL] = t + 1 if t + 1 < q else 0
    mem[st.S_ACTIVE] = 0
    mem[st.S_HOME_STOP] = 7  # homing: every endstop is hit at once

pl.idle = take_one
recalculate = pl._recalculate

def checked_recalculate(newest):
    # The incremental look-ahead must plan what a full pass over the queue plans.
    recalculate(newest)
    first = mem[st.S_TAIL]
    slots = []
    k = first
    while True:
        slots.append(k)
        if k == newest:
            break
        k = k + 1 if k + 1 < q else 0
    back = {}
    e = 0.0
    for k in reversed(slots):
        e = min(pl.max_entry[k], sqrt(e * e + 2.0 * pl.accel[k] * pl.mm[k]))
        back[k] = e
    v = min(back[first], pl.exit[first - 1 if first > 0 else q - 1])
    for i, k in enumerate(slots):
        v1 = 0.0 if k == newest else min(back[slots[i + 1]],
                                         sqrt(v * v + 2.0 * pl.accel[k] * pl.mm[k]))
        if (pl.entry[k], pl.exit[k]) != (v, v1):
            errors.append("slot %%d planned %%r, a full pass gives %%r"
                          %% (k, (pl.entry[k], pl.exit[k]), (v, v1)))
        v = v1
    counts["checked"] += 1

pl._recalculate = checked_recalculate
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
