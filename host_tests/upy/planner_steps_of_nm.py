# X's step at each position, by xyz_targets with no word named (X stays where it is:
# at the position), and by scaled_round; stdin (JSON): [steps/mm, [positions in nm]]...
import json
import sys
from array import array

from mixfw.cmd_motion import SPM_WORDS, xyz_targets
from mixfw.filament import scaled_round, spm_digits, steps_per_nm
from mixfw.ramp import array_offsets

nm = array("i", bytes(12))
zeros = array("i", bytes(12))
steps = array("i", bytes(4 * 5))
out = []
for s, xs in json.loads(sys.stdin.read()):
    spm = array("i", bytes(4 * SPM_WORDS))  # and no step kept
    spm_digits(s, spm, 0)
    # Its last five words: where the line's words, the offsets, the steps and the
    # travel are (no word named here: only the offsets and the steps are read).
    array_offsets(spm, SPM_WORDS - 3, (zeros, steps))
    p, q = steps_per_nm(s)
    got = []
    for x in xs:
        nm[0] = x
        xyz_targets(spm, 0, nm, array("i", bytes(12)), None)
        got.append(steps[0])
    out.append([got, [scaled_round(x, p, q) for x in xs]])
print(json.dumps(out))
