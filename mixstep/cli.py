"""The `mixstep` command."""
import argparse
import signal
import sys
import threading

from mixstep import paths
from mixstep.outfile import UsageError


def _settings(args, board="sim"):
    from mixstep import boards
    return boards.set_items(board, args.set)


def _sim(args):
    from mixstep import sim
    from mixstep.serve import default_flash
    settings = _settings(args, args.board)
    # Its flash only where asked: a run of a file repeats whatever M500 did elsewhere.
    config, files = (default_flash(args.config, args.files) if args.config or args.files
                     else (None, None))
    report = sim.run(args.gcode or paths.EXAMPLE_GCODE, args.trace, args.report,
                     heap_lock=args.heap_lock, board=args.board, config_path=config,
                     files_dir=files, settings=settings)
    sim.print_summary(report, ("lines", "sim_seconds", "wall_seconds", "steps", "status"))
    return 1 if report["errors"] else 0


def _serve(args):
    from mixstep import serve
    settings = _settings(args)
    return serve.main(tcp=args.tcp, http=args.http, pty=args.pty, realtime=args.realtime, settings=settings,
                      config=args.config, files=args.files, console_log=args.console_log)


def _add_flash_args(p):
    p.add_argument("--config", metavar="FILE",
                   help="the simulated flash's configuration file, kept by M500 "
                        "(default out/printer/mixstep.cfg)")
    p.add_argument("--files", metavar="DIR",
                   help="the simulated flash's G-code folder for M20-M32 "
                        "(default out/printer/files)")


def parser():
    """The command line: every subcommand and its arguments."""
    parser = argparse.ArgumentParser(prog="mixstep", description=__doc__)
    sub = parser.add_subparsers(dest="command", required=True)
    p = sub.add_parser("sim", help="run G-code on the simulated printer; write a trace and report")
    p.add_argument("gcode", nargs="?", help="G-code file (default: the example 3-colour print)")
    p.add_argument("--trace", help="write the GPIO trace here (VCD)")
    p.add_argument("--report", help="write the JSON report here")
    p.add_argument("--heap-lock", action="store_true",
                   help="lock the MicroPython heap around every step-loop call")
    p.add_argument("--board", default="sim",
                   help="run with this board's pin map and settings (boards/<name>)")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="a setting over the board's and the saved configuration's, e.g. "
                        "retract_policy=2 (repeatable)")
    p.add_argument("--config", metavar="FILE",
                   help="the simulated flash's configuration file, kept by M500 (default: "
                        "none, the board's settings)")
    p.add_argument("--files", metavar="DIR",
                   help="the simulated flash's G-code folder for M20-M32 (default: none)")
    p.set_defaults(run=_sim)
    p = sub.add_parser("serve", help="run the simulated printer for host software (TCP or PTY)")
    p.add_argument("--tcp", metavar="HOST:PORT", help="serve the TCP G-code console here")
    p.add_argument("--http", metavar="HOST:PORT", help="serve the web page here")
    p.add_argument("--pty", action="store_true", help="serve a pseudo-terminal; prints its path")
    p.add_argument("--realtime", type=float, default=1.0,
                   help="simulated seconds per wall second (0: as fast as possible)")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="a setting over the board's and the saved configuration's, e.g. "
                        "trace_records=60000 (repeatable)")
    _add_flash_args(p)
    p.add_argument("--console-log", metavar="FILE",
                   help="write every console line in and out, with the simulated time")
    p.set_defaults(run=_serve)
    from mixstep import detool, esteps, preview  # each registers its own subcommand
    for tool in (esteps, detool, preview):
        tool.add_parser(sub)
    from mixstep import advance  # `mixstep advance`: tool changes moved earlier by the purge
    advance.add_parser(sub)
    from mixstep import arcfit  # `mixstep arcfit`: runs of short moves on a circle -> G2/G3
    arcfit.add_parser(sub)
    from mixstep import tracecheck, tracepull  # `mixstep trace check|pull`
    p = sub.add_parser("trace", help="check a STEP/DIR trace against G-code; pull a board's capture")
    tsub = p.add_subparsers(dest="trace_command", required=True)
    tracecheck.add_parser(tsub)
    tracepull.add_parser(tsub)
    from mixstep import boards  # `mixstep boards check`: pin-map validation
    boards.add_parser(sub)
    from mixstep import deploy  # `mixstep deploy|freeze|board-check`: onto a board
    deploy.add_parser(sub)
    from mixstep import emu  # `mixstep emu print`: the firmware on an emulated Pico
    emu.add_parser(sub)
    return parser


def main(argv=None):
    args = parser().parse_args(argv)
    name = "mixstep " + args.command
    # SIGTERM as Ctrl-C while the command runs (restored after: main may be called
    # from another program).
    main_thread = threading.current_thread() is threading.main_thread()
    previous = signal.signal(signal.SIGTERM, _terminated) if main_thread else None
    try:
        return args.run(args)
    except KeyboardInterrupt:
        print("%s: interrupted" % name, file=sys.stderr)
        return 130
    except (UsageError, ValueError) as err:
        print("%s: %s" % (name, err), file=sys.stderr)
        return 2
    except OSError as err:  # a file that isn't there, a folder, a port in use
        what = ": %s" % err.filename if getattr(err, "filename", None) else ""
        print("%s: %s%s" % (name, err.strerror or err, what), file=sys.stderr)
        return 2
    finally:
        if main_thread:
            signal.signal(signal.SIGTERM, previous)


def _terminated(signum, frame):
    # SIGTERM as Ctrl-C: every `with` and `finally` runs, so no temporary file stays.
    raise KeyboardInterrupt


if __name__ == "__main__":
    sys.exit(main())
