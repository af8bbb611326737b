# Runs the firmware on the unix port against the simulated chip. Usage:
#   micropython sim_main.py [--edges FILE] [--heap-lock] [--quantum-us N]
#                           [--jitter-us N [--jitter-seed N]]
#                           [--tcp HOST:PORT] [--no-stdio] [--realtime FACTOR]
#                           [--config FILE] [--files DIR] [--set KEY=VALUE ...]
# By default it takes G-code on stdin and answers on stdout like a serial printer, in
# lockstep (virtual time passes only when the firmware waits). With --tcp it also
# serves TCP connections; --realtime paces virtual time against the wall clock (0:
# as fast as possible). When every console has closed, the queue drains and one
# `//sim {json}` line reports the run. --config is the simulated flash file of the
# configuration (M500/M501); without it the printer has no configuration storage.
# --files is the simulated flash folder for printing from flash (M20-M32).
# --set overrides a board setting before the machine is assembled, e.g.
# --set pin_writer=registers (VALUE: a number, a comma-separated tuple, or text).
# --jitter-us fires the timer callbacks up to N us late (interrupt latency; seeded by
# --jitter-seed, so a run repeats exactly).
import sys

# The script's own folder comes first on the path; board.py must be the board's from
# MICROPYPATH (boards/<name> before boards/sim), so look here last.
sys.path.append(sys.path.pop(0))
import gc
import json
import simmachine
import simtime
import simthermal

sys.modules["machine"] = simmachine
sys.modules["time"] = simtime


def _args(argv):
    opts = {"edges": None, "heap_lock": False, "quantum_us": 1000, "tcp": None,
            "stdio": True, "realtime": None, "config": None, "files": None, "set": [],
            "jitter_us": 0, "jitter_seed": 1}
    i = 1
    while i < len(argv):
        a = argv[i]
        if a in ("--edges", "--quantum-us", "--tcp", "--realtime", "--config", "--files",
                 "--jitter-us", "--jitter-seed"):
            i += 1
            opts[a[2:].replace("-", "_")] = argv[i]
        elif a == "--set":
            i += 1
            opts["set"].append(argv[i].split("=", 1))
        elif a == "--heap-lock":
            opts["heap_lock"] = True
        elif a == "--no-stdio":
            opts["stdio"] = False
        else:
            raise SystemExit("sim_main: unknown argument " + a)
        i += 1
    return opts


def _value(text):
    if "," in text:
        return tuple(_value(w) for w in text.split(",") if w)
    if text[:1] not in "0123456789+-.":
        return text  # MicroPython's float() would take "e0" for 0.0
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return text


def main():
    opts = _args(sys.argv)
    import board
    for key, text in opts["set"]:
        board.SETTINGS[key] = _value(text)
    # The simulated chip is the board's: its GPIOs, its register layout.
    simmachine.set_chip(board.SETTINGS.get("chip", "sim"))
    names = ["x", "y", "z"] + ["e%d" % i for i in range(board.SETTINGS["drives"])]
    simmachine.attach_world(board.PINS, names, board.SETTINGS.get("invert_dir", ()))
    simmachine.quantum_us = int(opts["quantum_us"])
    simmachine.set_jitter(int(opts["jitter_us"]), int(opts["jitter_seed"]))
    if opts["edges"]:
        simmachine.record_to(opts["edges"])
    import main as firmware
    from mixfw.console import StreamConsole
    interactive = opts["tcp"] is not None or opts["realtime"] is not None
    consoles = []
    if opts["stdio"]:
        consoles.append(StreamConsole(sys.stdin.buffer, sys.stdout.buffer,
                                      blocking=not interactive))
    listeners = []
    if opts["tcp"]:
        from mixfw.netconsole import TcpListener
        host, port = opts["tcp"].rsplit(":", 1)
        listeners.append(TcpListener(host, int(port)))
    if interactive:
        simmachine.pace(float(opts["realtime"] or 0))
    warnings = []
    config = firmware.Config(board.SETTINGS, opts["config"], warn=warnings.append)
    config.boot()
    printer = firmware.build(config, files_root=opts["files"])
    simthermal.install(simmachine, board, printer)
    # The last STEP pulse ends a few ticks after the queue empties, and a PIO state
    # machine still holds its last words: let the chip finish them before stopping.
    printer.finish.append(simmachine.idle)
    gc.collect()
    simmachine.heap_lock_ticks = opts["heap_lock"]
    firmware.run(consoles, listeners, printer, warnings)
    simmachine.drain_pio()
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
