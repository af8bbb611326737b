# geometry.lengths and geometry.junction for runs of moves on stdin (JSON). Each run:
# the geometry floats (GF_*) as float32 bits, and its moves: [G_D words, flags]. For
# every move: the planner's first float (its length, F_MM) as bits, G_LEN, G_DIST,
# the junction's V2 and what lengths() returned.
import json
import sys
from array import array

from uctypes import addressof

from mixfw import geometry as ge
from mixfw.ramp import array_offsets


def run_geometry(runs):
    # Each run: the geometry floats as bits, and its moves: (G_D words, flags).
    g = array("i", bytes(4 * ge.G_WORDS))
    f = array("f", bytes(4))
    out = []
    for gf_bits, moves in runs:
        gf = array("f", bytes(array("I", gf_bits)))
        # g's last three words: where gf and f are, then the move's flags.
        array_offsets(g, ge.G_WORDS - 3, (gf, f))
        for d, flags in moves:
            for i in range(4):
                g[ge.G_D + i] = d[i]
            g[ge.G_WORDS - 1] = flags
            returned = ge.lengths(addressof(g) >> 2)  # the array as its address over 4
            v2 = ge.junction(addressof(g) >> 2)
            out.append([list(array("I", bytes(f))), g[ge.G_LEN], g[ge.G_DIST], v2, returned])
    return out


print(json.dumps(run_geometry(json.loads(sys.stdin.read()))))
