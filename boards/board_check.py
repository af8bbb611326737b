# Bench check of a connected board, run on it with `mpremote run` (the host pushes
# the board's board.py first: `make board-check BOARD=... PORT=...`):
#   1. every STEP/DIR pin of the map is toggled a few times and read back, so a pin
#      shorted to a rail or to its neighbour shows up as "stuck";
#   2. a machine.Timer at the board's tick rate (hard on rp2) runs a minimal viper
#      callback for about a second: the achieved rate and the longest gap between
#      two calls, measured with time.ticks_us;
#   3. if the firmware is on the board, one call of its step loop is timed.
# It prints one JSON line. Motors stay unpowered: every ENABLE is set to "disabled"
# before a STEP pin moves, and heaters and fan are never touched.
import sys
import json
import time
import machine
import micropython
from micropython import const
from array import array
import board

TOGGLES = 4
MEASURE_MS = 1000
STEP_CALLS = 2000
_TICKS_MASK = const(0x3FFFFFFF)  # ticks_us wraps at 2**30 on the chips

# stats[0]: calls, [1]: ticks_us of the latest call, [2]: longest gap in us
stats = array("i", [0, 0, 0])
_ticks_us = time.ticks_us


@micropython.viper
def _count(_timer):
    p = ptr32(stats)  # noqa: F821 (viper built-in)
    now = int(_ticks_us())
    if p[0] > 0:
        gap = (now - p[1]) & _TICKS_MASK
        if gap > p[2]:
            p[2] = gap
    p[1] = now
    p[0] = p[0] + 1


@micropython.viper
def _empty(_timer):
    pass


def motor_names(settings):
    return ["x", "y", "z"] + ["e%d" % i for i in range(settings["drives"])]


def disable_drivers(pins, settings):
    off = 1 if settings["enable_active_low"] else 0
    for name in motor_names(settings):
        machine.Pin(pins[name + "_enable"], machine.Pin.OUT, value=off)


def toggle_step_dir(pins, settings):
    """Toggle each STEP/DIR pin; the keys whose pad did not follow the output."""
    stuck = []
    count = 0
    for name in motor_names(settings):
        for key in (name + "_step", name + "_dir"):
            pin = machine.Pin(pins[key], machine.Pin.OUT, value=0)
            ok = True
            for _ in range(TOGGLES):
                for level in (1, 0):
                    pin.value(level)
                    if pin.value() != level:
                        ok = False
            count += 1
            if not ok:
                stuck.append(key)
    return count, stuck


def make_timer(chip, freq, callback):
    if chip == "esp32":  # ESP32 timers have no hard callbacks
        return machine.Timer(0, mode=machine.Timer.PERIODIC, freq=freq, callback=callback)
    return machine.Timer(-1, mode=machine.Timer.PERIODIC, freq=freq, callback=callback,
                         hard=True)


def timer_rate(chip, tick_us):
    """(achieved calls per second, longest gap between calls in us)."""
    stats[0] = stats[1] = stats[2] = 0
    timer = make_timer(chip, 1000000 // tick_us, _count)
    try:
        time.sleep_ms(20)  # let the first calls settle
        calls0 = stats[0]
        t0 = time.ticks_us()
        time.sleep_ms(MEASURE_MS)
        calls1 = stats[0]
        t1 = time.ticks_us()
    finally:
        timer.deinit()
    elapsed_us = time.ticks_diff(t1, t0)
    return (calls1 - calls0) * 1000000 // max(1, elapsed_us), stats[2]


def call_cost_us(fn, calls):
    t0 = time.ticks_us()
    for _ in range(calls):
        fn(None)
    return time.ticks_diff(time.ticks_us(), t0) / calls


def step_call_us():
    """(cost of one idle step-loop call in us, cost of an empty viper call), or an
    error text if the firmware isn't on the board."""
    try:
        from mixfw import assemble
        printer = assemble.build(files_root=None)
    except Exception as e:  # report, don't fail: the pin and timer checks still count
        return None, None, "firmware not importable: %r" % (e,)
    return call_cost_us(printer.irq, STEP_CALLS), call_cost_us(_empty, STEP_CALLS), None


def run():
    settings = board.SETTINGS
    chip = settings.get("chip", "sim")
    tick_us = settings["tick_us"]
    errors = []
    report = {
        "board": board.NAME, "chip": chip, "platform": sys.platform,
        "version": list(sys.implementation.version[:3]),
        "mpy": getattr(sys.implementation, "_mpy", None),
        "tick_us": tick_us, "target_hz": 1000000 // tick_us,
    }
    disable_drivers(board.PINS, settings)
    report["pins_toggled"], report["stuck"] = toggle_step_dir(board.PINS, settings)
    try:
        report["achieved_hz"], report["max_gap_us"] = timer_rate(chip, tick_us)
    except (TypeError, ValueError) as e:  # e.g. hard=True before MicroPython 1.26
        report["achieved_hz"] = report["max_gap_us"] = None
        errors.append("timer: %r" % (e,))
    report["step_call_us"], report["empty_call_us"], err = step_call_us()
    if err:
        errors.append(err)
    disable_drivers(board.PINS, settings)
    report["errors"] = errors
    print(json.dumps(report))
    return report


if __name__ == "__main__":
    run()
