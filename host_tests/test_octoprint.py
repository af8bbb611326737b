"""OctoPrint, a real host, against the simulated printer over a pseudo-terminal: it
prints a short real slicer file (three tools, M117 messages) through its REST API, and
cancels a print during the M109 heat-up. OctoPrint lives in .venv-hosts/ (`make hosts`);
see octoprint_host.py for how it is set up. The figures go to out/octoprint_run.json."""
import json
import os
import re
import time

import pytest

from mixstep import paths
import octoprint_host as oh

GCODE = paths.ROOT / "testdata" / "short_3tool_m117_prusaslicer.gcode"
FIGURES = paths.ROOT / "out" / "octoprint_run.json"
FIRMWARE_NAME = "mixstep 0.1 (MicroPython)"
# Lines in OctoPrint's logs that mean the link or the firmware went wrong.
TROUBLE = ("Resend", "Error:", "Unexpected error", "Communication timeout",
           "Unknown command", " - ERROR - ")


@pytest.fixture
def need_octoprint():
    if oh.OCTOPRINT.exists():
        return
    reason = "OctoPrint %s is not installed in %s: run `make hosts`" % (
        oh.OCTOPRINT_VERSION, oh.HOSTS_VENV.name)
    if os.environ.get("MIXSTEP_REQUIRE_ALL") == "1":
        pytest.fail(reason + " (MIXSTEP_REQUIRE_ALL=1 asks for every test to run)")
    pytest.skip(reason)


def save_figures(key, figures):
    FIGURES.parent.mkdir(parents=True, exist_ok=True)
    try:
        data = json.loads(FIGURES.read_text())
    except (OSError, ValueError):
        data = {}
    data[key] = figures
    data["octoprint"] = oh.OCTOPRINT_VERSION
    FIGURES.write_text(json.dumps(data, indent=2) + "\n")


def gcode_commands(path):
    """The file's commands, comments and blank lines left out, as OctoPrint sends them."""
    out = []
    for raw in open(path):
        code = raw.split(";")[0].strip()
        if code:
            out.append(code)
    return out


def final_position(path):
    """Where X, Y and Z end, worked out from the file: G0/G1 in G90/G91, G92, and G28
    (the axes it names, all without one) homing to 0."""
    pos = {"X": 0.0, "Y": 0.0, "Z": 0.0}
    relative = False
    for code in gcode_commands(path):
        words = re.findall(r"([A-Z])([-+]?[0-9.]*)", code.upper())
        cmd = words[0][0] + words[0][1]
        args = {l: v for l, v in words[1:]}
        axes = [a for a in "XYZ" if a in args]
        if cmd in ("G0", "G1"):
            for a in axes:
                pos[a] = pos[a] + float(args[a]) if relative else float(args[a])
        elif cmd == "G28":
            for a in axes or "XYZ":
                pos[a] = 0.0
        elif cmd == "G92":
            for a in axes:
                pos[a] = float(args[a] or 0)
        elif cmd == "G90":
            relative = False
        elif cmd == "G91":
            relative = True
    return pos


def serial_entries(text):
    """serial.log as [(wall s, text)]: 'Send: ...', 'Recv: ...' and OctoPrint's notes."""
    out = []
    for line in text.splitlines():
        m = re.match(r"(\d{4}-\d\d-\d\d) (\d\d):(\d\d):(\d\d),(\d{3}) - (.*)$", line)
        if m:
            s = int(m.group(2)) * 3600 + int(m.group(3)) * 60 + int(m.group(4)) + \
                int(m.group(5)) / 1000
            out.append((s, m.group(6)))
    return out


def trouble(text):
    return [l for l in text.splitlines() if any(t in l for t in TROUBLE)]


def wait_for(condition, timeout_s, what, octoprint=None, period_s=0.2):
    """Poll condition() until it gives something true. With octoprint: fail at once if
    OctoPrint has dropped the connection (as it does on an Error: from the firmware),
    with the end of serial.log."""
    deadline = time.time() + timeout_s
    while True:
        value = condition()
        if value:
            return value
        if octoprint is not None:
            state = octoprint.state()
            if state.startswith(("Offline", "Error", "Closed")):
                tail = [l for l in octoprint.log_text("serial.log").splitlines()
                        if "Recv: T:" not in l][-15:]
                raise AssertionError("%s: OctoPrint is %r; serial.log ends:\n%s" % (
                    what, state, "\n".join(tail)))
        assert time.time() < deadline, "%s: not within %d s" % (what, timeout_s)
        time.sleep(period_s)


@pytest.fixture
def rig(tmp_path, need_octoprint):
    """Start the simulated printer and OctoPrint; the test connects and prints. Both are
    stopped at the end, OctoPrint disconnected first."""
    started = []

    def start(realtime, console_log=None):
        printer = oh.SimPrinter(realtime=realtime, console_log=console_log,
                                stderr_path=tmp_path / "printer.err")
        started.append(printer)
        octoprint = oh.OctoPrint(tmp_path / "octoprint")
        started.append(octoprint)
        octoprint.connect(printer.path)
        return printer, octoprint

    yield start
    for thing in reversed(started):
        if isinstance(thing, oh.OctoPrint):
            try:
                thing.disconnect()
            except (OSError, AssertionError):
                pass
        thing.stop()


def test_octoprint_prints_a_real_file(rig):
    printer, octoprint = rig(realtime=0)
    commands = gcode_commands(GCODE)
    poller = oh.Poller(octoprint)
    t0 = time.time()
    upload = octoprint.upload_and_print(GCODE)
    assert upload["done"] and upload["effectivePrint"], upload
    wait_for(lambda: "Print job done" in octoprint.log_text("octoprint.log")
             or "Print job failed" in octoprint.log_text("octoprint.log")
             or "Print job cancelled" in octoprint.log_text("octoprint.log"),
             150, "the print job ending", octoprint)
    job = wait_for(lambda: (lambda j: j if j["state"] == "Operational" else None)(
        octoprint.get("/api/job")), 30, "OctoPrint operational after the job")
    wall_s = time.time() - t0
    poller.stop()
    history = octoprint.get("/api/printer?history=true&limit=1000&exclude=sd,state")

    # The final position, asked through OctoPrint once the moves are done.
    octoprint.command("M400", "M114")
    serial = wait_for(lambda: (lambda t: t if re.search(r" - Recv: X:-?[0-9.]+ Y:", t)
                               else None)(octoprint.log_text("serial.log")),
                      30, "M114's answer in serial.log")
    log = octoprint.log_text("octoprint.log")
    entries = serial_entries(serial)
    sent = [t[len("Send: "):] for _, t in entries if t.startswith("Send: ")]
    job_sent = [s for s in sent if re.match(r"N\d+ ", s)]
    m114 = [t for _, t in entries if re.match(r"Recv: X:", t)][-1]
    got = {a: float(v) for a, v in re.findall(r"([XYZ]):(-?[0-9.]+)", m114.split("Count")[0])}
    want = final_position(GCODE)

    # The hot end as OctoPrint showed it while the job waited in M109 S200.
    heating = sorted({a for _, state, a, target in poller.samples
                      if state == "Printing" and target == 200 and a is not None and a < 195})
    history_heating = []  # tool0 in OctoPrint's history, from M109 S200 until near 200
    for h in history["temperature"].get("history", []):
        if "tool0" in h and h["tool0"]["target"] == 200:
            if h["tool0"]["actual"] >= 195:
                break
            history_heating.append(h["tool0"]["actual"])
    problems = trouble(serial) + trouble(log)
    save_figures("print", {
        "file": GCODE.name, "file_commands": len(commands), "wall_s": round(wall_s, 2),
        "octoprint_print_time_s": job["progress"]["printTime"],
        "octoprint_startup_s": round(octoprint.started_s, 2),
        "lines_sent": len(job_sent), "resends": sum("Resend" in l for l in problems),
        "errors": len([l for l in problems if "Resend" not in l]), "trouble": problems[:20],
        "m114": m114[len("Recv: "):], "expected": want,
        "heating_temperatures_polled": heating,
        "heating_temperatures_in_history": len(history_heating),
        "history_first_last": history_heating[:1] + history_heating[-1:],
    })

    assert job["progress"]["completion"] == 100, job
    assert "Print job done" in log
    assert 'Printer reports firmware name "%s"' % FIRMWARE_NAME in log
    # Every command of the file went out (with its line number), T1 and T2 included.
    assert len(job_sent) >= len(commands)
    for tool in ("T0", "T1", "T2"):
        assert any(re.match(r"N\d+ %s\*" % tool, s) for s in job_sent), tool
    assert any(re.match(r"N\d+ M117 Printing\.\.\.\*", s) for s in job_sent)
    assert sum(bool(re.match(r"N\d+ M117 Layer \d+\*", s)) for s in job_sent) == 6
    # The hot end rose through the wait, as OctoPrint showed it, not stuck at 22 C.
    assert len(history_heating) >= 5, history_heating
    assert history_heating == sorted(history_heating), history_heating
    assert history_heating[0] < 60 and history_heating[-1] > 150, history_heating
    # ... and GET /api/printer showed it between cold and hot at least once, live.
    assert any(25 < a < 195 for a in heating), poller.samples[:50]
    for axis in "XYZ":
        assert abs(got[axis] - want[axis]) < 0.006, (axis, m114, want)
    assert not problems, "\n".join(problems[:20])


def test_octoprint_cancel_ends_the_m109_wait(rig, tmp_path):
    """Cancel during M109. OctoPrint 1.11.8 (util/comm.py, cancelPrint) then sends M108
    when serial.abortHeatupOnCancel is on (the default); it goes out of band, while the
    M109 still waits for its ok, only when the firmware reported Cap:EMERGENCY_PARSER:1
    (otherwise it would queue behind the M109). The wait must end within 2 s of
    simulated time, read from the printer's console log."""
    console_log = tmp_path / "console.log"
    has_console_log = oh.serve_supports("--console-log")
    # In real time: the M109 S200 from 22 C then lasts about a minute, wall and simulated.
    printer, octoprint = rig(realtime=1, console_log=console_log if has_console_log else None)
    poller = oh.Poller(octoprint)
    octoprint.upload_and_print(GCODE)
    wait_for(lambda: re.search(r"Send: N\d+ M109 S200", octoprint.log_text("serial.log")),
             60, "M109 sent", octoprint)
    time.sleep(3)  # well into the heat-up
    before = [s for s in poller.samples if s[2] is not None][-1]
    t_cancel = time.time()
    octoprint.post("/api/job", {"command": "cancel"})
    wait_for(lambda: "Print job cancelled" in octoprint.log_text("octoprint.log"), 120,
             "the job cancelled", octoprint)
    wait_for(lambda: octoprint.get("/api/job")["state"] == "Operational", 120,
             "OctoPrint operational after the cancel")
    cancel_wall_s = time.time() - t_cancel
    poller.stop()
    serial = octoprint.log_text("serial.log")
    log = octoprint.log_text("octoprint.log")
    entries = serial_entries(serial)
    i109 = next(i for i, (_, t) in enumerate(entries) if re.match(r"Send: N\d+ M109", t))
    i108 = next((i for i, (_, t) in enumerate(entries) if re.match(r"Send: (N\d+ )?M108\b", t)),
                None)
    oks = [i for i, (_, t) in enumerate(entries[i109:], i109) if t.startswith("Recv: ok")]
    figures = {"hot_end_at_cancel": before[2], "cancel_to_operational_wall_s":
               round(cancel_wall_s, 2), "m108_sent": i108 is not None,
               "console_log": has_console_log}
    if i108 is not None:
        after = [entries[i][0] - entries[i108][0] for i in oks if i > i108][:2]
        figures["m108_to_next_oks_wall_s"] = [round(d, 3) for d in after]
    if has_console_log and console_log.exists():
        figures.update(console_cancel_figures(console_log))
    figures["trouble"] = (trouble(serial) + trouble(log))[:20]
    save_figures("cancel", figures)

    assert before[3] == 200 and before[2] < 190, before  # cancelled in the middle of the wait
    assert 'Printer reports firmware name "%s"' % FIRMWARE_NAME in log
    assert "supports emergency GCODEs" in log  # Cap:EMERGENCY_PARSER:1 seen
    assert i108 is not None, "OctoPrint sent no M108 on cancel"
    # Out of band: sent while the M109 still waited for its ok.
    assert oks and i108 < oks[0], entries[i109:i108 + 3]
    assert has_console_log, "mixstep serve has no --console-log: cannot time the wait"
    assert figures["m108_arrived"], "the printer's console log shows no M108"
    assert figures["m109_ok_after_m108_us"] is not None, "the M109 never got its ok"
    assert figures["m109_ok_after_m108_us"] <= 2_000_000, figures
    assert not figures["trouble"], "\n".join(figures["trouble"])


def console_cancel_figures(path):
    """From the printer's console log: when the M108 arrived, and when the ok answering
    the M109 went out. Every line received gets exactly one ok, so the ok for the k-th
    line received is the k-th ok sent, whichever order lines are run in: when the k-th
    ok (k counting up to the M108) has gone out, the M109 and the M108 both have theirs."""
    entries = oh.read_console_log(path)
    received = [(us, line) for us, d, line in entries if d == "<"]
    oks = [us for us, d, line in entries if d == ">" and line.startswith("ok")]
    k108 = next((k for k, (_, line) in enumerate(received) if re.search(r"\bM108\b", line)),
                None)
    k109 = next((k for k, (_, line) in enumerate(received) if re.search(r"\bM109\b", line)),
                None)
    figures = {"m108_arrived": k108 is not None, "m109_ok_after_m108_us": None,
               "console_lines": len(entries)}
    if k108 is None or k109 is None:
        return figures
    us108 = received[k108][0]
    figures["m109_wait_before_m108_us"] = us108 - received[k109][0]
    if len(oks) > k108:
        figures["m109_ok_after_m108_us"] = oks[k108] - us108
    return figures


def test_octoprints_feed_rate_and_flow_sliders_reach_the_printer(rig):
    """The control tab's sliders, through the REST API: OctoPrint sends M220 S and M221
    S, and the printer's M220/M221 reports (Marlin's words) then show them."""
    printer, octoprint = rig(realtime=0)
    octoprint.post("/api/printer/printhead", {"command": "feedrate", "factor": 125})
    octoprint.post("/api/printer/tool", {"command": "flowrate", "factor": 90})
    octoprint.command("M220", "M221")
    serial = wait_for(lambda: (lambda t: t if "Recv: echo:E0 Flow:" in t else None)(
        octoprint.log_text("serial.log")), 30, "M221's answer in serial.log", octoprint)
    sent = [t[len("Send: "):] for _, t in serial_entries(serial) if t.startswith("Send: ")]
    assert "M220 S125" in sent and "M221 S90" in sent, sent
    assert "Recv: FR:125%" in serial
    assert "Recv: echo:E0 Flow: 90%" in serial
    assert not trouble(serial), trouble(serial)


def test_octoprint_pauses_on_m600_shows_its_prompt_and_its_answer_resumes(rig, tmp_path):
    """The real file with M600 where its second layer starts, as a slicer's colour
    change puts it: on //action:paused OctoPrint pauses the job (its state Pausing: it
    turns Paused once the lines already sent are answered, and M600's `ok` comes when
    the change is done, as Marlin's, so that nothing a user sends while paused runs
    before it), its Action Command Prompt plugin shows M600's prompt, and answering it
    (the plugin's REST API, which force-sends M876 S0) resumes the print, which then
    completes."""
    lines = GCODE.read_text().splitlines()
    second_layer = [i for i, t in enumerate(lines) if t.startswith(";LAYER_CHANGE")][1]
    gcode = tmp_path / "short_3tool_m600.gcode"
    gcode.write_text("\n".join(lines[:second_layer] + ["M600"] + lines[second_layer:])
                     + "\n")
    printer, octoprint = rig(realtime=0)
    prompt_api = "/api/plugin/action_command_prompt"
    poller = oh.Poller(octoprint)
    upload = octoprint.upload_and_print(gcode)
    assert upload["done"] and upload["effectivePrint"], upload
    wait_for(lambda: octoprint.get("/api/printer?exclude=temperature,sd")["state"]["flags"][
        "pausing"], 120, "the job pausing on M600", octoprint)
    prompt = wait_for(lambda: octoprint.get(prompt_api), 30, "M600's prompt", octoprint)
    assert prompt["text"].startswith("Filament change") and prompt["choices"] == ["Continue"]
    time.sleep(1)  # the job stays paused while the prompt waits
    assert octoprint.get("/api/job")["state"].startswith("Paus")
    octoprint.post(prompt_api, {"command": "select", "choice": 0})
    wait_for(lambda: "Print job done" in octoprint.log_text("octoprint.log"), 150,
             "the print job ending", octoprint)
    job = wait_for(lambda: (lambda j: j if j["state"] == "Operational" else None)(
        octoprint.get("/api/job")), 30, "OctoPrint operational after the job")
    poller.stop()
    assert job["progress"]["completion"] == 100, job
    states = [state for _, state, _, _ in poller.samples]
    paused = states.index("Pausing")
    assert "Printing" in states[paused:]  # printing again after the answer
    serial = octoprint.log_text("serial.log")
    sent = [t[len("Send: "):] for _, t in serial_entries(serial) if t.startswith("Send: ")]
    assert any(re.match(r"(N\d+ )?M876 S0(\*\d+)?$", s) for s in sent), sent[-20:]
    assert "Printer signalled that it paused" in serial
    assert "Printer signalled that it resumed" in serial
    assert octoprint.get(prompt_api) is None  # the prompt closed
    assert not trouble(serial), trouble(serial)
