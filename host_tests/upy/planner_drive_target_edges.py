# For each case on stdin (JSON: steps/mm, weights, drive 0's filament and remainder
# after the move, the move's filament in nm): drive 0's filament, remainder and the
# drives' targets planned by filament.plan_e_words (viper) and by filament.plan_e in Python; first the
# lines the viper call planned.
import json
import sys

from mixfw import filament
from planner_sim import fast, pl, python, use, viper, whole

out = []
for spm, w, nm_f, rem_f, e_nm in json.loads(sys.stdin.read()):
    pl.set_drive_steps([spm] * pl.drives)
    w = tuple(w + [0] * (pl.drives - len(w)))
    total = sum(w)
    got = []
    for plan in (viper, python):
        use(plan)
        pl._shares = (w, total)  # the planner's weights, as after a move with them
        for i in range(pl.drives):
            # The filament before the move that leaves drive 0 at nm_f + rem_f / total.
            rem = (rem_f - e_nm * w[i]) % total if i == 0 else 0
            k = (e_nm * w[i] + rem - (rem_f if i == 0 else 0)) // total
            pl.drive_nm[i] = (nm_f if i == 0 else 12345) - k
            pl.drive_rem[i] = rem
        pl.targets_known = True
        pl.rem_total = total
        filament.resync(pl)  # the words from that state
        filament.plan_e(pl, e_nm, w)
        got.append([pl.drive_nm[0], pl.drive_rem[0], list(pl.drive_targets)])
    out.append(got)
use(whole)
print(json.dumps([fast[0], out]))
