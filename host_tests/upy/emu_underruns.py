# The planner's underrun count, where the step loop runs dry between moves and around
# waits, and M122's report of it: the counts and what M122 said.
import json

import simbuild
from mixfw import stepper as st

printer = simbuild.printer()
pl = printer.planner
mem = printer.mem
said = []


class Console:
    def write(self, text):
        said.append(text)


printer.current = printer.add_channel(Console())


def run(text):
    printer.run_line(printer.parser.parse(text, len(text)))


def step_loop_runs_dry():
    mem[st.S_TAIL] = mem[st.S_HEAD]
    mem[st.S_ACTIVE] = 0


run(b"G1 X10 F3000")
run(b"G1 X20")           # queued behind the first: no underrun
step_loop_runs_dry()
run(b"G1 X30")           # the queue ran dry between two moves: one
counts = [pl.underruns]
pl.idle = step_loop_runs_dry  # waits end at once
run(b"G4 P10")           # a dwell is a wait: the queue may run dry before and after it
run(b"G1 X40")
run(b"M400")
run(b"G1 X50")
counts.append(pl.underruns)
run(b"M122")
print(json.dumps({"counts": counts, "said": said}))
