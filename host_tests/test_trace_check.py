"""`mixstep trace check` and `mixstep trace pull` on real simulated prints: a true
trace passes, and each kind of corruption fails with a non-zero exit."""
import json
import re
import socket
import subprocess
import sys

import numpy as np
import pytest

from mixstep import cli, paths, serve, sim, trace, tracecheck, tracemodel, tracepull
from sigrok import need_sigrok

SAMPLES = paths.ROOT / "testdata"
PRINT = SAMPLES / "part_3tool_prusaslicer_rel.gcode"
# The print whose trace the corruption tests read: the shortest real slicer file (make
# test-all checks the whole example part too, with every other file, below).
PRINTED = SAMPLES / "short_3tool_m117_prusaslicer.gcode"
# Every committed slicer file; the 100,000-line planner benchmark by its first 1000
# lines (the rest is the same part again, and would take minutes to simulate).
BENCH_FILE = SAMPLES / "slic3r_part_x4_100k.gcode"
SLICER_FILES = sorted(p.name for p in SAMPLES.glob("*.gcode") if p != BENCH_FILE) + [
    "slic3r_part_x4_100k_head.gcode"]


@pytest.fixture(scope="module")
def traces(tmp_path_factory):
    """trace_of(name): the simulated trace of a testdata file, made once per module
    (each test that reads a print shares it)."""
    out = tmp_path_factory.mktemp("slicer_traces")
    made = {}

    def trace_of(name):
        if name not in made:
            gcode = SAMPLES / name
            if name == "slic3r_part_x4_100k_head.gcode":
                gcode = out / name
                with open(BENCH_FILE) as f:
                    gcode.write_text("".join(next(f) for _ in range(1000)))
            vcd = out / (name + ".vcd")
            report = sim.run(gcode, trace_path=vcd)
            assert report["errors"] == [], report["errors"][:5]
            made[name] = (gcode, vcd, report)
        return made[name]
    return trace_of


@pytest.fixture(scope="module")
def printed(traces):
    """PRINTED's trace, simulated once."""
    return traces(PRINTED.name)[1]


@pytest.fixture(scope="module")
def snippet(tmp_path_factory):
    """The print's first 400 lines with mixed tools (T0 1:2:3 by M567, T2 by
    M163/M164), so the mix check sees several drives at once. Short, so sigrok's
    constant-rate expansion stays small."""
    out = tmp_path_factory.mktemp("trace_snippet")
    lines = PRINT.read_text().splitlines(keepends=True)
    mixes = ["M567 P0 E1:2:3\n", "M163 S0 P0.2\n", "M163 S1 P0.5\n", "M163 S4 P0.3\n",
             "M164 S2\n"]
    gcode = out / "snippet.gcode"
    gcode.write_text("".join(lines[:21] + mixes + lines[21:400]))
    report = sim.run(gcode, trace_path=out / "snippet.vcd", edges_path=out / "snippet.edges")
    assert report["errors"] == []
    return gcode, out / "snippet.vcd", out / "snippet.edges", report


def _run_cli(*argv):
    return cli.main(["trace", "check"] + [str(a) for a in argv])


def _failed(report):
    return sorted(c["name"] for c in report["checks"] if c["ok"] is False)


def _ident(text, name):
    return re.search(rb"\$var wire 1 (\S+) " + name.encode() + rb" \$end", text).group(1)


def _keep_signals(text, keep):
    """A simulated VCD as a capture that probed only the signals named in keep: the
    other signals' declarations and changes are left out."""
    head, sep, body = text.partition(b"$enddefinitions $end\n")
    drop = set()
    kept_head = []
    for line in head.splitlines(keepends=True):
        var = re.match(rb"\$var wire 1 (\S+) (\S+) \$end", line)
        if var and var.group(2).decode() not in keep:
            drop.add(var.group(1))
        else:
            kept_head.append(line)
    kept_body = [l for l in body.splitlines(keepends=True)
                 if not (l[:1] in b"01" and l[1:].rstrip() in drop)]
    return b"".join(kept_head) + sep + b"".join(kept_body)


def _by_name(report):
    return {c["name"]: c for c in report["checks"]}


# --- the true trace -------------------------------------------------------------------

def test_the_simulated_print_passes_every_check(printed, capsys):
    assert _run_cli(printed, "--gcode", PRINTED) == 0
    out = capsys.readouterr().out
    assert "FAIL" not in out and "OK:" in out
    assert _run_cli(printed, "--gcode", PRINTED, "--json", "-") == 0
    report = json.loads(capsys.readouterr().out)
    by_name = {c["name"]: c for c in report["checks"]}
    assert by_name["steps_e2"]["measured"] == by_name["steps_e2"]["expected"] > 0
    assert by_name["moves"]["ok"] and by_name["moves"]["measured"] > 1000
    for name in ("pulse_high_us", "step_low_us", "dir_setup_us", "rate_x", "rate_e0", "mix"):
        assert by_name[name]["ok"] is True, by_name[name]


def test_expected_counts_agree_with_the_independent_model(board):
    from gcode_model import expected_steps
    want = expected_steps(PRINT, board["SETTINGS"]["steps_per_mm"])
    assert tracecheck.expected_from_gcode(PRINT, board["SETTINGS"])["steps"] == want


def test_mixed_tools_pass_and_the_mix_check_sees_several_drives(snippet):
    gcode, vcd_path, _, report = snippet
    result = tracecheck.check(vcd_path, gcode)
    assert _failed(result) == []
    assert sum(1 for d in ("e0", "e1", "e2", "e4") if report["steps"][d] > 0) == 4
    mix = next(c for c in result["checks"] if c["name"] == "mix")
    assert mix["measured"] > 0  # several drives share windows: not trivially exact
    assert mix["measured"] <= 1.5


def test_small_chunks_give_the_same_report(snippet):
    gcode, vcd_path, _, _ = snippet
    whole = tracecheck.check(vcd_path, gcode)
    pieces = tracecheck.check(vcd_path, gcode, chunk_bytes=4096)
    assert pieces["checks"] == whole["checks"]


def test_a_logic_analysers_names_are_mapped(snippet, tmp_path):
    gcode, vcd_path, _, _ = snippet
    renamed = tmp_path / "la.vcd"
    text = vcd_path.read_bytes()
    renamed.write_bytes(text.replace(b" e1_step $end", b" D0 $end").replace(b" e1_dir $end",
                                                                            b" D1 $end"))
    unmapped = tracecheck.check(renamed, gcode)
    assert unmapped["missing_signals"] == ["e1_step", "e1_dir"]
    assert _failed(unmapped) == ["steps_e1"]
    assert _run_cli(renamed, "--gcode", gcode, "--map", "e1_step=D0,e1_dir=D1") == 0


@pytest.mark.slow  # sigrok's own format; test_print decodes a trace with sigrok in make test
def test_a_sigrok_capture_reads_back_and_passes(snippet, tmp_path):
    need_sigrok()
    gcode, vcd_path, _, _ = snippet
    sr = tmp_path / "capture.sr"
    subprocess.run(["sigrok-cli", "-I", "vcd", "-i", str(vcd_path), "-o", str(sr)], check=True,
                   capture_output=True, timeout=600)
    result = tracecheck.check(sr, gcode)
    assert _failed(result) == []
    assert result["timescale_us"] == 1.0
    assert _run_cli(sr, "--gcode", gcode) == 0


def test_a_nanosecond_capture_reads_like_the_microsecond_one(snippet, tmp_path):
    """A logic analyser writes its VCD in ns: the same edges, every time stamp x1000
    and `$timescale 1ns`, give the same checks, measurements and messages."""
    gcode, vcd_path, _, _ = snippet
    text = vcd_path.read_bytes()
    assert b"$timescale 1 us $end" in text
    ns = re.sub(rb"(?m)^#(\d+)$", rb"#\g<1>000", text.replace(b"$timescale 1 us $end",
                                                               b"$timescale 1ns $end"))
    assert ns.count(b"000\n") > text.count(b"000\n") + 10000
    (tmp_path / "ns.vcd").write_bytes(ns)
    in_us = tracecheck.check(vcd_path, gcode)
    in_ns = tracecheck.check(tmp_path / "ns.vcd", gcode)
    assert in_us["timescale_us"] == 1.0 and in_ns["timescale_us"] == 0.001
    assert in_ns["checks"] == in_us["checks"]
    assert _failed(in_ns) == [] and _by_name(in_ns)["pulse_high_us"]["measured"] == 20.0


def test_a_capture_without_a_signal_the_gcode_moves_fails_and_names_it(snippet, tmp_path,
                                                                        capsys):
    """Probing only X of a print that also moves Y, Z and four drives: nothing it did
    probe is wrong, but the trace cannot show the rest, so it must not pass."""
    gcode, vcd_path, _, report = snippet
    assert report["steps"]["e0"] > 0 and report["steps"]["x"] > 0
    only_x = tmp_path / "only_x.vcd"
    only_x.write_bytes(_keep_signals(vcd_path.read_bytes(), {"x_step", "x_dir"}))
    result = tracecheck.check(only_x, gcode)
    moved = ["y", "z", "e0", "e1", "e2", "e4"]
    assert result["missing_signals"] == [n + k for n in moved for k in ("_step", "_dir")]
    assert _failed(result) == sorted("steps_" + n for n in moved)
    checks = _by_name(result)
    assert checks["steps_x"]["ok"] is True and checks["rate_x"]["ok"] is True
    assert checks["steps_e0"]["detail"] == ("the G-code moves e0, but e0_step and e0_dir "
                                            "are not in the trace")
    assert checks["steps_e3"]["ok"] is None  # never moved: may be left out
    assert _run_cli(only_x, "--gcode", gcode) == 1
    out = capsys.readouterr().out
    assert "FAIL steps_e0" in out and "OK:" not in out
    assert "FAILED: the G-code moves what the trace does not show: y_step, y_dir" in out


def test_only_signals_the_gcode_never_moves_may_be_left_out(snippet, tmp_path):
    """Leaving out e3 and e5, which the snippet never moves, passes; leaving out one
    DIR of a drive it moves fails, naming that DIR (its steps cannot be counted)."""
    gcode, vcd_path, _, report = snippet
    assert report["steps"]["e3"] == report["steps"]["e5"] == 0 < report["steps"]["e1"]
    text = vcd_path.read_bytes()
    wired = [n for n in paths.load_board("sim")["PINS"] if n.endswith(("_step", "_dir"))]
    fewer = tmp_path / "fewer.vcd"
    fewer.write_bytes(_keep_signals(text, {n for n in wired if n[:2] not in ("e3", "e5")}))
    assert _failed(tracecheck.check(fewer, gcode)) == []
    assert _run_cli(fewer, "--gcode", gcode) == 0
    no_dir = tmp_path / "no_dir.vcd"
    no_dir.write_bytes(_keep_signals(text, set(wired) - {"e1_dir"}))
    result = tracecheck.check(no_dir, gcode)
    assert result["missing_signals"] == ["e1_dir"]
    assert _failed(result) == ["steps_e1"]
    assert _by_name(result)["moves"]["ok"] is None  # cannot be followed without e1
    assert _run_cli(no_dir, "--gcode", gcode) == 1


# --- every real slicer file, and every mixing feature -----------------------------------

# make test checks the shortest file; make test-all every one.
@pytest.mark.parametrize("name", [n if n.startswith("short_") else pytest.param(
    n, marks=pytest.mark.slow) for n in SLICER_FILES])
def test_the_trace_of_every_real_slicer_file_passes(traces, name):
    gcode, vcd_path, report = traces(name)
    result = tracecheck.check(vcd_path, gcode)
    assert _failed(result) == [], [c for c in result["checks"] if c["ok"] is False]
    assert result["unmodelled"] == {} and result["refused_lines"] == 0
    for c in result["checks"]:
        if c["name"].startswith("steps_") and c["measured"] is not None:
            assert c["measured"] == report["steps"][c["name"][6:]], c


def mixing_gcode():
    """A short print that uses everything the trace check models: M92 first (as a
    six-drive machine's start G-code does), a palette and mixtures of it, M163/M164, M165, M567,
    G10/G11, retractions and a wipe, a gradient along Z and one along the filament, a
    purge longer than one block, and lines the firmware refuses."""
    lines = [
        "M92 X80 Y80 Z400 E100",  # every drive at 100 steps/mm
        "M302 P1",  # no heating in this test: allow cold extrusion
        "G28", "G21", "G90", "M83", "G1 Z0.3 F600",
        "M168 1:0:0,0:1:0,0:0:1,1:1:0", "M567 P4 U1:0:1:2",  # a palette's mixtures
        "M163 S0 P0.2", "M163 S1 P0.5", "M163 S4 P0.3", "M164 S5",
        "M567 P6 E1:2:3:0:0:1",
        "T0", "G1 X20 Y20 F3000", "G1 X40 E2.5 F1200", "G1 Y40 E2.5",
        # Refused, so not run: a bad checksum, beyond the soft limits, a malformed
        # number, an unknown tool and drive, over max_extrude_mm, an all-zero mix.
        "N1 G1 X30 E1*99", "G1 X300 E1", "G1 X1..2 E1", "T20", "M163 S7 P1", "G1 E250",
        "M567 P1 E0:0",
        "G10", "G1 X60 Y60 F6000", "G11",
        "T4", "G1 X80 E3 F1200", "G1 E-0.8 F2400", "G1 X90 Y50 F6000", "G1 E0.8 F2400",
        "G1 Y70 E2.2 F1200",
        "T5", "G1 X100 E2.4", "G1 X110 Y75 E-0.6 F3000",  # a wipe
        "G1 E0.6 F2400", "G1 Y90 E1.9 F1200",
        "M165 A0.25 B0.75", "G1 X120 E2.1",
        "T6", "G1 Y100 E2.3", "G10", "G11",
        "M92 E415",  # the drives' gearing changes mid-print
        "G1 X100 E2.0", "G1 E-1.5 F2400", "G1 E1.5",
        "M166 A0.3 Z1.5 I0 J1 S1",  # a Z gradient from T0 to T1
    ]
    z = 0.3
    for _ in range(4):
        z += 0.3
        lines += ["G1 Z%.1f F600" % z, "G1 X60 Y60 E1.7 F1500", "G1 X100 E1.6",
                  "G1 Y100 E1.6", "G10", "G1 X60 F6000", "G11"]
    lines += ["M169 E0:2,4:0,8:1",  # along the filament: T2 -> T0 -> T1
              "G1 X100 Y60 E3 F1500", "G1 X60 E3", "G1 Y100 E3", "G1 X100 E3",
              "M169", "T1", "G1 E60 F1200",  # over 20,000 steps: planned in pieces
              "G1 E-2 F2400", "G1 X20 Y20 F6000", "M400"]
    return "\n".join(lines) + "\n"


MIXING_RUNS = {
    "policy0_transitions": {"retract_policy": 0, "transition_l1_mm": 1.0,
                            "transition_l2_mm": 1.5},
    "policy1": {"retract_policy": 1},
    "policy2_transitions": {"retract_policy": 2, "transition_l1_mm": 0.5,
                            "transition_l2_mm": 1.0},
}


@pytest.mark.parametrize("run", sorted(MIXING_RUNS))
def test_a_print_with_every_mixing_feature_passes(tmp_path, run, capsys):
    settings = MIXING_RUNS[run]
    gcode = tmp_path / "mixing.gcode"
    gcode.write_text(mixing_gcode())
    vcd_path = tmp_path / "mixing.vcd"
    report = sim.run(gcode, trace_path=vcd_path, settings=settings)
    model = tracemodel.expected(gcode, tracecheck.board_settings("sim", settings))
    # The firmware refused exactly the lines the model says it does not run.
    refused = [int(e.split(":")[0].split()[1]) for e in report["errors"]]
    assert refused == [n for n, _ in model["refused"]] and len(refused) == 7
    result = tracecheck.check(vcd_path, gcode, settings=settings)
    assert _failed(result) == [], [c for c in result["checks"] if c["ok"] is False]
    assert result["unmodelled"] == {}
    checks = _by_name(result)
    assert checks["moves"]["measured"] > 40
    assert sum(1 for d in range(6) if checks["steps_e%d" % d]["measured"]) >= 4
    # The same from the command line, the settings as `mixstep serve --set` takes them.
    sets = [a for k, v in settings.items() for a in ("--set", "%s=%s" % (k, v))]
    assert _run_cli(vcd_path, "--gcode", gcode, *sets) == 0
    assert "OK:" in capsys.readouterr().out
    # Without them (the board's retract_policy 0, no transitions), where the settings
    # change the steps, the same trace is not what the G-code asks.
    assert tracecheck.check(vcd_path, gcode)["ok"] is False


# Tool pairs with lengths of their own, from:to:l1_mm:l2_mm as M926 sets them, around
# the default L1 1.0, L2 1.5 (L0 1.75 mm): T0 -> T4 shorter (L0 0.75), T4 -> T5 at once
# (L0 0), T5 -> T6 longer (L0 2.5, so moves wait for a pair's length). The mixing print
# changes tool in that order; its last change, T6 -> T1, reaches back only over
# gradient moves, which keep their own mixes, so no pair length would show there.
_PAIRS = ((0, 4, 0.5, 0.5), (4, 5, 0.0, 0.0), (5, 6, 2.0, 1.0))
_PAIR_SETTINGS = {"retract_policy": 2, "transition_l1_mm": 1.0, "transition_l2_mm": 1.5,
                  "transition_pairs": _PAIRS}


def test_a_print_with_per_pair_transitions_passes(sim_printer, tmp_path, capsys):
    """transition_pairs given to the firmware the way docs/G-Codes.md says (M926, M500, a
    restart) and to the check as a setting: the trace passes, and the same trace
    checked without any one of the pairs (that change at the default lengths) fails,
    so each pair counts. Not by `--set`: its VALUE is numbers or text split at commas
    (boards/sim/sim_main.py _value, mixstep.boards.setting_value), which has no way to
    spell a tuple of from:to:l1_mm:l2_mm tuples, and the firmware will not start on
    any spelling of it."""
    cfg = tmp_path / "mixstep.cfg"
    printer = sim_printer(config_path=cfg)
    for key in ("retract_policy", "transition_l1_mm", "transition_l2_mm"):
        assert printer.send("M926 I%s V%s" % (key, _PAIR_SETTINGS[key]))[-1] == "ok"
    for k, pair in enumerate(_PAIRS):
        line = "M926 Itransition_pairs_%d V%d:%d:%s:%s" % ((k,) + pair)
        assert printer.send(line)[-1] == "ok", line
    assert printer.send("M500")[-1] == "ok"
    printer.finish()
    gcode = tmp_path / "mixing.gcode"
    gcode.write_text(mixing_gcode())
    vcd_path = tmp_path / "mixing.vcd"
    report = sim.run(gcode, trace_path=vcd_path, config_path=cfg)
    assert len(report["errors"]) == 7, report["errors"]  # the lines the print has refused
    result = tracecheck.check(vcd_path, gcode, settings=_PAIR_SETTINGS)
    assert _failed(result) == [], [c for c in result["checks"] if c["ok"] is False]
    assert result["unmodelled"] == {}
    for k, pair in enumerate(_PAIRS):
        fewer = dict(_PAIR_SETTINGS, transition_pairs=_PAIRS[:k] + _PAIRS[k + 1:])
        assert "moves" in _failed(tracecheck.check(vcd_path, gcode, settings=fewer)), pair
    # The saved file itself, as the printer started with it: the same verdict.
    by_file = tracecheck.check(vcd_path, gcode, config=cfg)
    assert _failed(by_file) == [] and by_file["config"] == str(cfg)
    assert _run_cli(vcd_path, "--gcode", gcode, "--config", cfg) == 0
    # --set goes over it, as over the firmware's: a pair changed there counts.
    assert "moves" in _failed(tracecheck.check(
        vcd_path, gcode, config=cfg, settings={"transition_pairs": _PAIRS[1:]}))
    # A file the firmware refuses (edited by hand) is refused here too, with a message.
    edited = tmp_path / "edited.cfg"
    edited.write_bytes(cfg.read_bytes().replace(b"retract_policy = 2", b"retract_policy = 1"))
    assert _run_cli(vcd_path, "--gcode", gcode, "--config", edited) == 2
    assert "its checksum fails" in capsys.readouterr().err


def _numbered(n, text):
    line = "N%d %s" % (n, text)
    cs = 0
    for c in line.encode():
        cs ^= c
    return "%s*%d" % (line, cs)


def test_the_check_reads_gcode_as_the_firmware_does(tmp_path):
    """Line numbers and checksums, comments, long lines and odd words: the lines the
    firmware refuses (it answers Error:) are the lines the model does not run, and
    the trace of what did run passes."""
    lines = [
        "M83", "M302 P1", "G1 X5 E0.5 F1200 ; a comment with * and N99 in it",
        _numbered(1, "G1 X10 E0.5"), _numbered(2, "G1 X15 E0.5"),
        _numbered(2, "G1 X15 E0.5"),  # a repeat: answered ok, not run again
        _numbered(4, "G1 X99 E5"),  # a number skipped: refused
        "N3 G1 X20 E0.5*7",  # a wrong checksum: refused
        _numbered(3, "G1 X20 E0.5"), "N4 G1 X25 E0.5",  # a number without a checksum
        _numbered(4, "M110 N10"), _numbered(11, "G1 X25 E0.5"),
        "G1 X30 (a comment) E0.5", "G1 X35 E0.5 (unclosed", "g1 x35\te0.5",
        "G1 X40 E0.5" + " " * 90,  # over the 96-byte line buffer: refused
        "G1 X40 E0.5 ;" + "x" * 200,  # a long comment is not stored: fine
        "G1 X45 E1.2.3", "G1 X45 E-", "G1 X45 X46", "X45 E1", "G1.5 X45", "G1 E",
        "G1 X1234567890", "G1 X45.1234567891 E0.5",  # 9 significant digits are read
        "G1 F0 X50 E1", "M163 S1.0 P1", "M400",
    ]
    gcode = tmp_path / "protocol.gcode"
    gcode.write_text("\n".join(lines) + "\n")
    vcd_path = tmp_path / "protocol.vcd"
    report = sim.run(gcode, trace_path=vcd_path)
    model = tracemodel.expected(gcode, tracecheck.board_settings("sim"))
    refused = sorted(set(int(e.split(":")[0].split()[1]) for e in report["errors"]))
    assert refused == [n for n, _ in model["refused"]]
    assert len(refused) == 14
    result = tracecheck.check(vcd_path, gcode)
    assert _failed(result) == [] and result["refused_lines"] == 14
    assert _by_name(result)["steps_x"]["measured"] == report["steps"]["x"] > 0


def random_print(seed):
    """A random short print and the settings it runs with: tool changes and mixes,
    gradients along Z and E, G10/G11, retractions and wipes, tiny moves, absolute or
    relative E, under a random retract_policy with or without transitions. (Mixes
    whose 0.01 % steps tie exactly, and policy 1 with transitions, are left out: the
    firmware departs from the rule there, see the xfail tests.)"""
    import random
    rng = random.Random(seed)
    relative = rng.random() < 0.5
    lines = ["M302 P1", "G28", "G90", "M83" if relative else "M82", "G92 E0", "G1 Z0.3 F600"]
    e = 0.0
    x = y = 50.0
    for _ in range(rng.randint(30, 70)):
        r = rng.random()
        if r < 0.08:
            lines.append("T%d" % rng.randrange(8))
        elif r < 0.12:
            w = [rng.choice([0, 0, 1, 2, 5, 0.25, 0.5]) for _ in range(6)]
            w[0] = w[0] or 1
            lines.append("M567 P%d E%s" % (rng.randrange(8), ":".join("%g" % v for v in w)))
        elif r < 0.15:
            lines.append("M166 A0.3 Z%.1f I%d J%d S1" % (rng.uniform(0.5, 3), rng.randrange(6),
                                                         rng.randrange(6)))
        elif r < 0.17:
            lines.append("M169 E0:%d,%g:%d" % (rng.randrange(6), rng.uniform(1, 10),
                                               rng.randrange(6)))
        elif r < 0.19:
            lines.append("M169")
        elif r < 0.24:
            lines.append(rng.choice(["G10", "G11"]))
        elif r < 0.30:
            d = -rng.choice([0.5, 0.8, 1.0, 2.0, 0.013])
            e += d
            lines.append("G1 E%.5f F2400" % (d if relative else e))
        elif r < 0.33:
            lines.append("G1 Z%.2f F600" % rng.uniform(0.3, 3))
        else:
            x = min(240, max(5, x + rng.uniform(-30, 30)))
            y = min(240, max(5, y + rng.uniform(-30, 30)))
            d = rng.choice([0, rng.uniform(0.001, 3), rng.uniform(0.001, 0.05),
                            -rng.uniform(0, 0.5)])
            e += d
            lines.append("G1 X%.3f Y%.3f E%.5f F%d" % (x, y, d if relative else e,
                                                         rng.choice([1200, 3000, 6000])))
    policy = rng.choice([0, 1, 2])
    settings = {"retract_policy": policy}
    if policy != 1 and rng.random() < 0.6:
        settings.update(transition_l1_mm=rng.choice([0.5, 1.0]),
                        transition_l2_mm=rng.choice([0.0, 1.5]))
    return "\n".join(lines + ["M400"]) + "\n", settings


@pytest.mark.parametrize("seed", [1, 5, 6, 7])
def test_random_prints_pass(tmp_path, seed):
    text, settings = random_print(seed)
    gcode = tmp_path / "random.gcode"
    gcode.write_text(text)
    vcd_path = tmp_path / "random.vcd"
    report = sim.run(gcode, trace_path=vcd_path, settings=settings)
    model = tracemodel.expected(gcode, tracecheck.board_settings("sim", settings))
    refused = sorted(set(int(e.split(":")[0].split()[1]) for e in report["errors"]))
    assert refused == [n for n, _ in model["refused"]]
    result = tracecheck.check(vcd_path, gcode, settings=settings)
    assert _failed(result) == [], [c for c in result["checks"] if c["ok"] is False]


_HALF_STEP = "M83\nM302 P1\nG1 E0.7 F600\nG1 E-0.4\nM400\n"


def test_exactly_half_a_step_rounds_away_from_zero_not_as_doubles_fall(tmp_path):
    """First principles: E0.7 then E-0.4 leave exactly 0.3 mm of filament; at 5
    steps/mm that is 1.5 steps, and the rule (half away from zero) makes it 2. In
    doubles 0.7 - 0.4 is 0.29999999999999993, which rounds to 1: a check in floats
    would expect the wrong count. The model, and the firmware's trace, give 2."""
    assert int((0.7 - 0.4) * 5 + 0.5) == 1  # what doubles would say
    gcode = tmp_path / "half.gcode"
    gcode.write_text(_HALF_STEP)
    settings = {"steps_per_mm": (80.0, 80.0, 400.0, 5.0)}
    model = tracemodel.expected(gcode, tracecheck.board_settings("sim", settings))
    assert model["steps"]["e0"] == 2
    vcd_path = tmp_path / "half.vcd"
    report = sim.run(gcode, trace_path=vcd_path, settings=settings)
    assert report["errors"] == [] and report["steps"]["e0"] == 2
    assert _failed(tracecheck.check(vcd_path, gcode, settings=settings)) == []


def test_the_mixer_schedule_is_the_one_the_readme_specifies():
    """docs/Mixing.md: from a fresh start, weights 20/30/50 give drives 3,2,1,3,2,3,3,1,2,3."""
    picks = []
    before = [0, 0, 0]
    for n in range(1, 11):
        now = tracemodel.schedule_counts((2, 3, 5), n)
        picks.append(next(i + 1 for i in range(3) if now[i] != before[i]))
        before = now
    assert picks == [3, 2, 1, 3, 2, 3, 3, 1, 2, 3]
    assert tracemodel.schedule_counts((2, 3, 5), 25) == [5, 8, 12]  # two periods and 3,2,1,3,2


def test_mixes_are_the_specified_integer_weights():
    assert tracemodel.mix_weights([1, 2, 3], 3) == (1, 2, 3)  # whole numbers stay
    assert tracemodel.mix_weights([0.2, 0.5, 0.3], 3) == (2, 5, 3)
    from fractions import Fraction
    third = Fraction(1, 3)
    assert tracemodel.mix_weights([third] * 3, 3) == (3334, 3333, 3333)  # ties: lower first
    assert tracemodel.mix_weights([1, 0, 1e-9], 3) == (10000, 0, 1)  # asked for: kept
    with pytest.raises(tracemodel.Refused):
        tracemodel.mix_weights([0, 0], 3)


def test_the_check_imports_nothing_from_the_firmware(snippet):
    """The check must not share code with the firmware it checks, not even by the way
    it reads a board. So, in a fresh Python with firmware/ first on sys.path (where an
    import of mixfw would succeed), read two boards' settings and check a real trace,
    then look for any mixfw module loaded along the way."""
    gcode, vcd, _, _ = snippet
    code = ("import sys; sys.path.insert(0, %r)\n"
            "from mixstep import tracecheck\n"
            "for board in ('sim', 'pico'):\n"
            "    assert tracecheck.board_settings(board, {'retract_policy': '1'})['drives']\n"
            "report = tracecheck.check(%r, %r)\n"
            "assert report['ok'], [c for c in report['checks'] if c['ok'] is False]\n"
            "print([m for m in sys.modules if m == 'mixfw' or m.startswith('mixfw.')])"
            % (str(paths.FIRMWARE), str(vcd), str(gcode)))
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "[]"


_EQUAL_BEFORE_CHANGE = ("M83\nM302 P1\nT0\nG1 X20 Y5 E4 F1200\nG10\nG1 X40 F6000\n"
                        "G11\nT1\nG1 X60 E4 F1200\nM400\n")
_EQUAL_SETTINGS = {"retract_policy": 1, "transition_l1_mm": 1.0, "transition_l2_mm": 1.0}


def test_policy_1_retracts_every_drive_equally_before_a_transitioned_change(tmp_path):
    """retract_policy 1 pulls every drive equally (docs/G-Codes.md); a transition moves where
    the *printing* mix changes, not how a retraction pulls. So G10 just before T1, with
    transitions on, still takes 2 mm / 6 from each drive."""
    gcode = tmp_path / "equal.gcode"
    gcode.write_text(_EQUAL_BEFORE_CHANGE)
    model = tracemodel.expected(gcode, tracecheck.board_settings("sim", _EQUAL_SETTINGS))
    moves = model["moves"]
    at = next(i for i, m in enumerate(moves) if m[0] == 5)  # the G10
    before = moves[at - 1][2]
    pulled = [b - a for a, b in zip(moves[at][2], before)]
    assert min(pulled) >= 138 and max(pulled) <= 139  # 830 steps of 2 mm, over 6 drives


@pytest.mark.xfail(strict=True, reason="firmware: with transitions on, a retract_policy 1 "
                   "retraction waiting before a tool change takes the new tool's mix "
                   "instead of every drive equally (mixfw/transition.py set_mix "
                   "overwrites the move's own mix)")
def test_the_firmware_retracts_equally_before_a_transitioned_change(tmp_path):
    gcode = tmp_path / "equal.gcode"
    gcode.write_text(_EQUAL_BEFORE_CHANGE)
    vcd_path = tmp_path / "equal.vcd"
    report = sim.run(gcode, trace_path=vcd_path, settings=_EQUAL_SETTINGS)
    assert report["errors"] == []
    assert _failed(tracecheck.check(vcd_path, gcode, settings=_EQUAL_SETTINGS)) == []


def _small_moves_with_m204():
    lines = ["M83", "M302 P1", "M567 P0 E1:1:1", "T0", "G1 X1 F1200"]
    for i in range(40):
        lines += ["G1 X%d E0.0123" % (2 + i), "M204 S1000"]
    return "\n".join(lines + ["M400"]) + "\n"


def test_settings_applied_mid_print_lose_no_filament(tmp_path):
    """First principles: 40 moves of E0.0123 shared 1:1:1 feed each drive exactly
    40 x 0.0041 = 0.164 mm, 68.06 steps at 415 steps/mm: 68. An M204 (or M201, M203,
    M205, M92 X) between the moves changes nothing about the drives."""
    gcode = tmp_path / "m204.gcode"
    gcode.write_text(_small_moves_with_m204())
    model = tracemodel.expected(gcode, tracecheck.board_settings("sim"))
    assert [model["steps"]["e%d" % d] for d in range(3)] == [68, 68, 68]


@pytest.mark.xfail(strict=True, reason="firmware: every settings change (M204, M201, M203, "
                   "M205, M92, M930) sets each drive's exact filament to its whole steps "
                   "(Motion.apply -> Planner.set_drive_steps), so the part of a step carried "
                   "is lost each time: 80 steps per drive here instead of 68")
def test_the_firmware_loses_no_filament_when_settings_change_mid_print(tmp_path):
    gcode = tmp_path / "m204.gcode"
    gcode.write_text(_small_moves_with_m204())
    vcd_path = tmp_path / "m204.vcd"
    report = sim.run(gcode, trace_path=vcd_path)
    assert report["errors"] == []
    assert _failed(tracecheck.check(vcd_path, gcode)) == []


_TIED_MIX = "M83\nM302 P1\nM567 P0 E1:0.3:0.3:0:3.7:0.3\nT0\nG1 E100 F3600\nM400\n"


def test_a_tie_in_the_mix_goes_to_the_lower_drive():
    """1:0.3:0.3:0:3.7:0.3 in 0.01 % steps: exactly 1785 5/7, 535 5/7 (three times),
    0 and 6607 1/7, 9997 in whole steps. The 3 left go by largest remainder; e0, e1,
    e2 and e5 tie exactly at 5/7, and the rule gives ties to the lower drive: e0, e1,
    e2. (MicroPython's sort is not stable, and in doubles the four remainders differ in
    their last bits: the firmware gives it to e5.)"""
    from fractions import Fraction
    exact = [Fraction(1), Fraction(3, 10), Fraction(3, 10), 0, Fraction(37, 10), Fraction(3, 10)]
    assert tracemodel.mix_weights(exact, 6) == (1786, 536, 536, 0, 6607, 535)
    # The model reads the G-code's decimals exactly, so the M567 line gives that mix.
    line = tracemodel.parse_words("M567 P0 E1:0.3:0.3:0:3.7:0.3")
    weights = tracemodel._decimal_list(line.text.split()[1][1:])
    assert tracemodel.mix_weights(weights, 6) == (1786, 536, 536, 0, 6607, 535)


@pytest.mark.xfail(strict=True, reason="firmware: mixer.normalize gives ties to the lower "
                   "drive by a stable sort, but MicroPython's sort is not stable (and the "
                   "remainders are floats): e5 gets the step the rule gives e0, and 100 mm "
                   "then differ by 4 steps on e0 and e5")
def test_the_firmware_gives_a_tie_in_the_mix_to_the_lower_drive(tmp_path):
    gcode = tmp_path / "tie.gcode"
    gcode.write_text(_TIED_MIX)
    vcd_path = tmp_path / "tie.vcd"
    report = sim.run(gcode, trace_path=vcd_path)
    assert report["errors"] == []
    assert _failed(tracecheck.check(vcd_path, gcode)) == []


# A move with one X step and 3 mm of filament: T1's transition (L0 = 1.25 mm) splits
# it, and the split puts the X step in the first part, so the last 1.25 mm is no
# longer printing extrusion (it moves no axis).
_SPLIT_WITHOUT_XY = ("M83\nM302 P1\nG1 X10 F3000\nT0\nG1 X10.0125 E3 F1200\nT1\n"
                     "G1 X20 E1\nG1 X30 E1\nT2\nG1 X40 E3\nM400\n")
_L0_1_25 = {"transition_l1_mm": 0.5, "transition_l2_mm": 1.5}


def test_moves_wait_for_l0_of_printing_after_a_split():
    """First principles (docs/G-Codes.md): a move waits until L0 of printing extrusion follows
    it, and a change applies over the L0 before it. T2 comes 2 mm of printing after
    T1's split, so it reaches back over all of X30's 1 mm and the last 0.25 mm of X20:
    e2 prints 1.25 mm before T2's own move, 519 steps."""
    import tempfile
    from pathlib import Path
    with tempfile.TemporaryDirectory() as tmp:
        gcode = Path(tmp) / "split.gcode"
        gcode.write_text(_SPLIT_WITHOUT_XY)
        model = tracemodel.expected(gcode, tracecheck.board_settings("sim", _L0_1_25))
    before_t2 = [m for m in model["moves"] if m[0] < 10][-1][2]
    assert before_t2[2] == 519  # 1.25 mm at 415 steps/mm, rounded
    # T0 1.75 mm; T1 1.25 + 0.75 mm; T2 0.25 + 1 + 3 mm.
    assert [model["steps"]["e%d" % d] for d in range(3)] == [726, 830, 1764]


@pytest.mark.xfail(strict=True, reason="firmware: Transitions keeps a running total of the "
                   "printing extrusion waiting, and a split whose last part moves no axis "
                   "does not take that part out of it: moves are released before L0 of "
                   "printing follows them, and T2's transition cannot reach back at all")
def test_the_firmware_waits_for_l0_of_printing_after_a_split(tmp_path):
    gcode = tmp_path / "split.gcode"
    gcode.write_text(_SPLIT_WITHOUT_XY)
    vcd_path = tmp_path / "split.vcd"
    report = sim.run(gcode, trace_path=vcd_path, settings=_L0_1_25)
    assert report["errors"] == []
    assert _failed(tracecheck.check(vcd_path, gcode, settings=_L0_1_25)) == []


# --- corrupted traces -----------------------------------------------------------------

def test_steps_played_faster_than_the_axes_can_go_fail_the_rate_check(snippet, tmp_path):
    """The snippet's trace with its clock ten times faster ($timescale 100 ns): every
    step is still there in order and pulses and DIR setup are still long enough (20 us
    -> 2 us), but every axis now steps far beyond its maximum feed rate."""
    gcode, vcd_path, _, _ = snippet
    fast = tmp_path / "fast.vcd"
    fast.write_bytes(vcd_path.read_bytes().replace(b"$timescale 1 us $end",
                                                   b"$timescale 100 ns $end"))
    result = tracecheck.check(fast, gcode)
    moved = ["x", "y", "z", "e0", "e1", "e2", "e4"]
    assert _failed(result) == sorted("rate_" + n for n in moved)
    for n in moved:
        check = _by_name(result)["rate_" + n]
        assert check["measured"] > float(check["expected"].split()[1])
    assert _run_cli(fast, "--gcode", gcode) == 1

def test_a_dropped_step_pulse_fails(printed, tmp_path):
    text = printed.read_bytes()
    e1 = _ident(text, "e1_step")
    rise = text.index(b"\n1" + e1 + b"\n", len(text) // 2)
    fall = text.index(b"\n0" + e1 + b"\n", rise)
    bad = tmp_path / "dropped.vcd"
    bad.write_bytes(text[:rise] + text[rise + len(e1) + 2:fall] + text[fall + len(e1) + 2:])
    report = tracecheck.check(bad, PRINTED)
    assert "steps_e1" in _failed(report) and "moves" in _failed(report)
    assert _run_cli(bad, "--gcode", PRINTED) == 1


def test_one_dir_flipped_fails(snippet, tmp_path, capsys):
    """One e1 DIR change written with the level e1 already had: every edge time is
    kept, but the e1 steps up to its next DIR change now go the wrong way."""
    gcode, vcd_path, _, _ = snippet
    text = vcd_path.read_bytes()
    d1, e1 = _ident(text, "e1_dir"), _ident(text, "e1_step")
    changes = list(re.finditer(rb"\n([01])" + re.escape(d1) + rb"\n", text))
    assert len(changes) > 4
    for a, b in zip(changes[len(changes) // 2:], changes[len(changes) // 2 + 1:]):
        if text.find(b"\n1" + e1 + b"\n", a.end() - 1, b.start() + 1) >= 0:
            break  # e1 steps between this change and the next
    flipped = b"0" if a.group(1) == b"1" else b"1"
    bad = tmp_path / "flipped.vcd"
    bad.write_bytes(text[:a.start() + 1] + flipped + text[a.start() + 2:])
    report = tracecheck.check(bad, gcode)
    assert "steps_e1" in _failed(report) and "moves" in _failed(report)
    assert _run_cli(bad, "--gcode", gcode) == 1
    assert "FAIL steps_e1" in capsys.readouterr().out


def test_a_step_moved_to_another_drive_fails(snippet, tmp_path):
    """One e1 pulse written on e0's STEP instead, at the same times: the number of
    drive steps is unchanged, but e1 is a step short and e0 has one too many."""
    gcode, vcd_path, _, _ = snippet
    text = vcd_path.read_bytes()
    e0, e1 = _ident(text, "e0_step"), _ident(text, "e1_step")
    rise = text.index(b"\n1" + e1 + b"\n", len(text) // 2)
    fall = text.index(b"\n0" + e1 + b"\n", rise + 1)
    n = len(e1) + 3
    bad = tmp_path / "moved.vcd"
    bad.write_bytes(text[:rise] + b"\n1" + e0 + b"\n" + text[rise + n:fall]
                    + b"\n0" + e0 + b"\n" + text[fall + n:])
    report = tracecheck.check(bad, gcode)
    assert {"steps_e0", "steps_e1", "moves"} <= set(_failed(report))
    assert _run_cli(bad, "--gcode", gcode) == 1


def test_a_too_short_pulse_fails(printed, tmp_path):
    """One e1 pulse ends 1 us after it starts instead of a tick later."""
    text = printed.read_bytes()
    e1 = _ident(text, "e1_step")
    rise = text.index(b"\n1" + e1 + b"\n", len(text) // 2)
    stamp = text.rindex(b"\n#", 0, rise)
    t_rise = int(text[stamp + 2:text.index(b"\n", stamp + 1)])
    fall = text.index(b"\n0" + e1 + b"\n", rise)
    next_stamp = text.index(b"\n#", rise)
    early = b"\n#%d\n0" % (t_rise + 1) + e1
    bad = tmp_path / "short.vcd"
    bad.write_bytes(text[:next_stamp] + early + text[next_stamp:fall] + text[fall + len(e1) + 2:])
    report = tracecheck.check(bad, PRINTED)
    assert _failed(report) == ["pulse_high_us"]
    assert _run_cli(bad, "--gcode", PRINTED) == 1


def test_a_dir_change_too_close_to_step_fails(printed, tmp_path):
    """An e1 DIR change moved from its place to the very time of the next e1 step:
    every count still agrees, only the setup time is wrong."""
    text = printed.read_bytes()
    d1, e1 = _ident(text, "e1_dir"), _ident(text, "e1_step")
    changes = re.compile(rb"\n[01]" + re.escape(d1) + rb"\n")
    change = changes.search(text, len(text) // 2)
    while True:  # one whose next e1 step comes before any other e1 DIR change
        rise = text.index(b"\n1" + e1 + b"\n", change.end())
        following = changes.search(text, change.end())
        if following.start() > rise:
            break
        change = following
    line = text[change.start() + 1:change.end()]
    bad = tmp_path / "dir.vcd"
    bad.write_bytes(text[:change.start()] + text[change.end() - 1:rise + 1] + line
                    + text[rise + 1:])
    report = tracecheck.check(bad, PRINTED)
    assert _failed(report) == ["dir_setup_us"]
    assert _run_cli(bad, "--gcode", PRINTED) == 1


def test_the_trace_of_another_file_fails(printed):
    report = tracecheck.check(printed, SAMPLES / "slic3r_part_3tool_abs.gcode")
    assert "moves" in _failed(report) and any(n.startswith("steps_") for n in _failed(report))
    assert _run_cli(printed, "--gcode", SAMPLES / "slic3r_part_3tool_abs.gcode") == 1


def test_a_mix_that_bunches_its_steps_fails(tmp_path):
    """A 1:1 mix whose drive steps come all e0 then all e1: the totals and the move are
    right, but the windows are not."""
    gcode = tmp_path / "mix.gcode"
    gcode.write_text("M83\nM567 P0 E1:1\nT0\nG1 E1 F300\n")
    spm_e = paths.load_board("sim")["SETTINGS"]["steps_per_mm"][3]
    half = int(spm_e / 2 + 0.5)
    edges = [("e0", t) for t in range(half)] + [("e1", half + t) for t in range(half)]
    vcd_path = tmp_path / "bunched.vcd"
    _write_steps(vcd_path, edges)
    report = tracecheck.check(vcd_path, gcode)
    assert _failed(report) == ["mix"]
    # The same steps interleaved pass.
    _write_steps(vcd_path, [("e%d" % (i % 2), i) for i in range(2 * half)])
    assert _failed(tracecheck.check(vcd_path, gcode)) == []


def _write_steps(path, steps):
    """STEP pulses of 20 us every 100 us, DIR forward from the start."""
    import vcd
    with open(path, "w") as f, vcd.VCDWriter(f, timescale="1 us") as w:
        var = {n: w.register_var("t", n, "wire", size=1, init=0)
               for n in ("e0_step", "e0_dir", "e1_step", "e1_dir")}
        w.change(var["e0_dir"], 10, 1)
        w.change(var["e1_dir"], 10, 1)
        for drive, k in steps:
            w.change(var[drive + "_step"], 100 + 100 * k, 1)
            w.change(var[drive + "_step"], 120 + 100 * k, 0)


def test_unreadable_input_exits_2(tmp_path, capsys):
    junk = tmp_path / "junk.vcd"
    junk.write_text("not a trace\n")
    assert _run_cli(junk, "--gcode", PRINT) == 2
    assert _run_cli(tmp_path / "missing.vcd", "--gcode", PRINT) == 2
    assert "junk.vcd" in capsys.readouterr().err


# --- trace pull -----------------------------------------------------------------------

def _dump_from_edges(edges_path, tick_us):
    """The M7301 console reply a board would send for these edges."""
    times, gpios, levels = trace.read_edges(edges_path)
    assert (times % tick_us == 0).all()
    records = []
    for t in np.unique(times).tolist():
        at = times == t
        g, v = gpios[at], levels[at]
        records.append("trace:%d,%d,%d" % (t // tick_us, int(np.bitwise_or.reduce(1 << g[v == 1], initial=0)),
                                           int(np.bitwise_or.reduce(1 << g[v == 0], initial=0))))
    return (["echo:capture stopped", "trace:begin tick_us=%d records=%d overrun=0"
             % (tick_us, len(records))] + records + ["trace:end", "ok"])


def _rises(vcd_path, name):
    reader = tracecheck.VcdReader(vcd_path, [name])
    times, levels = [], []
    for t, _, v in reader.chunks():
        times.append(t)
        levels.append(v)
    reader.close()
    t, v = np.concatenate(times), np.concatenate(levels)
    return t[1:][(v[1:] == 1) & (v[:-1] == 0)]


@pytest.mark.slow
def test_pull_turns_a_dump_into_a_vcd_with_the_same_steps(snippet, tmp_path, board):
    gcode, vcd_path, edges, _ = snippet
    log = tmp_path / "console.log"
    log.write_text("\n".join(_dump_from_edges(edges, board["SETTINGS"]["tick_us"])) + "\n")
    pulled = tmp_path / "pulled.vcd"
    assert cli.main(["trace", "pull", "--log", str(log), "-o", str(pulled)]) == 0
    for name in ("x_step", "e0_step", "e1_step", "e4_step"):
        want = _rises(vcd_path, name)
        assert len(want) > 0
        assert np.array_equal(_rises(pulled, name), want), name
    assert _failed(tracecheck.check(pulled, gcode)) == []


def test_pull_maps_gpio_32_and_up_four_bits_down(monkeypatch):
    monkeypatch.setattr(trace, "signal_names", lambda board: {27: "x_step", 33: "y_step",
                                                              32: "y_dir"})
    assert tracepull.mask_bits("esp32") == {27: "x_step", 29: "y_step", 28: "y_dir"}


def test_pull_refuses_broken_dumps_and_reports_overrun(tmp_path):
    log = tmp_path / "log"
    out = tmp_path / "o.vcd"
    log.write_text("trace:begin tick_us=20 records=2 overrun=0\ntrace:1,64,0\ntrace:end\nok\n")
    assert cli.main(["trace", "pull", "--log", str(log), "-o", str(out)]) == 2
    log.write_text("ok\n")
    assert cli.main(["trace", "pull", "--log", str(log), "-o", str(out)]) == 2
    log.write_text("trace:begin tick_us=20 records=1 overrun=5\ntrace:1,64,0\ntrace:end\nok\n")
    assert cli.main(["trace", "pull", "--log", str(log), "-o", str(out)]) == 1
    assert out.exists()



def _ask(console, line):
    """Send one line on a TCP console; return its reply up to and including its ok
    (every line gets exactly one)."""
    console.write(line.encode("ascii") + b"\n")
    console.flush()
    reply = []
    while True:
        text = console.readline().decode("ascii", "replace").strip()
        assert text, "the printer closed the connection after %r" % line
        reply.append(text)
        if text == "ok" or text.startswith("ok "):
            return reply


def test_pull_over_tcp_from_the_served_printer_passes_trace_check(tmp_path, capsys):
    """The console path end to end: a host prints the start of a real file on `mixstep
    serve --tcp` with the capture on (M7300 S1), line by line, each after the last
    one's ok, and waits for the moves (M400); `mixstep trace pull --tcp` then fetches
    the ring over a second connection, and the VCD it writes passes `mixstep trace
    check` against those lines, step for step."""
    from net import free_port, wait_for_port
    gcode = tmp_path / "start.gcode"
    gcode.write_text("".join(PRINT.read_text().splitlines(keepends=True)[:45]))
    address = "127.0.0.1:%d" % free_port()
    # The default ring (512 records) holds a few dozen steps; these lines make thousands.
    proc = serve.serve_tcp(address, realtime=0, announce=lambda s: None,
                           settings={"trace_records": 60000})
    try:
        wait_for_port(address)
        host, port = address.rsplit(":", 1)
        with socket.create_connection((host, int(port)), timeout=60) as c, \
                c.makefile("rwb") as console:
            assert _ask(console, "M7300 S1")[-1] == "ok"
            for line in gcode.read_text().splitlines():
                reply = _ask(console, line)
                assert not [r for r in reply if r.startswith("Error")], (line, reply)
            _ask(console, "M400")
            pulled = tmp_path / "pulled.vcd"
            assert cli.main(["trace", "pull", "--tcp", address, "-o", str(pulled)]) == 0
            assert "records at 20 us per tick" in capsys.readouterr().out
    finally:
        proc.terminate()
        proc.wait()
    report = tracecheck.check(pulled, gcode)
    assert _failed(report) == []
    checks = _by_name(report)
    assert checks["steps_x"]["measured"] > 1000 and checks["steps_e0"]["measured"] > 100
    assert checks["moves"]["measured"] > 10
    assert _run_cli(pulled, "--gcode", gcode) == 0


@pytest.mark.parametrize("line", ["M163 S1 P9.999e-05", "M104 S5x", "G1 X1.2.3", "g1x10y5"])
def test_the_model_refuses_a_number_the_firmware_refuses(line):
    """The firmware answers these with Error:malformed number and runs nothing
    (test_gcode): the model must not take a part of the number either."""
    with pytest.raises(tracemodel.Refused, match="malformed number"):
        tracemodel.parse_words(line)


def test_homing_after_m92_goes_back_by_the_steps_the_trace_counted(tmp_path):
    """M92 counts the axes' planned steps anew where they stand; the trace's count is
    unchanged, and homing takes the axis back by that count, not by the new one."""
    gcode = tmp_path / "m92_home.gcode"
    gcode.write_text("\n".join(["G90", "G1 X50 Y50 F6000", "M92 X100 Y120", "G28 X",
                                "G1 X20 Y30", "G28", "G1 X10 Y10", "M400"]) + "\n")
    report = sim.run(gcode, trace_path=tmp_path / "m92_home.vcd")
    assert report["errors"] == []
    checked = tracecheck.check(tmp_path / "m92_home.vcd", gcode)
    assert checked["ok"], _failed(checked)
    steps = {c["name"]: c["expected"] for c in checked["checks"]}
    assert steps["steps_x"] == 10 * 100 and steps["steps_y"] == 10 * 120
