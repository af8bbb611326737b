"""What slicers and hosts send about a print besides its moves, on the firmware running
on the unix port: the feed rate and flow percentages (M220, M221), the slicer's
progress (M73, shown by M27 and in `mixstep sim`'s report), and what an unknown command
gets."""
import numpy as np
import pytest

from mixstep import paths, sim, trace

E_SPM = 415
X_SPM = 80


def test_m220_sets_the_speed_of_the_moves_that_follow_and_b_r_keep_and_restore(
        sim_printer, tmp_path, board):
    edges = tmp_path / "run.edges"
    p = sim_printer(edges_path=edges)
    assert p.send("M220") == ["FR:100%", "ok"]
    # 50 mm at F1200 (20 mm/s), then at 150 %, then back to the kept 100 %.
    p.send("G1 X50 F1200")
    p.send("M400")
    assert p.send("M220 B S150") == ["ok"]
    assert p.send("M220") == ["FR:150%", "ok"]
    p.send("G1 X100")
    p.send("M400")
    assert p.send("M220 R") == ["ok"]
    assert p.send("M220") == ["FR:100%", "ok"]
    p.send("G1 X150")
    p.finish()
    t, g, v = trace.read_edges(edges)
    rises = t[(g == board["PINS"]["x_step"]) & (v == 1)]
    assert len(rises) == 150 * X_SPM
    gaps = [np.median(np.diff(rises[i * 50 * X_SPM:(i + 1) * 50 * X_SPM])) for i in range(3)]
    tick = board["SETTINGS"]["tick_us"]
    assert gaps[0] == pytest.approx(1e6 / (20 * X_SPM), abs=tick)
    assert gaps[1] == pytest.approx(1e6 / (30 * X_SPM), abs=tick)
    assert gaps[2] == pytest.approx(gaps[0], abs=tick)


def test_m220_refuses_a_percentage_out_of_range_and_keeps_its_own(printer):
    for line in ("M220 S0", "M220 S1000", "M220 S-5", "M220 S50.5"):
        assert printer.send(line)[0].startswith("Error:"), line
    assert printer.send("M220") == ["FR:100%", "ok"]


MIX = ("M567 P0 E1:2:4", "T0", "M83")


def test_m221_scales_the_mixed_filament_exactly_over_many_moves(sim_printer):
    """93 % flow over 100 short moves feeds each drive exactly what 93 % of their sum
    fed at once feeds it: the percentage carries what falls below a nanometre, and the
    mix splits the whole as before."""
    scaled = sim_printer(cold_extrusion=True)
    for line in MIX + ("M221 S93",):
        scaled.send(line)
    assert scaled.send("M221") == ["echo:E0 Flow: 93%", "ok"]
    for i in range(1, 101):
        scaled.send("G1 X%.1f E0.0123 F3000" % (i * 0.5))
    whole = sim_printer(cold_extrusion=True)
    for line in MIX:
        whole.send(line)
    whole.send("G1 X50 E1.1439 F3000")  # 100 x 0.0123 mm x 0.93
    got, want = scaled.finish()["steps"], whole.finish()["steps"]
    assert got == want
    assert sum(got["e%d" % d] for d in range(3)) == round(1.1439 * E_SPM)


def test_m221_is_per_tool_and_leaves_firmware_retraction_alone(sim_printer, tmp_path):
    edges = tmp_path / "run.edges"
    p = sim_printer(cold_extrusion=True, edges_path=edges)
    for line in ("M83", "M221 T1 S50", "G1 E2 F600", "T1", "G1 E2"):
        assert p.send(line) == ["ok"], line
    assert p.send("M221 T0") == ["echo:E0 Flow: 100%", "ok"]
    assert p.send("M221") == ["echo:E1 Flow: 50%", "ok"]  # T1 is the active tool
    # G10 retracts retract_mm (2 mm) whatever the flow, and G11 pushes it back.
    p.send("G10")
    p.send("G11")
    steps = p.finish()["steps"]
    assert steps["e0"] == 2 * E_SPM and steps["e1"] == 1 * E_SPM
    _, e1 = trace.positions_of(*trace.read_edges(edges), "sim", "e1")
    assert e1.min() == (1 - 2) * E_SPM


def test_m221_refusals(printer):
    for line, error in (("M221 S0", "S0 out of range 1..999"),
                        ("M221 S1000", "S1000 out of range 1..999"),
                        ("M221 T16 S90", "tool T16 out of range T0..T15")):
        assert printer.send(line) == ["Error:" + error, "ok"], line
    assert printer.send("M221") == ["echo:E0 Flow: 100%", "ok"]


def test_m73_progress_is_kept_and_shown_by_m27_and_the_sim_report(tmp_path):
    """A real BambuStudio file's M73 lines: M27 and `mixstep sim`'s report show the
    last, with M117's message."""
    gcode = paths.ROOT / "testdata" / "tc_top_bambustudio_arcs.gcode"
    last = [l.split(";")[0].split() for l in gcode.read_text().splitlines()
            if l.startswith("M73 ")][-1]
    words = {w[0]: int(w[1:]) for w in last[1:]}
    path = tmp_path / "with_message.gcode"
    path.write_text(gcode.read_text() + "M117 Nearly there\nM27\n")
    report = sim.run(path)
    assert report["errors"] == []
    assert report["status"] == [
        "NORMAL MODE: Percent done: %d; print time remaining in mins: %d"
        % (words["P"], words["R"]), "echo:status: Nearly there"]


def test_m73_words_and_refusals(printer):
    assert printer.send("M27") == ["Not SD printing", "ok"]
    assert printer.send("M73 P12.5 R40 Q10 S50 C3 D4") == ["ok"]
    assert printer.send("M27") == [
        "Not SD printing",
        "NORMAL MODE: Percent done: 12; print time remaining in mins: 40; Change in mins: 3",
        "SILENT MODE: Percent done: 10; print time remaining in mins: 50; Change in mins: 4",
        "ok"]
    for line in ("M73 P101", "M73 R-1", "M73 P50 R-2"):
        assert printer.send(line)[0].startswith("Error:M73 "), line
    # A refused line keeps nothing of itself, P50 included.
    assert printer.send("M27")[1].startswith("NORMAL MODE: Percent done: 12;")


def test_an_unknown_g_code_is_refused_and_an_unknown_m_code_passed_over(printer):
    """A G-code the firmware lacks is motion the file needed (a probe's G29, a G5
    spline): an error, so a host stops the print rather than print it wrong; an unknown
    M-code is a setting or a report, passed over with Marlin's echo."""
    assert printer.send("G29") == [
        'Error:Unknown command: "G29" (a motion command this firmware lacks; the print '
        'would go wrong without it)', "ok"]
    assert printer.send("G5 I1 J2 P3 Q4 X5 Y6")[0].startswith('Error:Unknown command: "G5"')
    assert printer.send("M355 S1 P255") == ['echo:Unknown command: "M355"', "ok"]
    assert printer.send("M9999 S1") == ['echo:Unknown command: "M9999"', "ok"]
    assert printer.finish()["steps"]["x"] == 0
