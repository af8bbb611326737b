# safety.check_timer_support for chips and MicroPython versions: "ok" or the refusal.
import json

from mixfw import safety

res = []
for chip, version in (("rp2040", (1, 25, 0)), ("rp2350", (1, 24, 1)), ("rp2040", (1, 26, 0)),
                      ("esp32", (1, 20, 0)), ("sim", (1, 0, 0))):
    try:
        safety.check_timer_support(chip, version)
        res.append("ok")
    except RuntimeError as e:
        res.append(str(e))
print(json.dumps(res))
