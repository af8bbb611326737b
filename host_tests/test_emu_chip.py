"""The firmware on the emulated Pico, driven as a host drives it (mixstep.emu.Chip):
what only the chip shows. The PIO step backend assembled by rp2.asm_pio and run by
the emulated PIO; the planner and the step loop racing through real interrupts;
M112 arriving mid-move; printing from the emulated flash (M23/M24); a Ctrl-C byte on
the USB console. Each test boots the chip once and keeps to a few emulated seconds
(about 5 wall seconds each); their emulated and wall seconds go to out/emu_tests.json.
"""
import json
import time

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from mixstep import emu, paths, trace, tracecheck
from test_emu import EXCERPT, _emulator_or_skip

# make test-all only (the emulated Pico).
pytestmark = pytest.mark.slow

BOARD = paths.load_board("pico")
PINS = BOARD["PINS"]
SETTINGS = BOARD["SETTINGS"]
TICK_NS = SETTINGS["tick_us"] * 1000
# A hard timer's callback costs about 15 us: the step paths a timer drives ("timer",
# and "pio", a word per tick) run at 50 us ticks, as the boards say.
TIMER_TICK_US = 50
TIMER_TICK_NS = TIMER_TICK_US * 1000


def path_settings(name):
    """Settings for a step path, with the tick a timer-driven one needs."""
    if name == "pio_dma":
        return {"step_backend": name}
    return {"step_backend": name, "tick_us": TIMER_TICK_US}
XY_SPM, _, Z_SPM, E_SPM = SETTINGS["steps_per_mm"]
RECORD = paths.ROOT / "out" / "emu_tests.json"


@pytest.fixture(scope="module")
def timings():
    """Each test's emulated and wall seconds, written out when the module is done."""
    found = {}
    yield found
    if found:
        RECORD.parent.mkdir(exist_ok=True)
        RECORD.write_text(json.dumps(found, indent=2) + "\n")


@pytest.fixture
def chip(request, timings):
    """A factory of booted chips for one test; records the test's emulated seconds
    (boot included) and wall seconds."""
    _emulator_or_skip()
    chips = []
    wall0 = time.perf_counter()

    def boot(**kw):
        kw.setdefault("max_emu_s", 30)
        kw.setdefault("max_wall_s", 600)
        chips.append(emu.Chip("pico", **kw))
        return chips[-1]
    yield boot
    for c in chips:
        c.cleanup()
    timings[request.node.name] = {
        "emulated_seconds": round(sum(c.now for c in chips), 3),
        "wall_seconds": round(time.perf_counter() - wall0, 1)}


def rises(edges, name, after_ns=0, before_ns=float("inf")):
    times, gpios, levels = edges
    sel = (gpios == PINS[name]) & (levels == 1) & (times > after_ns) & (times < before_ns)
    return times[sel]


def net_steps_until(edges, t_ns):
    """Net steps per axis and drive from the edges up to emulated time t_ns."""
    times, gpios, levels = edges
    keep = times <= t_ns
    return trace.net_steps_of(times[keep], gpios[keep], levels[keep], "pico")


def count(m114_lines):
    """M114's `Count X:<n> Y:<n> Z:<n>` as {"x": n, ...}."""
    line = next(t for t in m114_lines if " Count " in t)
    words = line.split(" Count ")[1].split()
    return {w[0].lower(): int(w[2:]) for w in words}


def test_pio_backend_puts_edges_on_whole_ticks_at_the_planned_rate(chip, tmp_path):
    """step_backend "pio": the step loop feeds a state machine made by rp2.asm_pio,
    which the emulated PIO runs at one word per tick. Every STEP/DIR edge of the moves
    lies on one grid of whole ticks, pulses and DIR setup are whole ticks, and the
    lead axis cruises at its planned rate (each step within a tick of its time)."""
    gcode = tmp_path / "pio.gcode"
    # X leads the first move at 50 mm/s * 12/13: 3692.3 steps/s, 5.42 ticks a step.
    gcode.write_text("M302 P1\nG91\nG1 X12 Y5 F3000\nG1 X-4 Y-3 E1 F1800\nG1 Z0.5 F600\n")
    emu.board_spec("pico", path_settings("pio"))  # raises unless `boards check` passes it
    c = chip(settings=path_settings("pio"))
    printed = emu.stream(c, gcode, diag_every=0)
    assert printed["stopped"] is None and printed["errors"] == []
    assert printed["diagnostics"][-1]["underruns"] == 0
    c.close()
    vcd = tmp_path / "pio.vcd"
    c.write_vcd(vcd)
    check = tracecheck.check(vcd, gcode, board="pico")
    assert check["ok"], json.dumps([k for k in check["checks"] if not k["ok"]], indent=1)

    times, gpios, levels = edges = trace.read_edges(c.edges_path)
    start_ns = printed["start"]["nanos"]
    motion = {PINS[a + s] for a in ("x", "y", "z", "e0") for s in ("_step", "_dir")}
    sel = np.isin(gpios, list(motion)) & (times > start_ns)
    t, g, v = times[sel], gpios[sel], levels[sel]
    # One burst: every edge a whole number of ticks after the first.
    assert len(t) > 2000
    assert np.all((t - t[0]) % TIMER_TICK_NS == 0), np.unique((t - t[0]) % TIMER_TICK_NS)[:10]
    # STEP high and low times, DIR setup: whole ticks (so above), at least the ticks
    # the board's microseconds round up to.
    pulse_ticks = -(-SETTINGS["step_pulse_us"] // TIMER_TICK_US)
    for axis in ("x", "y", "z", "e0"):
        s = t[g == PINS[axis + "_step"]]
        lv = v[g == PINS[axis + "_step"]]
        assert lv[0] == 1 and np.all(lv[::2] == 1) and np.all(lv[1::2] == 0)
        assert np.min(s[1::2] - s[0::2][:len(s[1::2])]) >= pulse_ticks * TIMER_TICK_NS
        for d in t[g == PINS[axis + "_dir"]]:
            after = s[(s > d)]
            if len(after):
                assert after[0] - d >= TIMER_TICK_NS
    # The first move's cruise: X steps (up to X's turn) past both ramps
    # (0.83 mm of path each at 1500 mm/s^2: 62 X steps) come every 5 or 6 ticks,
    # 5.417 on average; Y's, every 13 ticks on average (Bresenham under X's steps).
    x_turn = t[(g == PINS["x_dir"]) & (v == 0)][0]
    x = rises(edges, "x_step", start_ns, x_turn)
    y = rises(edges, "y_step", start_ns, x_turn)
    assert len(x) == 960 and len(y) == 400
    planned_x = 1e9 / (50 * 12 / 13 * XY_SPM) / TIMER_TICK_NS
    cruise = np.diff(x[80:-80]) / TIMER_TICK_NS
    assert set(np.unique(cruise)) <= {np.floor(planned_x), np.ceil(planned_x)}
    assert abs(np.mean(cruise) - planned_x) < 0.01
    y_cruise = y[(y > x[80]) & (y < x[-80])]
    assert abs(np.mean(np.diff(y_cruise)) / TIMER_TICK_NS - planned_x * 12 / 5) < 0.05


def test_pio_dma_backend_prints_the_excerpt_with_steps_between_ticks(chip, tmp_path):
    """step_backend "pio_dma": the step loop fills 2 ms batches of timed edges that
    two chained DMA channels (rp2.DMA, hard IRQ) feed to a state machine made by
    rp2.asm_pio. The excerpt's trace does what its G-code asks, no refill came late,
    the steps land between the ticks (at their own times), and the step loop takes
    less of the CPU than an empty 20 kHz timer callback would."""
    emu.board_spec("pico", {"step_backend": "pio_dma"})  # raises unless `boards check` passes it
    c = chip(settings={"step_backend": "pio_dma"}, max_emu_s=20)
    printed = emu.stream(c, EXCERPT, diag_every=0)
    assert printed["stopped"] is None and printed["errors"] == []
    diag = printed["diagnostics"][-1]
    assert diag["underruns"] == 0 and diag["late_refills"] == 0
    c.close()
    vcd = tmp_path / "pio_dma.vcd"
    c.write_vcd(vcd)
    check = tracecheck.check(vcd, EXCERPT, board="pico")
    assert check["ok"], json.dumps([k for k in check["checks"] if not k["ok"]], indent=1)
    times, gpios, levels = trace.read_edges(c.edges_path)
    x = times[(gpios == PINS["x_step"]) & (levels == 1)].astype(np.int64)
    assert len(x) > 5000
    # Every 125 ns (a cycle of the 8 MHz state machine) of a tick holds steps.
    assert len(np.unique((x - x[0]) % TICK_NS)) == TICK_NS // 125
    start, end = printed["start"], printed["end"]
    step_s = sum(end["exc"][n] - start["exc"][n] for n in emu.STEP_EXCEPTIONS) / 1e9
    # About 12 %; an empty 20 kHz hard timer callback alone takes 30 % of the CPU.
    assert step_s / ((end["nanos"] - start["nanos"]) / 1e9) < 0.2


MOVE = st.tuples(st.integers(-80, 80), st.integers(-80, 80), st.integers(-6, 6),
                 st.integers(-3, 3), st.sampled_from([900, 1800, 3000, 6000]))


@pytest.mark.parametrize("backend", ["timer", "pio_dma"])
def test_moves_queued_while_the_steps_run_end_exactly(chip, backend):
    """Relative moves sent one per `ok` while the hard timer (or the DMA IRQ's batch
    fill) steps the ones before: the planner runs in the main loop with the step loop
    interrupting it. Where each
    sequence ends, by M114's Count and by the trace, is exact. Moves are whole steps
    of 0.05 mm (4 X/Y steps, 20 Z steps) and 0.2 mm of filament (83 e0 steps)."""
    c = chip(settings=path_settings(backend), max_emu_s=60)
    for line in ("M302 P1", "M211 S0", "G91"):  # M211 S0: anywhere, off the bed too
        assert c.command(line)[-1] == "ok"
    at = {"x": 0, "y": 0, "z": 0, "e0": 0}
    sequences = []

    @settings(max_examples=4, deadline=None, derandomize=True, database=None)
    @given(st.lists(MOVE, min_size=2, max_size=4))
    def ends_exactly(moves):
        sequences.append(moves)
        for dx, dy, dz, de, feed in moves:
            words = "G1 X%.2f Y%.2f Z%.2f E%.1f F%d" % (dx * 0.05, dy * 0.05, dz * 0.05,
                                                        de * 0.2, feed)
            assert c.command(words) == ["ok"], words
            at["x"] += dx * 4
            at["y"] += dy * 4
            at["z"] += dz * 20
            at["e0"] += de * 83
        assert c.command("M400") == ["ok"]
        got = count(c.command("M114"))
        assert got == {a: at[a] for a in "xyz"}
        net = net_steps_until(c.edges(), c.now * 1e9)
        assert {a: net[a] for a in at} == at

    ends_exactly()
    assert len(sequences) == 4


@pytest.mark.parametrize("backend", ["timer", "pio_dma"])
def test_m112_mid_move_stops_motion_at_once(chip, backend):
    """M112 sent while a 2 s move runs (its `ok` long gone): the step loop takes no
    step after the firmware reads it, the printer answers Error:, refuses moves until
    M999, and M114's Count is where the trace stopped. With pio_dma the DMA ring held
    steps for the next few ms: they never reach the pins and M114 does not count
    them."""
    c = chip(settings=path_settings(backend))
    assert c.command("G91") == ["ok"]
    assert c.command("G1 X100 F3000") == ["ok"]  # 8000 steps, 2 s
    c.run(for_s=0.3)
    c.send("M112\n")
    said = c.run(match="Error:", max_s=1)
    assert said[-1] == "Error:emergency stop (M112)"
    sent_at = next(t for t, way, text in c.transcript if way == ">" and "M112" in text)
    error_at = next(t for t, way, text in c.transcript if text.startswith("Error:emergency"))
    c.run(for_s=0.2)
    refused = c.command("G1 X1")
    assert refused[0].startswith("Error:printer halted") and refused[-1] == "ok"
    halted = count(c.command("M114"))
    edges = c.edges()
    x = rises(edges, "x_step")
    # Steps ran at 4000/s until the firmware read M112 (it polls the USB console
    # between lines and in every wait; USB delivery adds a few ms of virtual time
    # that vary with the host's load) and none came after that: the last one comes
    # before the Error: is sent, none in the 200 ms after. Before it reports, the halt
    # turns the heaters off, stops the DMA in the datasheet's order and starts the
    # state machine again with the pins' levels.
    x = x.astype(np.float64)
    assert error_at - sent_at < 0.012
    assert sent_at * 1e9 < x[-1] < error_at * 1e9
    # Cruising right up to the stop: 250 us a step, within a tick or two.
    assert np.max(np.diff(x[-50:])) <= 1e9 / 4000 + 2 * max(TICK_NS, TIMER_TICK_NS)
    assert halted["x"] == len(x) == net_steps_until(edges, c.now * 1e9)["x"] < 8000
    assert c.command("M999") == ["ok"]
    assert c.command("G1 X1") == ["ok"]
    assert c.command("M400") == ["ok"]
    assert count(c.command("M114"))["x"] == halted["x"] + 80
    assert len(rises(c.edges(), "x_step")) == len(x) + 80


@pytest.mark.parametrize("backend", ["timer", "pio_dma"])
def test_homing_stops_at_the_switch(chip, backend):
    """G28 from 20 mm and 10 mm away. With pio_dma the step loop runs batches ahead of
    the pins and sees the endstop late: the state machine made by rp2.asm_pio holds
    the pins from the switch on (its jmp pin), and the steps the ring held are taken
    back. By the trace the axes never pass the switch (the emulated endstop reads
    triggered at 0 and below), and M114's Count is 0 there."""
    c = chip(settings=path_settings(backend))
    for line in ("G91", "G1 X20 Y10 F6000", "G90", "G28 X Y", "G1 X1 F3000", "M400"):
        assert c.command(line)[-1] == "ok", line
    assert {a: n for a, n in count(c.command("M114")).items() if a in "xy"} == {"x": 80, "y": 0}
    edges = c.edges()
    for axis, end in (("x", 80), ("y", 0)):
        _, pos = trace.positions_of(*edges, "pico", axis)
        assert pos.min() == 0 and pos.max() == 20 * XY_SPM // (2 if axis == "y" else 1)
        assert pos[-1] == end, axis


def test_print_from_the_emulated_flash(chip, tmp_path):
    """A real slicer excerpt on the emulated flash next to the firmware, selected with
    M23 and started with M24: the printer reads it line by line between console
    lines, says when it is done, and the trace does what the file asks."""
    part = tmp_path / "part.gcode"
    with open(EXCERPT) as f:  # its start: homing, Z, then T0's perimeter
        part.write_text("".join(f.readlines()[:60]))
    c = chip(files={"part.gcode": part})
    listing = c.command("M20")
    assert "part.gcode %d" % part.stat().st_size in listing
    assert "File selected" in c.command("M23 part.gcode")
    assert c.command("M24") == ["ok"]
    c.run(match="Done printing file", max_s=20)
    assert c.command("M27")[0] == "SD printing byte %d/%d" % ((part.stat().st_size,) * 2)
    # The queue's last moves may outlast M113's 2 s: busy lines, then ok.
    assert set(c.command("M400", max_s=30)) <= {"busy: processing", "ok"}
    errors = [t for t in c.lines_since(0) if t.startswith("Error:")]
    assert errors == []
    c.close()
    vcd = tmp_path / "part.vcd"
    c.write_vcd(vcd)
    check = tracecheck.check(vcd, part, board="pico")
    assert check["ok"], json.dumps([k for k in check["checks"] if not k["ok"]], indent=1)
    steps = {k["name"][6:]: k["measured"] for k in check["checks"]
             if k["name"].startswith("steps_")}
    assert steps["x"] > 8000 and steps["e0"] > 100


def test_ctrl_c_byte_is_data_while_serving(chip):
    """A 0x03 byte alone and inside lines, sent during a move: MicroPython's Ctrl-C is
    off while the firmware serves (micropython.kbd_intr(-1)), so the move goes on to
    its end, each line with the byte is answered as a bad line, and the next answers."""
    c = chip()
    assert c.command("G91") == ["ok"]
    assert c.command("G1 X20 F3000") == ["ok"]  # 1600 steps, 0.45 s
    c.run(for_s=0.1)
    c.send(b"\x03")
    c.run(for_s=0.05)
    c.send(b"\n")  # ends the line the lone byte began
    for said in (c.run(oks=1), c.command("M118 E1 ctrl\x03c"), c.command("G1 X1\x03")):
        assert said == ["Error:byte 0x03 is a control character", "ok"]
    assert c.command("M400") == ["ok"]
    assert count(c.command("M114"))["x"] == 1600
    x = rises(c.edges(), "x_step")
    assert len(x) == 1600
    assert np.max(np.diff(x)) < 0.01 * 1e9  # no pause in the steps either
    assert not any(">>>" in t or "Traceback" in t or "KeyboardInterrupt" in t
                   for t in c.lines_since(0))


@pytest.mark.parametrize("settings", [{}, path_settings("timer")])
def test_the_six_drive_board_boots_with_room_in_its_heap(settings, tmp_path):
    """The imports leave the Pico's heap in pieces; the step loop's memory and, with
    pio_dma, its DMA ring need whole blocks of a few kB (the board's 10 us ticks need
    the largest ring). Booted as deployed, and with the timer fallback, the firmware
    answers and keeps 25 kB free after a collection for printing (with its 48-block
    queue, the arc code, the job commands, pressure advance's follower and M524:
    about 25.4 kB; the whole USB print's rows, bench/chip_print.py, hold with it). boot.py has
    set the board's clock first."""
    _emulator_or_skip()
    with emu.Chip("pico_6drives", settings=settings, max_emu_s=30, max_wall_s=600) as c:
        c.profile()
        diag = [t for t in c.command("M122") if t.startswith("echo:underruns")]
        c.profile(tmp_path / "profile.json")
    free = int(diag[0].split("mem_free_collected:")[1].split()[0])
    assert free >= 25000, diag
    clock_hz = json.loads((tmp_path / "profile.json").read_text())["clk_sys_hz"]
    assert clock_hz == pytest.approx(paths.load_board("pico_6drives")["SETTINGS"]["clock_hz"])
    assert clock_hz == pytest.approx(200e6)


def test_the_program_counters_profile_adds_up_to_the_planners_time(tmp_path):
    """bench/chip_pcprofile.py on the planner rows' excerpt, with the step path running:
    the time of a line, function by function in the main loop and in the interrupts,
    adds up to the time a line took (at the run's lines/s); the planner's functions are
    in the main loop's, and the step loop is the interrupts' most."""
    _emulator_or_skip()
    import importlib.util
    spec = importlib.util.spec_from_file_location(
        "chip_pcprofile", paths.ROOT / "bench" / "chip_pcprofile.py")
    pcprofile = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(pcprofile)
    got = pcprofile.profile(stepping=True, work=tmp_path)
    thread, irq = got["us_per_line"]["thread"], got["us_per_line"]["irq"]
    line_us = 1e6 / got["move_lines_per_s"]
    assert abs(sum(thread.values()) + sum(irq.values()) - line_us) < 0.01 * line_us
    for name in ("mixfw.cmd_motion.Motion.g1", "mixfw.planner._plan_move",
                 "mixfw.filament.plan_e_words", "mixfw.gcode._scan"):
        # A function another module imports is known by both names ("a = b").
        assert sum(us for key, us in thread.items() if name in key.split(" = ")) > 1, name
    assert "stepper.tick" in max(irq, key=irq.get)
    assert 0.05 * line_us < sum(irq.values()) < 0.3 * line_us
