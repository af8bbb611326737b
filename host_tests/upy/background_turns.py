# How often a wait's turns run the background tasks, and each_turn's: a wait of 200
# turns of the simulated chip's idle (a virtual millisecond each), counted by one task
# of each kind added to the printer's own.
import json
import sys

import simtime

sys.modules["time"] = simtime
import simbuild  # noqa: E402

printer = simbuild.printer()
counts = {"background": 0, "each_turn": 0, "turns": 0}


def counter(kind):
    def fn(now_ms):
        counts[kind] += 1
    return fn


printer.add_background(counter("background"))
printer.add_background(counter("each_turn"), True)


def done():
    counts["turns"] += 1
    return counts["turns"] > 200


printer.wait_until(done)
print(json.dumps(counts))
