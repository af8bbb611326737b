# For each (steps/mm, position in nm) on stdin (JSON): the position's step by
# scaled_round and by the full product, and the step's position back both ways.
import json
import sys

from mixfw.filament import NM_PER_MM, SPM_SCALE, div_round, scaled_round, spm_fixed, steps_per_nm

out = []
for spm, x in json.loads(sys.stdin.read()):
    p, q = steps_per_nm(spm)
    # Position to step (p/q) and step to position (q/p), against the product itself.
    out.append([scaled_round(x, p, q), div_round(x * spm_fixed(spm), NM_PER_MM * SPM_SCALE),
                scaled_round(x, q, p), div_round(x * NM_PER_MM * SPM_SCALE, spm_fixed(spm))])
print(json.dumps(out))
