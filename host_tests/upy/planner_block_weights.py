# planner.block_weights for each drive's step counts on stdin (JSON): whether the
# weights fit, the steps it read and the weights it set.
import json
import sys

from uctypes import addressof

from planner_sim import pl, planner

out = []
for counts in json.loads(sys.stdin.read()):
    # The planner's six drives: counts of fewer drives with 0 for the rest.
    n = len(counts)
    for i in range(pl.drives):
        pl._counts[i] = counts[i] if i < n else 0
        pl._weights[i] = 7
        pl._given[i] = 7
    fits = planner.block_weights(addressof(pl._abs_steps) >> 2)  # its address over 4
    out.append([fits, list(pl._given)[:n], list(pl._weights)[:n]])
print(json.dumps(out))
