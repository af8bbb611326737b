# What keeps a board safe when the firmware itself goes wrong: a step loop that can't
# be timed properly (refused) or stopped (a hard timer callback that raised is disabled
# and never runs again), a main loop or an interrupt that hangs (the hardware watchdog
# resets the chip), and every way out of the main loop (heaters off first, then the
# step loop, drivers and fan).
#
# A reset does not leave every output off: the RP2040's and RP2350's pads come up with
# pull-downs, so an active-low driver ENABLE is active from power-on, and after every
# watchdog reset, until boot.py drives it inactive. An external pull-up on EN (10 kOhm
# to the driver's VIO) keeps the drivers off until then, on any chip. Heater and fan
# outputs come up low, which leaves their MOSFETs off.
import gc
import sys
import time
import micropython
from mixfw import stepper as st
from mixfw.printer import run_each


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
    """The chip's watchdog, fed from the main loop and every wait: a main loop (or an
    interrupt) stuck for timeout_ms resets the board. It can't be turned off once
    started, and options.py keeps watchdog_ms within what every chip takes."""
    wdt = machine.WDT(timeout=timeout_ms)
    feed = wdt.feed
    printer.add_background(lambda now_ms: feed())
    return wdt


# rp2 timer callbacks can be hard (run in the interrupt) only since MicroPython 1.26;
# a soft one waits for the interpreter and would make the step timing worthless.
_HARD_TIMER_SINCE = const((1, 26, 0))


def check_timer_support(chip, version):
    """Refuse to run the step loop on a MicroPython that can't time it properly."""
    if chip in ("rp2040", "rp2350") and tuple(version[:3]) < _HARD_TIMER_SINCE:
        raise RuntimeError("mixstep needs MicroPython %d.%d or newer on %s for a hard "
                           "machine.Timer; this is %d.%d.%d: flash a newer MicroPython"
                           % (_HARD_TIMER_SINCE[:2] + (chip,) + tuple(version[:3])))


def start_timer(machine, printer, tick_us):
    """The timer owns the step loop: hard on rp2; soft on ESP32, whose timers have no
    hard callbacks (docs/Step_Timing.md: the jitter that gives). Returns what stops it
    (deinit()): the timer, or the DMA feed that runs the step loop instead."""
    chip = printer.settings.get("chip", "sim")
    if printer.feed:
        printer.feed.start(printer.pins)  # the DMA IRQ runs the step loop: no timer
        return printer.feed
    check_timer_support(chip, sys.implementation.version)
    freq = 1000000 // tick_us
    if chip == "esp32":
        return machine.Timer(0, mode=machine.Timer.PERIODIC, freq=freq, callback=printer.irq)
    return machine.Timer(-1, mode=machine.Timer.PERIODIC, freq=freq, callback=printer.irq,
                         hard=True)


def all_off(printer, step_loop):
    """On any way out of the main loop: heaters off first, as stopping the step loop
    (step_loop.deinit(): a timer's, or a DMA feed's, which allocates) can raise; then
    the drivers and the fan. Each runs even if one before it raised; returns the first
    fault, or None."""
    fault = run_each(printer.heaters_off)

    def drivers_off():
        printer.pins.all_enabled(False)
        printer.motion.enabled = 0

    later = run_each((step_loop.deinit, drivers_off, lambda: printer.thermal.set_fan(0.0)))
    return fault or later


def serve(printer):
    """Serve the started printer (assemble.start) until every console closes or M997;
    everything off on any way out, then M997's reset into the REPL."""
    gc.collect()  # the boot's garbage, and on a board the code that built the printer
    # A host's 0x03 byte on the USB console is data, not Ctrl-C: it must not stop a
    # print (and leave the heaters as they were).
    micropython.kbd_intr(-1)
    try:
        printer.serve()
    finally:
        fault = all_off(printer, printer.step_loop)
        micropython.kbd_intr(3)
    if fault is not None:
        raise fault  # everything is off: now the fault may stop the firmware
    if printer.leaving == "M997" and printer.repl_flag:
        with open(printer.repl_flag, "w") as f:
            f.write("M997\n")
        import machine
        machine.reset()
    return printer
