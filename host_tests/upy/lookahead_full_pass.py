# Plans the first 3000 lines of a G-code file (argv[1]) against a full ring, one block
# taken by the step loop at every wait (as bench/plan_rate.py does), and checks every
# incremental look-ahead pass against a full one. Prints the errors found and the
# blocks taken and checked, as JSON.
import json
import sys

import simbuild
from mixfw import lookahead, stepper as st
from mixfw import planner as planner_module

printer = simbuild.printer()
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
            errors.append("block %d enters at V2 %d after an exit at %d"
                          % (counts["blocks"], field(t, lookahead.L_ENTRY), last_exit[0]))
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
            errors.append("slot %d planned %r, a full pass gives %r" % (k, got, (v, v1)))
        v = v1
    counts["checked"] += 1


planner_module._recalculate = checked_recalculate
run = printer.run_line
parse = printer.parser.parse
run(parse(b"M302 P1", 7))
n = 0
for text in open(sys.argv[1], "rb"):
    text = text.rstrip()
    if text[:4] in (b"M109", b"M190", b"M116"):
        continue
    run(parse(text, len(text)))
    n += 1
    if n >= 3000:
        break
pl.synchronize()
print(json.dumps({"errors": errors[:5], "blocks": counts["blocks"], "checked": counts["checked"]}))
