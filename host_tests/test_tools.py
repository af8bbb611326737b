"""Virtual tools: set with M164, M165 and M567, reported by M165 R, and kept across a
reboot with the configuration. On the firmware running on the unix port."""
import pytest

from mixstep.simprinter import SimPrinter

E_SPM = 415


def test_tools_survive_a_reboot_and_report_in_a_pasteable_form(sim_printer, tmp_path):
    cfg = tmp_path / "mixstep.cfg"
    p = sim_printer(config_path=cfg)
    assert p.send("M567 P3 E1:2:3")[0] == "echo:T3 mix set; M500 keeps it after a restart"
    p.send("T5")
    p.send("M165 A1 B3")  # the active tool, T5
    p.send("M163 S2 P0.5")
    p.send("M163 S3 P0.5")
    p.send("M164 S9 P1")  # saved at once, with everything else
    report = [l for l in p.send("M165 R") if l.startswith("M567")]
    p.finish()

    again = sim_printer(config_path=cfg)
    assert [l for l in again.send("M165 R") if l.startswith("M567")] == report
    assert report[3] == "M567 P3 E1:2:3:0:0:0"
    assert report[5] == "M567 P5 E1:3:0:0:0:0"
    assert report[9] == "M567 P9 E0:0:1:1:0:0"
    assert report[0] == "M567 P0 E1:0:0:0:0:0"  # untouched tools keep their defaults
    assert report[7] == "M567 P7 E1:1:1:1:1:1"
    again.send("M302 P1")
    again.send("T3")
    again.send("G1 E6 F600")
    steps = again.finish()["steps"]
    assert (steps["e0"], steps["e1"], steps["e2"]) == (E_SPM, 2 * E_SPM, 3 * E_SPM)


def test_pasting_the_report_back_restores_the_tools(sim_printer):
    p = sim_printer()
    p.send("M567 P2 E5:0:1")
    p.send("M567 P11 E0:0:0:0:2:7")
    report = [l for l in p.send("M165 R") if l.startswith("M567")]
    p.finish()
    q = sim_printer()
    for line in report:
        assert q.send(line)[-1] == "ok"
    assert [l for l in q.send("M165 R") if l.startswith("M567")] == report
    q.finish()


def test_bad_mixes_are_refused_and_change_nothing(sim_printer):
    p = sim_printer()
    before = p.send("M165 R")
    assert p.send("M567 P2 E0:0:0")[0].startswith("Error:all-zero mix refused")
    assert p.send("M567 P16 E1")[0] == "Error:tool T16 out of range T0..T15"
    assert p.send("M567 P2 E1:x")[0].startswith("Error:malformed number")
    assert p.send("M567 P2 E1:1:1:1:1:1:1")[0].startswith("Error:mix has 7 weights")
    assert p.send("M165 A-1")[0].startswith("Error:weight for drive 0")
    assert p.send("M165")[0].startswith("Error:M165 needs drive weights")
    assert p.send("M165 R") == before
    p.finish()


def test_drives_with_different_steps_per_mm_each_get_their_share_of_filament(printer):
    """Drive 1 geared 2:1, drive 2 at 100 steps/mm: a 1:1:2 mix over 12 mm of E gives
    3, 3 and 6 mm of filament, each within one step, with E still in millimetres."""
    p = printer
    p.send("M926 Idrive_steps_per_mm_1 V830")
    p.send("M926 Idrive_steps_per_mm_2 V100")
    p.send("M930")
    p.send("M567 P0 E1:1:2")
    p.send("M83")
    for _ in range(40):  # many short moves: the split must not drift
        p.send("G1 E0.3 F1200")
    p.send("G1 E-2")  # a retraction and back leaves every drive where it was
    p.send("G1 E2")
    assert p.send("M114")[0].startswith("X:0.00 Y:0.00 Z:0.00 E:12.00")
    steps = p.finish()["steps"]
    assert abs(steps["e0"] - 3 * E_SPM) <= 1
    assert abs(steps["e1"] - 3 * 830) <= 1
    assert abs(steps["e2"] - 6 * 100) <= 1


def retract_run(sim_printer, policy, lines):
    """The lines on a printer with cold extrusion allowed under retract_policy: the
    steps at the end."""
    p = sim_printer(cold_extrusion=True)
    p.send("M926 Iretract_policy V%d" % policy)
    p.send("M930")
    for line in lines:
        assert p.send(line)[-1] == "ok"
    return p.finish()["steps"]


def test_retraction_policy_follow_the_mix_or_all_drives_equal(sim_printer):
    # Slicer-style: retract on T0, change tool, unretract on T1.
    lines = ["M83", "G1 E5 F600", "G1 E-2 F2400", "T1", "G1 E2 F2400", "G1 E1 F600"]
    follow = retract_run(sim_printer, 0, lines)
    assert (follow["e0"], follow["e1"]) == (3 * E_SPM, 3 * E_SPM)
    equal = retract_run(sim_printer, 1, lines)
    # Every drive pulled back equally and pushed back equally: each ends where it was.
    assert [equal["e%d" % d] for d in range(6)] == [5 * E_SPM, E_SPM, 0, 0, 0, 0]


def test_g10_g11_firmware_retraction_is_exact_and_keeps_the_logical_e(sim_printer):
    for policy in (0, 1):
        steps = retract_run(sim_printer, policy, [
            "M567 P0 E1:2:3", "M83", "G1 E6 F600", "G10", "G1 X10 F3000", "G11", "G10", "G10",
            "G11", "M114"])
        assert [steps["e%d" % d] for d in range(3)] == [E_SPM, 2 * E_SPM, 3 * E_SPM], policy
        assert steps["x"] == 800


def counters(reply):
    """'echo:filament used mm e0:1.749 e1:...' -> [1.749, ...]"""
    assert reply.startswith("echo:filament used mm ")
    return [float(w.split(":")[1]) for w in reply.split()[3:]]


def test_filament_counters_per_drive_are_reported_and_kept_across_a_reboot(sim_printer, tmp_path):
    cfg = tmp_path / "mixstep.cfg"
    p = sim_printer(config_path=cfg, cold_extrusion=True)
    p.send("M567 P0 E1:3")
    p.send("M83")
    p.send("G1 E8 F600")
    p.send("G1 E-1")  # net of retractions
    used = counters(p.send("M167")[0])
    # 7 mm net at 1:3, each drive within one step (1/415 mm) of its share.
    assert abs(used[0] - 1.75) <= 1 / E_SPM and abs(used[1] - 5.25) <= 1 / E_SPM
    assert used[0] + used[1] == pytest.approx(7.0, abs=1e-9) and used[2:] == [0.0] * 4
    p.send("M500")
    p.finish()
    q = sim_printer(config_path=cfg, cold_extrusion=True)
    q.send("T2")
    q.send("G1 E2 F600")
    assert counters(q.send("M167")[0]) == used[:2] + [2.0] + [0.0] * 3
    assert counters(q.send("M167 R")[0]) == [0.0] * 6
    assert counters(q.send("M167")[0]) == [0.0] * 6
    q.finish()


from hypothesis import example, given, settings, strategies as st  # noqa: E402


@settings(max_examples=25, deadline=None)
@given(moves=st.lists(st.tuples(
    st.lists(st.integers(0, 9), min_size=1, max_size=6).filter(any),
    st.floats(-1.5, 3.0).filter(lambda e: abs(e) > 1e-3).map(lambda e: round(e, 4))),
    min_size=1, max_size=25))
# Drive 5's exact filament is 51.49998 steps: its nanometres, rounded up, are 51.5003.
@example(moves=[([0, 0, 0, 8, 9, 9], 0.5), ([0, 0, 0, 9, 9, 2], 1.7379), ([1], 1.0),
                ([0, 0, 0, 5, 9, 5], -0.7493), ([0, 0, 3, 9, 9, 1], -0.5629)])
def test_any_sequence_of_mixes_and_moves_gives_each_drive_its_exact_share(moves):
    """A mix change before every move (a gradient at its finest), with retractions:
    each drive ends within half a step of its exact filament, so nothing drifts. The
    filament is held in whole nanometres (the share below one carried), so a share a
    hair below a half step may round up: the bound is half a step and a nanometre."""
    # Its own printer: hypothesis runs the test many times, and a fixture once.
    p = SimPrinter()
    p.send("M302 P1")
    p.send("M83")
    ideal_mm = [0.0] * 6
    for weights, e in moves:
        assert p.send("M567 P0 E" + ":".join(str(w) for w in weights))[-1] == "ok"
        assert p.send("G1 E%s F1200" % e)[-1] == "ok"
        total = sum(weights)
        for i, w in enumerate(weights):
            ideal_mm[i] += e * w / total
    steps = p.finish()["steps"]
    for i in range(6):
        assert abs(steps["e%d" % i] - ideal_mm[i] * E_SPM) <= 0.5 + E_SPM * 1e-6, (
            i, steps, ideal_mm)


def test_a_long_purge_gives_each_drive_its_exact_share(printer):
    """60 mm in one move is 24,900 E steps, more than one block of the mixer's integer
    range: it goes in pieces, and each drive still ends within half a step."""
    p = printer
    p.send("M83")
    weights = [266, 565, 240, 197]
    assert p.send("M567 P0 E" + ":".join(map(str, weights)))[-1] == "ok"
    assert p.send("G1 X20 E60 F600")[-1] == "ok"
    steps = p.finish()["steps"]
    for i, w in enumerate(weights):
        assert abs(steps["e%d" % i] - 60 * E_SPM * w / sum(weights)) <= 0.5 + 1e-6, steps
    assert steps["x"] == 20 * 80


def test_palette_mixtures_of_mixtures(printer):
    """Ovenbird's mixing matrix: tools as amounts of the palette's mixtures (u . P)."""
    p = printer
    assert p.send("M168")[0] == "echo:palette 0: 1.0000:0.0000:0.0000:0.0000:0.0000:0.0000"
    replies = p.send("M168 1:1,0:0:1,2:0:2")  # rows normalised
    assert replies[:3] == ["echo:palette 0: 0.5000:0.5000:0.0000:0.0000:0.0000:0.0000",
                           "echo:palette 1: 0.0000:0.0000:1.0000:0.0000:0.0000:0.0000",
                           "echo:palette 2: 0.5000:0.0000:0.5000:0.0000:0.0000:0.0000"]
    p.send("M567 P3 U1:0:1")  # half of mixture 0, half of mixture 2
    assert [l for l in p.send("M165 R") if l.startswith("M567 P3 ")] == ["M567 P3 E2:1:1:0:0:0"]
    assert p.send("M567 P3 U1:1:1:1")[0] == "Error:4 amounts for a palette of 3 mixtures"
    assert p.send("M567 P3 U1:-1")[0] == "Error:mixture amounts must be >= 0, got -1.0"
    assert p.send("M168 1:x")[0].startswith("Error:malformed palette row")
    assert p.send("M168 0:0")[0].startswith("Error:all-zero mix refused")
    p.send("T3")
    p.send("G1 E8 F1200")
    steps = p.finish()["steps"]
    assert (steps["e0"], steps["e1"], steps["e2"]) == (4 * E_SPM, 2 * E_SPM, 2 * E_SPM)


def test_replay_policy_takes_back_exactly_the_latest_steps_of_each_drive(sim_printer):
    """Retract 2 mm after 1 mm of T0 then 1.5 mm of T1: the replay policy pulls back
    1.5 mm on drive 1 and 0.5 mm on drive 0, and the unretraction after a change to T2
    pushes exactly those back, where following the mix would pull T2's drive."""
    lines = ["M83", "G1 E1 F600", "T1", "G1 E1.5 F600", "G1 E-2 F2400", "T2",
             "G1 E2 F2400", "G1 E1 F600"]
    steps = retract_run(sim_printer, 2, lines)
    assert [steps["e%d" % d] for d in range(3)] == [E_SPM, 623, E_SPM]  # 622.5 rounds up
    # Mid-way, after the retraction: drive 1 gave back all its steps, drive 0 the rest.
    mid = retract_run(sim_printer, 2, lines[:5] + ["M114"])
    assert abs(mid["e0"] - 0.5 * E_SPM) <= 1 and (mid["e1"], mid["e2"]) == (0, 0)
    follow = retract_run(sim_printer, 0, lines[:5] + ["M114"])
    assert follow["e0"] == E_SPM and follow["e1"] < 0  # the mix pulls T1's drive only


def test_replay_policy_covers_mixes_wipes_and_firmware_retraction(sim_printer):
    # A 1:2:3 mix, then a wipe (retraction while moving) and G10/G11 across a tool change.
    steps = retract_run(sim_printer, 2, [
        "M567 P0 E1:2:3", "M83", "G1 X5 E6 F600", "G1 X8 E-0.5 F3000", "G10", "T1",
        "G1 X20 F3000", "G11", "G1 E0.5 F600", "G1 X25 E1 F600"])
    # Everything taken back was pushed back to the same drives; then T1 extruded 1 mm.
    assert [steps["e%d" % d] for d in range(3)] == [E_SPM, 2 * E_SPM + E_SPM, 3 * E_SPM]
    assert steps["x"] == 25 * 80
