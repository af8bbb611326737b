# The planner with no step loop, for measuring and checking what it plans: its wait
# hook retires queued blocks itself, so no time passes and nothing steps.
#   retire_one: one block per wait, so the ring stays full and every new block is
#               planned against a full look-ahead queue, as while printing;
#   retire_all: every queued block at once, the cheapest look-ahead.
# Homing ends at once: every endstop is hit as the block is retired.
from mixfw import stepper as st


def retire_one(mem, queue_blocks):
    def wait():
        if mem[st.S_TAIL] != mem[st.S_HEAD]:
            tail = mem[st.S_TAIL] + 1
            mem[st.S_TAIL] = 0 if tail >= queue_blocks else tail
        mem[st.S_ACTIVE] = 0
        mem[st.S_HOME_STOP] = 7

    return wait


def retire_all(mem, queue_blocks):
    def wait():
        mem[st.S_TAIL] = mem[st.S_HEAD]
        mem[st.S_ACTIVE] = 0
        mem[st.S_HOME_STOP] = 7

    return wait
