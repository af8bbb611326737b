"""The step path's code runs from RAM in every deployment (mixfw/inram.py): in a frozen
image the firmware loads the step path's modules from copies on the board's filesystem,
whose code MicroPython loads into the heap, and refuses to start without them. A
frozen image is laid out here as two folders on the unix port: the frozen package and
the board's RAM folder."""
import ast
import shutil
import subprocess
from pathlib import Path

import pytest

from mixfw import inram
from mixstep import cli, deploy, paths

MIXFW = paths.FIRMWARE / "mixfw"
# Builds the printer from a frozen package and prints where each step-path module came
# from; exits with status 1 on an ImportError.
FROZEN_BUILD = Path(__file__).parent / "upy" / "inram_frozen_build.py"

def _run_frozen(tmp_path, in_ram):
    """A frozen image laid out in tmp_path, with the step-path modules in_ram copied to
    its RAM folder: the pio_dma board's printer built from it (FROZEN_BUILD)."""
    frozen = tmp_path / "frozen"
    shutil.copytree(MIXFW, frozen / "mixfw")
    ram = tmp_path / "ram"
    ram.mkdir()
    for name in in_ram:
        shutil.copy(MIXFW / (name + ".py"), ram / (name + ".py"))
    env = paths.micropython_env("pico_6drives")
    env["MICROPYPATH"] = env["MICROPYPATH"].replace(str(paths.FIRMWARE), str(frozen))
    return subprocess.run([paths.micropython(), "-X", "heapsize=4M", str(FROZEN_BUILD),
                           str(frozen), str(ram)],
                          capture_output=True, text=True, env=env, timeout=120)


def test_a_frozen_firmware_runs_its_step_path_from_the_ram_copies(tmp_path):
    proc = _run_frozen(tmp_path, inram.STEP_PATH)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    lines = proc.stdout.splitlines()
    where = dict(line.split(" ", 1) for line in lines if not line.startswith("irq"))
    assert set(where) == set(inram.STEP_PATH)
    for name, path in where.items():
        assert path.startswith(str(tmp_path / "ram")), (name, path)
    assert "irq True" in lines


def test_a_frozen_firmware_without_its_ram_copies_refuses_to_start(tmp_path):
    proc = _run_frozen(tmp_path, [n for n in inram.STEP_PATH if n != "stepper"])
    assert proc.returncode == 1
    assert "mixfw.stepper is not in" in proc.stdout
    assert "mixstep deploy --frozen" in proc.stdout


def _mixfw_imports(name):
    tree = ast.parse((MIXFW / (name + ".py")).read_text())
    found = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.module:
            if node.module == "mixfw":
                found.update(a.name for a in node.names)
            elif node.module.startswith("mixfw."):
                found.add(node.module.split(".")[1])
    return found


def test_the_step_path_list_holds_what_the_interrupts_import():
    # What each step-path module imports is in the list before it, or loaded before
    # the list is (compat: load imports it first; heap: assemble does).
    loaded = {"compat", "heap"}
    for name in inram.STEP_PATH:
        assert _mixfw_imports(name) <= loaded, name
        loaded.add(name)
    # Every module with code a hard interrupt runs is in the list.
    for name in ("stepper", "mixer", "ramp", "piodma"):
        assert name in inram.STEP_PATH


def test_deploy_frozen_copies_only_board_py_and_the_step_path(tmp_path):
    cmds = [[str(c) for c in cmd[3:]] for cmd in deploy.frozen_commands(tmp_path, "COM3")]
    # The old package goes first (a mixfw folder on the board would hide the frozen one),
    # kept as mixfw.bak until the new files are on.
    assert cmds[0][0] == "exec" and "os.rename('mixfw', 'mixfw.bak')" in cmds[0][1]
    assert "rm('mixfw_ram')" in cmds[0][1]
    assert cmds[1] == ["cp", str(tmp_path / "board.py"), ":"]
    assert cmds[2] == ["mkdir", ":mixfw_ram"]
    assert cmds[3] == (["cp"] + [str(tmp_path / "mixfw" / (n + ".mpy"))
                                 for n in inram.STEP_PATH] + [":mixfw_ram/"])
    assert cmds[4][0] == "exec" and cmds[4][1].endswith("rm('mixfw.bak')\n")
    assert cmds[5] == ["reset"]


def test_deploy_keeps_the_boards_own_board_py_unless_forced(tmp_path):
    def copies(board_py):
        return [[str(c) for c in cmd[3:]] for cmd in deploy.deploy_commands(
            tmp_path, "COM3", board_py)]
    board_py = str(tmp_path / "board.py")
    assert any(board_py in cmd for cmd in copies("copy"))
    assert not any(board_py in cmd for cmd in copies("keep"))
    forced = copies("replace")
    at = [i for i, cmd in enumerate(forced) if board_py in cmd][0]
    assert "os.rename('board.py', 'board.py.bak')" in forced[at - 1][1]


def test_deploy_frozen_dry_run(capsys):
    assert cli.main(["deploy", "--board", "pico", "--port", "/dev/ttyACM0", "--dry-run",
                     "--frozen"]) == 0
    out = capsys.readouterr().out
    assert "mkdir :mixfw_ram" in out and "cp -r" not in out


@pytest.mark.parametrize("name", ("pico", "esp32_devkit"))
def test_the_freeze_recipe_ends_with_the_ram_copies(name):
    text = deploy.freeze_text(name)
    assert "mixstep deploy --board %s --port PORT --frozen" % name in text.splitlines()


def test_a_build_from_mpy_files_loads_neither_inram_nor_the_software_pwm():
    # Each module loaded interns its names for good: these are of no use to this board.
    code = ("import sys, simmachine, simtime\n"
            "sys.modules['machine'] = simmachine\n"
            "sys.modules['time'] = simtime\n"
            "from mixfw import assemble\n"
            "assemble.build()\n"
            "print(sorted(m for m in ('mixfw.inram', 'mixfw.softpwm') if m in sys.modules))\n")
    proc = subprocess.run([paths.micropython(), "-X", "heapsize=4M", "-c", code],
                          capture_output=True, text=True,
                          env=paths.micropython_env("pico_6drives"), timeout=120)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert proc.stdout.strip() == "[]"
