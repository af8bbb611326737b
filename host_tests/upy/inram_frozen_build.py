# Builds the pio_dma board's printer (its step backend imports piodma) with the package
# taken for a frozen one (mixfw.FROZEN_PREFIX argv[1], the RAM copies' folder argv[2]),
# then prints where each step-path module came from; an ImportError is printed and
# ends the run with status 1.
import sys

import simmachine
import simtime

sys.modules["machine"] = simmachine
sys.modules["time"] = simtime
import mixfw  # noqa: E402
from mixfw import inram  # noqa: E402

mixfw.FROZEN_PREFIX = sys.argv[1]
inram.RAM_DIR = sys.argv[2]
try:
    from mixfw import assemble
    printer = assemble.build()
except ImportError as e:
    print("ImportError:", e)
    raise SystemExit(1)
for name in inram.STEP_PATH:
    print(name, sys.modules["mixfw." + name].__file__)
print("irq", printer.feed is not None)
