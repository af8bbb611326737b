# Whether the main loop's background tasks take anything from the heap between two
# control periods, five times.
import json

from heap_probe import allocates
import simbuild

printer = simbuild.printer()


def turn(a, b):
    printer._run_background()


turn(0, 0)  # the first control period
print(json.dumps([allocates(turn, 0, 0) for _ in range(5)]))
