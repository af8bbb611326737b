# The whole simulated printer, assembled by mixfw.assemble, with the configuration loaded
# at boot from argv[1], serving the G-code lines on stdin. A counting applier shows when
# settings are applied: the count and every axis's steps are printed last ("//end").
import json
import sys

import simmachine
import simtime

sys.modules["machine"] = simmachine
sys.modules["time"] = simtime
import board  # noqa: E402

simmachine.attach_world(board.PINS, ["x", "y", "z"] + ["e%d" % i for i in range(6)])
from mixfw import assemble as firmware  # noqa: E402
from mixfw import safety  # noqa: E402
from mixfw.console import StreamConsole  # noqa: E402

console = StreamConsole(sys.stdin.buffer, sys.stdout.buffer, blocking=True)
warnings = []
config = firmware.Config(board.SETTINGS, sys.argv[1], warn=warnings.append)
config.boot()
printer = firmware.build(config)
applied = [0]


def count_applies(settings):
    applied[0] += 1


config.appliers.append(count_applies)
firmware.start([console], printer=printer, warnings=warnings)
safety.serve(printer)
pos = simmachine.positions
print("//end " + json.dumps({"applied": applied[0],
      "steps": {n: pos[i] for i, n in enumerate(simmachine.step_names)}}))
