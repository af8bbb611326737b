"""Transitions in firmware: with L1/L2 set, a tool change applies L0 = L1 + L2/2 of
printing extrusion before the G-code places it, splitting the move that crosses that
point; the simulated trace shows the drive switch there."""
import pytest
import numpy as np

from mixstep import advance, paths, trace, tracecheck

E_SPM = 415
X_SPM = 80


def configured(sim_printer, tmp_path, l1_mm, l2_mm):
    """A configuration file with these L1 and L2 saved in it."""
    cfg = tmp_path / "mixstep.cfg"
    p = sim_printer(config_path=cfg)
    p.send("M926 Itransition_l1_mm V%s" % l1_mm)
    p.send("M926 Itransition_l2_mm V%s" % l2_mm)
    p.send("M500")
    p.finish()
    return cfg


def test_tool_change_applies_l0_early_and_the_trace_shows_it(sim_printer, tmp_path, board):
    cfg = configured(sim_printer, tmp_path, 1.0, 3.0)  # L0 = 2.5 mm
    edges = tmp_path / "run.edges"
    p = sim_printer(config_path=cfg, edges_path=edges, cold_extrusion=True)
    for line in ("M83", "G1 X10 E5 F1200", "T1", "G1 X20 E5", "M400"):
        assert p.send(line)[-1] == "ok"
    steps = p.finish()["steps"]
    # Each drive at its exact filament, rounded half away from zero: 1037.5 -> 1038.
    assert (steps["e0"], steps["e1"], steps["x"]) == (1038, 3113, 20 * X_SPM)
    # In the trace, drive e1's first step comes when X has reached the split point:
    # 2.5 mm of the first move's 5 mm of E before its end, so X = 5 mm.
    t, g, v = trace.read_edges(edges)
    pins = board["PINS"]
    first_e1 = t[(g == pins["e1_step"]) & (v == 1) & (t > 0)][0]
    x_before = np.sum((g == pins["x_step"]) & (v == 1) & (t > 0) & (t <= first_e1))
    assert abs(x_before - 5 * X_SPM) <= 1
    last_e0 = t[(g == pins["e0_step"]) & (v == 1) & (t > 0)][-1]
    assert last_e0 < first_e1


def test_a_tool_pair_uses_its_own_l1_and_l2(sim_printer, tmp_path, board):
    cfg = configured(sim_printer, tmp_path, 1.0, 3.0)  # L0 = 2.5 mm for any change without a pair
    p = sim_printer(config_path=cfg)
    assert p.send("M926 Itransition_pairs_0 V0:1:0.5:1.0")[-1] == "ok"  # T0 -> T1: 1 mm
    assert p.send("M926 Itransition_pairs_1 V0:99:1:1")[0].startswith(
        "Error:transition_pairs_1: tools (0, 99) must be T0..T15")
    assert p.send("M926 Itransition_pairs_1 V1:2:x")[0].startswith(
        "Error:transition_pairs_1: '1:2:x' is not a tool pair from:to:l1_mm:l2_mm")
    assert any(l.startswith("echo:M926 Itransition_pairs_0 V0:1:0.5:1.0 ;") for l in p.send("M503"))
    p.send("M500")
    p.finish()
    edges = tmp_path / "run.edges"
    p = sim_printer(config_path=cfg, edges_path=edges, cold_extrusion=True)
    for line in ("M83", "G1 X10 E5 F1200", "T1", "G1 X20 E5", "T0", "G1 X30 E5", "M400"):
        assert p.send(line)[-1] == "ok"
    p.finish()
    t, g, v = trace.read_edges(edges)
    pins = board["PINS"]

    def x_at(time):
        return np.sum((g == pins["x_step"]) & (v == 1) & (t > 0) & (t <= time)) / X_SPM

    e1 = t[(g == pins["e1_step"]) & (v == 1) & (t > 0)]
    e0 = t[(g == pins["e0_step"]) & (v == 1) & (t > 0)]
    # T0 -> T1 by its pair's 1 mm of E (2 mm of X); T1 -> T0 by the default 2.5 mm (5 mm).
    assert abs(x_at(e1[0]) - 8.0) <= 1.5 / X_SPM
    assert abs(x_at(e0[e0 > e1[0]][0]) - 15.0) <= 1.5 / X_SPM


def test_too_little_extrusion_before_a_change_is_reported(sim_printer, tmp_path):
    cfg = configured(sim_printer, tmp_path, 1.0, 3.0)
    p = sim_printer(config_path=cfg, cold_extrusion=True)
    p.send("M83")
    p.send("G1 X1 E1 F1200")
    reply = p.send("T1")
    assert reply[0] == ("echo:transition advanced 1.000 of 2.500 mm: too little extrusion "
                        "queued before the change")
    p.send("G1 X5 E4")
    steps = p.finish()["steps"]
    assert (steps["e0"], steps["e1"]) == (0, 5 * E_SPM)


@pytest.mark.slow
def test_the_example_print_with_firmware_transitions_keeps_every_step(sim_printer, tmp_path,
                                                                      board):
    cfg = configured(sim_printer, tmp_path, 1.0, 3.0)
    gcode = paths.ROOT / "testdata" / "part_3tool_prusaslicer_rel.gcode"
    p = sim_printer(config_path=cfg)
    errors = []
    for line in open(gcode):
        errors += [r for r in p.send(line.rstrip("\n")) if r.startswith("Error")]
    steps = p.finish()["steps"]
    assert errors == []
    from gcode_model import expected_steps
    plain = expected_steps(gcode, board["SETTINGS"]["steps_per_mm"])
    assert steps["x"] == plain["x"] and steps["y"] == plain["y"] and steps["z"] == plain["z"]
    # Filament moved between drives, none lost.
    assert abs(sum(steps["e%d" % d] for d in range(3)) - sum(plain["e%d" % d] for d in range(3))) <= 2
    assert steps["e0"] != plain["e0"]


@pytest.mark.slow
def test_firmware_transitions_put_every_boundary_where_advance_does(sim_printer, tmp_path, board):
    """The plain example printed with L1 = 1, L2 = 2.5 in firmware switches drives at
    the same steps as the G-code `mixstep advance --l1-mm 1 --l2-mm 2.5` writes: its
    trace passes trace check's move walk against the advanced file, where every drive
    step must fall in the E move that plans it. (L0 = 2.25 mm is 933.75 steps; an L0 of
    2.5 mm would be 1037.5, a tie that the file's 5 decimals can round the other way.)"""
    cfg = configured(sim_printer, tmp_path, 1.0, 2.5)
    gcode = paths.ROOT / "testdata" / "part_3tool_prusaslicer_rel.gcode"
    edges = tmp_path / "run.edges"
    p = sim_printer(config_path=cfg, edges_path=edges)
    for line in open(gcode):
        p.send(line.rstrip("\n"))
    p.finish()
    vcd = tmp_path / "firmware.vcd"
    trace.write_vcd(edges, vcd)
    advanced = tmp_path / "advanced.gcode"
    report = advance.advance_file(gcode, advanced, 1.0 + 2.5 / 2)
    assert sum(1 for c in report["changes"] if c.get("advanced_mm")) >= 10
    checked = {c["name"]: c for c in tracecheck.check(vcd, advanced)["checks"]}
    for name in ("moves", "steps_e0", "steps_e1", "steps_e2", "steps_x", "steps_y"):
        assert checked[name]["ok"] is True, checked[name]["detail"]
    # And against the plain file itself, trace check modelling the transitions from the
    # same settings (its own model, not the firmware's code): every step exact.
    same = {"transition_l1_mm": 1.0, "transition_l2_mm": 2.5}
    plain = tracecheck.check(vcd, gcode, settings=same)
    assert [c["name"] for c in plain["checks"] if c["ok"] is False] == []
    assert [c["name"] for c in tracecheck.check(vcd, gcode)["checks"]
            if c["ok"] is False and c["name"].startswith("steps_e")]
