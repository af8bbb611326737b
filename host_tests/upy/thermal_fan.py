# The part fan's PWM duty after M106 S128, M106 and M107 on the simulated printer.
import json
import sys

import simmachine
import simtime

sys.modules["machine"] = simmachine
sys.modules["time"] = simtime
import simanalog  # noqa: E402
import board  # noqa: E402
from mixfw import assemble  # noqa: E402

p = assemble.build()
out = []
for line in (b"M106 S128", b"M106", b"M107"):
    p.parser.parse(line, len(line))
    p.run_line(p.parser.line)
    out.append(simanalog.duty_of(board.PINS["part_fan"]))
print(json.dumps(out))
