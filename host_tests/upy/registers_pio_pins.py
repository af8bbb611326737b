# pio.out_range for STEP/DIR pins on one run of GPIOs, and its refusal of pins that
# are not.
import json

from mixfw import pio

names = ["x", "y"]
ok = pio.out_range({"x_step": 4, "x_dir": 5, "y_step": 6, "y_dir": 7}, names)
try:
    pio.out_range({"x_step": 4, "x_dir": 5, "y_step": 6, "y_dir": 9}, names)
    err = None
except ValueError as e:
    err = str(e)
print(json.dumps([ok, err]))
