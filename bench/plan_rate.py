# Planner throughput on the MicroPython unix port: every line of a G-code file goes
# through the firmware's parser and command table into the planner, with no stepping.
# The step loop is replaced by the planner's wait hook, which retires blocks itself:
#   full:  one block per wait, so the ring stays full and every new block is planned
#          against a full look-ahead queue, as while printing (the default);
#   empty: every queued block at once (S_TAIL = S_HEAD), the cheapest look-ahead.
# Heating waits (M109, M190, M116) are skipped and cold extrusion is allowed, as no
# time passes. Prints one JSON line: lines, G0/G1 lines, seconds, G1 lines per second.
#   MICROPYPATH=firmware:boards/sim micropython -X heapsize=2M bench/plan_rate.py FILE [full|empty]
import sys
import json
import time
import simmachine

sys.modules["machine"] = simmachine
import board
import main
from mixfw import stepper as st

SKIPPED = (b"M109", b"M190", b"M116")


def retire_one(mem, queue_blocks):
    def wait():
        if mem[st.S_TAIL] != mem[st.S_HEAD]:
            tail = mem[st.S_TAIL] + 1
            mem[st.S_TAIL] = 0 if tail >= queue_blocks else tail
        mem[st.S_ACTIVE] = 0
        mem[st.S_HOME_STOP] = 7  # homing: every endstop is hit at once

    return wait


def retire_all(mem, queue_blocks):
    def wait():
        mem[st.S_TAIL] = mem[st.S_HEAD]
        mem[st.S_ACTIVE] = 0
        mem[st.S_HOME_STOP] = 7

    return wait


def is_move(line):
    return line[:3] in (b"G1 ", b"G0 ")


def plan_file(path, mode):
    names = ["x", "y", "z"] + ["e%d" % i for i in range(board.SETTINGS["drives"])]
    simmachine.attach_world(board.PINS, names)
    printer = main.build(files_root=None)
    mem = printer.mem
    hook = retire_all if mode == "empty" else retire_one
    printer.planner.idle = hook(mem, printer.planner.queue)
    parse = printer.parser.parse
    run_line = printer.run_line
    run_line(parse(b"M302 P1", 7))
    moves = 0
    errors = []
    lines = 0
    f = open(path, "rb")  # streamed, as a board reads from its console or flash
    t0 = time.ticks_us()
    for number, text in enumerate(f, 1):
        lines = number
        text = text.rstrip(b"\r\n")
        if text[:4] in SKIPPED:
            continue
        if is_move(text):
            moves += 1
        try:
            run_line(parse(text, len(text)))
        except Exception as e:  # the firmware would answer Error: and go on
            if len(errors) < 10:
                errors.append("line %d: %r" % (number, e))
    printer.planner.synchronize()
    seconds = time.ticks_diff(time.ticks_us(), t0) / 1e6
    f.close()
    return {"file": path, "mode": mode, "lines": lines, "move_lines": moves,
            "seconds": seconds, "move_lines_per_s": moves / seconds, "errors": errors}


mode = sys.argv[2] if len(sys.argv) > 2 else "full"
print(json.dumps(plan_file(sys.argv[1], mode)))
