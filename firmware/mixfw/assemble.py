# Assembles the printer from the board's settings, as APrinter does in one place:
# each part gets its pins, timer and parameters passed in, in dependency order, and
# starts it: main.py at boot, then it drops this module and serves with safety.serve;
# the simulation starts it with its own consoles.
import gc
import sys
import machine
import board
import mixfw
from mixfw import heap
# A frozen image: the step path's code into RAM, before anything imports it (inram.py).
# Other deployments load every module into RAM anyway, and do without inram's names.
if mixfw.__path__.startswith(mixfw.FROZEN_PREFIX):
    from mixfw import inram
    inram.load(board.SETTINGS)
if board.SETTINGS.get("step_backend") == "pio_dma":
    import rp2  # noqa: F401 (Feed's: loaded before the reserve, which it would split)
# The planner sizes the reserve, so it and what it imports load before it (after
# inram.load, which must come first).
from mixfw import planner  # noqa: E402
# The modules from here on load beside a reserve that build() takes its arrays from
# (heap.py): their code would leave the heap in pieces too small for the arrays.
heap.reserve(planner.step_loop_bytes(board.SETTINGS))
from mixfw import stepper as st  # noqa: E402
from mixfw.pins import Pins  # noqa: E402
from mixfw.planner import Planner  # noqa: E402
from mixfw.printer import Printer  # noqa: E402
from mixfw.console import StreamConsole  # noqa: E402
from mixfw.config import Config  # noqa: E402
from mixfw.files import Files  # noqa: E402
from mixfw.thermal import Thermal  # noqa: E402
from mixfw.transition import Transitions, l0_mm  # noqa: E402
from mixfw import (cmd_motion, cmd_mixing, cmd_thermal, cmd_report,  # noqa: E402
                   cmd_config, cmd_files)
from mixfw import safety  # noqa: E402

# Commands whose arguments are text, not numbers; M486's module loads at its first
# use (add_lazy_command), so its object names are told here.
RAW_COMMANDS = (cmd_config.RAW_COMMANDS + cmd_files.RAW_COMMANDS + cmd_mixing.RAW_COMMANDS
                + cmd_report.RAW_COMMANDS + (("M", 486),))
# Where G-code files for printing from flash live.
_FILES_ROOT = const("/")
# Where the configuration lives on the board's flash filesystem.
_CONFIG_PATH = const("/mixstep.cfg")
# The web page's files (gzipped), as `mixstep deploy` puts them.
_WEB_ROOT = const("/web")
# Left by M997: the next boot skips the firmware once and leaves the REPL to mpremote.
_REPL_FLAG = const("/mixstep.repl")


def _ticks(us, tick_us):
    return max(1, -(-us // tick_us))


def load_config(path=_CONFIG_PATH, warn=print):
    """The board's defaults, overridden by the saved configuration if it is sound."""
    config = Config(board.SETTINGS, path, warn=warn, clock_hz=machine.freq())
    config.boot()
    return config


def _start_pio(mem, settings, pin_map):
    """The step loop feeds a PIO state machine (rp2 only); returns what it calls."""
    if settings.get("chip") not in ("rp2040", "rp2350"):
        raise ValueError("step_backend pio needs an RP2040 or RP2350, not %r"
                         % settings.get("chip"))
    import rp2
    from mixfw import pio
    names = ["x", "y", "z"] + ["e%d" % i for i in range(settings["drives"])]
    sm, first = pio.start(rp2, machine.Pin, pin_map, names, settings["tick_us"])
    mem[st.S_PIO] = 1
    mem[st.S_PIO_SHIFT] = first
    mem[st.S_PIO_LATENCY] = pio.LATENCY_TICKS
    return sm.put  # bound once: the interrupt must not look it up


def build_step_path(settings, pin_map):
    """What a printer's moves reach the pins through: the step loop's memory, the pins,
    the planner (its idle hook machine.idle until the printer's is set), the DMA feed
    (step_backend pio_dma, else None) and the step loop's interrupt handler."""
    tick_us = settings["tick_us"]
    # Step-loop memory: one array for state, mixer, pin masks and the block ring; it
    # and the DMA ring (step_backend pio_dma) are the largest blocks, so they come first.
    # The backend's module is imported before them: its code would split the free
    # blocks they need.
    capture = settings.get("trace_records", 0)
    piodma = None
    if settings.get("step_backend") == "pio_dma":
        from mixfw import piodma
    # Imported here, not with the others: one name fewer in the globals, which a
    # chip keeps in RAM.
    from mixfw.planner import lk_words
    heap.release()
    mem = heap.zeros(st.mem_words(settings["queue_blocks"], capture))
    lk = heap.zeros(lk_words(settings["queue_blocks"]))
    st.init_mem(mem, settings["queue_blocks"], capture)
    feed = None
    if piodma:
        feed = piodma.Feed(machine, mem, settings, pin_map)
    mem[st.S_PULSE_TICKS] = _ticks(settings["step_pulse_us"], tick_us)
    mem[st.S_DIR_TICKS] = _ticks(settings["dir_setup_us"], tick_us)
    pins = Pins(machine, pin_map, settings)
    for i, m in enumerate(pins.step_masks):
        mem[st.MASK_BASE + i] = m
    for i, m in enumerate(pins.dir_masks):
        mem[st.DIR_MASK_BASE + i] = m
    out = pins.out
    if settings.get("step_backend", "timer") == "pio":
        out = _start_pio(mem, settings, pin_map)
    elif pins.registers:
        out, offsets = pins.registers
        for i, word in enumerate(offsets):
            mem[st.S_REG_SET + i] = word
    planner = Planner(mem, settings, machine.idle, machine.disable_irq, machine.enable_irq,
                      lk, feed.irq if feed else None)
    planner.set_dir_invert(pins.dir_invert_mask)
    return mem, pins, planner, feed, st.make_irq(mem, out, pins.endstops)


def build(config=None, pin_map=None, files_root=_FILES_ROOT):
    config = config or Config(board.SETTINGS, None, clock_hz=machine.freq())
    settings = config.settings
    pin_map = pin_map or board.PINS
    mem, pins, planner, feed, irq = build_step_path(settings, pin_map)
    printer = Printer(settings["line_buffer_bytes"], machine.idle, RAW_COMMANDS)
    planner.idle = printer.idle
    motion = cmd_motion.Motion(planner, pins, settings, printer.reply)
    motion.feed = feed
    # A halt stops motion before anything is reported; steps the DMA ring still held
    # never reached the pins, so they are taken back before the queue is dropped.
    for stop in (printer.on_halt, printer.on_quick_stop):
        if feed:
            stop.append(feed.stop_and_take_back)
        stop.append(planner.abort)
        stop.append(motion.resync)
    cmd_motion.register(printer, motion)
    transitions = Transitions(
        planner, l0_mm(settings["transition_l1_mm"], settings["transition_l2_mm"]),
        settings["transition_pairs"], printer.reply)
    if transitions.l0_mm > 0:
        motion.queue = transitions
        planner.before_sync.append(transitions.flush)
        printer.on_halt.insert(0, motion.queue.drop)
        printer.on_quick_stop.insert(0, motion.queue.drop)
    mixing = cmd_mixing.Mixing(planner, settings, config, printer.reply, motion.queue,
                               motion)
    config.before_save.append(mixing.filament_used_mm)
    cmd_mixing.register(printer, mixing)
    thermal = Thermal(machine, pin_map, settings, printer)
    cmd_thermal.register(printer, thermal, motion)
    # filament change, loaded at its first use
    printer.add_lazy_command("M", 600, "mixfw.cmd_change", "FilamentChange",
                             (printer, motion, thermal, settings), "m600", guarded=True)
    # Filament runout inputs start M600 for their drive: only a board with some loads
    # the watcher.
    runout_gpios = [pin_map.get("e%d_runout" % i) for i in range(settings["drives"])]
    printer.runout = None
    if runout_gpios.count(None) < len(runout_gpios):
        from mixfw import runout
        printer.runout = runout.setup(machine, printer, runout_gpios, settings, mem)
    reports = cmd_report.Reports(printer, motion, planner, board.NAME,
                                 storage=config.path is not None, files=bool(files_root))
    cmd_report.register(printer, reports)
    # objects of a print, cancelling them: loaded at its first use
    printer.add_lazy_command("M", 486, "mixfw.cmd_objects", "Objects",
                             (motion, printer.reply), "m486")
    cmd_config.register(printer, config)
    # The trace capture, a debugging aid: its module loads at its first use.
    for number, method in ((7300, "m7300"), (7301, "m7301")):
        printer.add_lazy_command("M", number, "mixfw.cmd_trace", "Trace",
                                 (mem, settings, printer.reply), method)
    config.appliers.append(motion.apply)
    config.appliers.append(thermal.apply)
    config.appliers.append(mixing.apply)
    # bed levelling: loaded at the first of its commands, or now if a saved mesh is on
    levelling = (printer, motion, pins, config, pin_map, machine)
    for letter, number, method, guarded in (
            ("G", 29, "g29", True),  # probe a grid into the mesh, levelling on
            ("G", 30, "g30", True),  # probe the bed once
            ("M", 420, "m420", False),  # levelling S0/S1, fade Z, V reports the mesh
            ("M", 851, "m851", False)):  # the probe's offsets X Y Z
        printer.add_lazy_command(letter, number, "mixfw.mesh", "shared", levelling, method,
                                 guarded)
    if settings["mesh_enabled"]:
        from mixfw import mesh
        mesh.shared(*levelling)
    tmc_uart = getattr(board, "TMC_UART", None)
    if tmc_uart:  # the drivers' microsteps and current, before anything moves
        from mixfw import cmd_drivers
        cmd_drivers.setup(machine, tmc_uart, config, printer)
    # Every flash write (configuration, uploads, deletions) waits for the moves first.
    config.storage.wait_idle = planner.synchronize
    if files_root:
        reports.files = Files(files_root, printer, config.storage)
        cmd_files.register(printer, reports.files)
    printer.finish.append(planner.synchronize)
    printer.mem = mem
    printer.settings = settings
    printer.planner = planner
    printer.pins = pins
    printer.motion = motion
    printer.thermal = thermal
    printer.mixing = mixing
    printer.reports = reports
    printer.irq = irq
    printer.feed = feed
    if feed:  # the stopped feed runs again once everything else has stopped
        printer.on_halt.append(feed.resume)
        printer.on_quick_stop.append(feed.resume)
    return printer


def board_consoles(printer, warnings):
    """USB serial, a UART if configured, and the TCP console and the web page if the
    board is on a network and a password is set (what stops them goes to warnings)."""
    settings = printer.settings
    consoles = [StreamConsole(sys.stdin.buffer, sys.stdout.buffer)]
    if settings.get("console_uart", -1) >= 0:
        uart = machine.UART(settings["console_uart"], settings["console_baud"])
        consoles.append(StreamConsole(uart, uart))
    try:
        import network  # noqa: F401 (a board without a network has none)
    except ImportError:
        return consoles, []
    # Only now: the network's code and names stay off a board without one.
    from mixfw.webserver import board_listeners
    return consoles, board_listeners(printer, _WEB_ROOT, warnings)


def start(consoles=None, listeners=(), printer=None, warnings=None, repl_flag=_REPL_FLAG):
    """Build the printer (unless given one), start its step loop, safety checks and
    consoles; safety.serve(printer) then serves it. repl_flag: where M997 leaves its
    flag before the reset (None: no flag, no reset; the simulation). warnings: what
    loading the configuration said, told to every host (Printer.warnings)."""
    if printer is None:
        warnings = []
        # The imports left garbage in every hole of the heap; collected first, the
        # configuration's objects fill those holes and leave the large free blocks to
        # the step loop's arrays (without it they end in pieces under 5 KB on rp2).
        gc.collect()
        printer = build(load_config(warn=warnings.append))
    settings = printer.settings
    printer.step_loop = safety.start_timer(machine, printer, settings["tick_us"])
    printer.repl_flag = repl_flag
    printer.add_background(safety.StepWatch(printer, printer.mem, settings["step_stall_ms"]))
    safety.start_watchdog(machine, printer, settings["watchdog_ms"])
    warnings = warnings or []
    if consoles is None:
        consoles, listeners = board_consoles(printer, warnings)
        printer.max_channels = len(consoles) + printer.settings.get("tcp_max_clients", 4)
    printer.warnings = warnings
    for console in consoles:
        printer.add_channel(console)
    printer.listeners.extend(listeners)
    return printer


def drop():
    """This module's code is needed only to build and start the printer: main.py drops
    it before serving, and the kilobytes it held on the heap are free for printing.
    Nothing built here refers to the module (closures would: build makes none)."""
    del sys.modules[__name__]
    del mixfw.assemble


def repl_boot(flag=_REPL_FLAG):
    """True once after M997: the flag is taken away and the firmware stays off."""
    import os
    try:
        os.remove(flag)
    except OSError:
        return False
    print("mixstep: not started (M997 asked for the REPL); reset to start it again")
    return True

