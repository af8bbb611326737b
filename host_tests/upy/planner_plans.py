# Runs the lines on stdin (JSON) on the simulated printer, the step loop taking a block
# only when the planner waits for room. For each line that queued a block: the blocks
# waiting before it, its nominal V2, its nominal rate and its acceleration (lookahead's
# L_NOMINAL, L_RATE_NOM, L_ACC).
import json
import sys

import simbuild
from mixfw import lookahead
from mixfw import stepper as st
from mixfw.planner import waiting_blocks

printer = simbuild.printer()
pl = printer.planner
mem = printer.mem
run = printer.run_line
parse = printer.parser.parse
plans = []


def take_one():
    # The step loop takes a block only when the planner waits for room: so the queue
    # fills up from empty, one more block waiting with each line.
    t = mem[st.S_TAIL]
    if t != mem[st.S_HEAD]:
        mem[st.S_TAIL] = t + 1 if t + 1 < pl.queue else 0
    mem[st.S_ACTIVE] = 0


pl.idle = take_one
for text in json.loads(sys.stdin.read()):
    waiting = waiting_blocks(mem)
    head = mem[st.S_HEAD]
    run(parse(text.encode(), len(text)))
    if mem[st.S_HEAD] != head:
        at = head * lookahead.L_WORDS
        plans.append([waiting, pl.lk[at + lookahead.L_NOMINAL],
                      pl.lk[at + lookahead.L_RATE_NOM], pl.lk[at + lookahead.L_ACC]])
print(json.dumps(plans))
