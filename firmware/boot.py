# Runs at every boot and reset before main.py: every stepper driver off, before
# anything else. The RP2040's and RP2350's pads come up pulled low, which enables a
# driver whose ENABLE is active low from power-on until a pin drives it, after a
# watchdog reset too, and in the REPL that M997 leaves (main.py then starts nothing).
# An external pull-up on EN keeps the drivers off until this runs; pins.py drives the
# pins again when the machine is assembled. Nothing but machine, time and board is
# imported first: any other module could fail or take time with the drivers on. Then
# the chip's clock, as the board asks.
import machine
import time
import board


def _drivers_off():
    off = 1 if board.SETTINGS["enable_active_low"] else 0
    for name, gpio in board.PINS.items():
        if name.endswith("_enable"):
            machine.Pin(gpio, machine.Pin.OUT, value=off)


def _clock():
    # The board's clock_hz, before any peripheral takes its dividers from the clock (the
    # heaters' PWM, the step path's PIO, a UART). The RP2040 is certified at 200 MHz
    # with its core regulator at 1.15 V or more (pico-sdk 2.1.1; Klipper runs it so):
    # the regulator first, as the SDK does, then a millisecond for it to settle. A
    # clock refused leaves the one the chip booted with, which the firmware then reads.
    hz = board.SETTINGS.get("clock_hz", 0)
    if not hz or hz == machine.freq():
        return
    if board.SETTINGS["chip"] == "rp2040" and hz > 133_000_000:
        vreg = machine.mem32[0x40064000]  # VREG: VSEL in bits 7:4, 12 for 1.15 V
        if (vreg >> 4) & 15 < 12:
            machine.mem32[0x40064000] = vreg & ~0xF0 | 12 << 4
            time.sleep_ms(1)
    try:
        machine.freq(hz)
    except ValueError as err:
        print("clock_hz %d refused (%s): running at %d Hz" % (hz, err, machine.freq()))


_drivers_off()
_clock()
del _drivers_off, _clock  # boot.py's names would stay in main.py's globals
