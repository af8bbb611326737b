# Runs the firmware on the unix port against the simulated chip. Usage:
#   micropython sim_main.py [--edges FILE] [--heap-lock] [--quantum-us N]
#                           [--jitter-us N [--jitter-seed N]]
#                           [--tcp HOST:PORT] [--http HOST:PORT --web DIR]
#                           [--no-stdio] [--realtime FACTOR]
#                           [--config FILE] [--files DIR] [--set KEY=VALUE ...]
#                           [--console-log FILE] [--clock-hz N]
# By default it takes G-code on stdin and answers on stdout like a serial printer, in
# lockstep (virtual time passes only when the firmware waits). With --tcp it also
# serves TCP connections, and with --http the web page, its files (gzipped) from
# --web DIR, as a board's from its flash; --realtime paces virtual time against the wall clock (0:
# as fast as possible). When every console has closed, the queue drains and one
# `//sim {json}` line reports the run. --config is the simulated flash file of the
# configuration (M500/M501); without it the printer has no configuration storage.
# --files is the simulated flash folder for printing from flash (M20-M32). Both are
# written through simfaults.Flash, whose writes can stall the chip (M7103 F).
# --set overrides a setting, the board's and the saved configuration's, before the
# machine is assembled, e.g. --set pin_writer=registers (VALUE: a number, a
# comma-separated tuple, or text).
# --jitter-us fires the timer callbacks up to N us late (interrupt latency; seeded by
# --jitter-seed, so a run repeats exactly).
# --console-log writes every line the consoles receive and send, stamped with the
# simulated time: `<us> < <line>` received, `<us> > <line>` sent (as a host's serial
# log, but in the printer's own time).
# --clock-hz sets the simulated chip's system clock (machine.freq()) before the
# firmware starts, as boot.py sets the board's clock_hz (the default here too).
import sys

# The script's own folder comes first on the path; board.py must be the board's from
# MICROPYPATH (boards/<name> before boards/sim), so look here last.
sys.path.append(sys.path.pop(0))
import gc
import json
import simmachine
import simtime
import simanalog

sys.modules["machine"] = simmachine
sys.modules["time"] = simtime


def _args(argv):
    opts = {"edges": None, "heap_lock": False, "quantum_us": 1000, "tcp": None,
            "http": None, "web": None,
            "stdio": True, "realtime": None, "config": None, "files": None, "set": [],
            "jitter_us": 0, "jitter_seed": 1, "console_log": None, "clock_hz": None}
    i = 1
    while i < len(argv):
        a = argv[i]
        if a in ("--edges", "--quantum-us", "--tcp", "--http", "--web", "--realtime",
                 "--config", "--files",
                 "--jitter-us", "--jitter-seed", "--console-log", "--clock-hz"):
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


class ConsoleLog:
    """One file of every console's lines in and out, with the simulated time. The
    lines in are written as the bytes that came, whatever they are (a host may send
    any byte, and the firmware answers it)."""

    def __init__(self, path):
        self.f = open(path, "wb")

    def line(self, way, data):
        self.f.write(b"%d %s " % (simmachine.now_us, way.encode()))
        self.f.write(data if isinstance(data, (bytes, bytearray)) else data.encode())
        self.f.write(b"\n")
        self.f.flush()


class LoggedConsole:
    """A console whose lines also go to a ConsoleLog."""

    def __init__(self, console, log):
        self.console = console
        self.log = log
        self.blocking = getattr(console, "blocking", False)
        self.rx_line = bytearray()
        self.tx_line = ""

    def readinto(self, mv, block=False):
        n = self.console.readinto(mv, block)
        for i in range(max(n, 0)):
            c = mv[i]
            if c == 10:
                line = self.rx_line
                self.log.line("<", line[:-1] if line[-1:] == b"\r" else line)
                self.rx_line = bytearray()
            else:
                self.rx_line.append(c)
        return n

    def write(self, text):
        # Logged first: a host that has the line may read the log at once.
        whole = self.tx_line + text
        while "\n" in whole:
            done, whole = whole.split("\n", 1)
            self.log.line(">", done)
        self.tx_line = whole
        self.console.write(text)

    def close(self):
        if hasattr(self.console, "close"):
            self.console.close()


class LoggedListener:
    def __init__(self, listener, log):
        self.listener = listener
        self.log = log

    def accept(self, room):
        console = self.listener.accept(room)
        return console if console is None else LoggedConsole(console, self.log)


def _drivers_enabled(board):
    active = 0 if board.SETTINGS.get("enable_active_low") else 1
    return any(simmachine._levels[gpio] == active
               for name, gpio in board.PINS.items() if name.endswith("_enable"))


def _heap_bytes():
    """Live heap: what stays allocated after a full collection."""
    gc.collect()
    return gc.mem_alloc()


def main():
    opts = _args(sys.argv)
    # The heap is split into the simulation's own share (chip, edge buffer, thermal
    # model), the firmware's code (what importing its modules costs: bytecode, function
    # and class objects, module tables) and its data (what building the printer and
    # printing allocate). Each share is the live heap's growth over a stretch that only
    # that share runs in.
    heap_code = 0
    before = _heap_bytes()
    import board
    heap_code += _heap_bytes() - before
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
    before = _heap_bytes()
    from mixfw import assemble as firmware
    from mixfw import safety
    from mixfw.console import StreamConsole
    if opts["tcp"] or opts["http"]:
        from mixfw import netconsole
        from mixfw.netconsole import TcpListener
        # The network is this machine's, and so are a host's waits: its timeouts
        # (password, idle, slow sender, lockout) run on the real clock, not the
        # simulated one, which runs free between lines at --realtime 0.
        netconsole.time = simmachine.walltime
    heap_code += _heap_bytes() - before
    firmware_modules = sorted(name for name in sys.modules
                              if name in ("board", "main") or name.startswith("mixfw"))
    # Imported after the firmware: it uses the firmware's parser, whose code is the
    # firmware's share.
    import simthermal
    import simfaults
    import simswitch
    import simtmc
    import simbed
    # The configuration and the files are written through the simulated flash, which
    # holds the interrupts at each write as the chip does (M7103 F): the simulation's.
    flash = simfaults.Flash()
    data_from = _heap_bytes()
    interactive = opts["tcp"] or opts["http"] or opts["realtime"] is not None
    consoles = []
    if opts["stdio"]:
        consoles.append(StreamConsole(sys.stdin.buffer, sys.stdout.buffer,
                                      blocking=not interactive))
    if interactive:
        simmachine.pace(float(opts["realtime"] or 0))
    warnings = []
    # The board's clock, as its boot.py sets it, or --clock-hz: the PWM divides it.
    clock_hz = opts["clock_hz"] or board.SETTINGS.get("clock_hz")
    if clock_hz:
        simmachine.freq(int(clock_hz))
    config = firmware.Config(board.SETTINGS, opts["config"], flash, warn=warnings.append,
                             clock_hz=simmachine.freq())
    config.boot()
    # --set over the saved configuration too: the board's settings, then the saved
    # ones, then --set (the command line says what it wants for this run).
    if opts["set"]:
        asked = config._default_settings()
        for key, _ in opts["set"]:
            config.settings[key] = asked[key]
    printer = firmware.build(config, files_root=opts["files"])
    listeners = []
    try:
        gate = None
        if opts["tcp"]:
            host, port = opts["tcp"].rsplit(":", 1)
            listeners.append(TcpListener(host, int(port), printer.settings))
            gate = listeners[-1].gate
        if opts["http"]:
            from mixfw import webserver
            from mixfw.webserver import HttpListener
            webserver.time = simmachine.walltime  # as the network console's, above
            host, port = opts["http"].rsplit(":", 1)
            listeners.append(HttpListener(host, int(port), printer, opts["web"] or "web",
                                          gate))
    except ValueError as err:
        print("mixstep: %s" % err)
        sys.exit(2)
    if listeners:
        printer.max_channels = len(consoles) + printer.settings.get("tcp_max_clients", 4)
    if opts["console_log"]:
        log = ConsoleLog(opts["console_log"])
        consoles = [LoggedConsole(c, log) for c in consoles]
        listeners = [LoggedListener(l, log) for l in listeners]
    heap_data_at_rest = _heap_bytes() - data_from
    before = _heap_bytes()
    simthermal.install(simmachine, board, printer)
    simfaults.install(printer, flash)
    simswitch.install(printer)
    simtmc.install(printer)
    simbed.install(printer, board)
    # The last STEP pulse ends a few ticks after the queue empties, and a PIO state
    # machine still holds its last words: let the chip finish them before stopping.
    printer.finish.append(simmachine.idle)
    # The firmware's data is the live heap over data_from less what the simulation
    # added after it.
    data_from += _heap_bytes() - before
    simmachine.heap_peak_bytes = 0
    simmachine.heap_lock_ticks = opts["heap_lock"]
    fault = None
    try:
        firmware.start(consoles, listeners, printer, warnings, repl_flag=None)
        safety.serve(printer)
    except Exception as err:
        fault = err  # raised again below, once the report says what it left on
    # The print is over: a chip would go on to its REPL (and its watchdog would reset
    # it); the simulation only finishes its trace.
    simmachine.release_watchdogs()
    simmachine.drain_pio()
    simmachine.close()
    heap_after = _heap_bytes()
    pos = simmachine.positions
    report = {
        "sim_us": simmachine.now_us,
        "steps": {name: pos[i] for i, name in enumerate(simmachine.step_names)},
        # The firmware's heap, in bytes of this (64-bit) port: its modules as imported
        # here (compiled from .py, or loaded from .mpy); its data once built, before
        # the first line; the most data live at once during the run (sampled after a
        # collection every few hundred idle calls) and after it.
        "heap_code_bytes": heap_code,
        "heap_data_at_rest_bytes": heap_data_at_rest,
        "heap_data_peak_bytes": max(simmachine.heap_peak_bytes, heap_after) - data_from,
        "heap_data_after_bytes": heap_after - data_from,
        # The whole MicroPython heap in use, simulation included.
        "heap_process_peak_bytes": max(simmachine.heap_peak_bytes, heap_after),
        "firmware_modules": firmware_modules,
        # What the start-up found wrong (a saved configuration refused), as hosts hear.
        "warnings": warnings,
        # The firmware's largest buffer (step-loop state, block ring, trace ring):
        # bytes, the same on any port.
        "step_memory_bytes": len(printer.mem) * 4,
        # What the simulated chip itself holds (edge buffer), not the firmware's.
        "sim_buffer_bytes": simmachine.buffer_bytes(),
        "heap_locked": opts["heap_lock"],
        # What the outputs were left at when the firmware's main loop ended: heater
        # PWM duty (0..1) and whether any driver's ENABLE pin was active.
        "heater_duty_at_exit": {b.name: simanalog.duty_of(b.heater_gpio)
                                for b in simthermal.world.bodies},
        "drivers_enabled_at_exit": _drivers_enabled(board),
        # The progress (M73) and message (M117) the print left, as M27 shows them.
        "status": printer.reports.status(),
    }
    if opts["stdio"]:  # for the host that drives this console (mixstep sim, the tests)
        # Streamed: the report as one string would need a kilobyte in one piece of a
        # heap the print has just left in pieces.
        sys.stdout.write("//sim ")
        json.dump(report, sys.stdout)
        sys.stdout.write("\n")
    else:  # on the terminal of `mixstep serve --tcp`: a line for its user
        print("mixstep: the firmware stopped%s" % (
            " on M997 (a board restarts into its REPL)" if printer.leaving == "M997" else ""))
    if fault is not None:
        raise fault


main()
