# The planner with no step loop, for measuring and checking what it plans: its wait
# hook retires queued blocks itself, so no time passes and nothing steps.
#   retire_one: one block per wait, so the ring stays full and every new block is
#               planned against a full look-ahead queue, as while printing;
#   retire_all: every queued block at once, the cheapest look-ahead.
#   make_room:  retire_one's work as a function a bench calls itself between lines,
#               so that the planner finds room and never waits: on a board the step
#               path retires blocks, and the hook's calls (the planner's wait method,
#               then this closure) are not planning. It does what the step path does
#               for a block besides stepping it: it works out its ramp schedule.
# Homing ends at once: every endstop is hit as the block is retired.
from mixfw import stepper as st

# The words as constants, which the compiler folds: a closure over more than five
# names allocates its cells' list at every call on MicroPython (the waits run once a
# line), and a multi-block allocation on a chip's fragmented heap can cost hundreds of
# microseconds; module attributes would be lookups by name. Copies of stepper.py's
# layout, which host_tests/test_layouts.py checks.
_S_HEAD = const(0)
_S_TAIL = const(1)
_S_ACTIVE = const(2)
_S_HOME_STOP = const(27)
_S_QUEUE = const(26)
_BLOCK_BASE = const(123)
_B_WORDS = const(24)
schedule = st.schedule
_RAMP_IO = st.ramp_scratch()


@micropython.viper
def make_room(mem_buf, full: int):
    """Retire the oldest block if `full` or more are queued (full = queue - 1: the
    ring is full, and retire_one's wait would be called)."""
    mem = ptr32(mem_buf)
    q = mem[_S_QUEUE]
    head = mem[_S_HEAD]
    tail = mem[_S_TAIL]
    count = head - tail
    if count < 0:
        count += q
    if count and count >= full:
        # The step path's work on the block: its schedule, as it starts.
        schedule(mem_buf, _BLOCK_BASE + tail * _B_WORDS, _RAMP_IO)
        tail += 1
        mem[_S_TAIL] = 0 if tail >= q else tail
    mem[_S_ACTIVE] = 0
    mem[_S_HOME_STOP] = 7


def retire_one(mem, queue_blocks):
    def wait():
        make_room(mem, 1)

    return wait


def retire_all(mem, queue_blocks):
    def wait():
        # Each block's schedule, as the step path works it out at its start.
        while mem[_S_TAIL] != mem[_S_HEAD]:
            make_room(mem, 1)
        mem[_S_HOME_STOP] = 7

    return wait
