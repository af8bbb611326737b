"""step_backend "pio_dma" on the unix port: the step loop fills batches of timed edges
into a ring that the simulated chip's DMA feeds to its PIO state machine
(boards/sim/rp2.py). Every drive makes exactly the timer backend's steps, a refill
that comes late stalls the pins but never makes a wrong step, M112 mid-move leaves
M114 where the pins stopped, and the batch fill runs with the heap locked."""
import itertools

import numpy as np
import pytest

from mixstep import paths, trace
from mixstep.simprinter import SimPrinter

BOARD = "pico"
PINS = paths.load_board(BOARD)["PINS"]
# Real slicer output: homing, a tool change, perimeters with retractions.
GCODE = paths.ROOT / "testdata" / "part_3tool_prusaslicer_rel.gcode"
LINES = [l.rstrip("\n") for l in itertools.islice(open(GCODE), 500)]
PIO_DMA = {"step_backend": "pio_dma"}
TIMER = {"step_backend": "timer", "tick_us": 50}  # the Pico's timer runs at 50 us ticks


def run(tmp_path, name, settings, lines=LINES, before=()):
    edges = tmp_path / (name + ".edges")
    p = SimPrinter(edges_path=edges, heap_lock=True, settings=settings, board=BOARD)
    said = []
    for line in list(before) + lines:
        reply = p.send(line)
        assert not [r for r in reply if r.startswith("Error")], (line, reply)
        said += reply
    return p, edges, said


@pytest.fixture(scope="module")
def timer_steps(tmp_path_factory):
    p, _, _ = run(tmp_path_factory.mktemp("timer"), "timer", TIMER)
    return p.finish()["steps"]


def _late_refills(said):
    line = [t for t in said if t.startswith("echo:underruns:")][-1]
    return int(line.split("late_refills:")[1].split()[0])


def test_every_drive_makes_the_timer_backends_steps(tmp_path, timer_steps):
    """With the heap locked around every DMA IRQ (the batch fill): a fill that
    allocated, raised or used a float would stop the steps there."""
    p, edges, said = run(tmp_path, "dma", PIO_DMA, LINES + ["M400", "M122"])
    assert p.finish()["steps"] == timer_steps
    assert timer_steps["x"] != 0 and timer_steps["e0"] > 0 and timer_steps["e2"] > 0
    assert _late_refills(said) == 0
    # Pulses in spec (2 us), steps off the 50 us tick grid (the simulation's edges
    # are whole microseconds).
    t, g, v = trace.read_edges(edges)
    t = t.astype(np.int64)
    x = t[(g == PINS["x_step"])]
    lv = v[(g == PINS["x_step"])]
    rise, fall = x[lv == 1], x[lv == 0][-len(x[lv == 1]):]
    assert np.min(fall - rise) >= 2 and np.min(rise[1:] - fall[:-1]) >= 2
    assert len(set((rise % 50).tolist())) == 50


def test_a_late_refill_stalls_the_pins_but_makes_no_wrong_step(tmp_path, timer_steps):
    """Every DMA IRQ held back 3 ms (longer than a batch): the other channel ends
    first and the FIFO runs dry, so the refill has to start the armed channel
    itself. (One IRQ held back alone stalls nothing: the other channel's IRQ, on
    time, hands over the ready segment.)"""
    p, edges, said = run(tmp_path, "late", PIO_DMA, LINES + ["M400", "M122"],
                         before=["M7103 S3000 P1"])
    assert p.finish()["steps"] == timer_steps
    assert _late_refills(said) > 10


# Stops at every point of a 2 ms batch: at 301 ms the channel that read a segment has
# ended and the segment was refilled while the FIFO still held its last 8 words (4
# steps), which the ring no longer had to take back (the count was 4 over the pins).
@pytest.mark.parametrize("hang_ms", [300, 301, 302, 303])
def test_m112_mid_move_leaves_the_count_where_the_pins_stopped(tmp_path, hang_ms):
    p, edges, said = run(tmp_path, "m112", PIO_DMA,
                         ["G91", "G1 X100 F3000", "M7102 S%d" % hang_ms])
    assert p.send("M112")[0] == "Error:emergency stop (M112)"
    count = [t for t in p.send("M114") if " Count " in t][0]
    halted_x = int(count.split(" Count ")[1].split()[0][2:])
    assert 0 < halted_x < 8000
    assert p.send("M999") == ["ok"]
    assert p.send("G1 X1") == ["ok"]
    assert p.send("M400") == ["ok"]
    count = [t for t in p.send("M114") if " Count " in t][0]
    assert int(count.split(" Count ")[1].split()[0][2:]) == halted_x + 80
    assert p.finish()["steps"]["x"] == halted_x + 80


@pytest.mark.parametrize("backend", ["timer", "pio_dma"])
def test_homing_stops_the_pins_at_the_switch(tmp_path, backend):
    """The step loop runs batches ahead of the pins with pio_dma, so it sees the
    endstop late; the state machine holds the pins from the switch on (its jmp pin)
    and the steps the ring still held are taken back. The axis never goes past the
    switch (the simulated endstop reads triggered at 0 and below), and home is where
    the switch is, as with the timer."""
    p, edges, said = run(tmp_path, backend, TIMER if backend == "timer" else PIO_DMA,
                         ["G28", "G91", "G1 X30 Y20 Z2 F6000", "G90", "G28 X Y",
                          "G28 Z", "G1 X1 F3000", "M400"])
    count = [t for t in p.send("M114") if " Count " in t][0]
    assert count.split(" Count ")[1].split()[:3] == ["X:80", "Y:0", "Z:0"]
    assert p.finish()["steps"]["x"] == 80
    t, g, v = trace.read_edges(edges)
    for axis in "xyz":
        _, pos = trace.positions_of(t, g, v, BOARD, axis)
        assert pos.min() == 0 and pos[-1] == (80 if axis == "x" else 0), axis
