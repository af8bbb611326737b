"""`mixstep arcfit`: runs of G1 extrusion moves on a circle become G2/G3 arcs that pass
through every original point within the tolerance, with the same E, every other line
byte for byte; the fitted print runs in the simulation to the same end with the same
drive steps, and its trace passes `mixstep trace check` (the arcs' path included)."""
import math
from decimal import Decimal

import pytest

from mixstep import arcfit, cli, gcodeio, paths, sim, tracecheck

SAMPLES = paths.ROOT / "testdata"
CIRCLES = SAMPLES / "circles_tube_emu_excerpt.gcode"
CIRCLES_ARCS = SAMPLES / "circles_tube_arcs_emu_excerpt.gcode"
ARCS_HEADER = 2  # the comment lines the committed file has before the tool's output


def facets(cx, cy, r, start_deg, sweep_deg, step_mm, e_per_mm):
    """G1 lines along a circle in facets of about step_mm, from a travel to its start."""
    n = max(3, round(abs(math.radians(sweep_deg)) * r / step_mm))
    a0 = math.radians(start_deg)
    lines = ["G1 X%.3f Y%.3f F9000" % (cx + r * math.cos(a0), cy + r * math.sin(a0)),
             "G1 F1800"]
    for i in range(1, n + 1):
        a = a0 + math.radians(sweep_deg) * i / n
        lines.append("G1 X%.3f Y%.3f E%.5f" % (cx + r * math.cos(a), cy + r * math.sin(a),
                                               e_per_mm * 2 * r * math.sin(
                                                   abs(math.radians(sweep_deg)) / n / 2)))
    return lines


def generated(path):
    """Circles both ways, a loop closed on itself, a straight run, a square, a circle
    broken by a comment, and a circle with absolute E."""
    lines = ["M302 P1", "G21", "G90", "M83", "G1 Z0.2 F600"]
    lines += facets(60, 60, 10, 0, 350, 0.2, 0.05)          # CCW, most of a turn
    lines += facets(60, 60, 5, 90, -180, 0.3, 0.05)         # CW half
    lines += facets(90, 40, 8, 0, 360, 0.2, 0.04)           # a whole loop
    lines += ["G1 X20 Y20 F9000", "G1 F1800"] + ["G1 X%d Y20 E0.05" % (20 + i)
                                                  for i in range(1, 11)]  # straight
    lines += ["G1 X30 Y30 E0.5", "G1 X40 Y30 E0.5", "G1 X40 Y40 E0.5", "G1 X30 Y40 E0.5"]
    broken = facets(40, 90, 6, 0, 180, 0.25, 0.05)
    lines += broken[:20] + ["; a comment between two runs"] + broken[20:]
    absolute = facets(100, 100, 7, 45, 200, 0.2, 0.05)
    e = Decimal(0)
    lines += ["M82", "G92 E0"]
    for ln in absolute:
        if " E" in ln:
            head, de = ln.rsplit(" E", 1)
            e += Decimal(de)
            ln = "%s E%s" % (head, e)
        lines.append(ln)
    lines += ["M83", "G1 E-0.8 F2400", "M400"]
    path.write_text("\n".join(lines) + "\n")
    return path


def read(path):
    with open(path, newline="") as f:
        return list(gcodeio.Reader(f))


def e_total(lines):
    """The filament fed in all, as exact decimals of the E words."""
    total, last, relative = Decimal(0), Decimal(0), False
    for ln in lines:
        if ln.code in ("M82", "M83", "G90", "G91"):
            relative = ln.code in ("M83", "G91")
        elif ln.code == "G92" and ("E" in ln.words or not ln.words):
            last = Decimal(ln.words.get("E") or "0")
        elif ln.code in gcodeio.MOVES and "E" in ln.words:
            e = Decimal(ln.words["E"])
            total += e if relative else e - last
            last = last if relative else e
    return total


def check_fit(original, fitted, tolerance_mm):
    """Walk both files: every line of the fitted file is the original's, byte for byte,
    or an arc standing for a run of G1 moves whose every end lies on it within the
    tolerance, in its sweep, and whose E and end are the run's. Returns the arcs."""
    old, new = read(original), read(fitted)
    i = 0
    arcs = 0
    for ln in new:
        if ln.code not in gcodeio.ARCS:
            assert ln.raw == old[i].raw, (ln.lineno, ln.raw, old[i].raw)
            i += 1
            continue
        arcs += 1
        cx, cy, r, a0, sweep = gcodeio.arc(ln.start, ln.end, ln.words, ln.code == "G2")
        assert ln.start[:3] == old[i].start[:3]
        run_e = 0.0
        moves = 0
        while True:
            o = old[i]
            i += 1
            moves += 1
            assert o.code == "G1" and o.printing and o.end[2] == o.start[2], o.raw
            x, y = o.end[:2]
            assert abs(math.hypot(x - cx, y - cy) - r) <= tolerance_mm + 1e-4, o.raw
            turn = (math.atan2(y - cy, x - cx) - a0) * (1 if sweep > 0 else -1) % (2 * math.pi)
            assert turn <= abs(sweep) + 1e-6 or turn > 2 * math.pi - 1e-6, o.raw
            run_e += o.de_mm
            if o.end[:2] == ln.end[:2] and abs(run_e - ln.de_mm) < 1e-6:
                break
        assert moves >= arcfit.MIN_MOVES
        assert o.end == pytest.approx(ln.end, abs=1e-9)
        assert ln.words.get("F") == old[i - moves].words.get("F")
    assert i == len(old)
    assert e_total(new) == e_total(old)
    return arcs


def test_fitted_arcs_pass_through_the_moves_they_replace(tmp_path):
    src = generated(tmp_path / "circles.gcode")
    out = tmp_path / "arcs.gcode"
    summary = arcfit.arcfit(src, out, tolerance_mm=0.01)
    arcs = check_fit(src, out, 0.01)
    assert summary["arcs"] == arcs
    # 350 degrees, the CW half, the loop (all but its last moves: an arc under a whole
    # turn), the two halves of the broken circle, the absolute-E one.
    assert arcs == 6
    new = read(out)
    assert sum(ln.code == "G2" for ln in new) >= 1 and sum(ln.code == "G3" for ln in new) >= 5
    text = out.read_text()
    for kept in ["G1 X%d Y20 E0.05\n" % (20 + i) for i in range(1, 11)] + [
            "G1 X40 Y30 E0.5\n", "; a comment between two runs\n"]:
        assert kept in text
    # the absolute-E arc ends at the last move's E
    absolute = [ln for ln in new if ln.code in gcodeio.ARCS and ln.start[0] > 92]
    assert absolute and all(float(ln.words["E"]) > 1 for ln in absolute)


def test_a_tighter_tolerance_fits_fewer_moves(tmp_path):
    src = generated(tmp_path / "circles.gcode")
    loose = arcfit.arcfit(src, tmp_path / "loose.gcode", tolerance_mm=0.01)
    tight = arcfit.arcfit(src, tmp_path / "tight.gcode", tolerance_mm=0.0001)
    check_fit(src, tmp_path / "tight.gcode", 0.0001)
    assert tight["moves_fitted"] < loose["moves_fitted"]


def test_the_committed_circles_arcs_are_the_tools_output(tmp_path):
    out = tmp_path / "arcs.gcode"
    arcfit.arcfit(CIRCLES, out, tolerance_mm=0.01)
    committed = CIRCLES_ARCS.read_text().splitlines(keepends=True)
    assert all(line.startswith(";") for line in committed[:ARCS_HEADER])
    assert "".join(committed[ARCS_HEADER:]) == out.read_text()
    assert check_fit(CIRCLES, out, 0.01) >= 20


@pytest.fixture(scope="module")
def circles_printed(tmp_path_factory):
    out = tmp_path_factory.mktemp("arcfit")
    runs = {}
    for name, gcode in (("lines", CIRCLES), ("arcs", CIRCLES_ARCS)):
        report = sim.run(gcode, trace_path=out / (name + ".vcd"))
        assert report["errors"] == [], report["errors"][:3]
        runs[name] = (gcode, out / (name + ".vcd"), report)
    return runs


def test_the_fitted_print_ends_alike_with_the_same_drive_steps(circles_printed):
    lines, arcs = circles_printed["lines"][2], circles_printed["arcs"][2]
    assert arcs["steps"] == lines["steps"]
    assert arcs["lines"] < lines["lines"] / 10


def test_the_fitted_print_passes_trace_check_with_its_arcs_followed(circles_printed):
    gcode, vcd, _ = circles_printed["arcs"]
    report = tracecheck.check(vcd, gcode)
    assert report["ok"], [c for c in report["checks"] if c["ok"] is False]
    path = [c for c in report["checks"] if c["name"] == "arc_path"]
    assert path and path[0]["ok"] and int(path[0]["expected"].split()[0]) >= 20


def test_the_faceted_trace_is_not_the_arcs(circles_printed):
    """The faceted print's trace against the fitted G-code: the same ends and filament,
    but its X Y steps are the facets', not the arcs' segments: arc_path tells."""
    _, vcd, _ = circles_printed["lines"]
    report = tracecheck.check(vcd, circles_printed["arcs"][0])
    checks = {c["name"]: c for c in report["checks"]}
    assert checks["steps_x"]["ok"] and checks["steps_y"]["ok"] and checks["steps_e0"]["ok"]
    assert not report["ok"] and checks["arc_path"]["ok"] is False


def test_cli_fits_and_refuses_bad_arguments(tmp_path, capsys):
    src = generated(tmp_path / "circles.gcode")
    out = tmp_path / "arcs.gcode"
    assert cli.main(["arcfit", str(src), "-o", str(out), "--tolerance-mm", "0.01"]) == 0
    assert "arcs of" in capsys.readouterr().out and out.exists()
    before = src.read_bytes()
    assert cli.main(["arcfit", str(src), "-o", str(src)]) == 2
    assert "is the input file" in capsys.readouterr().err
    assert src.read_bytes() == before
    assert cli.main(["arcfit", str(src), "-o", str(tmp_path / "x.gcode"),
                     "--tolerance-mm", "0"]) == 2
    assert "tolerance must be > 0" in capsys.readouterr().err
    assert not (tmp_path / "x.gcode").exists()
    assert cli.main(["arcfit", str(tmp_path / "missing.gcode"), "-o", str(out)]) == 2
    assert "missing.gcode" in capsys.readouterr().err
