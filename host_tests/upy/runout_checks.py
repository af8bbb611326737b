# Whether a runout check takes anything from the heap: reading an input that reads
# present, counting reads of "gone", marking the drive out, waiting for it to feed and
# starting its change (Printer.pending). Prints the pending change's drive and, per
# check, whether it allocated.
import json

from heap_probe import allocates
import simbuild
import simmachine
import board
from mixfw.stepper import S_DRIVE_POS

printer = simbuild.printer()
watcher = printer.runout
gone = 1 if printer.settings["runout_active_high"] else 0


def check(a, b):
    watcher.check(0)


took = [allocates(check, 0, 0) for _ in range(3)]  # every input reads present
simmachine.set_input(board.PINS["e2_runout"], gone)
took += [allocates(check, 0, 0) for _ in range(8)]  # counted, then out, not fed
printer.mem[S_DRIVE_POS + 2] += 1  # drive 2 feeds
took.append(allocates(check, 0, 0))
print(json.dumps([printer.pending is watcher.change, watcher.drive, took]))
