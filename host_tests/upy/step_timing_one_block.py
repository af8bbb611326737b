# One block (stdin, JSON: n, r0, r_nom, r1, acc, phase) run by the step loop with the
# schedule the planner gives its record: the ticks (from 1, the first ramp tick) at
# which the lead axis (X) stepped.
import json
import sys
from array import array

from mixfw import stepper as st
from mixfw.planner import ramp_ticks
from step_timing_block import x_block

n, r0, r_nom, r1, acc, phase = json.loads(sys.stdin.read())
mem = x_block(n, r0, r_nom, r1, acc, phase)
regs = array("i", bytes(12))  # scratch set/clear registers at words 1, 2
mem[st.S_REG_SET] = 1
mem[st.S_REG_CLR] = 2
b = st.BLOCK_BASE
mem[b + st.B_ACCEL_UNTIL], mem[b + st.B_DECEL_AFTER], mem[b + st.B_RATE_DECEL] = \
    ramp_ticks(n, r0, r_nom, r1, acc)
ticks = []
t = 0
io = (mem, regs, None)
while mem[st.S_BLOCKS_DONE] == 0:
    t += 1
    if st.tick(io):
        ticks.append(t)
print(json.dumps(ticks))
