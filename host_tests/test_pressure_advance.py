"""Pressure advance (M900, Marlin's LIN_ADVANCE K per virtual tool), on the MicroPython
unix port: the drives push the mixed filament ahead by K times its speed and give it
back through the mixer, so every E move without advance (retractions, priming) and the
print's end find every drive exactly where it would be without; trace check follows
the advance from the trace's own speeds (tracecheck._AdvanceWalk). Real slicer output,
with retraction, tool changes and mixed tools."""
import pytest

from mixstep import paths, sim, trace, tracecheck

SAMPLES = paths.ROOT / "testdata"
PRINT = SAMPLES / "short_3tool_m117_prusaslicer.gcode"
# T0 1:2:3 and T2 0.2:0.5:0.3 over drives 0, 1 and 4, so the advance is shared.
MIXES = ["M567 P0 E1:2:3\n", "M163 S0 P0.2\n", "M163 S1 P0.5\n", "M163 S4 P0.3\n",
         "M164 S2\n"]
K_S = 0.08


def _head(tmp_path, lines=700, extra=()):
    """The print's first lines (its first tool change and the retractions around it),
    with mixed tools and the given lines after its start G-code."""
    text = PRINT.read_text().splitlines(keepends=True)
    gcode = tmp_path / "head.gcode"
    gcode.write_text("".join(text[:21] + MIXES + list(extra) + text[21:lines]))
    return gcode


def _advance(k=K_S):
    return {"tool_advance_k": (k,) * 16}


def _checked(tmp_path, gcode, settings, board="sim", heap_lock=False):
    vcd = tmp_path / "run.vcd"
    edges = tmp_path / "run.edges"
    report = sim.run(gcode, trace_path=vcd, edges_path=edges, board=board,
                     heap_lock=heap_lock, settings=settings)
    assert report["errors"] == []
    checked = tracecheck.check(vcd, gcode, board=board, settings=settings)
    failed = [c for c in checked["checks"] if c["ok"] is False]
    assert not failed, failed
    return report, {c["name"]: c for c in checked["checks"]}, edges


@pytest.mark.parametrize("policy", [0, pytest.param(1, marks=pytest.mark.slow),
                                    pytest.param(2, marks=pytest.mark.slow)])
def test_the_drives_end_where_they_would_without_advance(tmp_path, policy):
    """Every retraction policy: the same net steps per drive as without advance, every
    E-only move ending exactly on its filament, and the advance K times the speed at
    the ends of the printing moves; the drives stepped back while printing, as the
    advance came off on the way into corners."""
    gcode = _head(tmp_path)
    settings = dict(_advance(), retract_policy=policy)
    report, checks, edges = _checked(tmp_path, gcode, settings)
    plain = sim.run(gcode, settings={"retract_policy": policy})
    assert report["steps"] == plain["steps"]
    assert checks["advance"]["ok"] and "block ends" in checks["advance"]["detail"]
    times, gpios, levels = trace.read_edges(edges)
    for d in (0, 1):
        _, pos = trace.positions_of(times, gpios, levels, "sim", "e%d" % d)
        back = (pos[1:] < pos[:-1]).sum()
        # More back steps than the retractions' alone: the advance gave filament back.
        assert back > 0
    assert max(int(w) for w in checks["advance"]["detail"].split("the most ")[1].split()[:1]) > 5


def test_advance_with_transitions_and_on_the_pio_dma_path_under_a_locked_heap(tmp_path):
    """A mix change moved ahead of its line (transition_l1_mm), on the Pico's step path
    (PIO fed by DMA) with the heap locked around every step-loop call: the same
    drives' counts and a trace that passes every check."""
    gcode = _head(tmp_path, lines=500)
    settings = dict(_advance(0.05), transition_l1_mm=0.5)
    report, checks, _ = _checked(tmp_path, gcode, settings, board="pico", heap_lock=True)
    plain = sim.run(gcode, board="pico", settings={"transition_l1_mm": 0.5})
    assert report["steps"] == plain["steps"]
    assert checks["dir_setup_us"]["ok"] and checks["pulse_high_us"]["ok"]


def test_m900_sets_reports_and_keeps_each_tools_k(sim_printer, tmp_path):
    config = tmp_path / "config.txt"
    p = sim_printer(cold_extrusion=True, config_path=config)
    assert p.send("M900") == ["echo:Advance K=0.000", "ok"]
    assert p.send("M900 K0.06") == ["ok"]
    assert p.send("M900 T3 K0.4") == ["ok"]
    assert p.send("M900") == ["echo:Advance K=0.060", "ok"]
    assert p.send("M900 T3") == ["echo:Advance K=0.400", "ok"]
    assert p.send("T3") == ["ok"]
    assert p.send("M900") == ["echo:Advance K=0.400", "ok"]
    for line, error in (("M900 K10.5", "M900 K10.5 out of range 0..10 (s)"),
                        ("M900 K-1", "M900 K-1.0 out of range 0..10 (s)"),
                        ("M900 T16 K0.1", "tool T16 out of range T0..T15")):
        assert p.send(line) == ["Error:" + error, "ok"], line
    assert p.send("M900") == ["echo:Advance K=0.400", "ok"]
    assert p.send("M500")[-1] == "ok"
    p.finish()
    again = sim_printer(cold_extrusion=True, config_path=config)
    assert again.send("M900 T0") == ["echo:Advance K=0.060", "ok"]
    assert again.send("M900 T3") == ["echo:Advance K=0.400", "ok"]
    again.finish()


def test_no_advance_leaves_the_drives_to_the_blocks_and_k0_turns_it_off(sim_printer,
                                                                         tmp_path):
    """K 0 (the default) runs every drive as before: a move's drives step only
    forward; once K is set and turned off again, the same."""
    edges = tmp_path / "run.edges"
    p = sim_printer(cold_extrusion=True, edges_path=edges)
    for line in ("M83", "M165 A0.5 B0.5", "M900 K0.2", "G1 X20 E1 F3000", "G1 X40 E1",
                 "M900 K0", "G1 X60 E1", "G1 X80 E1"):
        assert p.send(line)[-1] == "ok", line
    steps = p.finish()["steps"]
    assert steps["e0"] + steps["e1"] == 4 * 415
    times, gpios, levels = trace.read_edges(edges)
    t0, pos0 = trace.positions_of(times, gpios, levels, "sim", "e0")
    assert (pos0[1:] < pos0[:-1]).any()  # the advance came back at the first stop
    t_x, pos_x = trace.positions_of(times, gpios, levels, "sim", "x")
    # After X reached 40 mm (K 0 from there), e0 only steps forward.
    at_40 = t_x[pos_x.tolist().index(40 * 80)]
    late = pos0[t0 > at_40]
    assert len(late) and (late[1:] >= late[:-1]).all()
