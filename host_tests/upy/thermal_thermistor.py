# Thermistor.celsius for ADC readings (argv[1], JSON: the Steinhart-Hart coefficients
# of a 10 kOhm NTC, raw readings for the Beta thermistor, raw readings for the
# Steinhart-Hart one), and the readings of an open and a shorted thermistor.
import json
import sys

from mixfw.thermal import OPEN_C, SHORT_C, Thermistor

(sh_a, sh_b, sh_c), beta_raws, sh_raws = json.loads(sys.argv[1])
beta = Thermistor(4700.0, 100000.0, 3950.0)
sh = Thermistor(10000.0, 10000.0, 3950.0, sh_a, sh_b, sh_c)
print(json.dumps({
    "beta": [beta.celsius(r) for r in beta_raws],
    "sh": [sh.celsius(r) for r in sh_raws],
    "open": beta.celsius(65535), "short": beta.celsius(0),
    "open_c": OPEN_C, "short_c": SHORT_C}))
