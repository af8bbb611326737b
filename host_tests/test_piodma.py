"""step_backend "pio_dma" on the unix port: the step loop fills batches of timed edges
into a ring that the simulated chip's DMA feeds to its PIO state machine
(boards/sim/rp2.py), laid out as the board's chip (RP2040: pico, RP2350: pico2). Every
drive makes exactly the timer backend's steps, a refill that comes late stalls the
pins but never makes a wrong step, M112 mid-move leaves M114 where the pins stopped,
a restart of the state machine moves no DIR pin, and the batch fill runs with the
heap locked."""
import itertools

import numpy as np
import pytest

from mixstep import paths, trace
from mixstep.simprinter import SimPrinter

BOARD = "pico"
PINS = paths.load_board(BOARD)["PINS"]
# Real slicer output: homing, a tool change, perimeters with retractions.
GCODE = paths.ROOT / "testdata" / "part_3tool_prusaslicer_rel.gcode"
LINES = [l.rstrip("\n") for l in itertools.islice(open(GCODE), 360)]
PIO_DMA = {"step_backend": "pio_dma"}
TIMER = {"step_backend": "timer", "tick_us": 50}  # the Pico's timer runs at 50 us ticks


def run(tmp_path, name, settings, lines=LINES, before=(), board=BOARD):
    edges = tmp_path / (name + ".edges")
    p = SimPrinter(edges_path=edges, heap_lock=True, settings=settings, board=board)
    said = []
    for line in list(before) + lines:
        reply = p.send(line)
        assert not [r for r in reply if r.startswith("Error")], (line, reply)
        said += reply
    return p, edges, said


@pytest.fixture(scope="module")
def timer_steps(tmp_path_factory):
    """The timer backend's steps for the example, per board (made once each)."""
    made = {}

    def of(board=BOARD):
        if board not in made:
            settings = TIMER if board == "pico" else {"step_backend": "timer"}
            p, _, _ = run(tmp_path_factory.mktemp("timer"), "timer", settings, board=board)
            made[board] = p.finish()["steps"]
        return made[board]
    return of


def _late_refills(said):
    line = [t for t in said if t.startswith("echo:underruns:")][-1]
    return int(line.split("late_refills:")[1].split()[0])


def test_every_drive_makes_the_timer_backends_steps(tmp_path, timer_steps):
    """With the heap locked around every DMA IRQ (the batch fill): a fill that
    allocated, raised or used a float would stop the steps there."""
    p, edges, said = run(tmp_path, "dma", PIO_DMA, LINES + ["M400", "M122"])
    steps = timer_steps()
    assert p.finish()["steps"] == steps
    assert steps["x"] != 0 and steps["e0"] > 0 and steps["e2"] > 0
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


# make test takes the RP2350, whose constants differ from those of the RP2040 that the
# other tests here run on; make test-all both chips.
@pytest.mark.parametrize("board", [pytest.param("pico", marks=pytest.mark.slow), "pico2"])
def test_a_late_refill_stalls_the_pins_but_makes_no_wrong_step(tmp_path, timer_steps, board):
    """Every DMA IRQ held back 3 ms (longer than a batch): the other channel ends
    first and the FIFO runs dry, so the refill has to start the armed channel
    itself, through the chip's own MULTI_CHAN_TRIGGER (0x430 on the RP2040, 0x450 on
    the RP2350: a write to the other chip's offset would start nothing). (One IRQ
    held back alone stalls nothing: the other channel's IRQ, on time, hands over
    the ready segment.)"""
    p, edges, said = run(tmp_path, "late", PIO_DMA, LINES + ["M400", "M122"],
                         before=["M7103 S3000 P1"], board=board)
    assert p.finish()["steps"] == timer_steps(board)
    assert _late_refills(said) > 10


# Stops at every point of a 2 ms batch: at 301 ms the channel that read a segment has
# ended and the segment was refilled while the FIFO still held its last 8 words (4
# steps), which the ring must still take back (else the count is 4 over the pins).
# On the RP2350 a channel aborted with EN set can start again (RP2350-E5) and feed the
# FIFO words of the stopped ring after the restart: the count would be off.
@pytest.mark.parametrize("board", ["pico", "pico2"])
@pytest.mark.parametrize("hang_ms", [300, 301, 302, 303])
def test_m112_mid_move_leaves_the_count_where_the_pins_stopped(tmp_path, hang_ms, board):
    p, edges, said = run(tmp_path, "m112", PIO_DMA,
                         ["G91", "G1 X100 F3000", "M7102 S%d" % hang_ms], board=board)
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


# Every homed axis makes the state machine again twice (watching its endstop, then
# not), each time after moves left DIR pins high; inverted motors home with DIR high.
@pytest.mark.parametrize("invert_dir", [(), ("x", "y", "z")])
def test_a_state_machine_restart_moves_no_dir_pin(tmp_path, invert_dir):
    """A StateMachine drives its pins to its program's out_init as it is made: each
    DIR pin goes through exactly the levels it does with the timer backend, which
    never restarts anything."""
    lines = ["G1 X30 Y20 Z2 F6000", "G28 X", "G1 X10 F6000", "G28 Y", "G1 X5 Y5 F6000",
             "G28 Z", "M400"]
    dirs = [g for name, g in PINS.items() if name.endswith("_dir")]
    levels = {}
    for backend, settings in (("timer", TIMER), ("pio_dma", PIO_DMA)):
        p, edges, _ = run(tmp_path, backend, dict(settings, invert_dir=invert_dir), lines)
        p.finish()
        t, g, v = trace.read_edges(edges)
        levels[backend] = {gpio: v[(g == gpio) & (t > 0)].tolist() for gpio in dirs}
    assert levels["pio_dma"] == levels["timer"]
    assert sum(len(lv) for lv in levels["timer"].values()) >= 6


def test_pio_dma_refuses_what_its_chip_constants_would_be_wrong_on(mp):
    out = mp.script_json("piodma_check_chip")
    assert out[:2] == ["ok", "ok"]
    assert out[2] == ("step_backend pio_dma needs the RP2350's Arm cores; this MicroPython "
                      "runs on its RISC-V cores (Raspberry Pi Pico2 with RP2350-RISCV): "
                      "flash the Arm build")
    assert out[3] == ("step_backend pio_dma: chip is 'rp2040', but this MicroPython's DMA "
                      "has CHAIN_TO at bit 13 (the rp2040's is at bit 11): flash the "
                      "MicroPython for the board's chip")
