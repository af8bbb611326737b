# 800 moves over mixes, extrusion and retraction past zero filament and metres forward,
# each drive's filament planned by filament.plan_e_words (viper) where it can; stdin "python":
# every plan by filament.plan_e in Python. Prints every drive's steps after every move, the
# targets, filament, remainders, bases, and how many lines the viper call planned.
import json
import sys

from planner_sim import fast, pl, printer, python, use, viper
from plan_only import retire_all

pl.idle = retire_all(printer.mem, pl.queue)
use(python if sys.stdin.read() == "python" else viper)
# Steps per mm whose p / q fit the words in machine words, in limbs, or not at all
# (a calibrated drive's 93.71234: plan_e plans every mix it has a share in).
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
