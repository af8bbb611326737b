"""The firmware on a MicroPython built like the chips: 32-bit, single-precision floats,
31-bit small ints (../shared/chip32, see its README; MIXSTEP_CHIP32 names another).

Exactness must not hang on the 64-bit port's doubles, and the step loop must not
allocate where a value passes 2**30. So: the example print runs heap-locked on it and
ends on the exact step counts, as on the 64-bit port; and the planner gives the same
steps on both builds for the slicer files in testdata/ and for a long synthetic print
(over 5 m of filament, tool changes, gradients, retractions under every policy).
"""
import os
import random
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest

from mixstep import paths, sim
from gcode_model import expected_steps

CHIP32 = Path(os.environ.get("MIXSTEP_CHIP32")
              or paths.ROOT.parent / "shared" / "chip32" / "micropython")
# Only where the shared build exists (not on CI machines): skipped even with
# MIXSTEP_REQUIRE_ALL=1, since no setup step can provide it.
pytestmark = pytest.mark.skipif(
    not CHIP32.is_file(),
    reason="no 32-bit MicroPython at %s (set MIXSTEP_CHIP32; it is not part of the "
           "setup, so this is skipped even with MIXSTEP_REQUIRE_ALL=1)" % CHIP32)

TESTDATA = paths.ROOT / "testdata"
EXAMPLE = TESTDATA / "part_3tool_prusaslicer_rel.gcode"
SLICER_FILES = ("part_3tool_prusaslicer_rel.gcode", "part_3tool_prusaslicer_abs.gcode",
                "slic3r_part_3tool_rel.gcode", "slic3r_part_3tool_abs.gcode",
                "cura_part_3tool.gcode")
STEP_NAMES = ["x", "y", "z"] + ["e%d" % d for d in range(6)]

def plan_steps(mp, gcode_path):
    """Every line through the firmware's parser and command table into the planner,
    with no stepping (upy/chip32_plan.py): the steps it handed the step loop for
    every axis and drive."""
    out = mp.script_json("chip32_plan", gcode_path)
    assert not out["errors"], out["errors"]
    return dict(zip(STEP_NAMES, out["steps"]))


def both_builds(mp, gcode_path):
    with ThreadPoolExecutor(2) as pool:
        runs = [pool.submit(plan_steps, on, gcode_path)
                for on in (mp.using(CHIP32), mp.using(paths.micropython()))]
        return [r.result() for r in runs]


def synthetic_print(path, seed=12):
    """A long print with every way E moves: relative and absolute E with G92, mixes and
    tool changes, Z and E gradients, E retractions, wipes and G10/G11 under each
    retract_policy. Returns its filament in mm."""
    rnd = random.Random(seed)
    out = ["G28", "G90", "M163 S0 P0.3", "M163 S1 P0.5", "M163 S2 P0.2", "M164 S4",
           "M567 P5 E1:2:3:0:1:0", "M165 A0.1 B0.2 C0.3 D0.15 H0.25 I0"]
    fed_mm = 0.0
    z = 0.2
    layer = 0
    for policy in (0, 1, 2):
        out += ["M926 Iretract_policy V%d" % policy, "M930"]
        for _ in range(70):
            layer += 1
            z = round(z + 0.2, 2) if z < 190 else 0.4
            kind = layer % 5
            if kind == 0:
                out.append("M166 A%.1f Z%.1f I0 J2 S1" % (z, z + 3))
            elif kind == 1:
                out.append("M169 E0:1,%d:3,%d:5" % (rnd.randint(20, 60), rnd.randint(70, 140)))
            elif kind == 2:
                out.append("M169")
            out.append("T%d" % rnd.randrange(6))
            absolute = layer % 2 == 0
            out += ["M82" if absolute else "M83", "G92 E0", "G1 Z%.2f F3000" % z]
            e_abs = 0.0
            for _ in range(140):
                x = rnd.uniform(10, 240)
                y = rnd.uniform(10, 240)
                de = round(rnd.uniform(0.002, 0.5), 5)
                fed_mm += de
                if absolute:
                    e_abs = round(e_abs + de, 5)
                    out.append("G1 X%.3f Y%.3f E%.5f F%d" % (x, y, e_abs, rnd.choice((1800, 2400, 4800))))
                else:
                    out.append("G1 X%.3f Y%.3f E%.5f F%d" % (x, y, de, rnd.choice((1800, 2400, 4800))))
                r = rnd.random()
                if r < 0.04:
                    out += ["G10", "G1 X%.3f F9000" % rnd.uniform(10, 240), "G11"]
                elif r < 0.08:
                    back = round(rnd.uniform(0.2, 2.0), 5)
                    if absolute:
                        out += ["G1 E%.5f F2400" % (e_abs - back), "G1 X%.3f F9000" % rnd.uniform(10, 240),
                                "G1 E%.5f F2400" % e_abs]
                    else:
                        out += ["G1 E-%.5f F2400" % back, "G1 X%.3f F9000" % rnd.uniform(10, 240),
                                "G1 E%.5f F2400" % back]
                elif r < 0.10 and not absolute:  # a wipe: retraction while moving
                    out += ["G1 X%.3f E-0.4 F3000" % rnd.uniform(10, 240), "G1 E0.4 F2400"]
                elif r < 0.11 and not absolute:  # T<n> mid-layer, after a retraction
                    out += ["G1 E-1.5 F2400", "T%d" % rnd.randrange(6), "G1 E1.5 F2400"]
    Path(path).write_text("\n".join(out) + "\n")
    return fed_mm


@pytest.mark.slow
def test_example_prints_heap_locked_on_chip32_with_the_exact_steps(monkeypatch):
    """The whole example, stepped by the viper step loop with the heap locked around
    every tick, on the 32-bit build: no allocation, and the exact step counts (those
    the G-code asks for, which the 64-bit port gives too)."""
    monkeypatch.setenv("MIXSTEP_MICROPYTHON", str(CHIP32))
    report = sim.run(EXAMPLE, heap_lock=True)
    assert not report["errors"], report["errors"][:5]
    want = expected_steps(EXAMPLE, paths.load_board("sim")["SETTINGS"]["steps_per_mm"])
    assert report["steps"] == want
    assert report["firmware_steps"] == want


@pytest.mark.parametrize("name", SLICER_FILES)
def test_slicer_files_plan_the_same_steps_on_both_builds(mp, name):
    path = TESTDATA / name
    chip32, wide = both_builds(mp, path)
    assert chip32 == wide
    assert chip32 == expected_steps(path, paths.load_board("sim")["SETTINGS"]["steps_per_mm"])


def test_long_synthetic_print_plans_the_same_steps_on_both_builds(mp, tmp_path):
    path = tmp_path / "long.gcode"
    fed_mm = synthetic_print(path)
    assert fed_mm > 5000
    chip32, wide = both_builds(mp, path)
    assert chip32 == wide
