"""G2/G3 arcs and G17/G18/G19 on the firmware (the unix port): each segment's end on
the circle, the last exactly at the end, E and the third axis split exactly, refusals
that move nothing, the segment options, and a simulated print checked by `mixstep trace
check`."""
import json
import math

import pytest

from mixstep import cli, paths, sim, tracecheck

SPM = 80  # the simulated board's X and Y steps/mm
Z_SPM = 400
MM = 10 ** 6


def run(mp, lines, heap=False):
    return mp.script_json("arcs_segments", stdin=json.dumps([lines, heap]).encode())


def on_circle(moves, centre_mm, radius_mm, steps_per_mm=(SPM, SPM), axes=(0, 1),
              max_chord_mm=1.0):
    """The worst distance of the moves' ends from the circle, in mm, and the
    tolerance: the sagitta of the longest chord allowed, plus half a step each way."""
    worst = 0.0
    for m in moves:
        p = [m[axes[i]] / steps_per_mm[i] for i in range(2)]
        worst = max(worst, abs(math.hypot(p[0] - centre_mm[0], p[1] - centre_mm[1]) - radius_mm))
    half = max_chord_mm / 2
    sagitta = radius_mm - math.sqrt(max(radius_mm ** 2 - half ** 2, 0))
    return worst, sagitta + math.hypot(0.5 / steps_per_mm[0], 0.5 / steps_per_mm[1])


@pytest.mark.parametrize("line, centre, radius, segments", [
    ("G3 X60 Y40 I10 J0", (60, 50), 10, 18),    # quarter, CCW: 72 a turn
    ("G2 X70 Y50 I10 J0", (60, 50), 10, 36),    # half, CW
    ("G2 X50 Y50 I10 J0", (60, 50), 10, 72),    # full circle, end at the start
    ("G3 X50 Y50 I50 J0", (100, 50), 50, 315),  # long: segments of at most 1 mm
    ("G2 X60 Y60 R10", (60, 50), 10, 18),       # R, the short way (CW)
    ("G2 X60 Y60 R-10", (50, 60), 10, 54),      # R < 0: the long way
    ("G3 X50 Y50 I0.5 J0", (50.5, 50), 0.5, 31),  # small: no segment under 0.1 mm
])
def test_segments_end_on_the_circle_and_the_last_exactly_at_the_end(mp, line, centre, radius,
                                                                   segments):
    got = run(mp, ["G1 X50 Y50 F3000", line])
    error, moves, _, pos_nm, _ = got[1]
    assert error is None
    assert len(moves) == segments
    end = [float(w[1:]) for w in line.split() if w[0] in "XY"]
    assert pos_nm[:2] == [round(v * MM) for v in end]
    assert moves[-1][:2] == [round(v * SPM) for v in end]
    worst, tolerance = on_circle(moves, centre, radius)
    assert worst <= tolerance
    # the way round: the first segment leaves the start the arc's way
    first = [moves[0][i] / SPM - centre[i] for i in range(2)]
    start = [50 - centre[0], 50 - centre[1]]
    turn = start[0] * first[1] - start[1] * first[0]
    assert (turn < 0) == line.startswith("G2")


def test_a_helix_splits_z_and_e_exactly_in_relative_modes(mp):
    got = run(mp, ["M302 P1", "G1 X50 Y50 F3000", "G91", "G3 X0 Y0 I10 J0 Z0.3 E1.23457",
                   "G3 X0 Y0 I10 J0 Z0.3 E1.23457 P2", "G90"])
    one, more = got[3], got[4]
    assert one[0] is None and more[0] is None
    assert one[3] == [50 * MM, 50 * MM, 300000] and one[4] == 1234570
    assert sum(m[3] for m in one[1]) == 1234570 and len(one[1]) == 72
    assert one[1][-1][2] == 0.3 * Z_SPM
    zs = [m[2] for m in one[1]]
    assert zs == sorted(zs)  # Z climbs steadily along the helix
    es = [m[3] for m in one[1]]
    assert max(es) - min(es) <= 1  # E in equal shares to the nanometre
    # P2: two more turns, three in all, 216 segments
    assert more[3] == [50 * MM, 50 * MM, 600000] and len(more[1]) == 216
    assert sum(m[3] for m in more[1]) == 1234570 and more[4] == 2 * 1234570


def test_g18_and_g19_turn_in_their_planes(mp):
    got = run(mp, ["G1 X50 Y50 Z10 F3000", "G18", "G2 X60 Z20 I0 K10",
                   "G19", "G3 Y60 Z30 J0 K10", "G17"])
    zx, yz = got[2], got[4]
    assert zx[0] is None and zx[3] == [60 * MM, 50 * MM, 20 * MM]
    worst, tol = on_circle(zx[1], (20, 50), 10, (Z_SPM, SPM), axes=(2, 0))
    assert worst <= tol
    assert yz[0] is None and yz[3] == [60 * MM, 60 * MM, 30 * MM]
    worst, tol = on_circle(yz[1], (50, 30), 10, (SPM, Z_SPM), axes=(1, 2))
    assert worst <= tol


@pytest.mark.parametrize("line, message", [
    ("G2 X60 Y50 R5 I5", "R or a centre"),
    ("G2 X60 Y50", "needs its centre"),
    ("G2 X60 Y60 R2", "cannot reach"),
    ("G2 X50 Y50 R5", "end apart from its start"),
    ("G2 X60 Y50 I0 J0", "radius is zero"),
    ("G2 X60 Y50 I5 P-1", "P (extra turns)"),
    ("G2 X60 Y50 I5 P1.5", "whole number"),
    ("G2 X60 Y50 I5 K0", "not K"),
    ("G2 X60 Y50 I4", "from its centre"),
    ("G2 X50 Y50 I-60", "soft limits"),  # a circle that leaves the bed midway
    ("G2 X60 Y50 I5 E300", "max_extrude_mm"),
])
def test_a_bad_arc_is_refused_and_moves_nothing(mp, line, message):
    got = run(mp, ["M302 P1", "G1 X50 Y50 F3000", line])
    error, moves, _, pos_nm, e_nm = got[2]
    assert error and message in error
    assert not moves and pos_nm == [50 * MM, 50 * MM, 0] and e_nm == 0


def test_an_arc_of_many_segments_takes_no_more_heap_than_a_short_one(mp):
    """Per segment nothing: what an arc takes is per line (its floats; with P turns,
    angles beyond the chips' small ints), so more segments take no more."""
    lines = ["M302 P1", "G1 X50 Y50 F3000", "G2 X50 Y50 I2 J0 E1", "G2 X50 Y50 I40 J0 E1",
             "G2 X50 Y50 I2 J0 E1 P1", "G2 X50 Y50 I40 J0 E1 P4"]
    got = run(mp, lines, heap=True)
    short, long, turn, turns = got[2], got[3], got[4], got[5]
    assert short[1] == 72 and long[1] > 250 and turn[1] == 144 and turns[1] > 1250
    assert long[2] <= short[2] and turns[2] <= turn[2]


def test_segment_options_are_shown_saved_and_used(sim_printer, tmp_path):
    cfg = tmp_path / "mixstep.cfg"
    p = sim_printer(config_path=cfg)
    shown = "\n".join(p.send("M503"))
    for name, value in (("min_arc_segment_mm", 0.1), ("max_arc_segment_mm", 1),
                        ("min_circle_segments", 72)):
        assert float(shown.split("M926 I%s V" % name)[1].split()[0]) == value
    assert p.send("M926 Imax_arc_segment_mm V0.25")[-1] == "ok"
    assert p.send("M926 Imin_circle_segments V360")[-1] == "ok"
    assert p.send("M500")[-1] == "ok"
    p.finish()
    text = cfg.read_text()
    assert "max_arc_segment_mm = 0.25" in text and "min_circle_segments = 360" in text
    again = sim_printer(config_path=cfg)
    shown = "\n".join(again.send("M503"))
    assert "M926 Imax_arc_segment_mm V0.25 " in shown
    assert "M926 Imin_circle_segments V360 " in shown
    again.finish()


def test_a_mix_gives_every_drive_the_same_steps_as_the_same_path_in_lines(sim_printer):
    """An arc's segments go the way of G1 lines: the same path as G1 lines through the
    arc's points (worked out here) gives every drive the same count."""
    arc = ["M302 P1", "M163 S0 P0.5", "M163 S1 P0.3", "M163 S2 P0.2", "M164 S0", "T0",
           "G1 X50 Y50 F3000", "G3 X50 Y50 I7 J0 E2.5"]
    p = sim_printer()
    for line in arc:
        assert p.send(line)[-1] == "ok"
    by_arc = p.finish()["steps"]
    # 72 segments (a full turn); E split as floor(total * i / n) nanometres
    lines = arc[:-1]
    e_nm = 2500000
    for i in range(1, 73):
        a = math.pi + 2 * math.pi * i / 72
        x, y = (57 + 7 * math.cos(a), 50 + 7 * math.sin(a)) if i < 72 else (50, 50)
        lines.append("G1 X%.6f Y%.6f E%.6f" % (x, y, (e_nm * i // 72) / MM))
    p = sim_printer()
    for line in lines:
        assert p.send(line)[-1] == "ok"
    by_lines = p.finish()["steps"]
    assert by_arc == by_lines
    assert by_arc["x"] == 50 * SPM and sum(by_arc["e%d" % d] for d in range(3)) > 0


def _helix_as_lines(start_lines, z0_mm, z1_mm, e_nm, n, end):
    """A helix round (57, 50) of radius 7 from (50, 50, z0) to `end` as G1 lines
    through the arc's segment ends (absolute E, split as the firmware splits it)."""
    lines = list(start_lines)
    z_nm = round((z1_mm - z0_mm) * MM)
    for i in range(1, n + 1):
        a = math.pi + 2 * math.pi * i / n
        x, y = (57 + 7 * math.cos(a), 50 + 7 * math.sin(a)) if i < n else end
        z = z0_mm + (z_nm * i // n) / MM
        lines.append("G1 X%.6f Y%.6f Z%.6f E%.6f" % (x, y, z, (e_nm * i // n) / MM))
    return lines


@pytest.mark.parametrize("settings", [{}, {"retract_policy": 2}], ids=["equal", "replay"])
def test_a_gradient_and_a_retraction_work_on_a_helix_as_on_its_lines(sim_printer, settings):
    """A gradient along Z mixes each segment by its height, and a retraction after it
    (then an unretraction) pulls and pushes each drive back exactly: as the same path
    sent as G1 lines does, drive by drive."""
    start = ["M302 P1", "M211 S0", "M163 S0 P1", "M164 S0", "M163 S1 P1", "M164 S1",
             "T0", "G1 X50 Y50 Z1 F3000", "M166 A1 Z2 I0 J1 S1"]
    after = ["G1 E2.2 F1800", "G1 E2.5"]
    arc = start + ["G3 X50 Y50 Z2 I7 J0 E2.5"] + after
    lines = _helix_as_lines(start, 1, 2, 2500000, 72, (50, 50)) + after
    counts = []
    for gcode in (arc, lines):
        p = sim_printer(settings=settings)
        for line in gcode:
            assert p.send(line)[-1] == "ok", line
        counts.append(p.finish()["steps"])
    assert counts[0] == counts[1]
    e = [counts[0]["e%d" % d] for d in range(2)]
    assert e[0] > 0 and e[1] > 0  # the gradient's two tools both printed


def arcs_gcode(path):
    """A print of arcs from known geometry: circles, halves by R, a helix, G18/G19
    turns, relative E, a retraction."""
    lines = ["M302 P1", "G21", "G90", "M83", "G1 Z0.2 F600", "G1 X40 Y40 F6000"]
    for k in range(3):
        r = 4 + 3 * k
        lines += ["G1 X%d Y40 F6000" % (40 - r), "G2 X%d Y40 I%d J0 E%.5f F1800" % (40 - r, r, 0.05 * r),
                  "G3 X%d Y40 R%d E%.5f" % (40 + r, r, 0.02 * r), "G3 X%d Y40 R-%d E%.5f" % (40 - r, r, 0.02 * r)]
    lines += ["G1 E-0.8 F2400", "G1 X70 Y70 F6000", "G1 E0.8 F2400",
              "G91", "G3 X0 Y0 I5 J0 Z0.4 E0.9 P1 F1200", "G90", "M82", "G92 E0",
              "G18", "G2 X75 Z5.6 I0 K5 E0.5", "G19", "G2 Y75 Z0.6 J0 K-5 E1.0", "G17",
              "M83", "G2 X70 Y70 R7.071068 E0.3", "M400"]
    path.write_text("\n".join(lines) + "\n")
    return path


@pytest.fixture(scope="module")
def arcs_trace(tmp_path_factory):
    out = tmp_path_factory.mktemp("arcs")
    gcode = arcs_gcode(out / "arcs.gcode")
    report = sim.run(gcode, trace_path=out / "arcs.vcd")
    assert not report.get("errors"), report.get("errors")
    return gcode, out / "arcs.vcd"


def test_trace_check_passes_a_print_of_arcs(arcs_trace):
    gcode, vcd = arcs_trace
    report = tracecheck.check(vcd, gcode)
    failed = [c for c in report["checks"] if c["ok"] is False]
    assert report["ok"], failed
    assert report["refused_lines"] == 0


def test_trace_check_fails_when_an_arc_went_elsewhere(arcs_trace, tmp_path):
    """The trace of the print, checked against G-code whose arcs end elsewhere or
    extrude more: the net steps disagree."""
    gcode, vcd = arcs_trace
    text = gcode.read_text()
    for old, new in (("G3 X0 Y0 I5 J0 Z0.4 E0.9 P1", "G3 X0 Y0 I5 J0 Z0.4 E1.1 P1"),
                     ("G2 X75 Z5.6 I0 K5", "G2 X70 Z10.6 I0 K5")):
        assert old in text
        other = tmp_path / "other.gcode"
        other.write_text(text.replace(old, new))
        report = tracecheck.check(vcd, other)
        assert not report["ok"], new


def test_trace_check_follows_the_path_of_every_arc(arcs_trace):
    gcode, vcd = arcs_trace
    report = tracecheck.check(vcd, gcode)
    path = [c for c in report["checks"] if c["name"] == "arc_path"]
    assert len(path) == 1 and path[0]["ok"] is True, path
    assert path[0]["expected"].startswith("13 arcs")


def _printed(tmp_path, name, lines):
    gcode = tmp_path / (name + ".gcode")
    gcode.write_text("\n".join(["M302 P1", "G90", "M83", "G1 Z0.2 F600", "G1 X50 Y50 F6000"]
                               + lines + ["M400"]) + "\n")
    report = sim.run(gcode, trace_path=tmp_path / (name + ".vcd"))
    assert not report.get("errors"), report.get("errors")
    return gcode, tmp_path / (name + ".vcd")


def test_trace_check_passes_arcs_after_g92_m92_and_g28(tmp_path):
    """The arcs' geometry is in G-code coordinates; the trace counts machine steps from
    home: G92 moves the one against the other, M92 changes what a step is, and homing
    steps back to 0 between arcs."""
    gcode, vcd = _printed(tmp_path, "shifted", [
        "G92 X10 Y-5", "G2 X10 Y-5 I6 J0 E0.5 F1800", "M92 X100 Y120",
        "G3 X22 Y-5 I6 J0 E0.4", "G1 X30 Y0", "G2 X40 Y0 R5 E0.2", "G28 X",
        "G1 X30 Y40 F6000", "G3 X30 Y40 I5 J0 E0.5", "G28", "G1 X20 Y20 Z0.4",
        "G2 X30 Y20 R5 E0.3"])
    report = tracecheck.check(vcd, gcode)
    assert report["ok"], [c for c in report["checks"] if c["ok"] is False]
    assert [c["ok"] for c in report["checks"] if c["name"] == "arc_path"] == [True]


# A trace of the first G-code checked against the second: both end in the same place
# with the same E, so the net steps agree, but the way between differs.
SAME_ENDS = {
    "the other way round": (["G3 X60 Y50 I5 J0 E1 F1800"], ["G2 X60 Y50 I5 J0 E1 F1800"],
                            "went another way round"),
    "one turn more": (["G2 X50 Y50 I5 J0 E1 P1 F1800"], ["G2 X50 Y50 I5 J0 E1 F1800"],
                      "fit no line of the G-code, the first at"),
    "one turn less": (["G2 X50 Y50 I5 J0 E1 F1800"], ["G2 X50 Y50 I5 J0 E1 P1 F1800"],
                      "stopped at 360.0 of its 720.0 degrees"),
    "two lines for the arc": (["G1 X55 Y55 E0.5 F1800", "G1 X60 Y50 E0.5"],
                              ["G2 X60 Y50 I5 J0 E1 F1800"], "off the arc of G-code line 6"),
}


@pytest.mark.parametrize("case", sorted(SAME_ENDS))
def test_trace_check_fails_a_path_that_left_the_arc(tmp_path, case):
    printed, asked, message = SAME_ENDS[case]
    _, vcd = _printed(tmp_path, "printed", printed)
    gcode = tmp_path / "asked.gcode"
    text = (tmp_path / "printed.gcode").read_text()
    gcode.write_text(text.replace("\n".join(printed), "\n".join(asked)))
    report = tracecheck.check(vcd, gcode)
    checks = {c["name"]: c for c in report["checks"]}
    assert all(checks[n]["ok"] for n in ("steps_x", "steps_y", "steps_e0"))
    assert not report["ok"] and checks["arc_path"]["ok"] is False
    assert message in checks["arc_path"]["detail"]
    assert "G-code line 6" in checks["arc_path"]["detail"]
    assert "FAIL arc_path" in tracecheck.format_report(report)


def test_real_arc_fitted_slicer_output_passes_trace_check(tmp_path):
    """BambuStudio's arc fitting (testdata/tc_top_bambustudio_arcs.txt): walls, wipes,
    bridges and infill with arcs of every size, each followed by the path check."""
    gcode = paths.ROOT / "testdata" / "tc_top_bambustudio_arcs.gcode"
    report = sim.run(gcode, trace_path=tmp_path / "tc_top.vcd")
    assert report["errors"] == [], report["errors"][:3]
    checked = tracecheck.check(tmp_path / "tc_top.vcd", gcode)
    assert checked["ok"], [c for c in checked["checks"] if c["ok"] is False]
    assert checked["refused_lines"] == 0
    path = [c for c in checked["checks"] if c["name"] == "arc_path"]
    assert path and path[0]["ok"] and path[0]["expected"].startswith("254 arcs")


def test_advance_moves_tool_changes_into_arcs_and_the_print_checks(tmp_path):
    """`mixstep advance` on a print of arcs with tool changes: each change, moved back
    by the purge, lands inside the arc before it where the geometry says, and the
    advanced file prints in the simulation and passes trace check, arcs' path and all."""
    src = tmp_path / "arcs_tools.gcode"
    src.write_text("\n".join([
        "M302 P1", "G90", "M83", "G1 Z0.2 F600", "T0", "G1 X40 Y50 F6000",
        "G2 X60 Y50 I10 J0 E2.0 F1800",  # half a turn round (50, 50), over the top
        "G3 X80 Y50 I10 J0 E2.0",        # half a turn round (70, 50), under it
        "T1", "G1 X90 Y50 E0.6",
        "G2 X90 Y50 I5 J0 E1.5",         # a whole turn round (95, 50)
        "T2", "G1 X100 Y60 E0.5", "M400"]) + "\n")
    out = tmp_path / "advanced.gcode"
    assert cli.main(["advance", str(src), "-o", str(out), "--purge-mm", "1"]) == 0
    lines = out.read_text().splitlines()

    def around(tool):
        at = lines.index(tool)
        return [dict((w[0], float(w[1:])) for w in lines[k].split()[1:]) | {"G": lines[k][:2]}
                for k in (at - 1, at + 1)]

    # T1 was after 4 mm of printing: at 3 mm, halfway along the G3 (E 1 of its 2), at
    # 270 degrees round (70, 50).
    before, after = around("T1")
    assert before["G"] == after["G"] == "G3"
    assert (before["X"], before["Y"]) == pytest.approx((70, 40), abs=1e-4)
    assert before["E"] == pytest.approx(1.0) and after["E"] == pytest.approx(1.0)
    assert (after["X"], after["Y"]) == (80, 50)
    # T2 was after 6.1 mm: at 5.1, a third of the way round the whole turn (E 0.5 of
    # 1.5), clockwise from 180 to 60 degrees round (95, 50).
    before, after = around("T2")
    assert before["G"] == after["G"] == "G2"
    assert (before["X"], before["Y"]) == pytest.approx((97.5, 50 + 5 * math.sin(math.pi / 3)),
                                                       abs=1e-4)
    assert before["E"] == pytest.approx(0.5) and after["E"] == pytest.approx(1.0)
    assert (after["X"], after["Y"]) == (90, 50)

    printed = {}
    for name, gcode in (("original", src), ("advanced", out)):
        report = sim.run(gcode, trace_path=tmp_path / (name + ".vcd"))
        assert report["errors"] == [], report["errors"][:3]
        printed[name] = report["steps"]
        checked = tracecheck.check(tmp_path / (name + ".vcd"), gcode)
        assert checked["ok"], [c for c in checked["checks"] if c["ok"] is False]
        assert [c["ok"] for c in checked["checks"] if c["name"] == "arc_path"] == [True]
    # The same path and filament; only which drive gives it moved.
    original, advanced = printed["original"], printed["advanced"]
    assert all(original[a] == advanced[a] for a in "xyz")
    drives = ["e%d" % d for d in range(6)]
    assert abs(sum(original[d] for d in drives) - sum(advanced[d] for d in drives)) <= 2
    # A purge's worth of filament goes from T0's drive to T2's; T1 gains as much at its
    # start as it gives up at its end.
    e_spm = paths.load_board("sim")["SETTINGS"]["steps_per_mm"][3]
    assert abs(original["e0"] - advanced["e0"] - e_spm) <= 1
    assert abs(advanced["e2"] - original["e2"] - e_spm) <= 1
    assert abs(advanced["e1"] - original["e1"]) <= 1
