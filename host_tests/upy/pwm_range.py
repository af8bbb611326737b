# mixfw.pwm.range_hz for each chip at the clocks boards boot with and overclocked, and
# whether the simulated chip's PWM takes each end and one Hz beyond each.
import json

import simanalog
import simmachine
from mixfw.pwm import range_hz


def takes(hz):
    try:
        simanalog.PWM(simmachine.Pin(16), freq=hz).deinit()
        return True
    except ValueError:
        return False


out = []
for chip, clocks in (("rp2040", (48, 125, 133, 200, 250)),
                     ("rp2350", (150, 300)), ("sim", (125, 200)),
                     ("esp32", (20, 80, 160, 240))):
    simmachine.set_chip(chip)
    for mhz in clocks:
        simmachine.freq(mhz * 1000000)
        lo, hi = range_hz(chip, simmachine.freq())
        out.append([chip, mhz, lo, hi, takes(lo), takes(hi),
                    takes(lo - 1), takes(hi + 1)])
print(json.dumps(out))
