"""`mixstep advance` on real slicer output (PrusaSlicer relative and absolute E, Slic3r
1.3 absolute and relative E, Cura 4.13 absolute E with its 16 mm switch retraction).

The checks read the output with their own small G-code reader, not the module's: it
counts as printing extrusion the positive E of moves that move X, Y or Z, outside
PrusaSlicer's wipes, the rule the module and the firmware's transitions follow too.
"""
import difflib
import io
import json
import math
import os

import pytest

from mixstep import advance as adv
from mixstep import cli

TESTDATA = os.path.join(os.path.dirname(__file__), "..", "testdata")
CURA = "cura_part_3tool.gcode"
FILES = ["part_3tool_prusaslicer_rel.gcode", "part_3tool_prusaslicer_abs.gcode",
         "slic3r_part_3tool_abs.gcode", "slic3r_part_3tool_rel.gcode", CURA]
TOL_MM = 1e-4


def read_lines(name):
    with open(os.path.join(TESTDATA, name), newline="") as f:
        return f.readlines()


def run(lines, purge, **kw):
    out = io.StringIO()
    report = adv.advance(iter(lines), out.write, purge, **kw)
    return out.getvalue().splitlines(keepends=True), report


def walk(lines):
    """Per line: (printing extrusion after the line, XYZ point or None, tool or None,
    feed rate in effect)."""
    x = y = z = e = 0.0
    feed = None
    rel_xyz = rel_e = wipe = False
    s = 0.0
    rows = []
    for line in lines:
        code = line.split(";")[0].split()
        point = tool = None
        if line.startswith(";WIPE_START"):
            wipe = True
        elif line.startswith(";WIPE_END"):
            wipe = False
        if code:
            cmd, words = code[0], {w[0]: float(w[1:] or 0) for w in code[1:]}
            if cmd in ("G0", "G1", "G2", "G3"):
                feed = words.get("F", feed)
                old = (x, y, z)
                if rel_xyz:
                    x, y, z = x + words.get("X", 0), y + words.get("Y", 0), z + words.get("Z", 0)
                else:
                    x, y, z = words.get("X", x), words.get("Y", y), words.get("Z", z)
                if "E" in words:
                    de = words["E"] if rel_e else words["E"] - e
                    e = e + de if rel_e else words["E"]
                    if de > 0 and (x, y, z) != old and not wipe:
                        s += de
                if (x, y, z) != old:
                    point = (x, y, z)
            elif cmd == "G92":
                if not words:
                    x = y = z = e = 0.0
                x, y, z, e = (words.get("X", x), words.get("Y", y), words.get("Z", z),
                              words.get("E", e))
            elif cmd == "G28":
                x = y = z = 0.0
            elif cmd in ("G90", "G91"):
                rel_xyz = rel_e = cmd == "G91"
            elif cmd in ("M82", "M83"):
                rel_e = cmd == "M83"
            elif cmd[0] == "T" and cmd[1:].isdigit():
                tool = int(cmd[1:])
        rows.append((s, point, tool, feed))
    return rows


def changes_in(lines):
    """(line number, tool, printing extrusion before it) of every T line."""
    return [(n, tool, s) for n, (s, _, tool, _) in enumerate(walk(lines), 1) if tool is not None]


def total_tolerance_mm(lines):
    """How far the two counting rules may part over a whole file: the module counts what
    an unretraction pushes beyond its retraction, and Slic3r rounds a wipe's retraction
    to 5 decimals, so up to 1e-5 mm for each unretraction."""
    primes = sum(1 for ln in lines if ln.startswith("G1 E") and not ln.startswith("G1 E-"))
    return TOL_MM + 1e-5 * primes


def check_output(lines_in, lines_out, report):
    """Everything that must hold for any purge; returns {input T line: mm advanced}."""
    rows_in, rows_out = walk(lines_in), walk(lines_out)
    # total printing extrusion preserved
    assert abs(rows_in[-1][0] - rows_out[-1][0]) < TOL_MM
    assert abs(rows_in[-1][0] - report["extrusion_mm"]) < total_tolerance_mm(lines_in)
    # the path preserved: the output's points, split points taken out, are the input's
    splits = [tuple(c["split_point"]) for c in report["changes"] if "split_point" in c]
    pts_in = [(p, f) for _, p, _, f in rows_in if p is not None]
    pts_out = [(p, f) for _, p, _, f in rows_out if p is not None]
    kept = []
    split_feeds = []
    for p, f in pts_out:
        hit = next((q for q in splits if max(abs(a - b) for a, b in zip(p, q)) < 1e-9), None)
        if hit is not None:
            splits.remove(hit)
            split_feeds.append((len(kept), f))  # the first half of the next kept move
        else:
            kept.append((p, f))
    assert not splits
    assert len(kept) == len(pts_in)
    assert max(max(abs(a - b) for a, b in zip(p[0], q[0])) for p, q in zip(kept, pts_in)) < 1e-6
    # both halves of a split move at the original move's feed rate
    assert [f for p, f in kept] == [f for p, f in pts_in]
    for k, f in split_feeds:
        assert f == pts_in[k][1], (kept[k], f)
    # tool changes: same lines, same order
    t_in, t_out = changes_in(lines_in), changes_in(lines_out)
    assert [lines_in[n - 1] for n, _, _ in t_in] == [lines_out[n - 1] for n, _, _ in t_out]
    # each moved change: the extrusion between its new and its original place
    moved = {c["line"]: c for c in report["changes"]}
    advanced = {}
    for (n_in, _, s_in), (n_out, _, s_out) in zip(t_in, t_out):
        if n_in not in moved:
            assert abs(s_in - s_out) < TOL_MM      # the initial selection stays put
            continue
        c = moved[n_in]
        assert c["out_line"] == n_out
        assert abs((s_in - s_out) - c["advanced_mm"]) < TOL_MM
        advanced[n_in] = s_in - s_out
    # every other line byte for byte, except split moves (one line in, two or more out)
    t_lines_in = {n for n, _, _ in t_in}
    t_lines_out = {n for n, _, _ in t_out}
    rest_in = [ln for n, ln in enumerate(lines_in, 1) if n not in t_lines_in]
    rest_out = [ln for n, ln in enumerate(lines_out, 1) if n not in t_lines_out]
    # (in absolute coordinates, a split move's second half is often the original line)
    splits = sum(1 for c in report["changes"] if "split_line" in c)
    added = 0
    sm = difflib.SequenceMatcher(None, rest_in, rest_out, autojunk=False)
    for op, i1, i2, j1, j2 in sm.get_opcodes():
        if op == "equal":
            continue
        assert op in ("replace", "insert") and i2 - i1 <= 1 and j2 - j1 > i2 - i1, (
            op, rest_in[i1:i2], rest_out[j1:j2])
        added += (j2 - j1) - (i2 - i1)
    assert added == splits
    return advanced


def test_counting_rules_agree_on_the_inputs():
    for name in FILES:
        lines = read_lines(name)
        _, report = run(lines, 0.0)
        assert abs(walk(lines)[-1][0] - report["extrusion_mm"]) < total_tolerance_mm(lines), name
        assert report["changes"] and not report["warnings"]


@pytest.mark.parametrize("name", FILES)
@pytest.mark.parametrize("purge_mm", [2.5, 0.37, 6.0])
def test_every_change_moves_by_the_purge(name, purge_mm):
    lines = read_lines(name)
    out, report = run(lines, purge_mm)
    advanced = check_output(lines, out, report)
    assert len(advanced) == len(changes_in(lines)) - 1
    warned = {w["line"] for w in report["warnings"]}
    for n, mm in advanced.items():
        if n not in warned:
            assert abs(mm - purge_mm) < TOL_MM, (n, mm)
    first = changes_in(lines)[1]
    assert warned == ({first[0]} if first[2] < purge_mm else set())


def test_zero_purge_changes_nothing():
    for name in FILES:
        lines = read_lines(name)
        out, report = run(lines, 0.0)
        assert out == lines


@pytest.mark.parametrize("name", FILES)
def test_closely_spaced_changes_all_shift_by_the_same_amount(name):
    lines = read_lines(name)
    ts = changes_in(lines)[1:]
    gaps = [b[2] - a[2] for a, b in zip(ts, ts[1:])]
    i = min(range(len(gaps)), key=gaps.__getitem__)
    purge_mm = gaps[i] * 1.25         # larger than the smallest gap between two changes
    out, report = run(lines, purge_mm)
    advanced = check_output(lines, out, report)
    warned = {w["line"] for w in report["warnings"]}   # only near the start of the print
    assert warned == {n for n, _, s in ts if s < purge_mm}
    assert ts[i][0] not in warned and ts[i + 1][0] not in warned
    for n, mm in advanced.items():
        if n not in warned:
            assert abs(mm - purge_mm) < TOL_MM
    # the close pair: both moved by the purge, still in order, with their gap kept
    t_out = changes_in(out)[1:]
    a, b = t_out[i], t_out[i + 1]
    assert a[0] < b[0] and a[1] == ts[i][1] and b[1] == ts[i + 1][1]
    assert abs((b[2] - a[2]) - gaps[i]) < TOL_MM
    assert b[2] < ts[i][2]           # the second change now comes before the first's old place


def test_too_little_extrusion_at_the_start_advances_as_far_as_possible():
    lines = read_lines(FILES[1])
    first = changes_in(lines)[1]
    out, report = run(lines, first[2] + 1.0)
    advanced = check_output(lines, out, report)
    assert abs(advanced[first[0]] - first[2]) < TOL_MM     # everything before it
    (warning,) = [w for w in report["warnings"] if w["line"] == first[0]]
    assert "not enough printing extrusion" in warning["message"]
    # it went right after the initial T0, as far back as the firmware's transition
    # reaches (over every move queued since): before any extrusion
    n_out = changes_in(out)[1][0]
    assert changes_in(out)[0][0] == n_out - 1
    assert walk(out)[n_out][0] == 0


def test_huge_purge_keeps_every_change_in_order():
    lines = read_lines(FILES[0])
    out, report = run(lines, 5000.0)
    check_output(lines, out, report)
    ts = [t for _, t, _ in changes_in(out)]
    assert ts == [t for _, t, _ in changes_in(lines)]


MATRIX = """\
# from to mm
default 2.5
0 2 1.2
T2 T0 4.75   ; the T is optional
* 1 3.3
"""


@pytest.mark.parametrize("name", FILES)
def test_purge_matrix(name):
    matrix = adv.PurgeMatrix(MATRIX)
    assert matrix.max_mm == 4.75
    assert (matrix(0, 2), matrix(2, 0), matrix(0, 1), matrix(1, 0)) == (1.2, 4.75, 3.3, 2.5)
    lines = read_lines(name)
    out, report = run(lines, matrix)
    advanced = check_output(lines, out, report)
    ts = changes_in(lines)
    warned = {w["line"] for w in report["warnings"]}
    seen = set()
    for (_, before, _), (n, after, _) in zip(ts, ts[1:]):
        if n not in warned:
            assert abs(advanced[n] - matrix(before, after)) < TOL_MM
        seen.add(matrix(before, after))
    assert len(seen) >= 3


def test_purge_matrix_errors():
    with pytest.raises(ValueError, match="line 2"):
        adv.PurgeMatrix("default 1\n0 1\n")
    with pytest.raises(ValueError, match="no rule"):
        adv.PurgeMatrix("0 1 2")(1, 0)


def test_pair_needing_more_than_the_gap_is_held_behind_the_previous_change():
    lines = read_lines(FILES[1])
    ts = changes_in(lines)
    gaps = [(b[2] - a[2], k) for k, (a, b) in enumerate(zip(ts[1:], ts[2:]), 1)]
    gap, k = min(gaps)
    pair = (ts[k][1], ts[k + 1][1])
    text = "default 0.1\n%d %d %.5f\n" % (pair[0], pair[1], gap + 0.5)
    out, report = run(lines, adv.PurgeMatrix(text))
    check_output(lines, out, report)
    held = [w for w in report["warnings"] if "held behind" in w["message"]]
    assert any(w["line"] == ts[k + 1][0] for w in held)
    assert [t for _, t, _ in changes_in(out)] == [t for _, t, _ in ts]


def test_memory_is_bounded_by_the_purge_not_the_file():
    lines = read_lines(FILES[1])
    _, small = run(lines, 2.5)
    _, large = run(lines, 25.0)
    assert small["max_buffered_lines"] < len(lines) / 20
    assert small["max_buffered_lines"] < large["max_buffered_lines"]
    out, capped = run(lines, 25.0, max_buffer_lines=50)
    assert capped["max_buffered_lines"] <= 51
    check_output(lines, out, capped)
    assert any("max_buffer_lines" in w["message"] for w in capped["warnings"])


def test_crlf_and_missing_final_newline_kept():
    lines = [ln.replace("\n", "\r\n") for ln in read_lines(FILES[0])]
    lines[-1] = lines[-1].rstrip("\r\n")
    out, report = run(lines, 2.5)
    check_output(lines, out, report)
    assert all(ln.endswith("\r\n") for ln in out[:-1]) and out[-1] == lines[-1]


def test_arc_split_exactly_on_the_arc():
    # G2/G3 split: the point lies on the circle at the right angle, E splits in proportion
    lines = ["G90\n", "M83\n", "T0\n", "G1 X10 Y0 Z0.2 F1200\n",
             "G3 X0 Y10 I-10 J0 E4.0 F900 ; quarter circle\n",
             "G2 X-10 Y0 R10 E2.0\n", "T1\n", "G1 X-10 Y-10 E1.0\n"]
    out, report = run(lines, 2.5)
    (c,) = report["changes"]
    assert c["split_line"] == 5 and abs(c["advanced_mm"] - 2.5) < 1e-9
    x, y, _ = c["split_point"]
    assert abs(math.hypot(x, y) - 10) < 1e-3
    assert abs(math.atan2(y, x) - (math.pi / 2) * (4.0 - 0.5) / 4.0) < 1e-4
    i = out.index("T1\n")
    assert out[i - 1].startswith("G3 X") and " E3.5 F900" in out[i - 1]
    assert out[i + 1].startswith("G3 X0 Y10 E0.5 I")
    assert out[i + 1].endswith(" ; quarter circle\n")
    # the second half keeps the centre: I J from its own start
    words = {w[0]: float(w[1:]) for w in out[i + 1].split(";")[0].split()[1:]}
    assert abs(x + words["I"]) < 1e-3 and abs(y + words["J"]) < 1e-3
    # an R arc (R > 0: the short way, clockwise, so about (-10, 10)) is split with I/J
    out, report = run(lines, 1.5)
    (c,) = report["changes"]
    assert c["split_line"] == 6
    x, y, _ = c["split_point"]
    assert abs(math.hypot(x + 10, y - 10) - 10) < 1e-3
    assert abs(math.atan2(y - 10, x + 10) - (-math.pi / 2) * 0.25) < 1e-4


def e_moves(lines):
    """(line number, E delta) of every E-only move (no X, Y, Z), absolute E as Cura."""
    e = 0.0
    moves = []
    for n, line in enumerate(lines, 1):
        code = line.split(";")[0].split()
        if code[:1] == ["G92"]:
            e = next((float(w[1:]) for w in code if w[0] == "E"), e)
        elif code[:1] in (["G0"], ["G1"]) and any(w[0] == "E" for w in code):
            v = next(float(w[1:]) for w in code if w[0] == "E")
            if not any(w[0] in "XYZ" for w in code[1:]):
                moves.append((n, v - e))
            e = v
    return moves


def test_cura_switch_retraction_is_paid_back_not_printed():
    """Cura retracts the old tool 16 mm before each change (switch_extruder_retraction_
    amount) and pushes that back, E only, when the tool comes back: no printing, so
    every change still moves by exactly the purge, in front of that retraction."""
    lines = read_lines(CURA)
    assert "M82 ;absolute extrusion mode\n" in lines
    assert sum(ln.startswith(";LAYER:") for ln in lines) == 20
    ts = changes_in(lines)
    assert len(ts) == 41 and {t for _, t, _ in ts} == {0, 1, 2}
    retractions = {n for n, de in e_moves(lines) if abs(de + 16) < 1e-4}
    for n, _, _ in ts[1:]:
        assert any(n - 5 < r < n for r in retractions), n     # just before each change
    out, report = run(lines, 2.5)
    advanced = check_output(lines, out, report)
    assert not report["warnings"] and len(advanced) == 40
    assert all(abs(mm - 2.5) < TOL_MM for mm in advanced.values())
    # In the output each change comes before the old tool's last printing and its
    # switch retraction, which stay where they were.
    t_out = changes_in(out)[1:]
    out_retractions = sorted(n for n, de in e_moves(out) if abs(de + 16) < 1e-4)
    assert len(out_retractions) == len(retractions)
    printed_mm = [s for s, _, _, _ in walk(out)]
    for n_out, _, _ in t_out:
        after = [r for r in out_retractions if r > n_out]
        assert after and printed_mm[after[0] - 1] > printed_mm[n_out - 1]


def test_odd_spellings_are_read_and_split():
    # lower case, glued words, leading zeros, an indented T: read as slicers write them
    lines = ["M83\n", "T0\n", "G1 Z0.2\n", "g01x10y0e4 ; odd\n", "   T1\n", "G1 X20 E1\n"]
    out, report = run(lines, 1.0)
    (c,) = report["changes"]
    assert c["split_line"] == 4 and c["split_point"] == [7.5, 0.0, 0.2]
    assert out[3:6] == ["G1 X7.5 Y0 E3\n", "   T1\n", "G1 X10 Y0 E1 ; odd\n"]


def test_cli_l1_l2_and_report(tmp_path, capsys):
    src = os.path.join(TESTDATA, FILES[1])
    out_path, rep_path = tmp_path / "out.gcode", tmp_path / "report.json"
    assert cli.main(["advance", src, "-o", str(out_path), "--l1-mm", "1.5",
                     "--l2-mm", "2.0", "--report", str(rep_path)]) == 0
    # The report is streamed as JSON lines: each change and warning, then a summary.
    records = [json.loads(line) for line in rep_path.read_text().splitlines()]
    report = records[-1]
    assert report["kind"] == "summary" and report["max_purge_mm"] == 2.5
    report["changes"] = [r for r in records if r["kind"] == "change"]
    report["warnings"] = [r for r in records if r["kind"] == "warning"]
    assert report["changes"] and len(report["changes"]) + len(report["warnings"]) == len(records) - 1
    with open(out_path, newline="") as f:
        check_output(read_lines(FILES[1]), f.readlines(), report)
    err = capsys.readouterr().err
    assert "advanced 2.50000 mm" in err
    matrix = tmp_path / "m.txt"
    matrix.write_text(MATRIX)
    assert cli.main(["advance", src, "-o", str(out_path), "--purge-matrix", str(matrix)]) == 0
    with pytest.raises(SystemExit):
        cli.main(["advance", src, "-o", str(out_path)])


# --- One rule with the firmware's transitions ---------------------------------------
# A file advanced by the purge and printed plainly must step every drive as the
# original printed with firmware transitions of that length (L0 = L1 + L2/2), also
# where a retraction straddles a change (one tool retracts, the next unretracts). Both
# sides are worked out by trace check's model (mixstep.tracemodel, tested against the
# firmware's traces in test_trace_check.py and test_transition.py).

def _drive_steps(path, settings):
    from mixstep import tracemodel
    return {k: v for k, v in tracemodel.expected(path, settings)["steps"].items()
            if k.startswith("e")}


def _same_steps_as_firmware_transitions(gcode, tmp_path, purge_mm, policy):
    from mixstep import tracecheck
    advanced = tmp_path / "advanced.gcode"
    adv.advance_file(gcode, advanced, purge_mm)
    plain = tracecheck.board_settings("sim", {"retract_policy": policy})
    with_transitions = dict(plain, transition_l1_mm=purge_mm, transition_l2_mm=0.0)
    firmware = _drive_steps(gcode, with_transitions)
    advanced_steps = _drive_steps(advanced, plain)
    return firmware, advanced_steps


@pytest.mark.parametrize("name", ["short_3tool_m117_prusaslicer.gcode", "cura_part_3tool.gcode",
                                  "slic3r_part_3tool_rel.gcode"])
@pytest.mark.parametrize("policy", [0, 1, 2])
def test_advanced_file_steps_each_drive_as_firmware_transitions_do(name, policy, tmp_path):
    """Real slicer output, whose changes retract with one tool and unretract with the
    next (PrusaSlicer's single-nozzle toolchange retraction, Cura's switch retraction,
    Slic3r's wipes)."""
    firmware, advanced = _same_steps_as_firmware_transitions(
        os.path.join(TESTDATA, name), tmp_path, 2.0, policy)
    assert firmware == advanced
    assert sum(1 for v in firmware.values() if v) >= 3


def _straddling_file(segments):
    """G-code of printing moves along X and tool changes, each change retracting r mm
    with the old tool and unretracting them with the new one (E-only) when r > 0."""
    lines = ["G21", "G90", "M83", "M302 P1", "T0", "G1 Z0.3 F600"]
    x = 0.0
    for kind, value, r in segments:
        if kind == "print":
            x += 1.0 + value
            lines.append("G1 X%.3f E%.5f F1800" % (x, value))
        else:
            if r:
                lines.append("G1 E-%.5f F2400" % r)
            lines.append("T%d" % value)
            if r:
                lines.append("G1 E%.5f F2400" % r)
    return "\n".join(lines) + "\n"


from hypothesis import given, settings as hsettings, strategies as hst, HealthCheck  # noqa: E402

_segment = hst.one_of(
    hst.tuples(hst.just("print"), hst.sampled_from([0.3, 0.8, 1.0, 2.5, 4.0, 7.3]),
               hst.just(0.0)),
    hst.tuples(hst.just("change"), hst.integers(0, 2), hst.sampled_from([0.0, 0.8, 2.0])))


@hsettings(max_examples=30, deadline=None, suppress_health_check=list(HealthCheck))
@given(hst.lists(_segment, min_size=4, max_size=24), hst.sampled_from([0, 1, 2]))
def test_changes_straddled_by_retractions_land_where_the_firmware_puts_them(segments, policy):
    import tempfile
    from pathlib import Path
    with tempfile.TemporaryDirectory() as tmp:
        gcode = Path(tmp) / "straddling.gcode"
        gcode.write_text(_straddling_file(segments))
        firmware, advanced = _same_steps_as_firmware_transitions(gcode, Path(tmp), 2.5, policy)
    assert firmware == advanced


def test_the_firmware_itself_agrees_on_a_straddling_file(tmp_path):
    """The issue's case and more on the simulated printer: T0 prints 10 mm, retracts
    0.8, T1 unretracts 0.8 and prints 10, T0 prints 1, T1 prints 9, purge 2.5 mm:
    the drives end at T0 8.5 mm and T1 21.5 mm of filament either way."""
    from mixstep import sim
    segments = [("print", 7.3, 0), ("print", 2.7, 0), ("change", 1, 0.8), ("print", 4.0, 0),
                ("print", 6.0, 0), ("change", 0, 0.0), ("print", 1.0, 0), ("change", 1, 2.0),
                ("print", 4.0, 0), ("print", 5.0, 0)]
    gcode = tmp_path / "straddling.gcode"
    gcode.write_text(_straddling_file(segments))
    advanced = tmp_path / "advanced.gcode"
    adv.advance_file(gcode, advanced, 2.5)
    with_transitions = sim.run(gcode, settings={"transition_l1_mm": 2.5})
    plain = sim.run(advanced)
    assert with_transitions["errors"] == plain["errors"] == []
    assert with_transitions["steps"] == plain["steps"]
    # 3527.5 and 8922.5 steps at 415 steps/mm, each rounded half away from zero
    assert (plain["steps"]["e0"], plain["steps"]["e1"]) == (3528, 8923)
