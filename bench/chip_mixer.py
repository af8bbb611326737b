# The chip bench's mixer run on the emulated Pico: bench/chip_rows.py puts it on the
# flash compiled as chip_mixer.mpy, with a main.py that imports it; the firmware's
# modules are the board's mixfw/*.mpy. It answers on the USB console, one line each,
# then `ok`:
#   M115     ok (the harness asks it once it has booted)
#   mixer    microseconds per E step of E-only blocks run by the step loop
#            (stepper.run_mix: a call of stepper.tick per step from a Python loop,
#            six drives of unequal weights), for each kind of pick: `bench:{json}`.
import sys
import gc
import json
import time

from mixfw import stepper

WEIGHTS = (1, 2, 3, 4, 5, 6)
STEPS = 2000


def us_per_step(moves, before=()):
    """Microseconds per step of the walk `moves` after the walk `before`, both from
    a fresh start: the two timed apart, the difference over moves' steps."""
    gc.collect()
    t0 = time.ticks_us()
    stepper.run_mix(WEIGHTS, before + moves)
    whole = time.ticks_diff(time.ticks_us(), t0)
    first = 0
    if before:
        gc.collect()
        t0 = time.ticks_us()
        stepper.run_mix(WEIGHTS, before)
        first = time.ticks_diff(time.ticks_us(), t0)
    return (whole - first) / sum(abs(m) for m in moves)


def mixer():
    return {
        "forward_new_us": us_per_step((STEPS,)),
        "back_new_us": us_per_step((-STEPS,)),
        # Back over steps just made forward, and forward over steps just made back.
        "back_known_us": us_per_step((-STEPS,), (STEPS,)),
        "forward_known_us": us_per_step((STEPS,), (-STEPS,)),
    }


def serve():
    while True:
        words = sys.stdin.readline().split()
        if words and words[0] == "mixer":
            print("bench:", end="")
            json.dump(mixer(), sys.stdout)
            print()
        print("ok")


serve()
