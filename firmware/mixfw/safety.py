# What keeps a board safe when the firmware itself goes wrong: a step loop that stopped
# (a hard timer callback that raised is disabled and never runs again), a main loop that
# hangs (the hardware watchdog resets the chip), and every way out of the main loop
# (heaters and drivers off).
import time
from mixfw import stepper as st


class StepWatch:
    """Halts the printer when the step loop's tick counter stops advancing. Runs from
    the main loop and every wait (Printer.add_background)."""

    def __init__(self, printer, mem, stall_ms):
        self.printer = printer
        self.mem = mem
        self.stall_ms = stall_ms
        self.ticks = mem[st.S_TICKS]
        self.since_ms = time.ticks_ms()

    def __call__(self, now_ms):
        ticks = self.mem[st.S_TICKS]
        if ticks != self.ticks:
            self.ticks = ticks
            self.since_ms = now_ms
        elif (time.ticks_diff(now_ms, self.since_ms) >= self.stall_ms
              and not self.printer.halted):
            # Reported once per halt: M999 clears it, and a still-dead timer halts again.
            self.since_ms = now_ms
            self.printer.halt("step timer stopped (no tick for %d ms); restart the board"
                              % self.stall_ms)


def start_watchdog(machine, printer, timeout_ms):
    """The chip's watchdog, fed from the main loop and every wait: a main loop stuck
    for timeout_ms resets the board, which leaves every output pin off. 0: none."""
    if not timeout_ms:
        return None
    wdt = machine.WDT(timeout=timeout_ms)
    feed = wdt.feed
    printer.add_background(lambda now_ms: feed())
    return wdt


def all_off(printer):
    """Heaters, fan and drivers off: on any way out of the main loop."""
    printer.thermal.all_off()
    printer.thermal.set_fan(0.0)
    printer.pins.all_enabled(False)
    printer.motion.enabled = 0
