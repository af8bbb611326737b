"""The simulated board's printer as assemble.build makes it on a board (no files, no
console), for scripts that drive its planner or commands directly. Import this first:
it puts the simulated chip in place of `machine` before any firmware module loads."""
import sys

import simmachine

sys.modules["machine"] = simmachine
import board  # noqa: E402  (after the simulated machine is in place)
from mixfw import assemble  # noqa: E402

STEP_NAMES = ["x", "y", "z"] + ["e%d" % i for i in range(6)]


def printer():
    simmachine.attach_world(board.PINS, STEP_NAMES)
    return assemble.build(files_root=None)
