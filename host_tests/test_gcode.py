"""The G-code parser as a unit, on the MicroPython unix port."""
import json

import pytest

PARSE = """
import json
from mixfw.gcode import Parser, GcodeError
p = Parser()
out = []
for s in json.loads(%r):
    b = s.encode()
    try:
        l = p.parse(b, len(b))
        words = {}
        for i in range(26):
            ch = chr(65 + i)
            if l.has(ch):
                words[ch] = l.float(ch) if l.has_value(ch) else None
        out.append([l.letter, l.number, words])
    except GcodeError as e:
        out.append("Error:" + str(e))
print(json.dumps(out))
"""


def parse(mp, *lines):
    return mp.json(PARSE % json.dumps(list(lines)))


def test_words_case_spacing_and_comments(mp):
    got = parse(mp, "G1 X76.923 Y79.437 E.06669", "g1x10y-2.5 ; move", "G1 (why) X1 ( ) Y2",
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
    out = mp.run("""
import micropython
from mixfw.gcode import Parser
p = Parser()
b = bytearray(b"G1 X76.923 Y79.437 Z0.2 E.06669 F1800 ; comment")
n = len(b)
i = 0
micropython.heap_lock()
while i < 100:
    p.parse(b, n)
    i += 1
micropython.heap_unlock()
print("done")
""")
    assert out.strip() == "done"


def test_each_line_keeps_nothing_of_the_line_before(mp):
    """The parser stores a line's command, N word and text arguments only where they
    differ from the line before's: each line still reads as itself, also after one
    with an N word, one with text arguments, or one whose command key is the same
    number (G70000 and M10000)."""
    lines = ["N5 G1 X1", "G1 X2", "M23 part.gcode", "G1 X3", "N6 M23 b.gcode", "M23 c",
             "G1 E1", "G70000", "M10000", "T1", "", "G1 X4"]
    got = mp.json("""
import json
from mixfw.gcode import Parser
p = Parser((("M", 23),))
out = []
for s in json.loads(%r):
    b = s.encode()
    l = p.parse(b, len(b))
    out.append([l.letter, l.number, l.has_line_number, l.line_number, l.args_text,
                l.present])
print(json.dumps(out))
""" % json.dumps(lines))
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
