# Faults of the firmware itself, injected by sim-only commands so tests can show what
# the board does about them (mixfw/safety.py):
#   M7101        the step loop's timer callback raises from its next tick on, as a bug
#                in a hard interrupt would; MicroPython then disables the timer
#   M7102 S<ms>  the main loop hangs for S ms of simulated time without feeding the
#                watchdog, as an endless loop in a command would
#   M7103 S<us> P<n>  every P-th DMA IRQ (step_backend pio_dma) runs S us late, as
#                after a stretch with interrupts off (a flash write)
#   M7103 F<us>  every flash write (each write to a file, its close, a rename, a
#                removal: see Flash) holds every interrupt, timer callbacks and DMA
#                IRQs, for F us, as the rp2 port erases and programs with interrupts
#                off (45 ms typical, 400 ms at worst); the PIO and DMA go on with what
#                they hold. F0: none, the default
#   M7103 W1     one such flash write now, without waiting for the moves, as the
#                firmware must never do: the stall it causes
#   M7103 C<bytes>  the flash takes only this many bytes more (C-1: no limit, the
#                default); a write beyond raises OSError ENOSPC, as a full one does
#   M7104        stopping the step path raises from now on, as one that allocates does
#                on an exhausted heap: the step timer's deinit, a DMA feed's stop
#                (step_backend pio_dma), and a halt hook that runs first
import simmachine
from mixfw.config import FileStorage


def _raise(timer):
    raise RuntimeError("fault injected by M7101")


def _raise_stop():
    raise RuntimeError("fault injected by M7104")


class Flash(FileStorage):
    """The board's flash as the rp2 port writes it (see M7103 F): the firmware's
    FileStorage, which waits for the moves, and then each change holds the
    interrupts."""

    hold_us = 0
    room_bytes = -1  # what the flash takes before it is full (-1: no limit)

    def hold(self):
        if self.hold_us:
            simmachine.hold_irqs(self.hold_us)

    def open(self, path, mode):
        f = FileStorage.open(self, path, mode)
        return f if "r" in mode else _Written(f, self.hold, self)

    def rename(self, old, new):
        FileStorage.rename(self, old, new)
        self.hold()

    def remove(self, path):
        FileStorage.remove(self, path)
        self.hold()


class _Written:
    """A file open for writing on Flash: each write and the close program flash."""

    def __init__(self, f, hold, flash):
        self.f = f
        self.hold = hold
        self.flash = flash

    def write(self, data):
        room = self.flash.room_bytes
        if room >= 0:
            if len(data) > room:
                raise OSError(28)  # ENOSPC
            self.flash.room_bytes = room - len(data)
        n = self.f.write(data)
        self.hold()
        return n

    def close(self):
        self.f.close()
        self.hold()


class Faults:
    def __init__(self, printer, flash=None):
        self.printer = printer
        self.flash = flash or Flash()

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

    # M7103 [S<us> P<n>] [F<us>] [W1] [C<bytes>]: hold back every n-th DMA IRQ by S us
    # (S0: none); every flash write holds the interrupts F us; W1: one flash write
    # now; C: the bytes the flash still takes (-1: any). Simulation only. Example:
    # M7103 S3000 P5, M7103 F400000, M7103 C10000
    def m7103(self, line):
        if line.has("F"):
            self.flash.hold_us = line.int("F", lo=0, hi=1000000)
        if line.has("C"):
            self.flash.room_bytes = line.int("C", lo=-1, hi=1 << 30)
        if line.has("S") or line.has("P") or not (line.has("F") or line.has("W")
                                                  or line.has("C")):
            import rp2
            rp2.set_irq_delay(line.int("S", 0, lo=0, hi=1000000),
                              line.int("P", 1, lo=1, hi=1000))
        if line.int("W", 0, lo=0, hi=1):
            self.flash.hold()

    # M7104: make stopping the step path raise. Simulation only. Example: M7104
    def m7104(self, line):
        for t in simmachine._timers:
            t.deinit = _raise_stop
        if self.printer.feed is not None:
            self.printer.feed.stop = _raise_stop
        self.printer.on_halt.insert(0, _raise_stop)


def install(printer, flash=None):
    """flash: the Flash the configuration and files are written through."""
    f = Faults(printer, flash)
    printer.register("M7101", f.m7101)  # simulation: the step timer's callback raises
    printer.register("M7102", f.m7102)  # simulation: hang the main loop S<ms>
    printer.register("M7103", f.m7103)  # simulation: DMA IRQs S<us> late; flash writes F<us>
    printer.register("M7104", f.m7104)  # simulation: stopping the step path raises
    return f
