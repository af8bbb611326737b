# Extruding lines with the cold extrusion guard on, no simulated time passing: for each
# line, the hot end's ADC reads so far and "ok" or the start of its error.
import json
import sys

import simmachine
import simtime

sys.modules["machine"] = simmachine
sys.modules["time"] = simtime
import board  # noqa: E402,F401  (the simulated board's, before the firmware)
from mixfw import assemble  # noqa: E402
from plan_only import retire_all  # noqa: E402

p = assemble.build()
p.planner.idle = retire_all(p.mem, p.planner.queue)
adc = p.thermal.hotend.adc
reads = [0]
read_u16 = adc.read_u16


def counted():
    reads[0] += 1
    return read_u16()


adc.read_u16 = counted
out = []
for text in (b"M302 S0", b"M83", b"G1 E0.1 F600", b"G1 E0.1", b"G1 X1 E0.1",
             b"G1 X2 E0.1", b"M302 S500", b"G1 E0.1"):
    try:
        p.run_line(p.parser.parse(text, len(text)))
        out.append([text.decode(), reads[0], "ok"])
    except Exception as e:
        out.append([text.decode(), reads[0], str(e)[:26]])
print(json.dumps(out))
