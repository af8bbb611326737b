"""`mixstep emu print`: the firmware on an emulated Raspberry Pi Pico.

The firmware is built for the board as `mixstep deploy` builds it (mixfw compiled with
mpy-cross for the chip, main.py and board.py as source) and put on the emulated
flash as a littlefs image. The chip (rp2040js, driven by emu/harness.mjs) boots
MicroPython, whose main.py serves the USB console; the harness streams the G-code
over the emulated USB CDC port one line per `ok`, as a host does, records the
STEP/DIR/ENABLE pins with the emulator's clock, moves each min endstop with its axis,
and feeds the thermistor inputs from a thermal model of the hot end and bed.
"""
import json
import sys
import os
import shutil
import subprocess
import tempfile
import time
from pathlib import Path

from mixstep import deploy, paths, trace

EMU = paths.ROOT / "emu"
HARNESS = EMU / "harness.mjs"
DEFAULT_IMAGE = paths.ROOT.parent / "shared" / "rp2emu"
# The Pico's filesystem as MicroPython's rp2 port lays it out for RPI_PICO: the last
# 1408 KiB of the 2 MiB flash, littlefs2 with 4 KiB blocks and 256-byte programs.
FS_OFFSET = 2 * 1024 * 1024 - 1408 * 1024
FS_BLOCK = 4096
FS_BLOCKS = 352
# The bodies of boards/sim/simthermal.py: a 40 W cartridge in a small block (about
# 45 s from cold to 200 C) and a 150 W bed.
HOTEND = dict(capacity_j_k=10.0, heater_w=40.0, loss_w_k=0.08, fan_loss_w_k=0.06)
BED = dict(capacity_j_k=120.0, heater_w=150.0, loss_w_k=1.2, fan_loss_w_k=0.0)
# The exceptions that run the step loop: MicroPython's rp2 port calls a hard
# machine.Timer's callback straight from a hardware alarm of the TIMER (IRQ 0-3,
# exceptions 16-19; v1.28 uses alarm 3). The report lists every exception's share.
STEP_EXCEPTIONS = (16, 17, 18, 19)


class EmuError(Exception):
    """Something to install or pass before the emulator can run, said so."""


def node():
    found = shutil.which("node")
    if not found:
        raise EmuError("node not found: install Node.js 18 or newer (e.g. `apt-get install "
                       "nodejs npm`), then run `make emu-setup`")
    return found


def check_setup():
    node()
    if not (EMU / "node_modules" / "rp2040js" / "package.json").exists():
        raise EmuError("the npm package rp2040js is not installed in emu/node_modules: run "
                       "`make emu-setup` (npm ci in emu/, from emu/package-lock.json)")


def image_files(image_dir=None):
    """(firmware.uf2, boot ROM) in the image folder; explains what is missing."""
    folder = Path(image_dir) if image_dir else DEFAULT_IMAGE
    uf2 = folder / "firmware.uf2"
    if not uf2.exists():
        raise EmuError("no firmware.uf2 in %s: pass --image DIR with MicroPython's Pico "
                       "firmware as firmware.uf2, e.g. the v1.28 RPI_PICO .uf2 from "
                       "micropython.org/download/RPI_PICO" % folder)
    for name in ("bootrom.js", "bootrom.bin"):
        if (folder / name).exists():
            return uf2, folder / name
    raise EmuError("no boot ROM (bootrom.js or bootrom.bin) in %s: MicroPython calls the "
                   "RP2040's ROM functions, which rp2040js's npm package does not ship. "
                   "Take demo/bootrom.ts of github.com/wokwi/rp2040js as bootrom.js, or "
                   "b1.bin built from github.com/raspberrypi/pico-bootrom-rp2040 (tag b1) "
                   "as bootrom.bin" % folder)


def make_fs_image(src_dir, out_path):
    """A littlefs image of src_dir's tree, as the Pico's MicroPython mounts it."""
    from littlefs import LittleFS
    lfs = LittleFS(block_size=FS_BLOCK, block_count=FS_BLOCKS, prog_size=256, read_size=32,
                   lookahead_size=32, name_max=255, disk_version=0x00020001)
    src_dir = Path(src_dir)
    for path in sorted(src_dir.rglob("*")):
        remote = "/" + path.relative_to(src_dir).as_posix()
        if path.is_dir():
            lfs.mkdir(remote)
        else:
            with lfs.open(remote, "wb") as f:
                f.write(path.read_bytes())
    Path(out_path).write_bytes(lfs.context.buffer)


def run_description(board, uf2, bootrom, fs_image, gcode, edges, result, diag_every,
                    max_emu_s, max_wall_s):
    spec = paths.load_board(board)
    pins, settings = spec["PINS"], spec["SETTINGS"]
    inverted = settings.get("invert_dir", ())
    endstops = [dict(axis=a, min_gpio=pins[a + "_min"], step_gpio=pins[a + "_step"],
                     dir_gpio=pins[a + "_dir"], forward_level=0 if a in inverted else 1,
                     active_high=bool(settings["endstop_active_high"]))
                for a in "xyz" if a + "_min" in pins]
    heaters = []
    for name, body in (("hotend", HOTEND), ("bed", BED)):
        if name + "_heater" not in pins:
            continue
        if any(settings.get("%s_sh_%s" % (name, k)) for k in "abc"):
            raise EmuError("the emulator's thermal model reads Beta thermistors only; "
                           "board %s sets Steinhart-Hart for %s" % (board, name))
        heaters.append(dict(body, name=name, heater_gpio=pins[name + "_heater"],
                            adc_channel=pins[name + "_thermistor"] - 26,
                            pullup_ohm=settings[name + "_pullup_ohm"],
                            r25_ohm=settings[name + "_r25_ohm"], beta=settings[name + "_beta"]))
    return dict(uf2=str(uf2), bootrom=str(bootrom), fs_image=str(fs_image),
                fs_offset=FS_OFFSET, gcode=str(gcode), edges=str(edges), result=str(result),
                record_pins=sorted(trace.signal_names(board)), endstops=endstops,
                heaters=heaters, fan_gpio=pins.get("part_fan", -1), diag_every=diag_every,
                max_emu_s=max_emu_s, max_wall_s=max_wall_s)


def _diag(text):
    """echo:underruns:0 mem_free:1 mem_free_collected:2 -> {"underruns": 0, ...}"""
    return {k: int(v) for k, v in (w.split(":") for w in text[len("echo:"):].split())}


def run(gcode_path, board="pico", trace_path=None, report_path=None, image_dir=None,
        diag_every=50, max_emu_s=600.0, max_wall_s=3600.0):
    """Print gcode_path on the emulated board; returns the report (see the README)."""
    check_setup()
    chip = deploy.board_chip(board)
    if chip != "rp2040":
        raise EmuError("the emulator is an RP2040 (rp2040js); board %s is %s" % (board, chip))
    uf2, bootrom = image_files(image_dir)
    wall0 = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="mixstep-emu-") as tmp:
        tmp = Path(tmp)
        build = deploy.build(board, tmp / "flash")
        make_fs_image(build, tmp / "fs.img")
        desc = run_description(board, uf2, bootrom, tmp / "fs.img", Path(gcode_path).resolve(),
                               tmp / "run.edges", tmp / "result.json", diag_every, max_emu_s,
                               max_wall_s)
        (tmp / "run.json").write_text(json.dumps(desc, indent=1))
        proc = subprocess.run([node(), str(HARNESS), str(tmp / "run.json")], cwd=str(EMU),
                              capture_output=True, text=True)
        if not (tmp / "result.json").exists():
            raise EmuError("the emulator failed (status %d): %s" % (
                proc.returncode, (proc.stderr or proc.stdout).strip()[-2000:]))
        res = json.loads((tmp / "result.json").read_text())
        if trace_path:
            trace.write_vcd(tmp / "run.edges", trace_path, board, timescale="1 ns",
                            date="mixstep emulated %s" % board)
        steps = trace.net_steps(tmp / "run.edges", board)
        keep = os.environ.get("MIXSTEP_EMU_KEEP")  # a folder to keep the run's files in
        if keep:
            shutil.copytree(tmp, keep, dirs_exist_ok=True)
    report = summarize(res, board, gcode_path, steps)
    report["wall_seconds"] = round(time.perf_counter() - wall0, 3)
    report["trace"] = str(trace_path) if trace_path else None
    if report_path:
        Path(report_path).write_text(json.dumps(report, indent=2) + "\n")
    return report


def summarize(res, board, gcode_path, steps):
    diags = [_diag(d["text"]) for d in res["diagnostics"]]
    last = diags[-1] if diags else {}
    report = {
        "gcode": str(gcode_path),
        "board": board,
        "lines": res["lines"],
        "errors": res["errors"],
        "stopped": res["stopped"],  # why the run ended early, or None
        "emulated_seconds": res["print"]["emu_seconds"] if res.get("print") else None,
        "boot_emulated_seconds": res["start_emu_s"],
        "emulator_wall_seconds": round(res["wall_seconds"], 3),
        "underruns": last.get("underruns"),
        "mem_free_min_bytes": min((d["mem_free_collected"] for d in diags), default=None),
        # gc.mem_free() as M122 found it, before its collection: garbage included.
        "mem_free_uncollected_min_bytes": min((d["mem_free"] for d in diags), default=None),
        "mem_free_samples": len(diags),
        "steps": steps,
        "heaters_c": {h["name"]: round(h["temp_c"], 1) for h in res["heaters"]},
        "boot_lines": res["boot_lines"],
        # What the firmware answered to the file's lines besides `ok` (the first 1000).
        "console": res["console"],
        "edges": res["edges"],
    }
    if res.get("print"):
        p = res["print"]
        span = p["emu_seconds"]
        exc = p["exceptions"]
        step = sum(exc.get(str(n), {}).get("seconds", 0) for n in STEP_EXCEPTIONS)
        report["cpu_step_fraction"] = round(step / span, 4) if span else None
        report["cpu_busy_fraction"] = round(1 - p["slept_seconds"] / span, 4) if span else None
        report["cpu_by_exception"] = {n: dict(e, fraction=round(e["seconds"] / span, 4))
                                      for n, e in exc.items()}
    return report


def _print(args):
    try:
        report = run(args.gcode or paths.EXAMPLE_GCODE, args.board, args.trace, args.report,
                     args.image, args.diag_every, args.max_emu_s, args.max_wall_s)
    except (EmuError, deploy.DeployError) as e:
        print("mixstep emu: %s" % e, file=sys.stderr)
        return 2
    keys = ("lines", "emulated_seconds", "emulator_wall_seconds", "wall_seconds",
            "cpu_step_fraction", "cpu_busy_fraction", "mem_free_min_bytes", "underruns",
            "stopped")
    summary = {k: report.get(k) for k in keys}
    summary["errors"] = len(report["errors"])
    print(json.dumps(summary, indent=2))
    for e in report["errors"][:20]:
        print(e, file=sys.stderr)
    if report["stopped"]:
        print("mixstep emu: stopped early: %s" % report["stopped"], file=sys.stderr)
    return 1 if report["errors"] or report["stopped"] else 0


def add_parser(sub):
    p = sub.add_parser("emu", help="run the firmware on an emulated board (rp2040js)")
    esub = p.add_subparsers(dest="emu_command", required=True)
    q = esub.add_parser("print", help="boot the firmware on an emulated Pico and print a "
                                      "G-code file over its USB console")
    q.add_argument("gcode", nargs="?", help="G-code file (default: the example 3-colour print)")
    q.add_argument("--board", default="pico", help="an RP2040 board (boards/<name>)")
    q.add_argument("--trace", help="write the STEP/DIR/ENABLE trace here (VCD, 1 ns)")
    q.add_argument("--report", help="write the JSON report here")
    q.add_argument("--image", metavar="DIR",
                   help="folder with MicroPython's firmware.uf2 and the boot ROM "
                        "(bootrom.js or bootrom.bin); default ../shared/rp2emu/")
    q.add_argument("--diag-every", type=int, default=50, metavar="N",
                   help="send M122 (underruns, free heap) every N lines; 0: at the end only")
    q.add_argument("--max-emu-s", type=float, default=600.0,
                   help="give up after this many emulated seconds")
    q.add_argument("--max-wall-s", type=float, default=3600.0,
                   help="give up after this many wall seconds")
    q.set_defaults(run=_print)
