# Metres of filament on each drive, single-drive and mixed, with retractions past the
# base's low edge: every drive's steps after every line, then the remainders, the
# exact filament (base + nm) and the bases. stdin "no base": the drives keep no base.
import json
import sys

import simbuild
from plan_only import retire_all

printer = simbuild.printer()
pl = printer.planner
pl.idle = retire_all(printer.mem, pl.queue)
if sys.stdin.read() == "no base":
    for pq in pl._per_nm:  # a drive's filament never leaves low..high: no base
        pq[3] = -(1 << 62)
        pq[4] = 1 << 62
lines = [b"M302 P1", b"M83", b"M567 P6 E0.1:0.15:0.2:0.25:0.12:0.18"]
for turn in range(9):
    # a metre on one drive, then a mix over all six with a remainder, then a
    # retraction past the base's low edge and back
    lines += [b"T%d" % (turn % 3)] + [b"G1 E150.0003 F6000"] * 6
    lines += [b"T6", b"G1 X%d E47.123457 F3000" % (turn % 2), b"G1 E-160.5", b"G1 E160.5"]
out = []
for raw in lines:
    printer.run_line(printer.parser.parse(raw, len(raw)))
    out.append(list(pl.drive_steps))
print(json.dumps({"steps": out, "rem": pl.drive_rem,
                  "nm": [pq[5] + nm for pq, nm in zip(pl._per_nm, pl.drive_nm)],
                  "bases": [pq[5] for pq in pl._per_nm]}))
