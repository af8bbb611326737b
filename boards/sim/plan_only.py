# The planner with no step loop, for measuring and checking what it plans: its wait
# hook retires queued blocks itself, so no time passes and nothing steps.
#   retire_one: one block per wait, so the ring stays full and every new block is
#               planned against a full look-ahead queue, as while printing;
#   retire_all: every queued block at once, the cheapest look-ahead.
# Homing ends at once: every endstop is hit as the block is retired.
from mixfw import stepper as st


def retire_one(mem, queue_blocks):
    # The words in locals: module attributes are lookups by name, which would charge a
    # bench with tens of microseconds a line of what no firmware does.
    tail_at, head_at, active_at, stop_at = st.S_TAIL, st.S_HEAD, st.S_ACTIVE, st.S_HOME_STOP

    def wait():
        tail = mem[tail_at]
        if tail != mem[head_at]:
            tail += 1
            mem[tail_at] = 0 if tail >= queue_blocks else tail
        mem[active_at] = 0
        mem[stop_at] = 7

    return wait


def retire_all(mem, queue_blocks):
    def wait():
        mem[st.S_TAIL] = mem[st.S_HEAD]
        mem[st.S_ACTIVE] = 0
        mem[st.S_HOME_STOP] = 7

    return wait
