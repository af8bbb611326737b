# Runs a G-code file on the simulated printer with edges recorded, and records for
# every block the step loop starts the record it runs (as the planner left it) and
# the time its velocity ramp begins. mixstep/steptiming.py compares the edges with the
# ideal trapezoid of each block. The timer callback is wrapped, so nothing in the
# firmware changes; the wrapper runs between ticks and allocates (no heap lock).
#   MICROPYPATH=firmware:boards/sim micropython boards/sim/step_times_sim.py GCODE EDGES BLOCKS
# BLOCKS gets one JSON line per block: ramp_origin_us, phase, flags, n, steps (X Y Z E),
# rate_init, rate_nom, rate_final, accel, accel_until, decel_after.
import sys
import json
import simmachine
import simtime
import simthermal

sys.modules["machine"] = simmachine
sys.modules["time"] = simtime
import board
from mixfw import assemble as firmware
from mixfw import safety
from mixfw import stepper as st
from mixfw.console import StreamConsole

RECORD_WORDS = (st.B_FLAGS, st.B_N, st.B_STEPS, st.B_STEPS + 1, st.B_STEPS + 2, st.B_STEPS + 3,
                st.B_RATE_INIT, st.B_RATE_NOM, st.B_RATE_FINAL, st.B_ACCEL,
                st.B_ACCEL_UNTIL, st.B_DECEL_AFTER)


class Replies:
    """The printer's answers: only errors are kept."""

    def __init__(self):
        self.errors = []

    def write(self, text):
        if text.startswith("Error:"):
            self.errors.append(text.strip())


def recording_irq(mem, out, endstops, tick_us, blocks):
    tick = st.tick
    io = (mem, out, endstops)

    def irq(_timer):
        was_active = mem[st.S_ACTIVE]
        tail = mem[st.S_TAIL]
        phase = mem[st.S_PHASE]
        dir_before = mem[st.S_DIR]
        tick(io)
        if was_active or (not mem[st.S_ACTIVE] and mem[st.S_TAIL] == tail):
            return  # no block started in this tick
        b = st.BLOCK_BASE + tail * st.B_WORDS
        # The ramp runs in the start tick unless DIR changed; then after the DIR
        # setup ticks. Its origin is one tick before the first ramp tick, where the
        # position was the carried phase.
        first_ramp_us = simmachine.now_us
        if mem[st.S_DIR] != dir_before:
            first_ramp_us += (mem[st.S_WAIT] + 1) * tick_us
        rec = [first_ramp_us - tick_us, phase] + [mem[b + w] for w in RECORD_WORDS]
        blocks.append(rec)

    return irq


def main():
    gcode_path, edges_path, blocks_path = sys.argv[1:4]
    names = ["x", "y", "z"] + ["e%d" % i for i in range(board.SETTINGS["drives"])]
    simmachine.attach_world(board.PINS, names)
    simmachine.record_to(edges_path)
    printer = firmware.build(files_root=None)
    simthermal.install(simmachine, board, printer)
    blocks = []
    pins = printer.pins
    out = pins.registers[0] if pins.registers else pins.out  # as build() passes it
    printer.irq = recording_irq(printer.mem, out, pins.endstops,
                                printer.settings["tick_us"], blocks)
    replies = Replies()
    console = StreamConsole(open(gcode_path, "rb"), replies, blocking=True)
    firmware.start([console], (), printer)
    safety.serve(printer)
    simmachine.close()
    with open(blocks_path, "w") as f:
        for rec in blocks:
            f.write(json.dumps(rec) + "\n")
    print(json.dumps({"blocks": len(blocks), "sim_us": simmachine.now_us,
                      "tick_us": printer.settings["tick_us"], "errors": replies.errors}))


main()
