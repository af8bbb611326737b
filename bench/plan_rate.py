# Planner throughput on the MicroPython unix port: every line of a G-code file goes
# through the firmware's parser and command table into the planner, with no stepping.
# Nothing steps; blocks are retired by hand (boards/sim/plan_only.py):
#   full:  after each line, the oldest block where the ring is full (make_room), so
#          every new block is planned against a full look-ahead queue, as while
#          printing, and the planner never waits (the default);
#   empty: every queued block at each wait (S_TAIL = S_HEAD), the cheapest look-ahead.
# Heating waits (M109, M190, M116) are skipped and cold extrusion is allowed, as no
# time passes. Prints one JSON line: lines, G0/G1 lines, seconds, G1 lines per second.
#   MICROPYPATH=firmware:boards/sim micropython -X heapsize=2M bench/plan_rate.py FILE [full|empty]
import sys
import json
import time
import simmachine

sys.modules["machine"] = simmachine
import board
from mixfw import assemble
from plan_only import make_room, retire_one, retire_all

SKIPPED = (b"M109", b"M190", b"M116")


def is_move(buf, i):
    return buf[i] == 71 and (buf[i + 1] == 49 or buf[i + 1] == 48) and buf[i + 2] == 32


def file_lines(path, chunk_bytes=4096):
    """(buffer, start, end) of each line, CR and LF left out. Read in chunks, as a board
    reads from its console or flash: MicroPython's readline() makes one read call per
    byte, which would cost more than parsing and planning the line."""
    buf = bytearray(chunk_bytes)
    mv = memoryview(buf)
    have = 0
    f = open(path, "rb")
    try:
        while True:
            got = f.readinto(mv[have:])
            have += got
            i = 0
            while i < have:
                j = buf.find(b"\n", i, have)
                if j < 0:
                    if got:
                        break  # the rest of the line is in the next chunk
                    j = have  # a last line with no newline
                end = j
                while end > i and buf[end - 1] == 13:
                    end -= 1
                yield mv, i, end
                i = j + 1
            if not got:
                return
            if i == 0 and have == chunk_bytes:
                raise ValueError("line longer than %d bytes" % chunk_bytes)
            buf[:have - i] = buf[i:have]
            have -= i
    finally:
        f.close()


def plan_file(path, mode):
    names = ["x", "y", "z"] + ["e%d" % i for i in range(board.SETTINGS["drives"])]
    simmachine.attach_world(board.PINS, names)
    printer = assemble.build(files_root=None)
    mem = printer.mem
    hook = retire_all if mode == "empty" else retire_one
    printer.planner.idle = hook(mem, printer.planner.queue)
    parse = printer.parser.parse
    run_line = printer.run_line
    run_line(parse(b"M302 P1", 7))
    full = printer.planner.queue - 1 if mode != "empty" else 0
    moves = 0
    errors = []
    lines = 0
    t0 = time.ticks_us()
    for mv, start, end in file_lines(path):
        lines += 1
        if end - start >= 4 and mv[start] == 77 and bytes(mv[start:start + 4]) in SKIPPED:
            continue
        if end - start >= 3 and is_move(mv, start):
            moves += 1
        try:
            run_line(parse(mv[start:end], end - start))
        except Exception as e:  # the firmware would answer Error: and go on
            if len(errors) < 10:
                errors.append("line %d: %r" % (lines, e))
        if full:
            make_room(mem, full)  # as a step path would: the planner never waits
    printer.planner.synchronize()
    seconds = time.ticks_diff(time.ticks_us(), t0) / 1e6
    return {"file": path, "mode": mode, "lines": lines, "move_lines": moves,
            "seconds": seconds, "move_lines_per_s": moves / seconds, "errors": errors}


mode = sys.argv[2] if len(sys.argv) > 2 else "full"
print(json.dumps(plan_file(sys.argv[1], mode)))
