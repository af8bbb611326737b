"""A step loop's array holding one queued block of n lead-axis (X) steps with a
record's rates, and the phase it inherits, for the step timing scripts."""
from array import array

from mixfw import stepper as st


def x_block(n, r0, r_nom, r1, acc, phase):
    mem = array("i", bytes(4 * st.mem_words(2)))
    mem[st.S_QUEUE] = 2
    mem[st.S_PULSE_TICKS] = 1  # as on the simulated board: high one tick, low one tick
    mem[st.MASK_BASE + st.X] = 1
    b = st.BLOCK_BASE
    mem[b + st.B_N] = mem[b + st.B_STEPS + st.X] = n
    mem[b + st.B_RATE_INIT] = r0
    mem[b + st.B_RATE_NOM] = r_nom
    mem[b + st.B_RATE_FINAL] = r1
    mem[b + st.B_ACCEL] = acc
    mem[st.S_PHASE] = phase
    mem[st.S_HEAD] = 1
    return mem
