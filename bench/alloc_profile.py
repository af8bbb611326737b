# What a planned G1 line allocates, by function (bench/chip_profile.py's list), on a
# unix port: run it on a 32-bit build with single-precision floats, whose boxed floats
# and 31-bit small ints allocate as the chips' do. The collector is off while the
# lines run, so the heap must hold them all (-X heapsize).
#   MICROPYPATH=firmware:boards/sim:bench micropython -X heapsize=16M bench/alloc_profile.py FILE [FIRST LAST]
import sys
import json
import simmachine

sys.modules["machine"] = simmachine
import board
from mixfw import assemble
from mixfw.gcode import command_key
from plan_only import retire_one
import chip_profile

SKIPPED = (b"M109", b"M190", b"M116")


def main(path, first, last):
    names = ["x", "y", "z"] + ["e%d" % i for i in range(board.SETTINGS["drives"])]
    simmachine.attach_world(board.PINS, names)
    printer = assemble.build(files_root=None)
    printer.planner.idle = retire_one(printer.mem, printer.planner.queue)
    run_line = printer.run_line
    for line in (b"M302 P1", b"M83"):  # the excerpts are relative E (see chip_main.py)
        run_line(printer.parser.parse(line, len(line)))
    with open(path, "rb") as f:
        data = [raw.rstrip(b"\r\n") for raw in f][first - 1:last]
    data = [raw for raw in data if raw[:4] not in SKIPPED]
    moves = sum(1 for raw in data if raw[:3] in (b"G1 ", b"G0 "))
    labels, totals = chip_profile.install(printer, command_key, heap=True)
    allocated = chip_profile.bytes_allocated(run_line, printer.parser.parse, data)
    functions = chip_profile.report(labels, totals, moves, "bytes")
    print(json.dumps({"move_lines": moves, "bytes_per_line": allocated / moves,
                      "functions": functions}))


args = sys.argv[1:]
main(args[0], int(args[1]) if len(args) > 1 else 1,
     int(args[2]) if len(args) > 2 else 1000000)
