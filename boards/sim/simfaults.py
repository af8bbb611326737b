# Faults of the firmware itself, injected by sim-only commands so tests can show what
# the board does about them (mixfw/safety.py):
#   M7101        the step loop's timer callback raises from its next tick on, as a bug
#                in a hard interrupt would; MicroPython then disables the timer
#   M7102 S<ms>  the main loop hangs for S ms of simulated time without feeding the
#                watchdog, as an endless loop in a command would
#   M7103 S<us> P<n>  every P-th DMA IRQ (step_backend pio_dma) runs S us late, as
#                after a stretch with interrupts off (a flash write)
import simmachine


def _raise(timer):
    raise RuntimeError("fault injected by M7101")


class Faults:
    def __init__(self, printer):
        self.printer = printer

    # M7101: break the step loop's timer. Simulation only. Example: M7101
    def m7101(self, line):
        for t in simmachine._timers:
            t._cb = _raise

    # M7102 S<ms>: hang the main loop for S ms. Simulation only. Example: M7102 S5000
    def m7102(self, line):
        line.require("S")
        end_us = simmachine.now_us + line.int("S", lo=0, hi=600000) * 1000
        while simmachine.now_us < end_us:
            simmachine.idle()

    # M7103 S<us> P<n>: hold back every n-th DMA IRQ by S us (S0: none). Simulation
    # only. Example: M7103 S3000 P5
    def m7103(self, line):
        import rp2
        rp2.set_irq_delay(line.int("S", 0, lo=0, hi=1000000), line.int("P", 1, lo=1, hi=1000))


def install(printer):
    f = Faults(printer)
    printer.register("M7101", f.m7101)  # simulation: the step timer's callback raises
    printer.register("M7102", f.m7102)  # simulation: hang the main loop S<ms>
    printer.register("M7103", f.m7103)  # simulation: DMA IRQs S<us> late, every P-th
    return f
