"""`mixstep.gcodeio`: the host tools' one G-code reader, against hand-worked lines, the
test-data files and an independent model of what each axis and drive is asked for."""
import math

import pytest
from hypothesis import given, settings, strategies as st

from gcode_model import expected_steps
from mixstep import gcodeio, paths

TESTDATA = paths.ROOT / "testdata"
FILES = ["part_3tool_prusaslicer_rel.gcode", "part_3tool_prusaslicer_abs.gcode",
         "slic3r_part_3tool_abs.gcode", "cura_part_3tool.gcode"]


def read(text):
    reader = gcodeio.Reader(text.splitlines(keepends=True))
    return reader, list(reader)


def test_positions_modes_and_e_deltas():
    _, lines = read("G1 X10 Y5 F1200\n"
                    "M83\n"
                    "G1 X20 E1.5\n"
                    "G91\n"
                    "G1 X1 Y-1 Z0.2 E0.5 ; relative, E too\n"
                    "G90\n"
                    "G1 E3\n"          # absolute E again: 3 - 2 = 1 mm fed, no XYZ
                    "M83\n"
                    "G1 X0 E-2\n")
    assert [ln.end for ln in lines] == [
        (10.0, 5.0, 0.0, 0.0), (10.0, 5.0, 0.0, 0.0), (20.0, 5.0, 0.0, 1.5),
        (20.0, 5.0, 0.0, 1.5), (21.0, 4.0, 0.2, 2.0), (21.0, 4.0, 0.2, 2.0),
        (21.0, 4.0, 0.2, 3.0), (21.0, 4.0, 0.2, 3.0), (0.0, 4.0, 0.2, 1.0)]
    assert [ln.de_mm for ln in lines] == [0, 0, 1.5, 0, 0.5, 0, 1.0, 0, -2.0]
    # printing: positive E and X/Y/Z moved; not the E-only prime nor the retraction
    assert [ln.printing for ln in lines] == [False, False, True, False, True, False, False,
                                             False, False]
    assert all(a.end is b.start for a, b in zip(lines, lines[1:]))
    assert lines[1].end is lines[1].start      # a line that moves nothing
    assert [ln.lineno for ln in lines] == list(range(1, 10))
    assert lines[4].code == "G1" and lines[4].words == {"X": "1", "Y": "-1", "Z": "0.2",
                                                        "E": "0.5"}


def test_g92_g28_offsets_give_the_machine_position():
    reader, lines = read("G28\nG1 X10 Y10 E5\nG92 X0 E0\nG1 X5 E1\nG92\nG1 Y2\n"
                         "G28 X\nG92 E-1 Z\n")
    ends = [ln.end for ln in lines]
    assert ends[2] == (0.0, 10.0, 0.0, 0.0) and ends[3] == (5.0, 10.0, 0.0, 1.0)
    assert ends[4] == (0.0, 0.0, 0.0, 0.0)     # G92 alone: all four zero
    assert ends[5] == (0.0, 2.0, 0.0, 0.0)
    assert ends[6] == (0.0, 2.0, 0.0, 0.0) and ends[7] == (0.0, 2.0, 0.0, -1.0)
    assert lines[2].de_mm == 0.0               # setting E feeds nothing
    # machine: X homed at the end (offset 0); Y 2 + the 10 the bare G92 took off;
    # E 6 mm fed net
    assert reader.offset == (0.0, 10.0, 0.0, 7.0)
    assert ends[-1][3] + reader.offset[3] == 6.0


def test_tools_markers_and_feed():
    reader = gcodeio.Reader([";LAYER_CHANGE\n", ";TYPE:External perimeter\n",
                             "T1 ; pick\n", "G1 X1 E1 F600\n", ";WIPE_START\n"])
    it = iter(reader)
    assert next(it).tool is None and reader.layer == 0
    next(it)
    assert reader.feature == "External perimeter"
    t = next(it)
    assert (t.code, t.tool, reader.tool) == ("T1", 1, 1)
    next(it)
    assert reader.feed_mm_min == 600.0 and not reader.wipe
    next(it)
    assert reader.wipe
    reader, lines = read(";LAYER:7\n;TYPE:WALL-OUTER\nG1 F1800\n;WIPE_END\n")
    assert reader.layer == 7 and reader.feature == "WALL-OUTER" and not reader.wipe
    assert lines[2].end == lines[2].start and reader.feed_mm_min == 1800.0


def test_mixing_commands_are_visible_as_codes_and_words():
    _, lines = read("M163 S0 P0.25\nM164 S2\nM165 A0.5 B0.5\nM567 P1 E0.5:0.5:0\n"
                    "T02\nM117 Hello T3\nN12 G1 X1*97\n")
    assert [(ln.code, dict(ln.words)) for ln in lines] == [
        ("M163", {"S": "0", "P": "0.25"}), ("M164", {"S": "2"}),
        ("M165", {"A": "0.5", "B": "0.5"}), ("M567", {"P": "1", "E": "0.5:0.5:0"}),
        ("T2", {}), ("M117", {}), ("G1", {"X": "1"})]
    assert lines[-1].tool == 2 and lines[-1].end[0] == 1.0


def test_lower_case_glued_and_indented_lines_read_as_slicers_write_them():
    _, plain = read("G1 X10.5 Y-2 E.5 F900\n")
    for text in ("g1 x10.5 y-2 e.5 f900\n", "G1X10.5Y-2E.5F900\n", "  G01 X10.5 Y-2 E.5 F900\n",
                 "G1 X 10.5 Y -2 E.5 F900 ; spaced\n"):
        _, other = read(text)
        assert other[0][2:9] == plain[0][2:9], text


def test_unreadable_move_changes_nothing_and_says_why():
    _, lines = read("G1 X1 E1\nG1 X1.2.3 E5\nG1 X\nG1 X2 E2\n")
    assert lines[1].code == "" and lines[1].error and lines[1].end == lines[0].end
    assert lines[2].error
    assert lines[3].de_mm == 1.0 and lines[3].error is None


def test_bytes_in_raw_bytes_out():
    raw = [b"; \xff odd byte\r\n", b"G1 X1 E2 ;\xe9\r\n", b"T1"]
    lines = list(gcodeio.Reader(raw))
    assert [ln.raw for ln in lines] == raw
    assert lines[1].end == (1.0, 0.0, 0.0, 2.0) and lines[2].tool == 1


def test_arcs_from_ij_and_r():
    # a quarter circle of radius 10 around the origin, counter-clockwise
    cx, cy, r, a0, sweep = gcodeio.arc((10, 0), (0, 10), {"I": "-10", "J": "0"}, False)
    assert (cx, cy, r) == (0.0, 0.0, 10.0) and a0 == 0.0
    assert sweep == pytest.approx(math.pi / 2)
    # R > 0 takes the short way; R < 0 the long way, about the other centre
    cx, cy, _, _, sweep = gcodeio.arc((0, 10), (-10, 0), {"R": "10"}, True)
    assert (cx, cy) == pytest.approx((-10, 10)) and sweep == pytest.approx(-math.pi / 2)
    cx, cy, _, _, sweep = gcodeio.arc((0, 10), (-10, 0), {"R": "-10"}, True)
    assert (cx, cy) == pytest.approx((0, 0)) and sweep == pytest.approx(-3 * math.pi / 2)
    # same start and end: a full circle
    assert gcodeio.arc((1, 0), (1, 0), {"I": "-1"}, True)[4] == pytest.approx(-2 * math.pi)
    _, lines = read("G1 X10 Y0\nG3 X10 Y0 I-10 E3\n")
    assert lines[1].printing                     # a full circle prints


@settings(max_examples=200, deadline=None)
@given(st.lists(st.tuples(st.sampled_from("XYZEF"),
                          st.floats(-1000, 1000, allow_nan=False).map(lambda v: round(v, 3))),
                min_size=1, max_size=5),
       st.booleans(), st.booleans())
def test_fast_path_and_general_path_agree(words, rel_xyz, rel_e):
    """Spaced upper-case moves take a fast path; anything else the general one."""
    modes = ("G91\n" if rel_xyz else "G90\n") + ("M83\n" if rel_e else "M82\n")
    body = " ".join("%s%s" % w for w in words)
    start = "G1 X3 Y4 Z5 E6\n"
    fast = read(modes + start + "G1 " + body + "\n")
    slow = read(modes + start + "g1 " + body.lower() + "\n")
    assert fast[1][-1][2:9] == slow[1][-1][2:9]
    assert fast[0].feed_mm_min == slow[0].feed_mm_min


@pytest.mark.parametrize("name", FILES)
def test_machine_positions_and_filament_per_tool_match_the_independent_model(name):
    """What `mixstep trace check` needs: every axis's machine position and each tool's
    net filament, here against host_tests/gcode_model.py."""
    spm = [80.0, 80.0, 400.0, 93.0]
    fed_mm = {}
    with open(TESTDATA / name, newline="") as f:
        reader = gcodeio.Reader(f)
        for ln in reader:
            if ln.de_mm:
                fed_mm[ln.tool or 0] = fed_mm.get(ln.tool or 0, 0.0) + ln.de_mm
        end = ln.end
    want = expected_steps(TESTDATA / name, spm, drives=3)

    def steps(mm, per_mm):
        v = mm * per_mm
        return int(v + 0.5) if v >= 0 else -int(0.5 - v)
    for i, axis in enumerate("xyz"):
        assert steps(end[i] + reader.offset[i], spm[i]) == want[axis]
    assert sorted(fed_mm) == [0, 1, 2]
    for tool, mm in fed_mm.items():
        assert abs(steps(mm, spm[3]) - want["e%d" % tool]) <= 1


def test_the_files_markers():
    seen = {}
    for name in FILES:
        with open(TESTDATA / name, newline="") as f:
            reader = gcodeio.Reader(f)
            layers, features, wipes = set(), set(), 0
            for ln in reader:
                layers.add(reader.layer)
                features.add(reader.feature)
                wipes += reader.wipe and ln.printing
        seen[name] = (len(layers - {None}), features, wipes)
    assert seen["cura_part_3tool.gcode"][0] == 20
    assert {"WALL-OUTER", "WALL-INNER", "SKIN", "FILL"} <= seen["cura_part_3tool.gcode"][1]
    assert seen["part_3tool_prusaslicer_rel.gcode"][0] == 20
    assert "External perimeter" in seen["part_3tool_prusaslicer_rel.gcode"][1]


def test_tuples_are_the_lines_unnamed():
    with open(TESTDATA / FILES[0], newline="") as f:
        named = list(gcodeio.Reader(f))
    with open(TESTDATA / FILES[0], newline="") as f:
        plain = list(gcodeio.Reader(f).tuples())
    assert all(type(ln) is gcodeio.Line for ln in named)
    assert [tuple(ln) for ln in named] == plain


def test_single_lines_without_state():
    assert gcodeio.parse(b"M104 T1 S150 ; standby\r\n") == ("M104", {"T": "1", "S": "150"})
    assert gcodeio.parse("  t02 ; pick\n") == ("T2", {})
    assert gcodeio.parse(";TYPE:FILL\n") == ("", {})
    assert [gcodeio.tool_of(c) for c in ("T2", "T", "T-1", "M104", "")] == [2, None, None,
                                                                              None, None]
