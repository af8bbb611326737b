"""Gradients: Marlin's M166 along Z, and M169 with several stops along Z or along the
filament extruded, on the firmware running on the unix port."""
import pytest

E_SPM = 415


@pytest.fixture
def relative_printer(printer):
    """conftest's printer (cold extrusion allowed) with E relative (M83)."""
    printer.send("M83")
    return printer


def test_m166_blends_two_tools_along_z_finer_than_one_percent(relative_printer):
    p = relative_printer
    assert p.send("M166 A0 Z2 I0 J1 S1")[0].startswith("echo:gradient along Z on")
    ideal = [0.0, 0.0]
    for layer in range(1, 8):  # Z 0.3 .. 2.1: the last layer is past the end stop
        z = 0.3 * layer
        p.send("G1 Z%.1f F600" % z)
        p.send("G1 X%d E7 F1200" % (10 * (layer % 2)))
        f = min(z / 2, 1.0)
        ideal[0] += 7 * (1 - f)
        ideal[1] += 7 * f
    steps = p.finish()["steps"]
    # Each layer's mix is exact to 1/10000: well within a step per drive overall.
    assert abs(steps["e0"] - ideal[0] * E_SPM) <= 1.5
    assert abs(steps["e1"] - ideal[1] * E_SPM) <= 1.5
    assert steps["e0"] + steps["e1"] == 49 * E_SPM  # E neither loses nor gains a step


def test_gradient_resolution_is_a_hundredth_of_a_percent(relative_printer):
    """At Z 0.1 of a 0..3 mm gradient the mix is 1/30 = 3.33 % drive 1: Marlin's 1 %
    steps would give 3 %, 138 steps short over these 100 mm; 0.01 % is within 2."""
    p = relative_printer
    p.send("M166 A0 Z3 I0 J1 S1")
    p.send("G1 Z0.1 F600")
    for i in range(10):
        p.send("G1 X%d E10 F1200" % (10 * (i % 2)))
    steps = p.finish()["steps"]
    assert abs(steps["e1"] - 100 * E_SPM / 30) <= 2, steps
    assert steps["e0"] + steps["e1"] == 100 * E_SPM


def test_m169_four_stops_along_z(relative_printer):
    p = relative_printer
    p.send("M169 Z0:0,1:1,2:2,3:0")
    ideal = [0.0] * 3
    stops = [(0.0, 0), (1.0, 1), (2.0, 2), (3.0, 0)]
    for layer in range(12):  # Z 0.125 .. 2.875, 5 mm of filament each
        z = 0.125 + 0.25 * layer
        p.send("G1 Z%.3f F600" % z)
        p.send("G1 X%d E5 F1200" % (10 * (layer % 2)))
        k = int(z)
        f = z - k
        ideal[stops[k][1]] += 5 * (1 - f)
        ideal[stops[k + 1][1]] += 5 * f
    steps = p.finish()["steps"]
    for d in range(3):
        assert abs(steps["e%d" % d] - ideal[d] * E_SPM) <= 1.5, (d, steps, ideal)
    assert sum(steps["e%d" % d] for d in range(6)) == 60 * E_SPM


def test_m166_alias_tool_and_s0(relative_printer):
    p = relative_printer
    p.send("M166 A0 Z1 I0 J1 S1 T7")
    assert p.send("M166")[0] == ("echo:gradient along Z on for T7: "
                                 "0:1.0000:0.0000:0.0000:0.0000:0.0000:0.0000, "
                                 "1:0.0000:1.0000:0.0000:0.0000:0.0000:0.0000")
    p.send("G1 Z0.25 F600")
    p.send("T7")
    p.send("G1 X10 E8 F1200")  # the gradient: a quarter of the way to T1
    p.send("T2")
    p.send("G1 X0 E4")  # T2 is not the alias: its own mix
    p.send("T7")
    assert p.send("M166 S0")[0].startswith("echo:gradient along Z off")
    p.send("G1 X10 E6")  # T7's own mix: all six drives equally
    steps = p.finish()["steps"]
    assert (steps["e0"], steps["e1"]) == (6 * E_SPM + E_SPM, 2 * E_SPM + E_SPM)
    assert steps["e2"] == 4 * E_SPM + E_SPM


def test_m169_four_stops_along_the_extruded_length(relative_printer):
    p = relative_printer
    p.send("M169 E0:0,10:1,20:2,30:0")
    for _ in range(60):
        p.send("G1 E0.5 F1200")
    steps = p.finish()["steps"]
    # Linear blends between stops: each drive gets 10 mm of the 30 mm.
    for d in range(3):
        assert abs(steps["e%d" % d] - 10 * E_SPM) <= 2, steps
    assert sum(steps["e%d" % d] for d in range(6)) == 30 * E_SPM


def test_gradient_alias_tool_and_switching_off(relative_printer):
    p = relative_printer
    p.send("M169 T7 Z0:0,1:1")
    p.send("G1 Z0.5 F600")
    p.send("T2")
    p.send("G1 E4 F1200")  # T2 is not the alias: its own mix
    p.send("T7")
    p.send("G1 E4 F1200")  # the gradient at Z0.5: half drive 0, half drive 1
    assert p.send("M169")[0] == "echo:no gradient"
    p.send("G1 E6 F1200")  # T7's own mix again: all six drives equally
    steps = p.finish()["steps"]
    assert steps["e2"] == 4 * E_SPM + E_SPM
    assert (steps["e0"], steps["e1"]) == (2 * E_SPM + E_SPM, 2 * E_SPM + E_SPM)


@pytest.mark.parametrize("line, reason", [
    ("M169 Z0:0", "at least 2 stops"),
    ("M169 Z1:0,1:1", "stops must increase"),
    ("M169 Z0:0,1:99", "tool T99 out of range"),
    ("M169 Z0-0", "malformed stop list"),
    ("M166 A0 Z2 I0", "missing parameter J"),
    ("M166 S1", "no gradient set"),
])
def test_bad_gradients_are_refused(relative_printer, line, reason):
    p = relative_printer
    reply = p.send(line)
    assert reply[0].startswith("Error:") and reason in reply[0], reply
    p.finish()
