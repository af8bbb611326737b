# The simulated chip's PIO, for step_backend "pio": a state machine running mixstep's
# one program (mixfw/pio.py), which outputs one word of pin levels per tick. The
# program text is not interpreted; its behaviour is: each word comes out when the
# previous one has had its tick, or when it arrives if the FIFO ran empty.
import simmachine


class PIO:
    IN_LOW = 0
    IN_HIGH = 1
    OUT_LOW = 2
    OUT_HIGH = 3
    SHIFT_LEFT = 0
    SHIFT_RIGHT = 1
    JOIN_NONE = 0
    JOIN_TX = 1
    JOIN_RX = 2


def asm_pio(**options):
    def assemble(program):
        return options
    return assemble


class StateMachine:
    def __init__(self, sm_id, program, freq, out_base):
        cycles_per_word = 20  # mixfw/pio.py: pull, then out with 18 cycles of delay
        simmachine.attach_pio(out_base.gpio, len(program["out_init"]),
                              cycles_per_word * 1000000 // freq)
        self.put = simmachine.pio_put

    def active(self, on=None):
        return 1
