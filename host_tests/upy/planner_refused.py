# Two moves with a mix; stdin "refuse": with three moves refused between them (targets
# beyond a 32-bit word). Prints the refusals, the drives' steps, filament and
# remainders and the position after them.
import json
import sys

import simbuild
from mixfw.planner import PlanError

printer = simbuild.printer()
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
