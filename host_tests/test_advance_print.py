"""End to end: the example print advanced by `mixstep advance`, printed on the
simulated printer. `test_advance.py` shows each moved change sits the purge amount of
printing extrusion before its old place (within 1e-4 mm); here the firmware must switch
drives exactly where the advanced G-code says, so every drive's steps equal what the
advanced file asks of it, to the step."""
import pytest
from mixstep import advance, paths, sim, tracecheck
from gcode_model import expected_steps

# make test-all only (a whole advanced print).
pytestmark = pytest.mark.slow

EXAMPLE = paths.ROOT / "testdata" / "part_3tool_prusaslicer_rel.gcode"


def test_advanced_print_switches_drives_where_the_advanced_gcode_says(tmp_path, board):
    advanced = tmp_path / "advanced.gcode"
    report = advance.advance_file(EXAMPLE, advanced, 2.5)
    moved = [c for c in report["changes"] if c.get("advanced_mm")]
    assert len(moved) >= 10
    assert all(abs(c["advanced_mm"] - 2.5) < 1e-4 for c in moved if not c.get("warned"))
    spm = board["SETTINGS"]["steps_per_mm"]
    vcd = tmp_path / "advanced.vcd"
    result = sim.run(advanced, trace_path=vcd)
    assert result["errors"] == []
    # Each colour boundary to the step: every drive step falls in the E move of the
    # advanced G-code that plans it, and each move ends with every drive at its target.
    checked = {c["name"]: c for c in tracecheck.check(vcd, advanced)["checks"]}
    assert checked["moves"]["ok"] is True, checked["moves"]
    want = expected_steps(advanced, spm)
    assert result["steps"] == want
    # The colours really moved: each drive's total differs from the plain print's.
    plain = expected_steps(EXAMPLE, spm)
    assert any(want["e%d" % d] != plain["e%d" % d] for d in range(3))
    # Total filament is the same; each drive rounds to its own nearest step.
    assert abs(sum(want["e%d" % d] for d in range(3)) - sum(plain["e%d" % d] for d in range(3))) <= 1
