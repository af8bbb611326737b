"""G28 against bouncing endstops (the simulation's M7105: after the step that reaches
the switch its level flips six times in 5 ms before it settles). The first closure is
home: once the switch has read triggered, the axis takes no further step in that
homing move, whatever the switch does while it bounces. With pio_dma the state
machine latches on its jmp pin until it is made again; the timer backends' step loop
looks at the switch every tick and latches the axis for the rest of the block."""
import numpy as np
import pytest

from mixstep import trace
from mixstep.simprinter import SimPrinter

BOUNCE = "M7105 S5000"
# Homed from several distances, so the switch is reached at different points of a step
# and of a batch.
AWAY = ("G1 X30 Y20 Z2 F6000", "G1 X17.3 Y4.1 Z0.7 F3000", "G1 X5 Y33.3 Z3.1 F4800")
BACKENDS = {
    "pio_dma": ("pico_6drives", {}),
    "timer": ("sim", {}),
    "registers": ("pico", {"step_backend": "timer", "tick_us": 50}),
    "pio": ("pico", {"step_backend": "pio", "tick_us": 50}),
}


def _home_again_and_again(tmp_path, backend):
    board, settings = BACKENDS[backend]
    edges = tmp_path / "homing.edges"
    p = SimPrinter(edges_path=edges, heap_lock=True, settings=settings, board=board)
    lines = [BOUNCE]
    for away in AWAY:
        lines += ["G91", away, "G90", "G28 X Y", "G28 Z"]
    counts = []
    for line in lines + ["G1 X1 F3000", "M400"]:
        reply = p.send(line)
        assert reply[-1] == "ok", (line, reply)
        if line == "G28 Z":
            counts.append([t for t in p.send("M114") if " Count " in t][0])
    report = p.finish()
    return board, counts, report, trace.read_edges(edges)


@pytest.mark.parametrize("backend", sorted(BACKENDS))
def test_a_bouncing_switch_stops_the_axis_at_its_first_closure(tmp_path, backend):
    board, counts, report, edges = _home_again_and_again(tmp_path, backend)
    assert all(c.split(" Count ")[1].split()[:3] == ["X:0", "Y:0", "Z:0"] for c in counts)
    assert report["steps"]["x"] == 80 and report["steps"]["y"] == report["steps"]["z"] == 0
    for axis in "xyz":
        _, pos = trace.positions_of(*edges, board, axis)
        # The switch is at 0: no step ever goes past it, and every homing move (each
        # run of steps down) ends on it.
        assert pos.min() == 0, axis
        d = np.diff(pos)
        ends = pos[1:-1][(d[:-1] < 0) & (d[1:] > 0)].tolist() + [pos[-1]]
        assert ends == [0] * len(AWAY) + ([80] if axis == "x" else []), axis
