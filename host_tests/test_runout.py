"""Filament runout inputs on the firmware running on the unix port: an input that reads
the filament gone (the sim-only M7107) starts M600 for its drive between two lines once
the drive feeds, debounced, one change at a time; M412 turns the watching off and on
and M500 keeps it. The prints are a real PrusaSlicer file of three tools (T<n> is
drive n), streamed as a host streams it."""
import numpy as np

from mixstep import paths, trace

E_SPM = 415
GCODE = paths.ROOT / "testdata" / "short_3tool_m117_prusaslicer.gcode"
WAITING = "then M108 or Continue"  # M600's wait has begun
# M600's lengths for these tests: an unload and a load the steps tell apart.
CHANGE = ("M926 Ichange_unload_mm V20", "M926 Ichange_load_mm V25")


def file_lines():
    return GCODE.read_text().splitlines()


def stream(p, lines, on_wait):
    """Send lines as a host does, each after the last one's `ok`, then M400 twice. When
    a change's wait begins, on_wait(index of the line being sent, lines seen since it
    was sent or since the wait before) says what to send (M108 or M876, which answer `ok` in their turn). A
    change runs between two lines, after the `ok` of the one during which its drive
    fed: the first M400 runs the queued moves, and a change they start runs before the
    second; one more M400 follows a last line that saw a change, for a change that one
    started. Returns every line the firmware sent, and the indices of the lines during
    whose sending a change waited."""
    seen, waited = [], []
    lines = list(lines) + ["M400", "M400"]
    i = 0
    while i < len(lines):
        line = lines[i]
        p.proc.stdin.write(line.encode() + b"\n")
        start = len(seen)
        answers_left = 1
        while answers_left:
            text = p._readline()
            seen.append(text)
            if text == "ok" or text.startswith("ok "):
                answers_left -= 1
            elif WAITING in text:
                waited.append(i)
                for reply in on_wait(i, seen[start:]):
                    p.proc.stdin.write(reply.encode() + b"\n")
                    answers_left += 1
                start = len(seen)
        if i == len(lines) - 1 and waited and waited[-1] == i:
            lines.append("M400")
        i += 1
    return seen, waited


def resume(i, since):
    return ["M108"]


def at_time(times, positions, t_us):
    """An axis's position (positions_of) at time t_us."""
    k = np.searchsorted(times, t_us, side="right")
    return int(positions[k - 1]) if k else 0


def logged_times(log, text):
    """The simulated times at which the firmware sent a line holding text."""
    out = []
    for raw in open(log, "rb"):
        stamp, way, line = raw.decode("utf-8", "replace").rstrip("\n").split(" ", 2)
        if way == ">" and text in line:
            out.append(int(stamp))
    return out


def test_a_runout_mid_print_changes_that_drive_and_the_print_ends_as_m600_says(
        sim_printer, tmp_path, board):
    """Drive 0's input reads its filament gone while T0 prints: between two lines the
    printer retracts, raises Z, parks, unloads drive 0, tells the host (OctoPrint's
    //action:paused, and M600's prompt) and waits; M108 resumes. The input still reads
    gone, which starts no second change. The drives, X, Y and Z end as they do with
    M600 D0 sent by the host where the change came, and drive 0 fed the load less the
    unload more, and the purge, than the print alone."""
    lines = file_lines()
    flip = lines.index("T0") + 40  # well into T0's first stretch
    edges, log = tmp_path / "runout.edges", tmp_path / "console.log"
    p = sim_printer(edges_path=edges, console_log=log)
    for line in CHANGE:
        assert p.send(line) == ["ok"]
    seen, waited = stream(p, lines[:flip] + ["M7107 D0 S1"] + lines[flip:], resume)
    report = p.finish()
    assert [t for t in seen if t.startswith("Error")] == []
    assert len(waited) == 1 and waited[0] > flip
    assert sum("filament_runout" in t for t in seen) == 1
    at = seen.index("//action:paused filament_runout 0")
    assert seen[at + 1] == "echo:filament runout on drive 0: M600 D0"
    assert "//action:prompt_show" in seen[at:] and "//action:resumed" in seen[at:]

    # On the trace: when the wait began the head was parked (change_park_mm: X 10,
    # Y 10, Z 5 mm up) and drive 0 had retracted retract_mm (the mix, T0: drive 0)
    # and unloaded 20 mm since the queued moves ran out.
    t, g, v = trace.read_edges(edges)
    runout_us = logged_times(log, "filament_runout 0")[0]
    wait_us = logged_times(log, WAITING)[0]
    pos = {a: trace.positions_of(t, g, v, "sim", a) for a in ("x", "y", "z", "e0", "e2")}
    spm = board["SETTINGS"]["steps_per_mm"]
    assert at_time(*pos["x"], wait_us) == 10 * spm[0]
    assert at_time(*pos["y"], wait_us) == 10 * spm[1]
    assert at_time(*pos["z"], wait_us) - at_time(*pos["z"], runout_us) == 5 * spm[2]
    e0_times, e0 = pos["e0"]
    between = e0[(e0_times >= runout_us) & (e0_times <= wait_us)]
    assert at_time(*pos["e0"], wait_us) == between.max() - (2 + 20) * E_SPM
    assert at_time(*pos["e2"], wait_us) == at_time(*pos["e2"], runout_us)

    # The same print with the host's M600 D0 where the change came.
    q = sim_printer()
    for line in CHANGE:
        assert q.send(line) == ["ok"]
    at_line = waited[0] - 1  # the streamed list had M7107 in it
    _, host_waited = stream(q, lines[:at_line] + ["M600 D0"] + lines[at_line:], resume)
    assert host_waited == [at_line]
    assert report["steps"] == q.finish()["steps"]
    # And the print alone: drive 0 fed 25 - 20 mm more, and the 30 mm purge.
    alone = sim_printer()
    stream(alone, lines, resume)
    alone_steps = alone.finish()["steps"]
    assert report["steps"]["e0"] - alone_steps["e0"] == (25 - 20 + 30) * E_SPM
    for axis in ("x", "y", "z", "e1", "e2"):
        assert report["steps"][axis] == alone_steps[axis], axis


def test_a_drive_the_mix_leaves_out_changes_when_a_tool_first_feeds_it(sim_printer):
    """Drive 2's input reads gone while T0 prints: T0 gives drive 2 no share, so the
    print goes on; the change starts once T2 feeds it, right after the tool change."""
    lines = file_lines()
    flip = lines.index("T0") + 40
    t2 = lines.index("T2")
    assert flip < t2
    p = sim_printer()
    stop = t2 + 60
    seen, waited = stream(p, lines[:flip] + ["M7107 D2 S1"] + lines[flip:stop], resume)
    assert len(waited) == 1
    assert t2 + 1 < waited[0] < stop
    assert "//action:paused filament_runout 2" in seen
    assert [t for t in seen if t.startswith("Error")] == []
    p.finish()


def test_a_glitch_shorter_than_the_debounce_starts_nothing(printer):
    """Five checks in a row, at least 10 ms apart: 30 ms of "gone" are a glitch, 100 ms
    a runout."""
    glitch = ["M83", "M7107 D0 S1", "G4 P30", "M7107 D0 S0", "G1 X10 E5 F600"]
    seen, waited = stream(printer, glitch, resume)
    assert waited == [] and seen == ["ok"] * 7
    seen, waited = stream(printer, ["M7107 D0 S1", "G4 P100", "G1 X20 E5"], resume)
    assert waited == [4] and "//action:paused filament_runout 0" in seen
    printer.finish()


def test_m412_turns_the_watching_off_and_on_and_m500_keeps_it(sim_printer, tmp_path):
    config = tmp_path / "mixstep.cfg"
    p = sim_printer(cold_extrusion=True, config_path=config)
    assert p.send("M412") == ["echo:Filament runout ON", "ok"]
    # Drive 1 feeds with its input reading gone.
    seen, waited = stream(p, ["M412 S0", "M83", "M7107 D1 S1", "G4 P100", "T1",
                              "G1 X10 E5 F600"], resume)
    assert waited == [] and seen == ["ok"] * 8
    assert p.send("M412") == ["echo:Filament runout OFF", "ok"]
    assert p.send("M412 S5") == ["Error:S5 out of range 0..1", "ok"]
    assert p.send("M412") == ["echo:Filament runout OFF", "ok"]
    assert p.send("M500") == ["ok"]
    # On again: the input, still gone, is read afresh and the next feed changes it.
    seen, waited = stream(p, ["M412 S1", "G4 P100", "G1 X20 E5"], resume)
    assert waited == [4] and "//action:paused filament_runout 1" in seen
    p.finish()
    again = sim_printer(config_path=config)
    assert again.send("M412") == ["echo:Filament runout OFF", "ok"]
    assert "M926 Irunout_enabled V0" in " ".join(again.send("M925 Irunout_enabled"))
    again.finish()


def test_one_change_at_a_time_and_none_again_until_the_input_reads_present(printer):
    """Drives 0 and 1 run out together under a mix of both: drive 0's change comes
    first and waits alone; its purge feeds drive 1, whose change follows it. Neither
    input, still gone, starts another; drive 0's reads present, then gone, and its
    next feed changes it again."""
    drives = []

    def answer(i, since):
        drives.append([t for t in since if "filament_runout" in t])
        return ["M876 S0"]

    seen, waited = stream(printer, ["M567 P0 E1:1", "T0", "M83", "M7107 D0 S1",
                                    "M7107 D1 S1", "G4 P100", "G1 X10 E5 F600"], answer)
    assert drives == [["//action:paused filament_runout 0"],
                      ["//action:paused filament_runout 1"]]
    assert seen.count("//action:resumed") == 2
    seen, waited = stream(printer, ["G1 X20 E5"], answer)
    assert waited == []
    seen, waited = stream(printer, ["M7107 D0 S0", "G4 P20", "M7107 D0 S1", "G4 P100",
                                    "G1 X30 E5"], answer)
    assert drives[2:] == [["//action:paused filament_runout 0"]]
    printer.finish()


def test_m7107_refuses_a_drive_without_an_input_and_bad_words(printer):
    for line, error in (("M7107 D6 S1", "D6 out of range 0..5"),
                        ("M7107 D1 S2", "S2 out of range 0..1"),
                        ("M7107 D1", "missing parameter S")):
        assert printer.send(line) == ["Error:" + error, "ok"], line


def test_a_check_takes_nothing_from_the_heap(mp):
    """The watcher runs every 10 ms of the main loop: reading the inputs, counting,
    marking a drive out and starting its change take nothing from the heap (not even a
    frame)."""
    pending, drive, took = mp.script_json("runout_checks")
    assert pending and drive == 2
    assert took == [False] * 12


def test_an_input_that_reads_high_when_the_filament_is_gone(sim_printer):
    p = sim_printer(cold_extrusion=True, settings={"runout_active_high": 1})
    seen, waited = stream(p, ["M83", "M7107 D0 S1", "G4 P100", "G1 X10 E5 F600"], resume)
    assert waited == [5] and "//action:paused filament_runout 0" in seen
    p.finish()
