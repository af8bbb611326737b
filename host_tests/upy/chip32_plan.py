# Every line of a G-code file (argv[1]) through the firmware's parser and command table
# into the planner, with no stepping: the planner's wait retires one block at a time
# (boards/sim/plan_only.py). Prints the steps the planner handed the step loop for
# every axis and drive, and the first errors.
import json
import sys

import simmachine

sys.modules["machine"] = simmachine
import board  # noqa: E402
from mixfw import assemble  # noqa: E402
from plan_only import retire_one  # noqa: E402

names = ["x", "y", "z"] + ["e%d" % i for i in range(board.SETTINGS["drives"])]
simmachine.attach_world(board.PINS, names)
printer = assemble.build(files_root=None)
printer.planner.idle = retire_one(printer.mem, printer.planner.queue)
replies = []
printer.reply = replies.append
errors = []
printer.run_line(printer.parser.parse(b"M302 P1", 7))
n = 0
for raw in open(sys.argv[1], "rb"):
    n += 1
    data = raw.split(b";")[0].strip()
    if not data or data[:4] in (b"M109", b"M190", b"M116"):
        continue
    try:
        printer.run_line(printer.parser.parse(data, len(data)))
    except Exception as e:
        errors.append("line %d: %r" % (n, e))
printer.planner.synchronize()
p = printer.planner
print(json.dumps({"steps": list(p.position_steps[:3]) + list(p.drive_steps),
                  "errors": errors[:10] + [r for r in replies if r.startswith("Error")][:10]}))
