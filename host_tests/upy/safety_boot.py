# boot.py on a board whose drivers are enabled active low (argv[1] "1") or high ("0"),
# from the levels a reset leaves: every driver's enable level after boot.py, after
# the M997 reset into the REPL (flag file argv[2]) too, and whether main.py would start
# the firmware then; and the system clock and the RP2040 regulator's VSEL boot.py left.
import json
import sys

import simmachine

sys.modules["machine"] = simmachine
import board  # noqa: E402

active_low = sys.argv[1] == "1"
board.SETTINGS["enable_active_low"] = active_low
simmachine.set_chip(board.SETTINGS["chip"])
enable = [g for name, g in sorted(board.PINS.items()) if name.endswith("_enable")]
for g in enable:
    # After a reset: pads pulled low, which enables an active-low driver; an
    # active-high one is enabled by a pin left high.
    simmachine._levels[g] = 0 if active_low else 1
import boot  # noqa: E402,F401  (what a reset runs first)

levels = [simmachine._levels[g] for g in enable]
clock = [simmachine.freq(), (simmachine.mem32[0x40064000] >> 4) & 15]
# M997's reset into the REPL: boot.py, then main.py starts nothing.
from mixfw import assemble  # noqa: E402

started = not assemble.repl_boot(sys.argv[2])
print(json.dumps([levels, [simmachine._levels[g] for g in enable], started, clock]))
