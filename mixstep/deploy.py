"""`mixstep deploy`, `mixstep freeze`, `mixstep board-check`: the firmware onto a board.

deploy compiles every module of firmware/mixfw with mpy-cross for the board's chip
into build/<board>/, checks that the board's MicroPython loads that .mpy version,
copies the files with mpremote and resets the board. A board running mixstep is
first asked with M997 to restart into the REPL, as it ignores mpremote's Ctrl-C.
boot.py, main.py and board.py stay source: MicroPython runs boot.py and main.py at
boot only as .py files (boot.py first: it turns the drivers off), and board.py is the
file one edits on the board (pins, settings) without a host.
"""
import json
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

from mixstep import boards, paths, webfiles
from mixfw import inram

# mpy-cross -march per chip: viper and native code are machine code for this core.
MARCH = {"rp2040": "armv6m", "rp2350": "armv7emsp", "esp32": "xtensawin"}
# Native architecture numbers in .mpy headers and sys.implementation._mpy, in the
# order of mpy-cross's -march list.
ARCH_NAMES = ("none", "x86", "x64", "armv6", "armv6m", "armv7m", "armv7em", "armv7emsp",
              "armv7emdp", "xtensa", "xtensawin", "rv32imc", "rv64imc")
# Oldest MicroPython per chip: rp2 timers have hard callbacks only since 1.26; the
# .mpy v6.3 files of this mpy-cross load from 1.23 on.
MIN_VERSION = {"rp2040": (1, 26, 0), "rp2350": (1, 26, 0), "esp32": (1, 23, 0)}
PLATFORM = {"rp2040": "rp2", "rp2350": "rp2", "esp32": "esp32"}
# MicroPython port and board to build a frozen image with.
PORT_BOARD = {"rp2040": ("rp2", "RPI_PICO"), "rp2350": ("rp2", "RPI_PICO2"),
              "esp32": ("esp32", "ESP32_GENERIC")}
SOURCE_FILES = ("boot.py", "main.py", "board.py")
# Chips whose boards have a network: the web page's files go onto their flash (web/).
NETWORK_CHIPS = ("esp32",)

# Run on the board: what MicroPython it is, as one JSON line.
INFO_CODE = ("import sys, json; i = sys.implementation; print(json.dumps({"
             "'version': list(i.version[:3]), 'mpy': getattr(i, '_mpy', None), "
             "'platform': sys.platform, 'machine': getattr(i, '_machine', '')}))")
# Run on the board: keep the previous mixfw package as mixfw.bak until the new one is
# on (a copy cut short leaves the old firmware to put back), and remove the step path
# copy, so no stale module survives (a left-over .py would even win over the new .mpy,
# and a mixfw folder would hide a frozen one). /mixstep.cfg stays.
_RM_CODE = ("import os\n"
               "def rm(p):\n"
               "    try:\n"
               "        mode = os.stat(p)[0]\n"
               "    except OSError:\n"
               "        return\n"
               "    if mode & 0x4000:\n"
               "        for n in os.listdir(p):\n"
               "            rm(p + '/' + n)\n"
               "        os.rmdir(p)\n"
               "    else:\n"
               "        os.remove(p)\n")
REMOVE_CODE = (_RM_CODE + "rm('mixfw.bak')\n"
               "try:\n"
               "    os.rename('mixfw', 'mixfw.bak')\n"
               "except OSError:\n"
               "    pass\n"
               "rm('%s')\n" % inram.RAM_DIR.lstrip("/"))
# Run on the board once the new package is on.
DROP_BACKUP_CODE = _RM_CODE + "rm('mixfw.bak')\n"
# Run on the board: whether it has a board.py of its own (the user's, edited there).
HAS_BOARD_CODE = ("import os, json\n"
                  "print(json.dumps({'board_py': 'board.py' in os.listdir()}))")
# Run on the board before a board.py replaces the user's: the old one is kept.
BACKUP_BOARD_CODE = ("import os\n"
                     "try:\n"
                     "    os.remove('board.py.bak')\n"
                     "except OSError:\n"
                     "    pass\n"
                     "os.rename('board.py', 'board.py.bak')\n")


class DeployError(Exception):
    """A reason not to touch the board, said so the user can act on it."""


def _tool(name):
    """A command installed next to this Python (.venv/bin) or on PATH."""
    local = Path(sys.executable).parent / name
    if local.exists():
        return str(local)
    found = shutil.which(name)
    if not found:
        raise DeployError("%s not found: run `make setup` (it installs %s into .venv)"
                          % (name, name))
    return found


def board_chip(board):
    """The board's chip, after its pin map passes `mixstep boards check`."""
    problems = boards.check_board(board)
    if problems:
        raise DeployError("board %s has pin-map problems; fix them first:\n  %s"
                          % (board, "\n  ".join(problems)))
    chip = paths.load_board(board)["SETTINGS"]["chip"]
    if chip not in MARCH:
        raise DeployError("board %s is chip %r, which runs on the host, not on a "
                          "MicroPython board (boards with a chip: %s)" % (
                              board, chip, ", ".join(n for n in boards.board_names()
                                                     if n != "sim")))
    return chip


def build(board, out_dir=None):
    """Compile the firmware for the board's chip into build/<board>/; returns the dir."""
    chip = board_chip(board)
    out = Path(out_dir) if out_dir else paths.ROOT / "build" / board
    if out.exists():
        shutil.rmtree(out)
    compile_mixfw(out, MARCH[chip])
    for name in ("boot.py", "main.py"):
        shutil.copy(paths.FIRMWARE / name, out / name)
    shutil.copy(paths.BOARDS / board / "board.py", out / "board.py")
    if chip in NETWORK_CHIPS:
        webfiles.build(out / "web")
    return out


# -O3: no line numbers in the bytecode and no asserts (the unix port's tests run them
# from source): 6 % less code, and on a chip the code lives in the heap.
OPT = "-O3"


def compile_mixfw(out, march):
    """Every module of firmware/mixfw compiled with mpy-cross -march=<march> into
    <out>/mixfw/*.mpy."""
    (out / "mixfw").mkdir(parents=True, exist_ok=True)
    cross = _tool("mpy-cross")
    for src in sorted((paths.FIRMWARE / "mixfw").glob("*.py")):
        dst = out / "mixfw" / (src.stem + ".mpy")
        cmd = [cross, "-march=" + march, OPT, "-s", "mixfw/" + src.name, "-o", str(dst),
               str(src)]
        proc = subprocess.run(cmd, capture_output=True, text=True)
        if proc.returncode != 0:
            raise DeployError("mpy-cross failed on %s:\n%s" % (src.name, proc.stderr.strip()))


def mpy_header(path):
    """(mpy version, sub-version, native arch number) from a .mpy file's header."""
    head = Path(path).read_bytes()[:4]
    if len(head) < 4 or head[0] != ord("M"):
        raise DeployError("%s is not a .mpy file" % path)
    return head[1], head[2] & 3, head[2] >> 2


def mpy_qstrs(path):
    """The names a .mpy file interns as it loads: the strings of its qstr table (those
    not in mpy-cross's own table). The table follows the 4-byte header: its count and
    the object count as variable-length ints, then each entry as (length << 1) |
    static, and for a name not static its bytes and a 0."""
    data = Path(path).read_bytes()
    at = 4

    def vuint():
        nonlocal at
        value = 0
        while True:
            byte = data[at]
            at += 1
            value = (value << 7) | (byte & 0x7F)
            if not byte & 0x80:
                return value

    names = []
    count = vuint()
    vuint()  # the objects
    for _ in range(count):
        entry = vuint()
        if not entry & 1:
            names.append(data[at:at + (entry >> 1)].decode())
            at += (entry >> 1) + 1
    return names


def check_mpy_compatible(board_mpy, headers):
    """Refuse unless the board loads every file: the same .mpy version, and for files
    with native (viper) code the same sub-version and architecture.
    board_mpy: the board's sys.implementation._mpy (None if it has none);
    headers: mpy_header() of each compiled file."""
    if board_mpy is None:
        raise DeployError("the board's MicroPython has no sys.implementation._mpy, so it "
                          "predates the .mpy files mpy-cross writes here: flash a newer "
                          "MicroPython")
    ver, sub, arch = board_mpy & 0xFF, (board_mpy >> 8) & 3, board_mpy >> 10
    for f_ver, f_sub, f_arch in sorted(set(headers)):
        if f_ver != ver:
            raise DeployError(
                "mpy version mismatch: mpy-cross writes .mpy v%d, the board's MicroPython "
                "loads v%d. Flash a MicroPython that matches mpy-cross (or pin mpy-cross "
                "to the board's version in pyproject.toml)" % (f_ver, ver))
        if f_arch and f_sub != sub:
            raise DeployError("mpy sub-version mismatch: native code compiled as v%d.%d, "
                              "the board's MicroPython loads v%d.%d" % (f_ver, f_sub, ver, sub))
        if f_arch and f_arch != arch:
            raise DeployError(
                "architecture mismatch: the viper code is compiled for %s, the board's "
                "MicroPython runs %s: is --board right for this board?" % (
                    _arch_name(f_arch), _arch_name(arch)))


def _arch_name(number):
    return ARCH_NAMES[number] if number < len(ARCH_NAMES) else "arch %d" % number


def check_board_info(info, chip):
    """Refuse a board that runs another platform or too old a MicroPython."""
    if info.get("platform") != PLATFORM[chip]:
        raise DeployError("the board reports platform %r, but this board definition is "
                          "for %s (%s)" % (info.get("platform"), chip, PLATFORM[chip]))
    version = tuple(info.get("version", ()))[:3]
    if version < MIN_VERSION[chip]:
        raise DeployError("the board runs MicroPython %s; mixstep on %s needs %s or newer%s"
                          % (".".join(map(str, version)), chip,
                             ".".join(map(str, MIN_VERSION[chip])),
                             " (hard machine.Timer callbacks)" if chip != "esp32" else ""))


def _connect(port):
    return [_tool("mpremote"), "connect", port]


def _show(cmd):
    print(" ".join(shlex.quote(str(c)) for c in cmd))


def _json_line(text):
    for line in reversed(text.splitlines()):
        if line.startswith("{"):
            return json.loads(line)
    raise DeployError("no JSON line in the board's answer:\n%s" % text)


def _run(cmd, capture=False):
    proc = subprocess.run([str(c) for c in cmd], capture_output=capture, text=True)
    if proc.returncode != 0:
        raise DeployError("`%s` failed (status %d)%s" % (
            " ".join(map(str, cmd[:4])), proc.returncode,
            ":\n" + (proc.stderr or proc.stdout).strip() if capture else ""))
    return proc.stdout


def stop_firmware(port, wait_s=10.0):
    """A board running mixstep ignores mpremote's Ctrl-C (a host's 0x03 must not stop a
    print), so ask it with M997 to restart into the REPL once, and wait for its port to
    come back. A board that is not running mixstep just sees a line at its REPL."""
    if send_m997(port):
        wait_for_port(port, wait_s)


def send_m997(port):
    """True if mixstep answered M997 on port (it then leaves and the board resets)."""
    import serial  # pyserial, which mpremote needs too
    import time
    try:
        link = serial.Serial(port, 115200, timeout=0.2)
    except (serial.SerialException, OSError) as e:
        raise DeployError("could not open %s: %s" % (port, e))
    try:
        link.write(b"\nM997\n")
        link.flush()
    except (serial.SerialException, OSError) as e:
        link.close()
        raise DeployError("could not write to %s: %s" % (port, e))
    text = b""
    with link:
        try:
            deadline = time.monotonic() + 3.0
            while time.monotonic() < deadline and b"ok" not in text and b">>>" not in text:
                text += link.read(256)
        except (serial.SerialException, OSError):
            # The port went away after M997, before its ok was read: the board is
            # resetting, which only mixstep does on M997 (a REPL answers an error).
            return True
    return b"ok" in text


def wait_for_port(port, wait_s):
    """A board that resets drops its USB serial port and brings it back."""
    import serial
    import time
    deadline = time.monotonic() + wait_s
    time.sleep(0.5)
    while time.monotonic() < deadline:
        try:
            serial.Serial(port, 115200, timeout=0.2).close()
            return
        except (serial.SerialException, OSError):
            time.sleep(0.2)
    raise DeployError("%s did not come back after M997 within %.0f s" % (port, wait_s))


def _board_py_commands(out, c, board_py):
    """board_py: "copy" (the board has none), "replace" (--force: the board's is kept as
    board.py.bak) or "keep" (the board's own stays)."""
    if board_py == "keep":
        return []
    backup = [c + ["exec", BACKUP_BOARD_CODE]] if board_py == "replace" else []
    return backup + [c + ["cp", out / "board.py", ":"]]


def deploy_commands(out, port, board_py="copy"):
    """The mpremote commands that put build dir `out` onto the board."""
    c = _connect(port)
    sources = [out / name for name in SOURCE_FILES if name != "board.py"]
    return ([c + ["exec", REMOVE_CODE],
             c + ["cp"] + sources + [":"]]
            + _board_py_commands(out, c, board_py)
            + [c + ["cp", "-r", out / "mixfw", ":"]]
            + _web_commands(out, c)
            + [c + ["exec", DROP_BACKUP_CODE],
               c + ["reset"]])


def _web_commands(out, c):
    return [c + ["cp", "-r", out / "web", ":"]] if (out / "web").exists() else []


def frozen_commands(out, port, board_py="copy"):
    """The mpremote commands for a board whose image has the firmware frozen in:
    board.py, and the step path's modules into inram.RAM_DIR, from which the frozen
    firmware loads their code into RAM (mixfw/inram.py)."""
    c = _connect(port)
    ram_dir = inram.RAM_DIR.lstrip("/")
    return ([c + ["exec", REMOVE_CODE]]
            + _board_py_commands(out, c, board_py)
            + [c + ["mkdir", ":" + ram_dir],
               c + ["cp"] + [out / "mixfw" / (name + ".mpy") for name in inram.STEP_PATH]
               + [":" + ram_dir + "/"]]
            + _web_commands(out, c)
            + [c + ["exec", DROP_BACKUP_CODE],
               c + ["reset"]])


def _board_py(port, force):
    """What to do with board.py on the board (see _board_py_commands), asked of it."""
    has = _json_line(_run(_connect(port) + ["exec", HAS_BOARD_CODE], capture=True))
    if not has.get("board_py"):
        return "copy"
    return "replace" if force else "keep"


def deploy(board, port, dry_run=False, frozen=False, force=False):
    chip = board_chip(board)
    out = build(board)
    headers = [mpy_header(p) for p in sorted((out / "mixfw").glob("*.mpy"))]
    info_cmd = _connect(port) + ["exec", INFO_CODE]
    make = frozen_commands if frozen else deploy_commands
    if dry_run:
        print("# built %s (%d modules, -march=%s); on the board this would run:"
              % (out, len(headers), MARCH[chip]))
        print("# send M997 on %s: a running mixstep restarts into the REPL once" % port)
        print("# check the board's MicroPython (version, .mpy ABI) before copying:")
        for cmd in [info_cmd] + make(out, port, "replace" if force else "copy"):
            _show(cmd)
        print("# board.py goes on only where the board has none%s" % (
            "" if force else " (--force replaces the board's, kept as board.py.bak)"))
        return 0
    stop_firmware(port)
    info = _json_line(_run(info_cmd, capture=True))
    check_board_info(info, chip)
    check_mpy_compatible(info.get("mpy"), headers)
    board_py = _board_py(port, force)
    for cmd in make(out, port, board_py):
        _run(cmd)
    if board_py == "keep":
        print("kept the board's own board.py; --force replaces it with %s (the board's "
              "kept as board.py.bak)" % (paths.BOARDS / board / "board.py"))
    elif board_py == "replace":
        print("replaced the board's board.py; its old one is board.py.bak")
    print("deployed %s to %s (MicroPython %s)" % (board, port, ".".join(map(str, info["version"]))))
    return 0


def freeze_text(board):
    """How to build a MicroPython image with the firmware frozen in."""
    chip = board_chip(board)
    port, mp_board = PORT_BOARD[chip]
    manifest = (paths.BOARDS / board / "manifest.py").resolve()
    need = ".".join(map(str, MIN_VERSION[chip]))
    lines = [
        "# %s (%s): MicroPython %s or newer%s." % (
            board, chip, need, ", for hard machine.Timer callbacks" if port == "rp2" else ""),
        "git clone --depth 1 --branch v%s https://github.com/micropython/micropython"
        % need + "   # or any newer release tag",
        "cd micropython",
        "make -C mpy-cross",
    ]
    if port == "esp32":
        lines.append("# needs ESP-IDF in the version ports/esp32/README.md names: "
                     ". $IDF_PATH/export.sh")
    lines += [
        "make -C ports/%s BOARD=%s submodules" % (port, mp_board),
        "make -C ports/%s BOARD=%s FROZEN_MANIFEST=%s" % (port, mp_board, manifest),
    ]
    if port == "rp2":
        lines.append("# flash: hold BOOTSEL while plugging in, then copy "
                     "ports/rp2/build-%s/firmware.uf2 onto the RP2 drive" % mp_board)
    else:
        lines.append("# flash: esptool.py --chip esp32 --port PORT write_flash -z 0x1000 "
                     "ports/esp32/build-%s/firmware.bin" % mp_board)
    lines += [
        "# then the step path's modules, which run from RAM, never from the flash "
        "cache (%s), and board.py:" % ", ".join(inram.STEP_PATH),
        "mixstep deploy --board %s --port PORT --frozen" % board,
    ]
    lines.append("# A board.py on the board's flash overrides the frozen one (the "
                 "filesystem comes first on sys.path), so pins stay editable.")
    return "\n".join(lines)


def freeze(board):
    print(freeze_text(board))
    return 0


def evaluate_check(report):
    """Problems in a board_check.py report; empty if the board is fit to print."""
    problems = list(report.get("errors", ()))
    if report.get("stuck"):
        problems.append("pins that did not follow the output (shorted or loaded?): %s"
                        % ", ".join(report["stuck"]))
    target, achieved = report.get("target_hz"), report.get("achieved_hz")
    if achieved is not None and target and achieved < 0.98 * target:
        problems.append("the timer reaches %d Hz of %d Hz: raise tick_us" % (achieved, target))
    cost = report.get("step_call_us")
    if cost is not None and cost >= report.get("tick_us", 0) / 2:
        problems.append("one step-loop call takes %.1f us, over half the %d us tick: raise "
                        "tick_us" % (cost, report["tick_us"]))
    return problems


def board_check(board, port, dry_run=False, force=False):
    board_chip(board)
    c = _connect(port)
    push = c + ["cp", paths.BOARDS / board / "board.py", ":board.py"]
    run = c + ["run", paths.BOARDS / "board_check.py"]
    if dry_run:
        print("# send M997 on %s: a running mixstep restarts into the REPL once" % port)
        for cmd in (push, run):
            _show(cmd)
        return 0
    stop_firmware(port)
    board_py = _board_py(port, force)
    if board_py == "keep":
        raise DeployError("the board has a board.py of its own, which board-check would "
                          "replace with %s: --force does (the board's is kept as "
                          "board.py.bak)" % (paths.BOARDS / board / "board.py"))
    if board_py == "replace":
        _run(c + ["exec", BACKUP_BOARD_CODE])
    _run(push)
    report = _json_line(_run(run, capture=True))
    print(json.dumps(report))
    problems = evaluate_check(report)
    for p in problems:
        print("%s: %s" % (board, p), file=sys.stderr)
    print("%s: %s" % (board, "ok" if not problems else "%d problem(s)" % len(problems)))
    return 1 if problems else 0


def _guard(fn, *args):
    try:
        return fn(*args)
    except DeployError as e:
        print("error: %s" % e, file=sys.stderr)
        return 2


def add_parser(sub):
    p = sub.add_parser("deploy", help="compile the firmware for a board and copy it on")
    p.add_argument("--board", required=True, help="board name (boards/<NAME>)")
    p.add_argument("--port", required=True, help="the board's serial port, e.g. /dev/ttyACM0")
    p.add_argument("--dry-run", action="store_true",
                   help="build, then print the mpremote commands instead of running them")
    p.add_argument("--frozen", action="store_true",
                   help="the board runs an image with the firmware frozen in (mixstep "
                        "freeze): copy only board.py and the step path's modules, "
                        "which run from RAM")
    p.add_argument("--force", action="store_true",
                   help="replace the board's own board.py (kept as board.py.bak)")
    p.set_defaults(run=lambda a: _guard(deploy, a.board, a.port, a.dry_run, a.frozen,
                                        a.force))
    p = sub.add_parser("freeze", help="print how to build a MicroPython image with the "
                                      "firmware frozen in")
    p.add_argument("--board", required=True, help="board name (boards/<NAME>)")
    p.set_defaults(run=lambda a: _guard(freeze, a.board))
    p = sub.add_parser("board-check", help="check pins, timer rate and step-loop cost on "
                                           "a connected board")
    p.add_argument("--board", required=True, help="board name (boards/<NAME>)")
    p.add_argument("--port", required=True, help="the board's serial port")
    p.add_argument("--dry-run", action="store_true",
                   help="print the mpremote commands instead of running them")
    p.add_argument("--force", action="store_true",
                   help="replace the board's own board.py (kept as board.py.bak)")
    p.set_defaults(run=lambda a: _guard(board_check, a.board, a.port, a.dry_run,
                                        a.force))
