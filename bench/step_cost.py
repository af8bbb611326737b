# Cost of one step-loop call on the MicroPython unix port, for a tick in which X, Y, Z
# and E all step with six mixing drives active and the mixer choosing; also an idle
# tick (no step due). Each is given as a ratio to an empty viper function with the
# same arguments, called the same way in the same run. The step loop writes the pins
# as on a chip (pin_writer "registers" of an RP2040: set/clear registers through
# ptr32, here the simulated chip's register bank in RAM). Beside it: the Pin.value
# path, whose cost is mostly the simulated chip recording every edge. (The step loop
# has no bytecode build since it reads its records through pointers of its own:
# pointer arithmetic is viper's alone.)
#   MICROPYPATH=firmware:boards/sim micropython bench/step_cost.py
import sys
import json
import time
import micropython
import simmachine

sys.modules["machine"] = simmachine
import board
from mixfw import assemble
from mixfw import stepper as st

CALLS = 200000
REPEATS = 5


@micropython.viper
def empty(io) -> int:
    return 0


def time_calls(fn, io):
    simmachine.flush()
    i = 0
    t0 = time.ticks_us()
    while i < CALLS:
        fn(io)
        i += 1
    return time.ticks_diff(time.ticks_us(), t0) / CALLS


def stepping_printer(settings, registers=False):
    if registers:
        settings = dict(settings, pin_writer="registers", chip="rp2040")
    printer = assemble.build(assemble.Config(settings, None), files_root=None)
    # The register writer passes the bank, not a function, as `out`.
    printer.out = printer.pins.registers[0] if registers else printer.pins.out
    mem = printer.mem
    mem[st.S_PULSE_TICKS] = 0  # STEP stays high: every call is a full stepping tick
    b = st.BLOCK_BASE
    n = 1 << 29
    mem[b + st.B_N] = n
    for i in range(4):
        mem[b + st.B_STEPS + i] = n
    mem[b + st.B_RATE_INIT] = mem[b + st.B_RATE_NOM] = mem[b + st.B_RATE_FINAL] = st.ONE
    mem[b + st.B_ACCEL_UNTIL] = 0
    mem[b + st.B_DECEL_AFTER] = n
    mem[b + st.B_MIX] = 7
    for i in range(6):
        mem[b + st.B_MIX + 1 + i] = 1 + i  # six drives, unequal, all active
    mem[st.S_HEAD] = 1
    return printer


def idle_printer(settings):
    printer = stepping_printer(settings)
    b = st.BLOCK_BASE
    mem = printer.mem
    mem[b + st.B_RATE_INIT] = mem[b + st.B_RATE_NOM] = mem[b + st.B_RATE_FINAL] = 1
    return printer


def main_bench():
    names = ["x", "y", "z"] + ["e%d" % i for i in range(6)]
    simmachine.attach_world(board.PINS, names)
    settings = board.SETTINGS
    simmachine.now_us = 1  # past #0, so only real level changes are recorded
    reg = stepping_printer(settings, registers=True)
    idle = idle_printer(settings)
    cases = [
        ("empty_viper_us", empty, reg),
        ("step_tick_us", st.tick, reg),
        ("step_tick_pin_us", st.tick, stepping_printer(settings)),
        ("idle_tick_us", st.tick, idle),
    ]
    # Rounds over every case, keeping each one's best: a slow spell from other
    # processes then hits a case in one round, not the reference in all of them.
    res = {}
    for _ in range(REPEATS):
        for case in cases:
            name, fn, printer = case[:3]
            us = time_calls(fn, (printer.mem, printer.out, printer.pins.endstops))
            res[name] = min(us, res.get(name, us))
    e = res["empty_viper_us"]
    res["step_loop_ratio"] = res["step_tick_us"] / e
    res["idle_tick_ratio"] = res["idle_tick_us"] / e
    res["step_loop_pin_ratio"] = res["step_tick_pin_us"] / e
    print(json.dumps(res))


main_bench()
