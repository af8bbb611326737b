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

from mixstep import boards, deploy, paths, sim, trace
from mixfw.options import FIRMWARE_DEFAULTS

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
# exceptions 16-19; v1.28 uses alarm 3); with step_backend pio_dma the DMA's IRQ 0
# (IRQ 11, exception 27) does. The report lists every exception's share.
STEP_EXCEPTIONS = (16, 17, 18, 19, 27)
# How the harness marks its answers on stdout (see emu/harness.mjs, "the controller").
ANSWER = "@emu "


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


def board_spec(board, settings=None):
    """The board's board.py namespace with `settings` laid over its SETTINGS, after
    `mixstep boards check` passes it so."""
    spec = paths.load_board(board)
    spec["SETTINGS"] = dict(spec["SETTINGS"], **(settings or {}))
    problems = boards.check(spec, board)
    if problems:
        raise EmuError("board %s%s has pin-map problems:\n  %s" % (
            board, " with %s" % settings if settings else "", "\n  ".join(problems)))
    return spec


def run_description(spec, uf2, bootrom, fs_image, max_emu_s, max_wall_s):
    board = spec["NAME"]
    pins, settings = spec["PINS"], spec["SETTINGS"]
    inverted = settings.get("invert_dir", ())
    endstops = [dict(axis=a, min_gpio=pins[a + "_min"], step_gpio=pins[a + "_step"],
                     dir_gpio=pins[a + "_dir"], forward_level=0 if a in inverted else 1,
                     active_high=bool(settings["endstop_active_high"]))
                for a in "xyz" if a + "_min" in pins]
    # Runout inputs read the filament present: the emulated pads have no pull-ups.
    gone_high = settings.get("runout_active_high", FIRMWARE_DEFAULTS["runout_active_high"])
    inputs = [dict(gpio=gpio, level=0 if gone_high else 1)
              for key, gpio in sorted(pins.items()) if key.endswith("_runout")]
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
                fs_offset=FS_OFFSET, record_pins=sorted(trace.signal_names(board)),
                endstops=endstops, inputs=inputs, heaters=heaters,
                fan_gpio=pins.get("part_fan", -1),
                max_emu_s=max_emu_s, max_wall_s=max_wall_s)


class Stopped(EmuError):
    """The chip did not get where it was asked to: no answer within the time given,
    a time limit of the run, the chip halted."""


def _settings_source(settings):
    """Lines laid over board.py's SETTINGS, for a run with other settings."""
    return ("\n# mixstep emu: this run's settings\nSETTINGS = dict(SETTINGS, %s)\n"
            % ", ".join("%s=%r" % kv for kv in sorted(settings.items())))


class Chip:
    """The firmware booted on an emulated board, driven as a host drives it over USB.

    The firmware is built as `mixstep deploy` builds it, with `settings` laid over the
    board's (written into board.py on the flash) and `files` ({name: local path}) next
    to it on the flash, where M20-M32 find G-code files. The chip's clock runs only
    inside send-and-wait calls (command, run), so a test's own work costs no emulated
    time. `transcript` holds the USB traffic as (emulated s, way, text): '>' bytes
    the chip received, '<' a line it sent."""

    def __init__(self, board="pico", image_dir=None, settings=None, files=None,
                 max_emu_s=600.0, max_wall_s=3600.0):
        check_setup()
        chip = deploy.board_chip(board)
        if chip != "rp2040":
            raise EmuError("the emulator is an RP2040 (rp2040js); board %s is %s"
                           % (board, chip))
        self.board = board
        self.settings = dict(settings or {})
        spec = board_spec(board, self.settings)
        uf2, bootrom = image_files(image_dir)
        self._tmp = tempfile.TemporaryDirectory(prefix="mixstep-emu-")
        self.dir = Path(self._tmp.name)
        self.transcript = []
        self.now = 0.0
        self.stopped = None
        self.final = None
        self._edge_files = 0
        self.proc = None
        self._stderr = None
        try:
            build = deploy.build(board, self.dir / "flash")
            if self.settings:
                with open(build / "board.py", "a") as f:
                    f.write(_settings_source(self.settings))
            for name, src in (files or {}).items():
                shutil.copy(src, build / name)
            make_fs_image(build, self.dir / "fs.img")
            desc = run_description(spec, uf2, bootrom, self.dir / "fs.img", max_emu_s,
                                   max_wall_s)
            (self.dir / "run.json").write_text(json.dumps(desc, indent=1))
            self._stderr = open(self.dir / "harness.err", "w+")
            self.proc = subprocess.Popen(
                [node(), str(HARNESS), str(self.dir / "run.json")], cwd=str(EMU),
                stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=self._stderr,
                text=True, encoding="utf-8")
            hello = self._answer()
            self.uf2_blocks = hello.get("uf2_blocks")
            self.connected_s = hello.get("connected_emu_s")
            self.boot_lines = [t for _, way, t in self.transcript if way == "<"]
            if not hello.get("ready"):
                raise Stopped(hello["stopped"])
        except BaseException:
            self.cleanup()
            raise

    # --- talking to the harness ---
    def _request(self, **op):
        self.proc.stdin.write(json.dumps(op) + "\n")
        self.proc.stdin.flush()
        return self._answer()

    def _answer(self):
        while True:
            text = self.proc.stdout.readline()
            if not text:
                self._stderr.seek(0)
                raise EmuError("the emulator failed (status %s): %s" % (
                    self.proc.wait(), self._stderr.read().strip()[-2000:]))
            if text.startswith(ANSWER):
                break
        got = json.loads(text[len(ANSWER):])
        self.now = got["emu_s"]
        self.stopped = got["stopped"]
        self.transcript.extend(tuple(e) for e in got["events"])
        got["lines"] = [e[2] for e in got["events"] if e[1] == "<"]
        return got

    # --- as a host ---
    def send(self, data):
        """Bytes (or latin-1 text) to the chip's USB console; nothing runs yet."""
        if isinstance(data, bytes):
            data = data.decode("latin-1")
        self._request(op="send", data=data)

    def run(self, oks=0, match=None, for_s=None, max_s=60.0):
        """Let the chip run until `oks` lines `ok`, a line starting with `match`, or
        `for_s` emulated seconds, whichever comes first. Returns the lines it sent
        meanwhile; raises Stopped if none came within max_s emulated seconds."""
        got = self._request(op="run", oks=oks, match=match, for_s=for_s, max_s=max_s)
        if not got["met"]:
            raise Stopped(got["stopped"] or "no %s within %g emulated s (it said: %s)" % (
                "line %r" % match if match else "ok", max_s, " | ".join(got["lines"][-8:])))
        return got["lines"]

    def command(self, text, max_s=60.0):
        """Send one line and run until its ok: every line the chip sent, ok last."""
        self.send(text + "\n")
        return self.run(oks=1, max_s=max_s)

    def lines_since(self, t):
        """The lines the chip sent at or after emulated second t."""
        return [text for at, way, text in self.transcript if way == "<" and at >= t]

    # --- what was measured ---
    def cpu(self):
        """Emulated nanoseconds so far, asleep, and per exception number (0: thread
        mode): {nanos, slept, exc, entries}."""
        return self._request(op="cpu")["cpu"]

    def profile(self, path=None, gated=False):
        """Profile the program counter from now on (emu/harness.mjs; gated: only while
        the chip's last write to WATCHDOG SCRATCH0 was 1); with path, stop and write
        the profile there as JSON: {clk_sys_hz, thread, irq}, each {self: {address:
        cycles}, by: {native function's address, or 0: flash cycles}}."""
        self._request(op="profile", on=path is None, gated=gated,
                      path=str(path) if path else None)

    def edges(self):
        """(times_ns, gpios, levels) of every recorded pin edge so far."""
        self._edge_files += 1
        path = self.dir / ("edges-%d.bin" % self._edge_files)
        self._request(op="edges", path=str(path))
        return trace.read_edges(path)

    def close(self):
        """End the emulation; the pin edges are then in edges_path. Returns the
        heaters' temperatures and the emulator's own figures."""
        if self.final is None:
            self.final = self._request(op="end", edges=str(self.edges_path))
            self.proc.wait()
        return self.final

    @property
    def edges_path(self):
        return self.dir / "run.edges"

    def write_vcd(self, path):
        trace.write_vcd(self.edges_path, path, self.board, timescale="1 ns",
                        date="mixstep emulated %s" % self.board)

    def net_steps(self):
        return trace.net_steps(self.edges_path, self.board)

    def cleanup(self):
        """Stop the emulator if it still runs and remove the run's files."""
        if self.proc and self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait()
        if self._stderr:
            self._stderr.close()
        keep = os.environ.get("MIXSTEP_EMU_KEEP")  # a folder to keep the run's files in
        if keep and self.dir.exists():
            shutil.copytree(self.dir, keep, dirs_exist_ok=True)
        self._tmp.cleanup()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.cleanup()


def _diag(text):
    """echo:underruns:0 mem_free:1 mem_free_collected:2 -> {"underruns": 0, ...}"""
    return {k: int(v) for k, v in (w.split(":") for w in text[len("echo:"):].split())}


def _diagnose(chip, out):
    for text in chip.command("M122"):
        if text.startswith("echo:underruns:"):
            out["diagnostics"].append(_diag(text))


def stream(chip, gcode_path, diag_every=50):
    """Print a file as a host does: one line per `ok`, then M400, with M122 after every
    diag_every lines and at the end. Returns what the chip answered."""
    out = dict(lines=0, errors=[], console=[], diagnostics=[], stopped=None,
               start=chip.cpu(), end=None)
    try:
        with open(gcode_path, encoding="latin-1") as f:
            for number, raw in enumerate(f, 1):
                if diag_every and number > 1 and (number - 1) % diag_every == 0:
                    _diagnose(chip, out)
                for text in chip.command(raw.rstrip("\r\n")):
                    if text.startswith("Error:"):
                        out["errors"].append("line %d: %s" % (number, text))
                    if text != "ok" and len(out["console"]) < 1000:
                        out["console"].append("line %d: %s" % (number, text))
                out["lines"] += 1
        chip.command("M400")
        out["end"] = chip.cpu()
        _diagnose(chip, out)
    except Stopped as e:
        out["stopped"] = "%s (line %d)" % (e, out["lines"] + 1)
    return out


def run(gcode_path, board="pico", trace_path=None, report_path=None, image_dir=None,
        diag_every=50, max_emu_s=600.0, max_wall_s=3600.0, settings=None):
    """Print gcode_path on the emulated board; returns the report (docs/Emulator.md)."""
    wall0 = time.perf_counter()
    with Chip(board, image_dir, settings, max_emu_s=max_emu_s, max_wall_s=max_wall_s) as chip:
        printed = stream(chip, gcode_path, diag_every)
        final = chip.close()
        if trace_path:
            chip.write_vcd(trace_path)
        steps = chip.net_steps()
        boot_lines = chip.boot_lines
    report = summarize(printed, final, board, gcode_path, steps, boot_lines)
    report["settings"] = dict(settings or {})
    report["wall_seconds"] = round(time.perf_counter() - wall0, 3)
    report["trace"] = str(trace_path) if trace_path else None
    if report_path:
        Path(report_path).write_text(json.dumps(report, indent=2) + "\n")
    return report


def summarize(printed, final, board, gcode_path, steps, boot_lines):
    diags = printed["diagnostics"]
    last = diags[-1] if diags else {}
    start, end = printed["start"], printed["end"]
    report = {
        "gcode": str(gcode_path),
        "board": board,
        "lines": printed["lines"],
        "errors": printed["errors"],
        "stopped": printed["stopped"],  # why the run ended early, or None
        "emulated_seconds": (end["nanos"] - start["nanos"]) / 1e9 if end else None,
        "boot_emulated_seconds": start["nanos"] / 1e9,
        "emulator_wall_seconds": round(final["wall_seconds"], 3),
        "underruns": last.get("underruns"),
        "mem_free_min_bytes": min((d["mem_free_collected"] for d in diags), default=None),
        # gc.mem_free() as M122 found it, before its collection: garbage included.
        "mem_free_uncollected_min_bytes": min((d["mem_free"] for d in diags), default=None),
        "mem_free_samples": len(diags),
        "steps": steps,
        "heaters_c": {h["name"]: round(h["temp_c"], 1) for h in final["heaters"]},
        "boot_lines": boot_lines,
        # What the firmware answered to the file's lines besides `ok` (the first 1000).
        "console": printed["console"],
        "edges": final["edges"],
    }
    if end:
        span = (end["nanos"] - start["nanos"]) / 1e9
        exc = {}
        for n in range(len(start["exc"])):
            seconds = (end["exc"][n] - start["exc"][n]) / 1e9
            if seconds > 0:
                exc[str(n)] = {"seconds": seconds,
                               "entries": end["entries"][n] - start["entries"][n]}
        step = sum(exc.get(str(n), {}).get("seconds", 0) for n in STEP_EXCEPTIONS)
        slept = (end["slept"] - start["slept"]) / 1e9
        report["cpu_step_fraction"] = round(step / span, 4) if span else None
        report["cpu_busy_fraction"] = round(1 - slept / span, 4) if span else None
        report["cpu_by_exception"] = {n: dict(e, fraction=round(e["seconds"] / span, 4))
                                      for n, e in exc.items()}
    return report


# The step paths that run a timer callback every tick (timer, pio) need ticks this long
# on an RP2040: a callback costs about 15 us (boards/pico/board.py).
_CALLBACK_TICK_MIN_US = 50


def check_tick(board, settings):
    """EmuError for a step path a tick too short for it, said before the emulator
    spends a minute finding out."""
    s = dict(paths.load_board(board)["SETTINGS"], **settings)
    if s.get("step_backend") in ("timer", "pio") and s["tick_us"] < _CALLBACK_TICK_MIN_US:
        raise EmuError("step_backend %s runs a timer callback every tick, which takes "
                       "about 15 us on an RP2040: %d us ticks leave it no time; add "
                       "--set tick_us=%d" % (s["step_backend"], s["tick_us"],
                                             _CALLBACK_TICK_MIN_US))


def _print(args):
    try:
        settings = boards.set_items(args.board, args.set)
        check_tick(args.board, settings)
        # The excerpt `make emu` prints: the whole example takes the emulator hours.
        report = run(args.gcode or paths.ROOT / "testdata" / "part_3tool_emu_excerpt.gcode",
                     args.board, args.trace, args.report, args.image, args.diag_every,
                     args.max_emu_s, args.max_wall_s, settings=settings)
    except (EmuError, deploy.DeployError) as e:
        print("mixstep emu: %s" % e, file=sys.stderr)
        return 2
    sim.print_summary(report, ("lines", "emulated_seconds", "emulator_wall_seconds",
                               "wall_seconds", "cpu_step_fraction", "cpu_busy_fraction",
                               "mem_free_min_bytes", "underruns", "stopped"))
    if report["stopped"]:
        print("mixstep emu: stopped early: %s" % report["stopped"], file=sys.stderr)
    return 1 if report["errors"] or report["stopped"] else 0


def add_parser(sub):
    p = sub.add_parser("emu", help="run the firmware on an emulated board (rp2040js)")
    esub = p.add_subparsers(dest="emu_command", required=True)
    q = esub.add_parser("print", help="boot the firmware on an emulated Pico and print a "
                                      "G-code file over its USB console")
    q.add_argument("gcode", nargs="?", help="G-code file (default: the first lines of the "
                                            "example 3-colour print, as make emu prints)")
    q.add_argument("--board", default="pico", help="an RP2040 board (boards/<name>)")
    q.add_argument("--trace", help="write the STEP/DIR/ENABLE trace here (VCD, 1 ns)")
    q.add_argument("--report", help="write the JSON report here")
    q.add_argument("--image", metavar="DIR",
                   help="folder with MicroPython's firmware.uf2 and the boot ROM "
                        "(bootrom.js or bootrom.bin); default ../shared/rp2emu/")
    q.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="override a board setting for this run, written into board.py on "
                        "the emulated flash, e.g. step_backend=pio (repeatable)")
    q.add_argument("--diag-every", type=int, default=50, metavar="N",
                   help="send M122 (underruns, free heap) every N lines; 0: at the end only")
    q.add_argument("--max-emu-s", type=float, default=600.0,
                   help="give up after this many emulated seconds")
    q.add_argument("--max-wall-s", type=float, default=3600.0,
                   help="give up after this many wall seconds")
    q.set_defaults(run=_print)
