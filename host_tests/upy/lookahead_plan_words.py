# lookahead.plan_words for each case on stdin (JSON: the planner's six floats as
# float32 bits, n, entry_v2): prints the block's planning words (lookahead.L_*) of each.
import json
import sys
from array import array

from uctypes import addressof

from mixfw import lookahead as la
from mixfw.ramp import array_offsets

lk = array("i", bytes(4 * la.L_WORDS))
W = la.W_WORDS
w = array("i", bytes(4 * W))
out = []
for bits, n, entry_v2 in json.loads(sys.stdin.read()):
    f = array("f", bytes(array("I", bits)))
    # The io array's last seven words: where lk and the floats are (and the step
    # loop's words, which only recalculate reads), the slot, n, entry_v2, no rate cap.
    array_offsets(w, W - 7, (lk, f))
    w[W - 4] = 0
    w[W - 3] = n
    w[W - 2] = entry_v2
    w[W - 1] = 0
    la.plan_words(addressof(w) >> 2)  # the array as its address over 4
    out.append(list(lk))
print(json.dumps(out))
