"""G2/G3 segments as Motion hands them to its queue, with a recorder in place of the
planner. stdin: JSON [lines, heap] (G-code texts; heap: also count the bytes each line
takes from the heap, collection off). Prints JSON: per line [error text or null,
[[x_steps, y_steps, z_steps, e_nm], ...] each queued move's end and filament (or
the count of moves with heap), bytes
taken, logical X Y Z nm after it, logical E nm]."""
import gc
import json
import sys

import simbuild
from mixfw.gcode import GcodeError

lines, heap = json.loads(sys.stdin.read())
printer = simbuild.printer()
motion = printer.motion


class Recorder:
    """Takes the planner's place: keeps each move's end steps and filament."""

    def __init__(self, real):
        self.position_steps = real.position_steps
        self.mix_id = real.mix_id
        self.moves = []
        self.count = 0

    def add_move(self, steps, feed_mm_s, dir_masks=None, e_nm=0, mix=None, replay=False):
        p = self.position_steps
        for i in range(3):
            p[i] = steps[i]
        if heap:  # nothing that grows with the segments while the heap is watched
            self.count += 1
        else:
            self.moves.append([p[0], p[1], p[2], e_nm])


recorder = Recorder(motion.queue)
motion.queue = recorder
out = []
for text in lines:
    raw = text.encode()
    line = printer.parser.parse(raw, len(raw))
    recorder.moves = []
    recorder.count = 0
    error = None
    used = 0
    gc.collect()
    if heap:
        gc.disable()
    before = gc.mem_alloc()
    try:
        printer.run_line(line)
    except GcodeError as e:
        error = str(e)
    used = gc.mem_alloc() - before
    gc.enable()
    out.append([error, recorder.moves or recorder.count, used, list(motion.pos_nm), motion.e_nm])
print(json.dumps(out))
