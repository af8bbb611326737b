"""Deploying to boards: the mpy-cross build of the whole firmware for every board, the
.mpy version check, the mpremote commands of --dry-run, the freeze recipe, and
boards/board_check.py run against the simulated chip."""
import json
import os
import subprocess

import pytest

from mixstep import boards, cli, deploy, paths

# Every board in boards/; a new one needs its architecture stated here.
REAL_BOARDS = tuple(n for n in boards.board_names() if n != "sim")
ARCH = {"pico": "armv6m", "pico2": "armv7emsp", "esp32_devkit": "xtensawin",
        "skr_pico": "armv6m", "fysetc_e4": "xtensawin", "pico_6drives": "armv6m"}
MODULES = sorted(p.stem for p in (paths.FIRMWARE / "mixfw").glob("*.py"))


def unix_mpy():
    """sys.implementation._mpy of the unix port: the same mpy-cross release."""
    out = subprocess.run([paths.micropython(), "-c",
                          "import sys; print(sys.implementation._mpy)"],
                         capture_output=True, text=True, check=True).stdout
    return int(out)


def board_mpy(version, sub, arch_name):
    return version | sub << 8 | deploy.ARCH_NAMES.index(arch_name) << 10


@pytest.mark.parametrize("name", REAL_BOARDS)
def test_build_every_module(name, tmp_path):
    out = deploy.build(name, tmp_path / name)
    built = sorted(p.stem for p in (out / "mixfw").glob("*.mpy"))
    assert built == MODULES
    for source in ("boot.py", "main.py"):
        assert (out / source).read_text() == (paths.FIRMWARE / source).read_text()
    assert (out / "board.py").read_text() == (paths.BOARDS / name / "board.py").read_text()
    headers = [deploy.mpy_header(p) for p in (out / "mixfw").glob("*.mpy")]
    # Modules with viper code carry the chip's architecture; the rest carry none.
    native = {deploy.ARCH_NAMES[arch] for _, _, arch in headers if arch}
    assert native == {ARCH[name]}
    version, sub = {(v, s) for v, s, a in headers if a}.pop()
    deploy.check_mpy_compatible(board_mpy(version, sub, ARCH[name]), headers)


def test_build_matches_the_unix_port_release(tmp_path):
    # mpy-cross and the unix port are pinned to the same release: same .mpy version.
    out = deploy.build("pico", tmp_path)
    version = {deploy.mpy_header(p)[0] for p in (out / "mixfw").glob("*.mpy")}
    assert version == {unix_mpy() & 0xFF}


def test_version_check_refuses_mismatches():
    viper_v63 = (6, 3, deploy.ARCH_NAMES.index("armv6m"))
    bytecode_v6 = (6, 0, 0)
    ok = board_mpy(6, 3, "armv6m")
    deploy.check_mpy_compatible(ok, [viper_v63, bytecode_v6])
    with pytest.raises(deploy.DeployError, match="mpy version mismatch.*v6.*v5"):
        deploy.check_mpy_compatible(board_mpy(5, 3, "armv6m"), [bytecode_v6])
    with pytest.raises(deploy.DeployError, match="sub-version"):
        deploy.check_mpy_compatible(board_mpy(6, 2, "armv6m"), [viper_v63])
    with pytest.raises(deploy.DeployError, match="armv6m.*xtensawin"):
        deploy.check_mpy_compatible(board_mpy(6, 3, "xtensawin"), [viper_v63])
    with pytest.raises(deploy.DeployError, match="no sys.implementation._mpy"):
        deploy.check_mpy_compatible(None, [bytecode_v6])
    # Bytecode alone loads on any architecture of the same version.
    deploy.check_mpy_compatible(board_mpy(6, 3, "xtensawin"), [bytecode_v6])


def test_board_info_check():
    good = {"platform": "rp2", "version": [1, 26, 0]}
    deploy.check_board_info(good, "rp2040")
    with pytest.raises(deploy.DeployError, match="1.25.1.*1.26.0 or newer"):
        deploy.check_board_info({"platform": "rp2", "version": [1, 25, 1]}, "rp2040")
    with pytest.raises(deploy.DeployError, match="platform 'esp32'"):
        deploy.check_board_info({"platform": "esp32", "version": [1, 27, 0]}, "rp2350")
    deploy.check_board_info({"platform": "esp32", "version": [1, 24, 0]}, "esp32")


def test_deploy_dry_run(capsys):
    assert cli.main(["deploy", "--board", "esp32_devkit", "--port", "/dev/ttyUSB0",
                     "--dry-run"]) == 0
    lines = [l for l in capsys.readouterr().out.splitlines() if "mpremote" in l]
    assert all("connect /dev/ttyUSB0" in l for l in lines)
    assert "exec" in lines[0] and "_mpy" in lines[0]  # the version check comes first
    out = str(paths.ROOT / "build" / "esp32_devkit")
    assert any(l.endswith(" %s/boot.py %s/main.py :" % (out, out)) for l in lines)
    assert any(l.endswith(" %s/board.py :" % out) for l in lines)
    assert any("cp -r" in l and l.endswith("build/esp32_devkit/mixfw :") for l in lines)
    assert lines[-1].endswith("reset")


def test_deploy_refuses_the_sim_and_broken_maps(capsys):
    assert cli.main(["deploy", "--board", "sim", "--port", "x", "--dry-run"]) == 2
    assert "runs on the host" in capsys.readouterr().err
    assert cli.main(["deploy", "--board", "nope", "--port", "x", "--dry-run"]) == 2
    assert "no board of that name" in capsys.readouterr().err


def test_board_check_dry_run(capsys):
    assert cli.main(["board-check", "--board", "pico2", "--port", "COM3", "--dry-run"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0] == "# send M997 on COM3: a running mixstep restarts into the REPL once"
    assert lines[1].endswith("connect COM3 cp %s :board.py" % (paths.BOARDS / "pico2" / "board.py"))
    assert lines[2].endswith("connect COM3 run %s" % (paths.BOARDS / "board_check.py"))


@pytest.mark.parametrize("name,make", [
    ("pico", "make -C ports/rp2 BOARD=RPI_PICO FROZEN_MANIFEST="),
    ("pico2", "make -C ports/rp2 BOARD=RPI_PICO2 FROZEN_MANIFEST="),
    ("fysetc_e4", "make -C ports/esp32 BOARD=ESP32_GENERIC FROZEN_MANIFEST="),
])
def test_freeze_recipe(name, make):
    text = deploy.freeze_text(name)
    assert make + str(paths.BOARDS / name / "manifest.py") in text
    assert ("1.26.0" if "rp2" in make else "1.23.0") in text


@pytest.mark.parametrize("name", REAL_BOARDS)
def test_manifest_names_existing_files(name):
    """Run the manifest with stand-ins for MicroPython's manifest functions."""
    here = paths.BOARDS / name
    seen = []

    def module(path, base_path="."):
        seen.append(here / base_path / path)

    def package(path, base_path="."):
        seen.append(here / base_path / path / "__init__.py")

    def include(path):
        assert path == "$(PORT_DIR)/boards/manifest.py"  # the port's _boot.py and friends
        seen.append(None)

    exec((here / "manifest.py").read_text(),
         {"module": module, "package": package, "include": include})
    assert seen[0] is None and len(seen) == 5
    assert all(p.exists() for p in seen[1:]), seen
    assert seen[1].resolve() == (here / "board.py").resolve()
    assert seen[2].resolve() == (paths.FIRMWARE / "boot.py").resolve()  # drivers off first


def test_evaluate_board_check_report():
    good = {"target_hz": 20000, "achieved_hz": 19990, "tick_us": 50, "step_call_us": 12.0,
            "stuck": [], "errors": []}
    assert deploy.evaluate_check(good) == []
    assert "raise tick_us" in deploy.evaluate_check(dict(good, achieved_hz=15000))[0]
    assert "over half" in deploy.evaluate_check(dict(good, step_call_us=30.0))[0]
    assert "x_step" in deploy.evaluate_check(dict(good, stuck=["x_step"]))[0]


@pytest.mark.parametrize("name", ("pico", "esp32_devkit"))
def test_board_check_script_on_the_simulated_chip(name):
    """board_check.py with the board's map on the simulated chip: in virtual time the
    timer hits its rate exactly, and the firmware builds with this board's map."""
    env = paths.micropython_env(name)
    env["MICROPYPATH"] = os.pathsep.join(str(p) for p in (
        paths.FIRMWARE, paths.BOARDS / name, paths.BOARDS / "sim", paths.BOARDS))
    code = ("import sys, simmachine, simtime\n"
            "sys.modules['machine'] = simmachine\n"
            "sys.modules['time'] = simtime\n"
            "import board_check\n"
            "board_check.run()\n")
    proc = subprocess.run([paths.micropython(), "-c", code], capture_output=True, text=True,
                          env=env, timeout=300)
    assert proc.returncode == 0, proc.stderr
    report = json.loads(proc.stdout.strip().splitlines()[-1])
    board = paths.load_board(name)
    drives = board["SETTINGS"]["drives"]
    assert report["board"] == name
    assert report["pins_toggled"] == 2 * (3 + drives)
    assert report["stuck"] == [] and report["errors"] == []
    assert report["achieved_hz"] == report["target_hz"] == 1000000 // board["SETTINGS"]["tick_us"]
    assert report["max_gap_us"] == board["SETTINGS"]["tick_us"]
    assert report["step_call_us"] is not None
    assert deploy.evaluate_check(report) == []
