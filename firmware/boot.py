# Runs at every boot and reset before main.py: every stepper driver off, before
# anything else. The RP2040's and RP2350's pads come up pulled low, which enables a
# driver whose ENABLE is active low from power-on until a pin drives it, after a
# watchdog reset too, and in the REPL that M997 leaves (main.py then starts nothing).
# An external pull-up on EN keeps the drivers off until this runs; pins.py drives the
# pins again when the machine is assembled. Nothing but machine and board is imported
# first: any other module could fail or take time with the drivers on.
import machine
import board


def _drivers_off():
    off = 1 if board.SETTINGS["enable_active_low"] else 0
    for name, gpio in board.PINS.items():
        if name.endswith("_enable"):
            machine.Pin(gpio, machine.Pin.OUT, value=off)


_drivers_off()
del _drivers_off  # boot.py's names would stay in main.py's globals
