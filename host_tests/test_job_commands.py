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
    """A G-code the firmware lacks is motion the file needed (a G5 spline, G12's nozzle
    clean): an error, so a host stops the print rather than print it wrong; an unknown
    M-code is a setting or a report, passed over with Marlin's echo."""
    assert printer.send("G5 I1 J2 P3 Q4 X5 Y6") == [
        'Error:Unknown command: "G5" (a motion command this firmware lacks; the print '
        'would go wrong without it)', "ok"]
    assert printer.send("G12 P1 S2")[0].startswith('Error:Unknown command: "G12"')
    assert printer.send("M355 S1 P255") == ['echo:Unknown command: "M355"', "ok"]
    assert printer.send("M9999 S1") == ['echo:Unknown command: "M9999"', "ok"]
    assert printer.finish()["steps"]["x"] == 0


def _read_until(p, text):
    """The firmware's lines up to the first that holds text."""
    seen = []
    while not seen or text not in seen[-1]:
        seen.append(p._readline())
    return seen


def test_m600_parks_changes_a_drive_waits_for_the_host_and_goes_back(sim_printer, board):
    """M600 D1 mid-print: the mix retracts, Z rises, the head parks, drive 1 unloads;
    the host hears //action:paused and a prompt; M876 (the prompt's Continue) resumes:
    drive 1 loads, the mix purges, the head goes back and the print goes on where it
    was, its logical E untouched."""
    p = sim_printer()
    for line in ("M104 S200", "M109 S200", "G28", "M83", "G1 X50 Y40 Z0.3 F3000",
                 "G1 X60 E1"):
        assert p.send(line)[-1] == "ok", line
    p.proc.stdin.write(b"M600 D1 U20 L25 P5 X5 Y7 Z10\n")
    waiting = _read_until(p, "then M108 or Continue")
    assert "//action:paused" in waiting and "//action:prompt_show" in waiting
    p.proc.stdin.write(b"M876 S0\n")
    resumed = _read_until(p, "ok")
    assert resumed[-3:] == ["//action:prompt_end", "//action:resumed", "ok"]
    assert p._readline() == "ok"  # the M876 line's own turn: nothing more
    p.send("M400")
    m114 = [t for t in p.send("M114") if not t.startswith("busy:")]
    assert m114[0].startswith("X:60.00 Y:40.00 Z:0.30 E:1.00 Count X:4800 Y:3200"), m114
    p.send("G1 X70 E1")
    steps = p.finish()["steps"]
    spm = board["SETTINGS"]["steps_per_mm"]
    # Drive 1: unloaded 20, loaded 25; the mix (T0, drive 0): 1 + 5 purged + 1 mm.
    assert steps["e1"] == 5 * E_SPM and steps["e0"] == 7 * E_SPM
    assert steps["x"] == 70 * spm[0] and steps["z"] == round(0.3 * spm[2])


def test_m600_turns_the_hot_end_off_after_its_timeout_and_heats_it_again(sim_printer):
    p = sim_printer()
    for line in ("M926 Ichange_heater_timeout_s V3", "M930", "M104 S200", "M109 S200",
                 "G28", "G1 X20 Y20 Z1 F3000"):
        assert p.send(line)[-1] == "ok", line
    p.proc.stdin.write(b"M600\n")
    off = _read_until(p, "hot end off after 3 s")
    assert "//action:paused" in off
    p.proc.stdin.write(b"M108\n")
    back = _read_until(p, "ok")
    assert "echo:filament change: heating the hot end to 200 C" in back
    assert back[-2:] == ["//action:resumed", "ok"]
    assert p._readline() == "ok"  # the M108 line's own
    temp = float(p.send("M105")[-1].split()[1][2:])  # ok T:<now> /<target> ...
    assert temp >= 195  # heated again before the print went on
    p.finish()


def test_m600_refuses_bad_words_and_a_cold_hot_end_without_moving(printer):
    for line, error in (("M600 D6", "D6 out of range 0..5"),
                        ("M600 X-1", "M600 X-1.0 out of range 0..250"),
                        ("M600 U500", "M600 U500.0 out of range 0..200")):
        assert printer.send(line) == ["Error:" + error, "ok"], line
    assert printer.send("M302 P0")[-1] == "ok"
    got = printer.send("M600")
    assert got[0].startswith("Error:cold extrusion prevented") and got[-1] == "ok"
    assert printer.finish()["steps"] == {k: 0 for k in (
        "x", "y", "z", "e0", "e1", "e2", "e3", "e4", "e5")}
