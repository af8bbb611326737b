# cmd_motion.xyz_targets for each case on stdin (JSON: the G1 line, the position in nm,
# relative, the travel or null, the steps the queue is at or null): its verdict, the
# target in nm and the steps (X Y Z, then E's nm).
import json
import sys
from array import array

from mixfw.cmd_motion import MOVE_BITS, SPM_WORDS, xyz_targets
from mixfw.gcode import Parser
from mixfw.filament import spm_digits
from mixfw.ramp import array_offsets

p = Parser()
spm = array("i", bytes(4 * SPM_WORDS))
for i, s in enumerate((80.0, 93.71234, 400.0)):
    spm_digits(s, spm, 3 * i)
steps = array("i", bytes(4 * 5))
out = []
for text, pos, relative, travel, at in json.loads(sys.stdin.read()):
    b = text.encode()
    line = p.parse(b, len(b))
    target = array("i", bytes(12))
    off = array("i", bytes(12))
    travel_nm = array("i", travel) if travel else off
    # spm's last five words: where the line's words, the offsets, the steps and the
    # travel are.
    array_offsets(spm, SPM_WORDS - 5, (line.mant, line.decimals, off, steps, travel_nm))
    # The word before them: the modes, relative (1) and soft limits (2).
    spm[SPM_WORDS - 6] = (1 if relative else 0) | (2 if travel else 0)
    got = xyz_targets(spm, line.present & MOVE_BITS, array("i", pos), target, at)
    out.append([got, list(target), list(steps)])
print(json.dumps(out))
