# The simulated thermistor (simthermal.Body) at 20, 60, 120 and 200 C, read back by
# the firmware's Thermistor: a Beta one, and a Steinhart-Hart one with the
# coefficients in argv[1] (JSON).
import json
import sys

import simthermal
from mixfw.thermal import Thermistor

sh_a, sh_b, sh_c = json.loads(sys.argv[1])
base = {"hotend_pullup_ohm": 4700.0, "hotend_r25_ohm": 100000.0,
        "hotend_beta": 3950.0, "hotend_sh_a": 0.0, "hotend_sh_b": 0.0,
        "hotend_sh_c": 0.0}
sh = dict(base, hotend_pullup_ohm=10000.0, hotend_r25_ohm=10000.0,
          hotend_sh_a=sh_a, hotend_sh_b=sh_b, hotend_sh_c=sh_c)
out = []
for s in (base, sh):
    body = simthermal.Body("hotend", 30, 33, s, 10.0, 40.0, 0.1)
    th = Thermistor(s["hotend_pullup_ohm"], s["hotend_r25_ohm"], s["hotend_beta"],
                    s["hotend_sh_a"], s["hotend_sh_b"], s["hotend_sh_c"])
    row = []
    for t in (20.0, 60.0, 120.0, 200.0):
        body.temp_c = t
        row.append(th.celsius(body.read_u16()))
    out.append(row)
print(json.dumps(out))
