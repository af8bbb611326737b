"""`mixstep detool`: slicer tools become mixing virtual tools. The end-to-end check
prints the converted example on the simulated printer and counts every drive's steps."""
import pytest

from mixstep import cli, detool, paths, sim
from gcode_model import expected_steps

EXAMPLE = paths.ROOT / "testdata" / "part_3tool_prusaslicer_rel.gcode"
CURA = paths.ROOT / "testdata" / "cura_part_3tool.gcode"
# Invertible, so matching the three drive totals pins down every tool's share.
MATRIX = "0.7,0.3,0;0,0.5,0.5;0.2,0.3,0.5"


def test_matrix_rows_are_normalised_and_bad_rows_refused(tmp_path):
    assert detool.parse_matrix("2,1,1;0,3,0") == [[0.5, 0.25, 0.25], [0.0, 1.0, 0.0]]
    f = tmp_path / "m.txt"
    f.write_text("# palette\n1 1\n0, 4   # pure drive 1\n")
    assert detool.parse_matrix(str(f)) == [[0.5, 0.5], [0.0, 1.0]]
    with pytest.raises(ValueError, match="all zero"):
        detool.parse_matrix("1,0;0,0")
    with pytest.raises(ValueError, match="negative"):
        detool.parse_matrix("1,-1")
    with pytest.raises(ValueError, match="row 1 has 3 drives"):
        detool.parse_matrix("1,0;1,0,0")


def test_small_weights_are_written_as_plain_decimals_the_firmware_reads_whole(sim_printer):
    """0.0001 as %g writes it (1e-04) would be read by any G-code parser as 1 followed
    by an E word: the mix 1:0.0001 written out must come back as 9999:1 from the
    firmware itself."""
    text = detool.header([[1.0, 0.0001, 0.0]], [0]).decode()
    assert "e-" not in text and "M163 S1 P0.0001" in text
    printer = sim_printer()
    for line in text.splitlines():
        if not line.startswith(";"):
            assert printer.send(line)[-1] == "ok"
    assert printer.send("M165 R")[0] == "M567 P0 E9999:1:0:0:0:0"
    with pytest.raises(ValueError, match="millionth"):
        detool.decimal(1e-7)


def test_defines_used_tools_converts_temperatures_keeps_other_bytes(tmp_path):
    src = tmp_path / "in.gcode"
    src.write_bytes(b"; made by a slicer\r\n"
                    b"M104 T0 S210\r\n"
                    b"M104 T1 S150 ; standby for the idle nozzle\r\n"
                    b"T0\r\n"
                    b"G1  X1 E1.5 ;  odd   spacing stays\r\n"
                    b"T2 ; change\r\n"
                    b"M109 T2 S215\r\n"
                    b"G1 X2 E1\r\n")
    out = tmp_path / "out.gcode"
    summary = detool.detool(src, out, detool.parse_matrix("1,0,0;0,1,0;1,1,2"))
    assert summary == {"tools": [0, 2], "temperatures_converted": 2, "temperatures_dropped": 1}
    lines = out.read_bytes().split(b"\r\n")
    assert lines[0] == b"; made by a slicer"  # the slicer's leading comments stay first
    code = [l for l in lines if l and not l.startswith(b";")]
    assert code == [
        b"M163 S0 P1", b"M163 S1 P0", b"M163 S2 P0", b"M164 S0",
        b"M163 S0 P0.25", b"M163 S1 P0.25", b"M163 S2 P0.5", b"M164 S2",  # T1 is never used
        b"M104 S210",
        b"T0",
        b"G1  X1 E1.5 ;  odd   spacing stays",
        b"T2 ; change",
        b"M109 S215",
        b"G1 X2 E1",
    ]
    # The idle nozzle's standby temperature must not reach the only hot end.
    assert any(l.startswith(b"; mixstep detool: dropped") and b"M104 T1 S150" in l for l in lines)


def test_unknown_tool_is_refused(tmp_path):
    src = tmp_path / "in.gcode"
    src.write_text("T3\nG1 X1 E1\n")
    with pytest.raises(ValueError, match="T3 but the matrix has only 2 rows"):
        detool.detool(src, tmp_path / "o.gcode", detool.parse_matrix("1,0;0,1"))


@pytest.mark.parametrize("example", [EXAMPLE, CURA], ids=["prusaslicer", "cura"])
def test_example_lines_unchanged_except_the_header(tmp_path, example):
    out = tmp_path / "out.gcode"
    cli.main(["detool", str(example), "-o", str(out), "--matrix", MATRIX])
    original = example.read_bytes().splitlines(keepends=True)
    converted = out.read_bytes().splitlines(keepends=True)
    start = converted.index(b"; mixstep detool: slicer tool T<n> is virtual tool T<n>, "
                            b"mix = matrix row n\n")
    end = start + 1 + 3 * 5  # per tool: a comment, M163 for each of 3 drives, M164
    header = converted[start:end]
    assert [l.split()[0] for l in header if not l.startswith(b";")] == \
        [b"M163"] * 3 + [b"M164"] + [b"M163"] * 3 + [b"M164"] + [b"M163"] * 3 + [b"M164"]
    # It goes after the slicer's leading comments, before the first command.
    assert all(l.startswith(b";") or not l.strip() for l in converted[:start])
    assert not converted[end].startswith(b";") and converted[end].strip()
    # The file has no tool-named temperatures, so everything else is byte for byte.
    assert converted[:start] + converted[end:] == original


@pytest.mark.slow
def test_simulated_print_gives_each_drive_its_matrix_share(tmp_path, board):
    out = tmp_path / "mixed.gcode"
    detool.detool(EXAMPLE, out, detool.parse_matrix(MATRIX))
    report = sim.run(out)
    assert report["errors"] == []
    steps_per_mm = board["SETTINGS"]["steps_per_mm"]
    # Steps each slicer tool asks for: what its drive gets when tools are pure drives.
    per_tool = expected_steps(EXAMPLE, steps_per_mm)
    matrix = detool.parse_matrix(MATRIX)
    for drive in range(3):
        want = sum(matrix[tool][drive] * per_tool["e%d" % tool] for tool in range(3))
        assert want > 10000
        # 30 tool changes: the mixer keeps each drive within a step of its share.
        assert abs(report["steps"]["e%d" % drive] - want) <= 3, drive
    assert report["steps"]["e3"] == report["steps"]["e4"] == report["steps"]["e5"] == 0
    assert report["steps"]["y"] == per_tool["y"] and report["steps"]["z"] == per_tool["z"]
