# Runs the firmware on the unix port against the simulated chip, taking G-code on
# stdin and answering on stdout like a serial printer. Usage:
#   micropython sim_main.py [--edges FILE] [--heap-lock] [--quantum-us N]
# When stdin ends, the queue drains and one `//sim {json}` line reports the run.
import sys
import gc
import json
import simmachine

sys.modules["machine"] = simmachine


def _args(argv):
    opts = {"edges": None, "heap_lock": False, "quantum_us": 1000}
    i = 1
    while i < len(argv):
        a = argv[i]
        if a == "--edges":
            i += 1
            opts["edges"] = argv[i]
        elif a == "--heap-lock":
            opts["heap_lock"] = True
        elif a == "--quantum-us":
            i += 1
            opts["quantum_us"] = int(argv[i])
        else:
            raise SystemExit("sim_main: unknown argument " + a)
        i += 1
    return opts


def main():
    opts = _args(sys.argv)
    import board
    names = ["x", "y", "z"] + ["e%d" % i for i in range(board.SETTINGS["drives"])]
    simmachine.attach_world(board.PINS, names)
    simmachine.quantum_us = opts["quantum_us"]
    if opts["edges"]:
        simmachine.record_to(opts["edges"])
    import main as firmware
    from mixfw.console import StreamConsole
    console = StreamConsole(sys.stdin.buffer, sys.stdout.buffer, blocking=True)
    gc.collect()
    simmachine.heap_lock_ticks = opts["heap_lock"]
    printer = firmware.run(console)
    simmachine.close()
    gc.collect()
    pos = simmachine.positions
    report = {
        "sim_us": simmachine.now_us,
        "steps": {name: pos[i] for i, name in enumerate(simmachine.step_names)},
        "heap_at_rest_bytes": gc.mem_alloc(),
        "heap_peak_bytes": max(simmachine.heap_peak_bytes, gc.mem_alloc()),
        # What the simulated chip itself holds (edge buffer), not the firmware's.
        "sim_buffer_bytes": simmachine.buffer_bytes(),
        "heap_locked": opts["heap_lock"],
    }
    sys.stdout.write("//sim " + json.dumps(report) + "\n")


main()
