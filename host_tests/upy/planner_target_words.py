# X targets just beyond +-(2**30 - 1) steps, a few steps from where X is, given to
# add_move in the planner's own target_steps (as g1 writes them) or as a list: for
# each, "planned" or the start of the refusal, and whether the position is right.
import json

from planner_sim import pl, planner, printer
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
