# PIO step output for RP2040/RP2350 (step_backend "pio"). The timer interrupt only
# feeds a state machine's FIFO, one word per tick: the levels of the STEP/DIR pins,
# which must be one contiguous run of GPIOs from out_base. The state machine spends
# exactly one tick on each word, so edges come out on exact tick multiples, a fixed
# LATENCY_TICKS behind their ticks: interrupt jitter below that is absorbed, where
# register writes would pass it straight to the pins.
#
# A burst of words starts with LATENCY_TICKS words of the old levels and goes on while
# the step loop has work; when it goes idle the state machine stalls on an empty FIFO
# with the pins held. The next burst starts when its first word arrives, so the
# latency of the interrupt that opens a burst delays the whole burst (not its pulses).

_CYCLES_PER_TICK = const(20)  # the program below: pull (1) + out (1) + 18 delay
LATENCY_TICKS = const(4)  # a joined TX FIFO holds 8 words


def out_range(pin_map, names):
    """(first GPIO, count) of the STEP/DIR pins, refused unless they are contiguous."""
    gpios = sorted(pin_map[n + s] for n in names for s in ("_step", "_dir"))
    first = gpios[0]
    if gpios != list(range(first, first + len(gpios))):
        raise ValueError("step_backend pio needs the STEP/DIR pins on one run of GPIOs; "
                         "they are on %s" % gpios)
    return first, len(gpios)


def start(rp2, Pin, pin_map, names, tick_us, sm_id=0):
    """The state machine, running; its put() is what the step loop calls."""
    first, count = out_range(pin_map, names)

    @rp2.asm_pio(out_init=(rp2.PIO.OUT_LOW,) * count, out_shiftdir=rp2.PIO.SHIFT_RIGHT,
                 fifo_join=rp2.PIO.JOIN_TX)
    def step_levels():
        pull(block)  # noqa: F821 (PIO assembler names)
        out(pins, 32)[18]  # noqa: F821

    sm = rp2.StateMachine(sm_id, step_levels, freq=_CYCLES_PER_TICK * 1000000 // tick_us,
                          out_base=Pin(first))
    sm.active(1)
    return sm, first
