"""The register path: the step loop writes the chip's GPIO set/clear registers with
viper ptr32, here into the simulated chip's register bank laid out like each chip's.
Its trace must be identical to the Pin.value path's. Also the on-board trace capture
(M7300/M7301), inverted DIR pins, and the hard-timer version check."""
import itertools
import json

import numpy as np
import pytest

from mixstep import paths, trace
from mixstep.simprinter import SimPrinter

# Real slicer output: the start of the example print, with two tool changes.
GCODE = paths.ROOT / "testdata" / "part_3tool_prusaslicer_rel.gcode"
LINES = [l.rstrip("\n") for l in itertools.islice(open(GCODE), 1200)]


def run(tmp_path, name, settings, lines=LINES, heap_lock=True, board="sim", jitter_us=0):
    edges = tmp_path / (name + ".edges")
    p = SimPrinter(edges_path=edges, heap_lock=heap_lock, settings=settings, board=board,
                   jitter_us=jitter_us)
    for line in lines:
        reply = p.send(line)
        assert not [r for r in reply if r.startswith("Error")], (line, reply)
    return p, edges


@pytest.fixture(scope="module")
def pin_path(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("pins")
    p, edges = run(tmp, "pin", {})
    return p.finish()["steps"], edges.read_bytes()


# Each chip's register layout, through real boards' pin maps: the SKR Pico drives
# GPIO 28/29, the ESP32 boards GPIO 32/33 through the second register pair.
@pytest.mark.parametrize("board", ["pico"] + [pytest.param(b, marks=pytest.mark.slow) for b in (
    "pico2", "skr_pico", "esp32_devkit", "fysetc_e4")])
def test_register_writes_give_the_same_trace_as_pin_writes(tmp_path, board):
    # The timer path, which pico takes when asked (its default is pio_dma), at the
    # 50 us ticks its board.py gives the timer.
    timer = {"step_backend": "timer"}
    if board == "pico":
        timer["tick_us"] = 50
    # The first tool change and the perimeters after it.
    lines = LINES[:500]
    p, pin_edges = run(tmp_path, "pin", dict(timer, pin_writer="pin"), lines, board=board)
    pin_steps = p.finish()["steps"]
    p, reg_edges = run(tmp_path, "reg", dict(timer, pin_writer="registers"), lines,
                       board=board)
    steps = p.finish()["steps"]
    assert steps == pin_steps
    assert steps["e0"] > 0 and steps["x"] != 0
    assert reg_edges.read_bytes() == pin_edges.read_bytes()


def _captured(board_name, tick_us, tmp_path):
    """The example's lines 40-200 recorded with M7300, the host draining the capture
    after every line while the print goes on. Returns the records, the edges file
    and the board's STEP GPIOs."""
    p, edges = run(tmp_path, "capture", {"trace_records": 30000, "tick_us": tick_us},
                   LINES[:40] + ["M7300 S1"], board=board_name)
    records = []
    for line in LINES[40:200] + ["M400", None]:
        if line:
            p.send(line)
        dump = p.send("M7301")
        head = dump[0].split()
        assert head[0] == "trace:begin" and head[1] == "tick_us=%d" % tick_us
        assert head[3] == "overrun=0"
        assert dump[-2:] == ["trace:end", "ok"] and len(dump) == int(head[2][8:]) + 3
        records += [tuple(int(v) for v in l[len("trace:"):].split(",")) for l in dump[1:-2]]
    assert p.send("M7300 S0")[-1] == "ok"
    p.finish()
    pins = paths.load_board(board_name)["PINS"]
    return records, edges, sorted(g for name, g in pins.items() if name.endswith("_step"))


def _rises(records, step_bits, tick_us, mask=1):
    return [(tick * tick_us, bit) for tick, s, c in records for bit in step_bits
            if ((s, c)[mask] >> bit) & 1]


def test_trace_capture_records_every_step_loop_write(tmp_path):
    records, edges, step_bits = _captured("sim", 20, tmp_path)
    # Every STEP rise the chip made while recording is in the records, at the same
    # tick spacing: recording stopped after the last move, so the two end together.
    captured = _rises(records, step_bits, 20, 0)
    t, g, v = trace.read_edges(edges)
    rising = (v == 1) & (t > 0) & np.isin(g, step_bits)
    chip = list(zip(t[rising].tolist(), g[rising].tolist()))[-len(captured):]
    assert len(captured) > 1000 and len(chip) == len(captured)
    assert [b for _, b in captured] == [b for _, b in chip]
    assert [w - captured[0][0] for w, _ in captured] == [w - chip[0][0] for w, _ in chip]


def test_trace_capture_with_pio_dma_has_every_step_and_its_fall(tmp_path):
    """pio_dma writes a step's fall into the ring with the step (no fall tick): the
    capture records it a pulse's ticks later. The pins put each step inside its
    tick, so the records (whole ticks) are each within a tick of the pins' time."""
    records, edges, step_bits = _captured("pico", 50, tmp_path)
    captured = _rises(records, step_bits, 50, 0)
    falls = _rises(records, step_bits, 50, 1)
    assert [b for _, b in falls] == [b for _, b in captured]
    assert all(f - r == 50 for (f, _), (r, _) in zip(falls, captured))
    t, g, v = trace.read_edges(edges)
    rising = (v == 1) & (t > 0) & np.isin(g, step_bits)
    chip = list(zip(t[rising].tolist(), g[rising].tolist()))[-len(captured):]
    assert len(captured) > 1000 and len(chip) == len(captured)
    assert [b for _, b in captured] == [b for _, b in chip]
    offset = np.array([w for w, _ in chip]) - np.array([w for w, _ in captured])
    assert offset.max() - offset.min() <= 50


def test_trace_capture_without_a_ring_is_refused():
    p = SimPrinter(settings={"trace_records": 0})
    assert p.send("M7300 S1")[0].startswith("Error:no trace ring")
    assert p.send("M7301")[0].startswith("Error:no trace ring")
    p.finish()


def test_inverted_dir_pins_drive_the_motor_the_same_way(tmp_path, board):
    lines = ["M302 P1", "G1 X10 Y5 E3 F3000", "G1 X2 E1", "M400"]
    p, plain = run(tmp_path, "plain", {}, lines)
    plain_steps = p.finish()["steps"]
    p, inverted = run(tmp_path, "inverted", {"invert_dir": ("x", "e0")}, lines)
    assert p.finish()["steps"] == plain_steps  # the simulated motors are wired reversed
    pins = board["PINS"]

    def dir_levels(edges, name):
        """The DIR level in force at each STEP rise of the axis."""
        t, g, v = trace.read_edges(edges)
        level = 0
        levels = []
        for gpio, lv in zip(g.tolist(), v.tolist()):
            if gpio == pins[name + "_dir"]:
                level = lv
            elif gpio == pins[name + "_step"] and lv == 1:
                levels.append(level)
        return levels

    for name in ("x", "e0"):
        assert dir_levels(inverted, name) == [1 - v for v in dir_levels(plain, name)]
        assert 0 in dir_levels(plain, name) and 1 in dir_levels(plain, name)
    assert dir_levels(inverted, "y") == dir_levels(plain, "y") != []


def test_rp2_needs_micropython_1_26_for_a_hard_timer(mp):
    out = mp.script_json("registers_timer_support")
    assert out[0] == ("mixstep needs MicroPython 1.26 or newer on rp2040 for a hard "
                      "machine.Timer; this is 1.25.0: flash a newer MicroPython")
    assert out[1].startswith("mixstep needs MicroPython 1.26 or newer on rp2350")
    assert out[2:] == ["ok", "ok", "ok"]


@pytest.mark.slow
def test_pio_output_is_the_register_trace_a_fixed_latency_later(tmp_path):
    """On the Pico the step loop feeds a (simulated) PIO state machine one word of pin
    levels per tick; every edge comes out exactly LATENCY_TICKS (4 ticks of 50 us)
    after the register path would have written it, and nothing else changes."""
    # At 50 us ticks, as a timer-driven step path runs on the Pico (board.py).
    p, reg = run(tmp_path, "reg", {"step_backend": "timer", "tick_us": 50}, board="pico")
    reg_steps = p.finish()["steps"]
    p, pio = run(tmp_path, "pio", {"step_backend": "pio", "tick_us": 50}, board="pico")
    assert p.finish()["steps"] == reg_steps
    pins = paths.load_board("pico")["PINS"]
    step_path = [g for name, g in pins.items() if name.endswith(("_step", "_dir"))]
    t0, g0, v0 = trace.read_edges(reg)
    t1, g1, v1 = trace.read_edges(pio)
    # The ENABLE pins are not the state machine's: they change at once.
    a = (t0 > 0) & np.isin(g0, step_path)
    b = (t1 > 0) & np.isin(g1, step_path)
    assert np.array_equal(g0[a], g1[b]) and np.array_equal(v0[a], v1[b])
    assert set((t1[b] - t0[a]).tolist()) == {4 * 50}
    assert a.sum() > 10000


def _step_path_edges(edges, board):
    """(time_us, gpio, level) of the STEP/DIR edges after the start, as int64."""
    pins = paths.load_board(board)["PINS"]
    step_path = [g for name, g in pins.items() if name.endswith(("_step", "_dir"))]
    t, g, v = trace.read_edges(edges)
    keep = (t > 0) & np.isin(g, step_path)
    return t[keep].astype(np.int64), g[keep], v[keep]


@pytest.mark.slow
@pytest.mark.parametrize("board", ["pico", "pico2"])
def test_pio_keeps_interrupt_jitter_off_the_pins_within_a_burst(tmp_path, board):
    """The step timer fires each callback up to 3 ticks late (seeded, in order). With
    PIO every edge is still there, in order, and every interval between edges is the
    jitter-free trace's to the microsecond, so pulse widths, step spacing and DIR
    setup stay whole ticks, except across an idle gap: a burst that starts when the
    state machine has run empty starts when its first callback runs, so that
    callback's lateness shifts the whole burst. The register path under the same
    jitter has its edges moved one by one."""
    tick_us = paths.load_board(board)["SETTINGS"]["tick_us"]
    idle_gap_us = 6 * tick_us  # pio.LATENCY_TICKS + 2: the burst has ended
    lines = LINES[:400]
    p, calm = run(tmp_path, "calm", {"step_backend": "pio"}, lines, board=board)
    steps = p.finish()["steps"]
    p, shaken = run(tmp_path, "shaken", {"step_backend": "pio"}, lines, board=board,
                    jitter_us=3 * tick_us)
    assert p.finish()["steps"] == steps and steps["e0"] > 0
    p, reg = run(tmp_path, "reg", {"step_backend": "timer"}, lines, board=board,
                 jitter_us=3 * tick_us)
    assert p.finish()["steps"] == steps
    t0, g0, v0 = _step_path_edges(calm, board)
    t1, g1, v1 = _step_path_edges(shaken, board)
    t2, g2, v2 = _step_path_edges(reg, board)
    assert len(t0) > 100000
    assert np.array_equal(g0, g1) and np.array_equal(v0, v1)
    assert np.array_equal(g0, g2) and np.array_equal(v0, v2)
    assert (t0 % tick_us == 0).all()
    gap0, gap1, gap2 = np.diff(t0), np.diff(t1), np.diff(t2)
    moved = np.flatnonzero(gap1 != gap0)
    # Only burst starts move (the print's few idle waits: homing, heating)...
    assert 1 <= len(moved) <= 5 and (gap0[moved] >= idle_gap_us).all(), gap0[moved]
    # ...each as a whole, by less than a tick more than the jitter.
    bursts = np.split(t1 - t0, moved + 1)
    assert all(len(set(b.tolist())) == 1 for b in bursts)
    assert all(abs(int(b[0])) < 4 * tick_us for b in bursts)
    # The register path passes the jitter on: most intervals change, and the
    # shortest one between two edges falls far below a tick.
    assert (gap2 != gap0).sum() > len(gap0) // 4
    assert gap0[gap0 > 0].min() == tick_us > 3 * gap2[gap2 > 0].min()


def test_pio_needs_the_step_pins_in_one_run_of_gpios(mp):
    out = mp.script_json("registers_pio_pins")
    assert out == [[4, 4], "step_backend pio needs the STEP/DIR pins on one run of GPIOs; "
                           "they are on [4, 5, 6, 9]"]


def test_capture_pull_and_check_a_real_print_end_to_end(tmp_path):
    """The on-board path: record from power-up, drain M7301 into a console log while
    the print runs, `mixstep trace pull --log` it into a VCD, and `mixstep trace check`
    that VCD against the G-code: it must pass, step for step."""
    from mixstep import cli
    snippet = tmp_path / "snippet.gcode"
    snippet.write_text("\n".join(LINES[:400]) + "\n")
    p = SimPrinter(settings={"trace_records": 60000})
    log = [] + p.send("M7300 S1")
    for line in LINES[:400] + ["M400"]:
        p.send(line)
        log += p.send("M7301")
    p.finish()
    assert all("overrun=0" in l for l in log if l.startswith("trace:begin"))
    (tmp_path / "console.log").write_text("\n".join(log) + "\n")
    vcd = tmp_path / "pulled.vcd"
    assert cli.main(["trace", "pull", "--log", str(tmp_path / "console.log"), "-o", str(vcd)]) == 0
    assert cli.main(["trace", "check", str(vcd), "--gcode", str(snippet),
                     "--json", str(tmp_path / "check.json")]) == 0
    report = json.loads((tmp_path / "check.json").read_text())
    assert report["ok"] is True
    names = {c["name"] for c in report["checks"]}
    assert {"steps_e0", "steps_x", "moves", "pulse_high_us", "dir_setup_us"} <= names
