"""M486, cancelling objects, on the firmware running on the unix port: real PrusaSlicer
files of three labelled objects (testdata/objects_3copies_prusaslicer.txt), one of them
cancelled before it prints, part way through, or brought back. `trace check`, whose
model of the G-code knows cancelled objects, checks each trace; the tests also work
out from the file alone what the cancelled object would have extruded."""
import re

import pytest

from mixstep import paths, trace, tracecheck
from mixstep.simprinter import SimPrinter

SAMPLES = paths.ROOT / "testdata"
FILES = {"relative_e": SAMPLES / "objects_3copies_prusaslicer_rel.gcode",
         "absolute_e": SAMPLES / "objects_3copies_prusaslicer_abs.gcode"}
E_SPM = 415
_START = re.compile(r"; printing object (.*)$")
_STOP = re.compile(r"; stop printing object (.*)$")


def labelled(path, out, extra=()):
    """The file with PrusaSlicer 2.5's object comments written as the M486 lines
    PrusaSlicer 2.6 writes for Marlin (M486 T<count> and each object's name before the
    first object, M486 S<n> and S-1 around each object's moves). extra: {line number of
    the file: [lines to put before it]}, as a host would send them there."""
    lines = path.read_text().splitlines()
    names = []
    for text in lines:
        m = _START.match(text)
        if m and m.group(1) not in names:
            names.append(m.group(1))
    first = next(i for i, t in enumerate(lines) if _START.match(t))
    extra = dict(extra)
    out_lines = []
    for i, text in enumerate(lines):
        if i == first:
            out_lines.append("M486 T%d" % len(names))
            for n, name in enumerate(names):
                out_lines += ["M486 S%d" % n, "M486 A%s" % name, "M486 S-1"]
        out_lines += extra.get(i + 1, [])
        m = _START.match(text)
        if m:
            out_lines.append("M486 S%d" % names.index(m.group(1)))
        out_lines.append(text)
        if _STOP.match(text):
            out_lines.append("M486 S-1")
    out.write_text("\n".join(out_lines) + "\n")
    return out, names


def drive_filament_mm(path, cancelled=None, lines=None):
    """Per tool (on the simulated board tool n prints with drive n alone), the filament
    the file feeds, worked out from the file alone, with the object named `cancelled`
    skipped as docs/G-Codes.md says: inside it a move's E is not fed, only followed in
    how much filament would be retracted (a retraction adds to it, extrusion takes from
    it down to 0), and where the skip ends one E move makes the filament retracted what
    it would have been. lines: skip only within that range of line numbers (1-based)."""
    fed = {}
    tool = 0
    absolute = False
    e = 0.0
    retracted = 0.0  # as fed
    skip_retracted = None  # while skipping: as it would be
    name = None

    def after(depth, delta):
        return depth - delta if delta < 0 else max(0.0, depth - delta)

    for number, raw in enumerate(path.read_text().splitlines(), 1):
        start, stop = _START.match(raw), _STOP.match(raw)
        if start:
            name = start.group(1)
        elif stop:
            name = None
        skipping = name is not None and name == cancelled and (
            lines is None or number in lines)
        if skipping and skip_retracted is None:
            skip_retracted = retracted
        elif not skipping and skip_retracted is not None:
            delta = retracted - skip_retracted
            fed[tool] = fed.get(tool, 0.0) + delta
            retracted = after(retracted, delta)
            skip_retracted = None
        code = raw.split(";")[0].strip()
        if not code:
            continue
        cmd, *rest = code.split()
        words = dict((w[0], w[1:]) for w in rest)
        if re.fullmatch(r"T\d+", cmd):
            tool = int(cmd[1:])
        elif cmd in ("M82", "M83"):
            absolute = cmd == "M82"
        elif cmd == "G92" and "E" in words:
            e = float(words["E"])
        elif cmd in ("G0", "G1") and "E" in words:
            v = float(words["E"])
            delta = v - e if absolute else v
            e = v if absolute else e + v
            if skip_retracted is not None:
                skip_retracted = after(skip_retracted, delta)
            else:
                fed[tool] = fed.get(tool, 0.0) + delta
                retracted = after(retracted, delta)
    return fed


def final_xy_e(path):
    """Where the file leaves X, Y and its logical E (no G91 in these files)."""
    pos = {"X": 0.0, "Y": 0.0, "E": 0.0}
    absolute = False
    for raw in path.read_text().splitlines():
        code = raw.split(";")[0].strip()
        if not code:
            continue
        cmd, *rest = code.split()
        if cmd[0] != "G" and cmd not in ("M82", "M83"):
            continue
        words = dict((w[0], float(w[1:] or 0)) for w in rest)
        if cmd in ("M82", "M83"):
            absolute = cmd == "M82"
        elif cmd == "G28":
            for k in [k for k in "XY" if k in words] or "XY":
                pos[k] = 0.0
        elif cmd == "G92":
            pos.update((k, v) for k, v in words.items() if k in pos)
        elif cmd in ("G0", "G1"):
            for k in "XY":
                if k in words:
                    pos[k] = words[k]
            if "E" in words:
                pos["E"] = words["E"] if absolute else pos["E"] + words["E"]
    return pos


def run(gcode, tmp_path):
    """The file through the simulated printer, then M400 and M114: its report (with
    "errors", the lines answered with one, and "m114", the position), and its trace."""
    edges = tmp_path / (gcode.stem + ".edges")
    vcd = tmp_path / (gcode.stem + ".vcd")
    printer = SimPrinter(edges_path=edges)
    errors = []
    for number, raw in enumerate(gcode.read_text().splitlines(), 1):
        errors += ["line %d: %s" % (number, r) for r in printer.send(raw)
                   if r.startswith("Error:")]
    printer.send("M400")
    m114 = printer.send("M114")[0]
    report = printer.finish()
    report.update(errors=errors, m114=m114)
    trace.write_vcd(edges, vcd)
    return report, vcd


def _check_passes(vcd, gcode):
    result = tracecheck.check(vcd, gcode)
    failed = [c for c in result["checks"] if c["ok"] is False]
    assert failed == [], failed
    assert result["unmodelled"] == {}
    return result


@pytest.mark.parametrize("mode", sorted(FILES))
def test_a_cancelled_object_extrudes_nothing_and_the_rest_prints_as_sliced(mode, tmp_path):
    """M486 P1 before the print (as a host sends it): object 1's printing moves feed no
    filament, each drive's steps fall by exactly that object's printing filament on the
    drive's tool (its retractions and their undoing net to nothing), the travel runs
    so the head ends where the file leaves it, and E stays the file's E."""
    source = FILES[mode]
    whole, names = labelled(source, tmp_path / "whole.gcode")
    first = next(i for i, t in enumerate(source.read_text().splitlines(), 1)
                 if _START.match(t))
    cancelled, _ = labelled(source, tmp_path / "cancelled.gcode", {first: ["M486 P1"]})
    assert len(names) == 3
    whole_report, _ = run(whole, tmp_path)
    report, vcd = run(cancelled, tmp_path)
    assert report["errors"] == [] and whole_report["errors"] == []
    _check_passes(vcd, cancelled)
    fed = drive_filament_mm(source, names[1])
    for d in range(3):
        # The whole print's drives as the file says (a check of the rule's reading),
        # and the cancelled print's.
        assert abs(whole_report["steps"]["e%d" % d]
                   - drive_filament_mm(source)[d] * E_SPM) <= 1, d
        assert abs(report["steps"]["e%d" % d] - fed[d] * E_SPM) <= 1, d
    # The object printed with every tool, and each drive fed less for its cancel.
    dropped = [whole_report["steps"]["e%d" % d] - report["steps"]["e%d" % d]
               for d in range(3)]
    assert min(dropped) >= 0 and sum(dropped) > 0.25 * sum(
        whole_report["steps"]["e%d" % d] for d in range(3))
    assert report["steps"]["x"] == whole_report["steps"]["x"]
    assert report["steps"]["y"] == whole_report["steps"]["y"]
    end = final_xy_e(source)
    assert report["m114"].startswith("X:%.2f Y:%.2f Z:" % (end["X"], end["Y"]))
    assert " E:%.2f " % end["E"] in report["m114"]


def test_an_object_cancelled_part_way_and_brought_back_passes_the_check(tmp_path):
    """M486 C while object 1 prints its second layer, M486 U1 before its fifth: what it
    printed before and after stays, what lay between is skipped, and the filament it
    would have retracted at the cancel is put right where the skip ends."""
    source = FILES["relative_e"]
    lines = source.read_text().splitlines()
    starts = [i for i, t in enumerate(lines, 1) if _START.match(t)
              and t.endswith("copy 1")]
    assert len(starts) >= 5
    cancel_at = starts[1] + 20  # inside its second layer's moves
    back_at = starts[4]
    gcode, names = labelled(source, tmp_path / "part_way.gcode",
                            {cancel_at: ["M486 C"], back_at: ["M486 U1"]})
    whole, _ = labelled(source, tmp_path / "whole.gcode")
    whole_report, _ = run(whole, tmp_path)
    report, vcd = run(gcode, tmp_path)
    assert report["errors"] == []
    _check_passes(vcd, gcode)
    fed = drive_filament_mm(source, names[1], range(cancel_at, back_at))
    for d in range(3):
        assert abs(report["steps"]["e%d" % d] - fed[d] * E_SPM) <= 1, d
    assert sum(report["steps"]["e%d" % d] for d in range(3)) < \
        sum(whole_report["steps"]["e%d" % d] for d in range(3)) - 1000


def test_m486_answers_and_refusals(printer):
    assert printer.send("M486") == ["echo:objects:0 current:-1 cancelled:none", "ok"]
    for line in ("M486 T2", "M486 S0", "M486 AFirst part", 'M486 S1 A"Second part"',
                 "M486 S-1"):
        assert printer.send(line) == ["ok"], line
    assert printer.send("M486 P1") == ["echo:object 1 cancelled", "ok"]
    assert printer.send("M486") == [
        "echo:object 0 First part", "echo:object 1 Second part cancelled",
        "echo:objects:2 current:-1 cancelled:1", "ok"]
    for line, error in (
            ("M486 C", "M486 C cancels the current object, and none is"),
            ("M486 S1000", "M486 S1000: objects are -1..999"),
            ("M486 P-1", "M486 P-1: objects are 0..999"),
            ("M486 X2", "M486 takes T S P U C and A<name>, not 'X2'"),
            ("M486 S1.5", "M486 S needs a whole number, got '1.5'"),
            ("M486 AName", "M486 A names the current object, and none is (M486 S)")):
        assert printer.send(line) == ["Error:" + error, "ok"], line
    for line in ("M486 U1", "M486 S0", "M486 C"):
        printer.send(line)
    assert printer.send("M486")[-2] == "echo:objects:2 current:0 cancelled:0"
    # A new print (T) forgets what the last one cancelled.
    printer.send("M486 T3")
    assert printer.send("M486")[-2] == "echo:objects:3 current:-1 cancelled:none"
    assert printer.finish()["steps"]["x"] == 0
