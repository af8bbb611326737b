"""`mixstep sim`: stream a G-code file through the simulated printer, one line per
`ok` as a host does, and write the GPIO trace (VCD) and a JSON report."""
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from mixstep import paths, trace
from mixstep.outfile import refuse_input, replacing, temporary_path
from mixstep.simprinter import SimPrinter

HEAP_CODE = paths.BOARDS / "sim" / "heap_code.py"


def run(gcode_path, trace_path=None, report_path=None, heap_lock=False, edges_path=None,
        board="sim", config_path=None, files_dir=None, settings=None):
    """edges_path keeps the raw edge records (see trace.read_edges) for analysis; board:
    whose pin map and settings, on a simulated chip of its kind; config_path and
    files_dir: the simulated flash (M500, M20-M32), none by default; settings: board
    settings to override, as `mixstep serve --set` ({"retract_policy": 2})."""
    gcode_path = Path(gcode_path)
    for out in (trace_path, report_path, edges_path):
        refuse_input(out, gcode_path)
    # The edges of a run (tens of MB) live in a temporary folder that goes on every
    # exit, an error or Ctrl-C (and SIGTERM, which the command turns into an exit).
    with tempfile.TemporaryDirectory(prefix="mixstep-sim-") as tmp, \
            open(gcode_path, "rb") as f:  # the bytes as a host would send them
        edges = Path(edges_path) if edges_path else Path(tmp) / "run.edges"
        wall0 = time.perf_counter()
        printer = SimPrinter(edges_path=edges, heap_lock=heap_lock, board=board,
                             config_path=config_path, files_dir=files_dir,
                             settings=settings)
        errors = []
        lines = 0
        try:
            for number, raw in enumerate(f, 1):
                replies = printer.send(raw.rstrip(b"\r\n"))
                lines += 1
                for text in replies:
                    if text.startswith("Error:"):
                        errors.append("line %d: %s" % (number, text))
            fw = printer.finish()
        except BaseException:
            printer.proc.kill()
            printer.proc.wait()
            raise
        sim_wall = time.perf_counter() - wall0
        if trace_path:
            with temporary_path(trace_path) as part:
                trace.write_vcd(edges, part, board)
        steps = trace.net_steps(edges, board)
        wall = time.perf_counter() - wall0
    report = {
        "gcode": str(gcode_path),
        "board": board,
        "lines": lines,
        "errors": errors,
        # What the firmware's start-up found wrong: a saved configuration it refused.
        "warnings": fw["warnings"],
        # The progress (M73) and message (M117) the print left, as M27 shows them.
        "status": fw["status"],
        "steps": steps,
        "firmware_steps": fw["steps"],
        "sim_seconds": fw["sim_us"] / 1e6,
        "wall_seconds": round(wall, 3),
        "firmware_wall_seconds": round(sim_wall, 3),
        # The firmware's heap on this 64-bit port (see boards/sim/sim_main.py): its
        # code as imported here, its data at rest after boot, at the peak of the run
        # and after it; total: code and the data peak.
        "heap_code_bytes": fw["heap_code_bytes"],
        "heap_data_at_rest_bytes": fw["heap_data_at_rest_bytes"],
        "heap_data_peak_bytes": fw["heap_data_peak_bytes"],
        "heap_data_after_bytes": fw["heap_data_after_bytes"],
        "heap_total_peak_bytes": fw["heap_code_bytes"] + fw["heap_data_peak_bytes"],
        "heap_process_peak_bytes": fw["heap_process_peak_bytes"],
        "firmware_modules": fw["firmware_modules"],
        "step_memory_bytes": fw["step_memory_bytes"],
        "sim_buffer_bytes": fw["sim_buffer_bytes"],
        "heap_locked_step_loop": fw["heap_locked"],
        "trace": str(trace_path) if trace_path else None,
        # Where the settings came from, in their order over the board's.
        "config": str(config_path) if config_path else None,
        "set": {k: list(v) if isinstance(v, tuple) else v for k, v in (settings or {}).items()},
    }
    if report_path:
        with replacing(report_path) as out:
            out.write(json.dumps(report, indent=2) + "\n")
    return report


def print_summary(report, keys):
    """A run's chosen figures as JSON on stdout, its first errors on stderr."""
    summary = {k: report.get(k) for k in keys}
    summary["errors"] = len(report["errors"])
    print(json.dumps(summary, indent=2))
    for text in report.get("warnings", ()):
        print(text, file=sys.stderr)
    for e in report["errors"][:20]:
        print(e, file=sys.stderr)


def code_heap(modules, board="sim"):
    """The heap the firmware's modules hold on the unix port, in two parts (see
    boards/sim/heap_code.py): {"compiled_bytes": bytecode and constants, which a
    frozen board keeps in flash, "module_body_bytes": the objects the module bodies
    make at import, which it keeps in RAM}. modules: names such as a run's
    report["firmware_modules"]."""
    done = subprocess.run([paths.micropython(), "-X", "heapsize=2M", str(HEAP_CODE)]
                          + list(modules), capture_output=True, text=True,
                          env=paths.micropython_env(board), timeout=600)
    if done.returncode != 0:
        raise RuntimeError("heap_code.py failed: %s" % done.stderr.strip()[-2000:])
    return json.loads(done.stdout.strip().splitlines()[-1])
