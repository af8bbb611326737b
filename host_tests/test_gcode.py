"""The G-code parser as a unit, on the MicroPython unix port."""
import json

import pytest


def parse(mp, *lines):
    """The lines through the parser (upy/gcode_parse.py)."""
    return mp.script_json("gcode_parse", stdin=json.dumps(list(lines)).encode())


def test_words_case_spacing_and_comments(mp):
    got = parse(mp, "G1 X76.923 Y79.437 E.06669", "g1 x10 y-2.5 ; move", "G1 (why) X1 ( ) Y2",
                "  M163   S 0 P+0.2  ", "G28 X", "T2", "", "; just a comment")
    assert got == [
        ["G", 1, {"X": 76.923, "Y": 79.437, "E": 0.06669}],
        ["G", 1, {"X": 10.0, "Y": -2.5}],
        ["G", 1, {"X": 1.0, "Y": 2.0}],
        ["M", 163, {"S": 0.0, "P": 0.2}],
        ["G", 28, {"X": None}],
        ["T", 2, {}],
        ["", 0, {}],
        ["", 0, {}],
    ]


@pytest.mark.parametrize("line, reason", [
    ("G1 X1.2.3", "malformed number after X"),
    ("G1 X-", "malformed number after X"),
    # A number is read whole or not at all: no exponent, no lower-case letter after it.
    ("M163 S1 P9.999e-05", "malformed number after P"),
    ("M104 S5x", "malformed number after S"),
    ("g1x10y5", "malformed number after G"),
    ("G1 X1 X2", "parameter X given twice"),
    ("X10", "line must start with G, M or T"),
    ("G1 X1 (open", "unclosed ( comment"),
    ("G1 X12345678901", "number too long"),
    ("G1 X1 #", "unexpected character"),
    ("G", "G needs a number"),
])
def test_bad_lines_name_the_problem(mp, line, reason):
    (got,) = parse(mp, line)
    assert got.startswith("Error:") and reason in got


def test_parsing_a_line_allocates_nothing(mp):
    out = mp.script("gcode_parse_heap_locked")
    assert out.strip() == "done"


def test_each_line_keeps_nothing_of_the_line_before(mp):
    """The parser stores a line's command, N word and text arguments only where they
    differ from the line before's: each line still reads as itself, also after one
    with an N word, one with text arguments, or one whose command key is the same
    number (G70000 and M10000)."""
    lines = ["N5 G1 X1", "G1 X2", "M23 part.gcode", "G1 X3", "N6 M23 b.gcode", "M23 c",
             "G1 E1", "G70000", "M10000", "T1", "", "G1 X4"]
    got = mp.script_json("gcode_line_state", stdin=json.dumps(lines).encode())
    x, e = 1 << 23, 1 << 4
    assert got == [
        ["G", 1, True, 5, "", x],
        ["G", 1, False, 0, "", x],
        ["M", 23, False, 0, "part.gcode", 0],
        ["G", 1, False, 0, "", x],
        ["M", 23, True, 6, "b.gcode", 0],
        ["M", 23, False, 0, "c", 0],
        ["G", 1, False, 0, "", e],
        ["G", 70000, False, 0, "", 0],
        ["M", 10000, False, 0, "", 0],
        ["T", 1, False, 0, "", 0],
        ["", 0, False, 0, "", 0],
        ["G", 1, False, 0, "", x],
    ]
