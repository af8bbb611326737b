"""Commands and replies as a host sees them, on the firmware running on the unix port."""
import numpy as np
import pytest

from mixstep import trace

E_SPM = 415


class Session:
    def __init__(self, sim_printer, tmp_path):
        self.edges = tmp_path / "run.edges"
        # These tests are about motion and mixing, not heating: allow cold extrusion.
        self.printer = sim_printer(edges_path=self.edges, heap_lock=True, cold_extrusion=True)
        self.replies = []

    def send(self, *lines):
        for line in lines:
            self.replies.append(self.printer.send(line))
        return self.replies[-1]

    def finish(self):
        self.report = self.printer.finish()
        return self.report["steps"]

    def edges_of(self, pin):
        t, g, v = trace.read_edges(self.edges)
        return t[g == pin], v[g == pin]


@pytest.fixture
def session(sim_printer, tmp_path):
    return Session(sim_printer, tmp_path)


def test_every_line_gets_one_ok_and_bad_lines_an_error_first(session):
    lines = ["G21", "; comment only", "", "G1 X1.2.3", "M9999", "G20", "G1 X" + "1" * 120,
             "G1 X\x01", "M163 S9 P1", "T16", "G4 P-1", "G1 F0", "M106 S300", "M104 S900",
             "G1 X5 F3000"]
    session.send(*lines)
    assert len(session.replies) == len(lines)
    for r in session.replies:
        assert r[-1] == "ok"
    got = {lines[i]: r[:-1] for i, r in enumerate(session.replies)}
    assert got["G21"] == [] and got["; comment only"] == [] and got[""] == []
    assert got["G1 X1.2.3"] == ["Error:malformed number after X"]
    assert got["M9999"] == ['echo:Unknown command: "M9999"']
    assert got["G20"] == ["Error:G20 (inch units) is not supported; use G21 (mm)"]
    assert got["G1 X" + "1" * 120] == ["Error:line longer than 96 bytes"]
    assert got["G1 X\x01"] == ["Error:byte 0x01 is a control character"]
    assert got["M163 S9 P1"] == ["Error:S9 out of range 0..5"]
    assert got["T16"] == ["Error:tool T16 out of range T0..T15"]
    assert got["G4 P-1"] == ["Error:dwell time must be >= 0"]
    assert got["G1 F0"][0].startswith("Error:feed rate F must be > 0")
    assert got["M106 S300"][0].startswith("Error:fan speed")
    assert got["M104 S900"][0].startswith("Error:temperature")
    assert session.finish()["x"] == 5 * 80  # the stream carried on after every error


def test_reports_in_marlin_form(session):
    session.send("G28", "G1 X10 Y5 Z1 F3000", "M109 S200", "M190 S60")
    (report,) = session.send("M105")
    words = report.split()
    assert words[0] == "ok" and words[1].startswith("T:") and words[2] == "/200.0"
    assert abs(float(words[1][2:]) - 200) < 3 and abs(float(words[3][2:]) - 60) < 3
    assert words[4] == "/60.0" and words[5].startswith("@:") and words[6].startswith("B@:")
    session.send("M400")
    assert session.send("M114")[0] == "X:10.00 Y:5.00 Z:1.00 E:0.00 Count X:800 Y:400 Z:400"
    assert session.send("M115")[0].startswith("FIRMWARE_NAME:mixstep")
    assert session.send("M109 S201")[-1] == "ok"
    session.finish()


def test_g28_from_power_up_makes_no_net_motion(session, board):
    session.send("G28", "M400")
    steps = session.finish()
    assert all(v == 0 for v in steps.values())
    rises, _ = session.edges_of(board["PINS"]["x_step"])
    assert len(rises[rises > 0]) == 0


def test_g28_named_axis_returns_it_to_its_endstop(session):
    session.send("G1 X10 Y20 F6000", "G28 X")
    assert session.send("M114")[0].startswith("X:0.00 Y:20.00")
    steps = session.finish()
    assert steps["x"] == 0 and steps["y"] == 1600


def test_mix_change_never_reaches_back_to_queued_moves(session):
    # No M400 between them: the E moves are still queued when T1 is parsed.
    session.send("G1 E5 F600", "T1", "G1 E10", "T7", "G1 E16")
    steps = session.finish()
    assert steps["e0"] == 5 * E_SPM + E_SPM  # T7 = equal mix of 6 drives: 1 mm each
    assert steps["e1"] == 5 * E_SPM + E_SPM
    assert [steps["e%d" % i] for i in range(2, 6)] == [E_SPM] * 4


def test_m163_m164_set_the_active_tool(session):
    session.send("M163 S0 P1", "M163 S1 P3", "M164", "G1 E4 F600")
    steps = session.finish()
    assert (steps["e0"], steps["e1"]) == (415, 1245)


def test_all_zero_mix_is_refused_and_printing_goes_on_with_the_old_mix(session):
    assert session.send("M163 S0 P0", "M164 S0")[0].startswith("Error:all-zero mix refused")
    session.send("G1 E2 F600")
    steps = session.finish()
    assert steps["e0"] == 2 * E_SPM


def test_retract_and_unretract_leave_every_drive_where_it_was(sim_printer, tmp_path):
    mix = ["M163 S0 P1", "M163 S1 P2", "M163 S2 P4", "M163 S3 P0.5", "M164", "M83"]
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    plain = Session(sim_printer, tmp_path / "a")
    plain.send(*mix, "G1 E3.1 F1200")
    retracted = Session(sim_printer, tmp_path / "b")
    retracted.send(*mix, "G1 E2.5 F1200", "G1 E-0.8 F2400", "G1 E0.8", "G1 E-2", "G1 E2.6")
    assert plain.finish() == retracted.finish()


def test_m92_e_sets_every_drive(session):
    session.send("M92 E100", "G1 E2 F600", "T3", "G1 E3")
    steps = session.finish()
    assert steps["e0"] == 200 and steps["e3"] == 100


def test_m92_x_keeps_the_position_in_mm_and_later_moves_use_it(session):
    """The axes stay where they are in millimetres when their steps/mm change: X's
    step is its position at the new steps/mm, also for moves that leave X alone."""
    session.send("G1 X10 F6000", "M400")
    assert session.send("M114")[0].endswith("Count X:800 Y:0 Z:0")
    session.send("M92 X100", "G1 Y5", "M400")
    assert session.send("M114")[0] == "X:10.00 Y:5.00 Z:0.00 E:0.00 Count X:800 Y:400 Z:0"
    session.send("G1 X12", "M400")
    assert session.send("M114")[0].endswith("Count X:1000 Y:400 Z:0")


def test_g4_dwells_in_the_queue(session):
    session.send("G1 X1 F600", "G4 P750", "G1 X2")
    steps = session.finish()
    assert steps["x"] == 160
    assert session.report["sim_us"] >= 750000


def test_m17_m18_drive_the_enable_pins(session, board):
    session.send("M17", "M18 X")
    session.finish()
    _, x = session.edges_of(board["PINS"]["x_enable"])
    _, y = session.edges_of(board["PINS"]["y_enable"])
    assert list(x) == [1, 0, 1]  # active low: off at #0, on at M17, off at M18 X
    assert list(y) == [1, 0, 1]  # ... and every driver off when the main loop ends


def test_a_move_turns_on_the_drivers_it_needs_while_others_stay_off(session, board):
    """Each move turns on its own axes' drivers, and E's the drives': also where a
    driver no move names (Z here) stays off, so not every driver is on."""
    session.send("G1 X1 Y1 F600", "G1 X2 E1", "M18 X", "G1 X3")
    session.finish()
    pins = board["PINS"]
    _, x = session.edges_of(pins["x_enable"])
    _, y = session.edges_of(pins["y_enable"])
    _, z = session.edges_of(pins["z_enable"])
    _, e5 = session.edges_of(pins["e5_enable"])
    assert list(x) == [1, 0, 1, 0, 1]  # active low: on at G1 X1, off at M18 X, on again
    assert list(y) == [1, 0, 1]
    assert list(e5) == [1, 0, 1]  # every drive, at G1 X2 E1: E may be mixed over all
    assert list(z) == [1]  # never on


def test_look_ahead_keeps_speed_through_collinear_segments(session, board):
    # The look-ahead alone: M205 B0 turns off Marlin's SLOWDOWN, which would slow the
    # moves planned while the queue fills (test_planner.py has it).
    session.send("M205 B0")
    session.send(*["G1 X%d F6000" % i for i in range(1, 11)])
    session.finish()
    t, v = session.edges_of(board["PINS"]["x_step"])
    rises = t[(v == 1) & (t > 0)]
    assert len(rises) == 800
    seconds = (rises[-1] - rises[0]) / 1e6
    # One trapezoid: 10 mm at 100 mm/s plus 100/1500 s of ramps = 0.167 s. Stopping at
    # every joint would take 10 triangles of 1 mm: 0.52 s.
    assert 0.15 < seconds < 0.19
    cruise_us = np.median(np.diff(rises))
    assert cruise_us == pytest.approx(1e6 / (100 * 80), abs=board["SETTINGS"]["tick_us"])


def test_positions_beyond_the_32_bit_range_are_refused_whole(session):
    """X Y Z are kept in 32-bit integers of nanometres: a word, target or G92 offset
    beyond +-1,073 mm is refused with the axis named, and a G92 refused sets nothing."""
    session.send("M211 S0", "G1 X10 Y20 F6000")
    beyond = "Error:%s beyond +-1073 mm: positions are kept in 32-bit integers of nanometres"
    assert session.send("G1 Y1100")[0] == beyond % "Y"
    assert session.send("G91", "G1 X1000")[0] == "ok"
    assert session.send("G1 X100")[0] == beyond % "X"
    assert session.send("G90", "G92 Y5 X-1000")[0] == beyond % "X"
    assert session.send("M114")[0].startswith("X:1010.00 Y:20.00 Z:0.00")
    assert session.send("G92 X5 Y7", "M114")[0].startswith("X:5.00 Y:7.00 Z:0.00")
    # E is not held to that range: G1 reads an E word beyond it in Python.
    session.send("M302 P1", "M82", "G92 E1500", "G1 E1500.5 F600", "M83", "G1 E-0.25")
    assert session.send("M114")[0].startswith("X:5.00 Y:7.00 Z:0.00 E:1500.25")


def test_m119_reports_endstops_and_soft_limits_guard_moves(session):
    assert session.send("M119") == ["Reporting endstop status", "x_min: TRIGGERED",
                                    "y_min: TRIGGERED", "z_min: TRIGGERED", "ok"]
    session.send("G1 X5 F3000", "M400")
    assert session.send("M119")[1] == "x_min: open"
    assert session.send("G1 X251")[0] == "Error:move to X251.000 is outside the soft limits 0..250 mm"
    assert session.send("G1 Z-1")[0].startswith("Error:move to Z-1.000 is outside the soft limits")
    session.send("M211 S0")
    assert session.send("G1 X251") == ["ok"]
    # M211 S0 holds while other settings change (each change applies them all).
    assert session.send("M203 X400", "M201 X2000") == ["ok"]
    assert session.send("M211") == ["echo:Soft endstops: Off", "ok"]
    assert session.send("G1 X252") == ["ok"]
    assert session.finish()["x"] == 252 * 80
