# One block (stdin, JSON: n, r0, r_nom, r1, acc, phase) run through the DMA ring's
# batches twice, in lockstep: by the step loop, and by a copy of it compiled with no
# ramp tick passed over at once (_RAMP_SKIP_MAX 0). The record leaves its schedule to
# the step loop (F_SCHEDULE), as the look-ahead's do. Prints whether every batch's
# words were the same, and the steps, ticks, words and batches.
import json
import sys
from array import array

from mixfw import stepper as st
from step_timing_block import x_block

record = json.loads(sys.stdin.read())
src = open(st.__file__).read()
cut = src.replace("_RAMP_SKIP_MAX = const(1024)", "_RAMP_SKIP_MAX = const(0)")
assert cut != src
tick_by_tick = {"__name__": "tick_by_tick"}
exec(cut, tick_by_tick)


def printer():
    mem = x_block(*record)
    mem[st.S_DIR_TICKS] = 1
    mem[st.S_PIO] = 2
    mem[st.R_TC] = 80  # 10 us ticks of the PIO's 8 MHz
    mem[st.R_BATCH_TICKS] = 200
    mem[st.R_PULSE_CYC] = 16
    mem[st.R_LEVEL_BITS] = 9
    mem[st.BLOCK_BASE + st.B_FLAGS] = st.F_SCHEDULE
    return mem, array("i", bytes(4 * 400))


# In lockstep, batch by batch: a slow block is millions of ticks.
skipping = printer()
stepping = printer()
same = True
batches = words = 0
while skipping[0][st.S_BLOCKS_DONE] == 0 or batches < 2:
    got = []
    for (mem, ring), tick in ((skipping, st.tick), (stepping, tick_by_tick["tick"])):
        mem[st.R_W] = 0
        w = tick((mem, ring, None))
        got.append(ring[:w])
    words += len(got[0])
    batches += 1
    if got[0] != got[1] or batches > 100000:
        same = False
        break
mem = skipping[0]
print(json.dumps({"same": same, "steps": mem[st.S_POS + st.X], "ticks": mem[st.S_TICKS],
                  "words": words, "batches": batches}))
