"""Step timing on the unix port: every step against the ideal time of that step in the
trapezoid planned for its block (mixstep.steptiming, the measurement `make bench`
reports). A step can only fall on a tick, so a step loop on the plan takes each step
at the first tick at or after its ideal time: 0 to one tick late, never early."""
import json
from math import isqrt

import numpy as np
import pytest
from hypothesis import assume, example, given, settings, strategies as st

from mixstep import paths, steptiming

SAMPLES = paths.ROOT / "testdata"
BOUND_US = 25  # Klipper's step-compression bound


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


ONE = 1 << 28


@st.composite
def trapezoids(draw):
    """Records as the planner writes them: rates between the slowest it allows (at rest
    within half a step) and half a step per tick, entry and exit reachable in n steps;
    the phase a block inherits is below a step's rate."""
    return _record(draw, draw(st.integers(500, 20000)), 300)


def _record(draw, acc, most_steps):
    """A record of up to most_steps steps at acc, as trapezoids() says."""
    floor = isqrt(acc * ONE)
    assume(floor < ONE // 2)
    rate = st.integers(floor, ONE // 2)
    r_nom = draw(rate)
    r0 = min(draw(rate), r_nom)
    r1 = min(draw(rate), r_nom)
    n = draw(st.integers(1, most_steps))
    assume(abs(r0 * r0 - r1 * r1) <= 2 * acc * n * ONE)
    phase = draw(st.integers(0, ONE // 2 - 1))
    return n, r0, r_nom, r1, acc, phase


@settings(max_examples=40, deadline=None)
@given(trapezoids())
@example((299, 4538098, 7607192, 523895, 591, 138445))  # 0.0200004 of a tick after it
def test_any_planned_trapezoid_is_stepped_within_a_tick_of_its_ideal_times(mp, record):
    """One block run by the step loop with the schedule the planner gives its record
    (upy/step_timing_one_block.py): each tick at which the lead axis (X) stepped."""
    n, r0, r_nom, r1, acc, phase = record
    ticks = np.array(mp.script_json("step_timing_one_block",
                                     stdin=json.dumps(record).encode()))
    assert len(ticks) == n
    ideal = steptiming.ideal_times_us(np.arange(1, n + 1), phase / ONE, n, r0 / ONE,
                                      r_nom / ONE, r1 / ONE, acc / ONE)  # one "us" a tick
    late = ticks - ideal
    # The ramp leaves the plan by less than a few acc in position: hundredths of a tick
    # even at the slowest rate (two hundredths and a little, seen).
    assert late.min() >= -0.03
    assert late.max() <= 1.03


@st.composite
def long_ramps(draw):
    """Records with ramps of hundreds to thousands of 10 us ticks, at the accelerations a
    print's moves have there (planner.py's ACC: a rate of tens a tick each tick), and
    any the skip takes (below _RAMP_SKIP_ACC)."""
    acc = draw(st.one_of(st.integers(1, 200), st.integers(200, 0x7FFFF)))
    n, r0, r_nom, r1, acc, phase = _record(draw, acc, 3000)
    assume(n * ONE // min(r0, r1) <= 4000000)  # ticks: a few thousand batches
    return n, r0, r_nom, r1, acc, phase


@settings(max_examples=40, deadline=None)
@given(long_ramps())
def test_a_ramps_ticks_passed_over_at_once_make_the_words_tick_by_tick_makes(mp, record):
    """One block run through the DMA ring's batches by the step loop and by a copy of
    it that passes over no ramp tick at once (upy/step_timing_ring_twice.py): the same
    words in every batch."""
    got = mp.script_json("step_timing_ring_twice", stdin=json.dumps(record).encode())
    assert got["steps"] == record[0]
    assert got["same"], (record, got)


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
