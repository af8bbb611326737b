"""Step timing on the unix port: every step against the ideal time of that step in the
trapezoid planned for its block (mixstep.steptiming, the measurement `make bench`
reports). A step can only fall on a tick, so a step loop on the plan takes each step
at the first tick at or after its ideal time: 0 to one tick late, never early."""
import json
from math import isqrt

import numpy as np
import pytest
from hypothesis import assume, given, settings, strategies as st

from mixstep import paths, steptiming

SAMPLES = paths.ROOT / "testdata"
BOUND_US = 25  # Klipper's step-compression bound (issue 6)


@pytest.mark.parametrize("gcode, lines", [
    # Homing, a Z lift, retractions, travel and the skirt.
    ("part_3tool_prusaslicer_rel.gcode", 60),
    # Homing, a long Z move, a slow E-only prime, travel and the skirt.
    ("cura_part_3tool.gcode", 60),
])
def test_steps_of_a_real_print_fall_within_a_tick_of_the_plan(tmp_path, gcode, lines):
    snippet = tmp_path / "snippet.gcode"
    snippet.write_text(steptiming.snippet(SAMPLES / gcode, lines))
    res = steptiming.measure(snippet, tmp_path)
    assert res["firmware_errors"] == []
    assert res["step_time_blocks"] > 20
    # Slowing down to a low exit speed once left the last steps milliseconds late.
    assert res["step_time_error_all_axes_max_us"] <= BOUND_US
    assert res["step_time_error_earliest_us"] >= -1


# One block run by the step loop with the schedule the planner gives its record; the
# ticks (from 1, the first ramp tick) at which the lead axis (X) stepped.
ONE_BLOCK = """
import sys, json
from array import array
from mixfw import stepper as st
from mixfw.planner import ramp_ticks

n, r0, r_nom, r1, acc, phase = json.loads(sys.stdin.read())
mem = array("i", bytes(4 * st.mem_words(2)))
mem[st.S_QUEUE] = 2
mem[st.S_PULSE_TICKS] = 1  # as on the simulated board: high one tick, low one tick
mem[st.MASK_BASE + st.X] = 1
regs = array("i", bytes(12))  # scratch set/clear registers at words 1, 2
mem[st.S_REG_SET] = 1
mem[st.S_REG_CLR] = 2
b = st.BLOCK_BASE
mem[b + st.B_N] = mem[b + st.B_STEPS + st.X] = n
mem[b + st.B_RATE_INIT] = r0
mem[b + st.B_RATE_NOM] = r_nom
mem[b + st.B_RATE_FINAL] = r1
mem[b + st.B_ACCEL] = acc
mem[b + st.B_ACCEL_UNTIL], mem[b + st.B_DECEL_AFTER], mem[b + st.B_RATE_DECEL] = \\
    ramp_ticks(n, r0, r_nom, r1, acc)
mem[st.S_PHASE] = phase
mem[st.S_HEAD] = 1
ticks = []
t = 0
io = (mem, regs, None)
while mem[st.S_BLOCKS_DONE] == 0:
    t += 1
    if st.tick(io):
        ticks.append(t)
print(json.dumps(ticks))
"""

ONE = 1 << 28


@st.composite
def trapezoids(draw):
    """Records as the planner writes them: rates between the slowest it allows (at rest
    within half a step) and half a step per tick, entry and exit reachable in n steps;
    the phase a block inherits is below a step's rate."""
    acc = draw(st.integers(500, 20000))
    floor = isqrt(acc * ONE)
    rate = st.integers(floor, ONE // 2)
    r_nom = draw(rate)
    r0 = min(draw(rate), r_nom)
    r1 = min(draw(rate), r_nom)
    n = draw(st.integers(1, 300))
    assume(abs(r0 * r0 - r1 * r1) <= 2 * acc * n * ONE)
    phase = draw(st.integers(0, ONE // 2 - 1))
    return n, r0, r_nom, r1, acc, phase


@settings(max_examples=40, deadline=None)
@given(trapezoids())
def test_any_planned_trapezoid_is_stepped_within_a_tick_of_its_ideal_times(mp, record):
    n, r0, r_nom, r1, acc, phase = record
    ticks = np.array(mp.json(ONE_BLOCK, stdin=json.dumps(record).encode()))
    assert len(ticks) == n
    ideal = steptiming.ideal_times_us(np.arange(1, n + 1), phase / ONE, n, r0 / ONE,
                                      r_nom / ONE, r1 / ONE, acc / ONE)  # one "us" a tick
    late = ticks - ideal
    # The ramp leaves the plan by less than a few acc in position: hundredths of a tick
    # even at the slowest rate.
    assert late.min() >= -0.02
    assert late.max() <= 1.02


@settings(max_examples=200, deadline=None)
@given(trapezoids())
def test_the_trapezoid_formulas_agree_with_the_motions_physics(record):
    """ideal_times_us (the trapezoid's corners in closed form) against
    physics_times_us (the fastest motion v^2 = v0^2 + 2as allows, within the cruise
    speed and the braking to the exit speed, with its pieces found by bisection): the
    same times, to far below a tick, for any block the planner may record."""
    n, r0, r_nom, r1, acc, phase = record
    args = (np.arange(1, n + 1), phase / ONE, n, r0 / ONE, r_nom / ONE, r1 / ONE, acc / ONE)
    closed = steptiming.ideal_times_us(*args)
    physics = steptiming.physics_times_us(*args)
    assert np.abs(closed - physics).max() <= 1e-6 * max(1.0, physics.max())
