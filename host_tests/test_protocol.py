"""The host protocol under attack: a hostile client, floods, M112 on a full queue, and
Hypothesis fuzzing of the intake, the parser and the protocol checks.

The oracle for "executed exactly once" is motion: every move a test sends is relative
(G91) and lands on a step count the simulated chip counts itself, so a lost line shows
as missing steps and a line run twice as extra steps."""
import fnmatch
import json
import re
import socket
import sys
import threading
import time

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

from mixstep import paths, serve, trace
from mixstep.simprinter import SIM_MAIN, SimPrinter
from net import free_port

X_SPM = 80  # steps/mm on X and Y of the simulated board
LINE_BYTES = 96
STEP_PINS = (0, 2, 4)  # x, y, z STEP gpios
HALT_BROADCAST = "Error:emergency stop (M112)"

# How many hostile lines the tests below send; test_zz_counts checks and prints them.
COUNTS = {"hostile": 0, "fuzz": 0}


def checksum(text):
    cs = 0
    for b in text.encode("latin-1"):
        cs ^= b
    return cs


def numbered(n, command):
    """A line as printcore sends it: N<n> <command>*<xor of the bytes before *>."""
    body = "N%d %s" % (n, command)
    return "%s*%d" % (body, checksum(body))


def group(lines):
    """Output lines -> answers: each answer is every line up to and including its ok."""
    answers, cur = [], []
    for text in lines:
        cur.append(text)
        if text == "ok" or text.startswith("ok "):
            answers.append(cur)
            cur = []
    return answers, cur


def count_lines(data):
    return data.count(b"\n")


class Stdio:
    """The simulated printer over its process pipes, driven by raw bytes."""

    def __init__(self, **kw):
        self.printer = SimPrinter(**kw)
        self.proc = self.printer.proc

    def ask(self, raw):
        """One line (bytes or str, newline added), waiting for its answer."""
        if isinstance(raw, str):
            raw = raw.encode("latin-1")
        COUNTS["hostile"] += 1
        self.proc.stdin.write(raw + b"\n")
        out = []
        while True:
            out.append(self.printer._readline())
            if out[-1] == "ok" or out[-1].startswith("ok "):
                return out

    def flood(self, data, count="hostile"):
        """Write everything at once without waiting for any ok, then close the stream;
        returns (answers, report). A thread reads meanwhile, as a real host would."""
        COUNTS[count] += count_lines(data)
        out = []
        reader = threading.Thread(target=lambda: out.extend(
            r.decode("ascii", "replace").rstrip("\r\n") for r in self.proc.stdout))
        reader.start()
        self.proc.stdin.write(data)
        self.proc.stdin.close()
        reader.join(120)
        assert not reader.is_alive(), "firmware did not finish the flood"
        assert self.proc.wait(30) == 0
        sim = [l for l in out if l.startswith("//sim ")]
        assert len(sim) == 1, out[-5:]
        answers, rest = group([l for l in out if not l.startswith("//sim ")])
        assert rest == [], "lines after the last ok: %r" % rest
        return answers, json.loads(sim[0][6:])


# ---------------------------------------------------------------------------------
# 1. Hostile client over stdin, one line at a time
# ---------------------------------------------------------------------------------

def test_numbered_lines_checksums_resend_and_repeats():
    host = Stdio()
    moves = 0  # G1 X1 lines that must run: 80 X steps each

    def expect(raw, want):
        got = host.ask(raw)
        assert got == want, "%r -> %r, expected %r" % (raw, got, want)

    def resend(reason, last):
        return ["Error:%s, Last Line: %d" % (reason, last), "Resend: %d" % (last + 1), "ok"]

    expect(numbered(-1, "M110 N-1"), ["ok"])  # printcore's opening line
    expect(numbered(0, "G91"), ["ok"])
    expect(numbered(1, "G1 X1 F3000"), ["ok"])
    moves += 1
    expect(numbered(1, "G1 X1 F3000"), ["ok"])  # repeated: acknowledged, not run again
    good2 = numbered(2, "G1 X1")
    body2 = good2.split("*")[0]
    # Wrong checksums: off by one, empty, not a number, and a payload byte flipped in
    # transit under the right checksum of the original.
    expect("%s*%d" % (body2, checksum(body2) ^ 1), resend("checksum mismatch", 1))
    expect(body2 + "*", resend("checksum mismatch", 1))
    expect(body2 + "*x7", resend("checksum mismatch", 1))
    expect(good2.replace("X1", "X7"), resend("checksum mismatch", 1))
    expect(numbered(3, "G1 X1"), resend("Line Number is not Last Line Number+1", 1))
    expect(body2, resend("No Checksum with line number", 1))
    expect("G1 X1*%d" % checksum("G1 X1"), resend("No Line Number with checksum", 1))
    expect(good2, ["ok"])
    moves += 1
    expect(good2, ["ok"])  # the host resends a line it thinks was lost
    expect(numbered(1, "G1 X1 F3000"), ["ok"])  # an older one again
    # Lines that arrive intact but are bad G-code use up their number: no Resend.
    expect(numbered(3, "M9999"), ['echo:Unknown command: "M9999"', "ok"])
    expect(numbered(4, "G1 X999"),
           ["Error:move to X1001.000 is outside the soft limits 0..250 mm", "ok"])
    expect(numbered(5, "M163 S9 P1"), ["Error:S9 out of range 0..5", "ok"])
    expect(numbered(6, "G1 X1.2.3"), ["Error:malformed number after X", "ok"])
    expect(numbered(7, "G1 X1"), ["ok"])
    moves += 1
    # M110 renumbers; the line it rides on may carry any number.
    expect(numbered(50, "M110 N100"), ["ok"])
    expect(numbered(101, "G1 X1"), ["ok"])
    moves += 1
    expect(numbered(100, "G1 X1"), ["ok"])  # below the last line: a repeat
    expect(numbered(103, "G1 X1"), resend("Line Number is not Last Line Number+1", 101))
    expect(numbered(102, "G1 X1"), ["ok"])
    moves += 1
    host.ask("M400")
    assert host.ask("M114")[0].endswith("Count X:%d Y:0 Z:0" % (moves * X_SPM))
    assert host.printer.finish()["steps"]["x"] == moves * X_SPM


def _repeat_and_skip_of_bad_lines():
    host = Stdio()
    host.ask(numbered(1, "G91"))
    # A line that was already answered, sent again because the host missed the answer:
    # acknowledged, not parsed and judged again.
    bad2 = numbered(2, "G1 X1.2.3")
    assert host.ask(bad2) == ["Error:malformed number after X", "ok"]
    assert host.ask(numbered(3, "G1 X1")) == ["ok"]
    got_repeat = host.ask(bad2)
    # Line 4 lost: line 5 must be answered with Resend: 4, whatever its G-code says.
    got_skip = host.ask(numbered(5, "G1 X1.2.3"))
    assert host.ask(numbered(4, "G1 X1")) == ["ok"]
    assert host.printer.finish()["steps"]["x"] == 2 * X_SPM  # each G1 X1 once
    return got_repeat, got_skip


def test_line_number_checked_before_the_gcode_is_judged():
    got_repeat, got_skip = _repeat_and_skip_of_bad_lines()
    assert got_repeat == ["ok"]
    assert got_skip == ["Error:Line Number is not Last Line Number+1, Last Line: 3",
                        "Resend: 4", "ok"]


def test_bare_m110_keeps_the_line_number():
    host = Stdio()
    for n in range(1, 4):
        assert host.ask(numbered(n, "G21")) == ["ok"]
    assert host.ask("M110") == ["ok"]
    assert host.ask(numbered(4, "G21")) == ["ok"]
    host.printer.finish()


# Bad lines that each hold a relative X move: if any of them ran, X would move.
BAD_LINES = [
    (b"G1 X1 " + b" " * (LINE_BYTES - 5), "Error:line longer than 96 bytes"),
    (b"G1 X1" + b"0" * 200, "Error:line longer than 96 bytes"),
    (b"G1 X1\x00", "Error:byte 0x00 is a control character"),
    (b"\x00G1 X1", "Error:byte 0x00 is a control character"),
    (b"G1 X1\x7f", "Error:byte 0x7f is a control character"),
    (b"G1 X1\x1b[2J", "Error:byte 0x1b is a control character"),
    # Bytes above 127 are kept for text (UTF-8), and refused in words.
    (b"G1 X1\x80", "Error:malformed number after X"),
    (b"G1 \xffX1", "Error:unexpected byte 0xff"),
    (b"G1 X1 \xc3\xa4", "Error:unexpected byte 0xc3"),
    (bytes(range(128, 256)), "Error:line longer than 96 bytes"),
    (bytes(range(128, 200)), "Error:unexpected byte 0x80"),
    (b"\xfe\xed\xfa\xce" * 40, "Error:line longer than 96 bytes"),
    (b"G1 X1.2.3", "Error:malformed number after X"),
    (b"G1 X--1", "Error:malformed number after X"),
    (b"G1 X-", "Error:malformed number after X"),
    (b"G1 X", "Error:parameter X needs a number"),
    (b"G1 X1 X1", "Error:parameter X given twice"),
    (b"G1 X1 F0", "Error:feed rate F must be > 0, got 0.0"),
    (b"G1 X1 F-5", "Error:feed rate F must be > 0, got -5.0"),
    (b"G1 X1 (comment", "Error:unclosed ( comment"),
    (b"G1 X9999999999", "Error:number too long for X"),
    # Relative moves, so the target named in the message depends on where X is.
    (b"G1 X300", "Error:move to X3??.000 is outside the soft limits 0..250 mm"),
    (b"G1 X-50", "Error:move to X-*.000 is outside the soft limits 0..250 mm"),
    (b"Q1 X1", "Error:line must start with G, M or T, not Q"),
    (b"1 X1", "Error:unexpected character '1'"),
    (b"G1.5 X1", "Error:unsupported command G1.5"),
    (b"G X1", "Error:G needs a number"),
    (b"M163 S1", "Error:missing parameter P"),
    (b"M163 S9 P1", "Error:S9 out of range 0..5"),
    (b"T16", "Error:tool T16 out of range T0..T15"),
    (b"M106 S300", "Error:fan speed S300.0 out of range 0..255"),
    (b"G20", "Error:G20 (inch units) is not supported; use G21 (mm)"),
]


def matches(answer, error):
    """answer == [error, "ok"], error being a pattern (fnmatch) for soft-limit texts."""
    return len(answer) == 2 and answer[1] == "ok" and fnmatch.fnmatchcase(answer[0], error)


def test_bad_lines_get_one_error_each_and_do_not_run():
    host = Stdio()
    assert host.ask("G91") == ["ok"]
    moves = 0
    for raw, error in BAD_LINES:
        got = host.ask(raw)
        assert matches(got, error), (raw, got)
        # A good line after each bad one: the stream goes on and nothing leaked over.
        assert host.ask("G1 X1 F6000") == ["ok"], raw
        moves += 1
    # An unknown M-code is passed over, as Marlin does; an unknown G-code is motion the
    # file needed, refused with an error.
    for raw in (b"M9999", b"M9999 X1"):
        assert host.ask(raw) == ['echo:Unknown command: "M9999"', "ok"]
    lacks = ('Error:Unknown command: "%s" (a motion command this firmware lacks; the '
             'print would go wrong without it)')
    assert host.ask(b"G9999") == [lacks % "G9999", "ok"]
    # A number past 9999, whose key another letter's command shares, named as sent.
    assert host.ask(b"G552250000 G0 G0") == [lacks % "G552250000", "ok"]
    assert host.ask(b"M552250000 G0 G0") == ['echo:Unknown command: "M552250000"', "ok"]
    # Edges of what is fine: exactly 96 stored bytes, long comments (not stored), tabs,
    # CR LF, lower case, spaces inside words, blank and comment-only lines.
    fine = [b"G1 X1" + b" " * (LINE_BYTES - 5), b"G1 X1 ;" + b"c" * 300, b"G1\tX1\r",
            b"g1 x1", b"G1 X 1", b"", b"   ", b"; only a comment \xff\x00", b"(hi) G1 X1"]
    for raw in fine:
        assert host.ask(raw) == ["ok"], raw
    moves += 6
    host.ask("M400")
    assert host.ask("M114")[0] == "X:%d.00 Y:0.00 Z:0.00 E:0.00 Count X:%d Y:0 Z:0" % (
        moves, moves * X_SPM)
    assert host.printer.finish()["steps"]["x"] == moves * X_SPM


def test_unterminated_last_line_still_gets_an_answer():
    # A G-code file whose last line lacks a newline, streamed and closed: the line must
    # either run or be refused, never vanish ("nothing is dropped silently").
    host = Stdio()
    host.ask("G91")
    host.proc.stdin.write(b"G1 X5 F6000")
    COUNTS["hostile"] += 1
    host.proc.stdin.close()
    out = [r.decode("ascii", "replace").rstrip() for r in host.proc.stdout]
    host.proc.wait(30)
    answers = [l for l in out if l == "ok" or l.startswith("Error:")]
    steps = [l for l in out if l.startswith("//sim ")][0]
    # Either it ran (ok, and X moved) or it was refused with an Error and an ok.
    assert "ok" in answers, "no answer to the unterminated line; output: %r" % out
    assert ('"x": %d' % (5 * X_SPM)) in steps or any(l.startswith("Error:") for l in answers)


# ---------------------------------------------------------------------------------
# 2. Floods: hundreds of lines without waiting for ok
# ---------------------------------------------------------------------------------

def move_stream(first, last, axis="X", skip=(), corrupt=()):
    out = []
    for n in range(first, last + 1):
        if n in skip:
            continue
        line = numbered(n, "G1 %s0.1 F3000" % axis)
        if n in corrupt:
            line = line.replace("%s0.1" % axis, "%s0.7" % axis)  # checksum now wrong
        out.append(line)
    return out


def test_flood_over_stdin_with_repeats_gaps_and_resends():
    n_moves = 300
    lines = [numbered(0, "M110 N0"), "G91"]
    # Round 1: every line twice in a row (the copy must be acknowledged, not run),
    # line 100 corrupted in transit (both copies) and line 150 lost.
    for line in move_stream(1, n_moves, skip={150}, corrupt={100}):
        lines += [line, line]
    # Round 2: the host resends from the line the firmware asked for, twice over (a
    # host that resent too early), then M400 so the queue drains before M114.
    lines += move_stream(100, n_moves) + move_stream(100, n_moves) + ["M400", "M114"]
    host = Stdio()
    answers, report = host.flood(("\n".join(lines) + "\n").encode())
    assert len(answers) == len(lines)  # one answer per line: none lost, none doubled
    resends = [a for a in answers if len(a) == 3 and a[1] == "Resend: 100"]
    assert [a[0] for a in resends[:2]] == ["Error:checksum mismatch, Last Line: 99"] * 2
    # Everything after the corrupt line in round 1 (101..300 less the lost 150, twice)
    # is out of sequence and asked for again.
    assert [a[0] for a in resends[2:]] == [
        "Error:Line Number is not Last Line Number+1, Last Line: 99"] * (2 * 199)
    others = [a for a in answers[:-1] if a not in resends]
    assert others == [["ok"]] * len(others)
    assert answers[-1][0].endswith("Count X:%d Y:0 Z:0" % (n_moves * 8))
    assert report["steps"]["x"] == n_moves * 8  # every move exactly once


def test_flood_of_unnumbered_lines_mixed_with_garbage():
    n_moves = 400
    lines = [b"G91"]
    bad = [raw for raw, _ in BAD_LINES]
    for i in range(n_moves):
        lines.append(b"G1 Y0.1 F6000")
        lines.append(bad[i % len(bad)])
    host = Stdio()
    answers, report = host.flood(b"\n".join(lines) + b"\n")
    assert len(answers) == len(lines)
    for i, a in enumerate(answers[1:]):
        if i % 2 == 0:
            assert a == ["ok"]
        else:
            assert matches(a, BAD_LINES[(i // 2) % len(BAD_LINES)][1]), a
    assert report["steps"]["y"] == n_moves * 8 and report["steps"]["x"] == 0


# ---------------------------------------------------------------------------------
# 3. The TCP console: one hostile connection, then two flooding at once
# ---------------------------------------------------------------------------------

class TcpHost:
    def __init__(self, port):
        deadline = time.time() + 20
        while True:
            try:
                self.sock = socket.create_connection(("127.0.0.1", port), timeout=60)
                break
            except OSError:
                assert time.time() < deadline, "no TCP console on port %d" % port
                time.sleep(0.05)
        self.f = self.sock.makefile("rb")
        assert self.readline() == "start"

    def readline(self):
        raw = self.f.readline()
        assert raw, "connection closed by the printer"
        return raw.decode("ascii", "replace").rstrip("\r\n")

    def answers(self, n):
        got, cur = [], []
        while len(got) < n:
            cur.append(self.readline())
            if cur[-1] == "ok" or cur[-1].startswith("ok "):
                got.append(cur)
                cur = []
        return got

    def send_all(self, data):
        """Send from a thread while the caller reads: a host that never waits."""
        COUNTS["hostile"] += count_lines(data)
        t = threading.Thread(target=self.sock.sendall, args=(data,))
        t.start()
        return t

    def ask(self, line):
        self.send_all(line.encode("latin-1") + b"\n").join()
        return self.answers(1)[0]

    def close(self):
        self.sock.close()


@pytest.fixture
def tcp_printer():
    port = free_port()
    proc = serve.serve_tcp("127.0.0.1:%d" % port, realtime=0, announce=lambda s: None)
    yield port
    proc.terminate()
    proc.wait(10)


def test_tcp_hostile_client_and_two_flooding_connections(tcp_printer):
    a = TcpHost(tcp_printer)
    assert a.ask("G91") == ["ok"]
    for raw, error in BAD_LINES:
        a.send_all(raw + b"\n").join()
        got = a.answers(1)[0]
        assert matches(got, error), (raw, got)
    assert a.ask(numbered(5, "G1 X1")) == [
        "Error:Line Number is not Last Line Number+1, Last Line: 0", "Resend: 1", "ok"]
    assert a.ask("N1 G1 X1*%d" % (checksum("N1 G1 X1") ^ 4)) == [
        "Error:checksum mismatch, Last Line: 0", "Resend: 1", "ok"]
    # A client that sends garbage and a half line, then hangs up: the printer drops that
    # connection and keeps serving the others. The half line may have been cut short
    # by the hang-up ("G1 X100" of "G1 X1000"?), so it must not run.
    rude = TcpHost(tcp_printer)
    rude.send_all(b"\x00\xff garbage\nG1 X100 F6000").join()
    assert rude.answers(1) == [["Error:byte 0x00 is a control character", "ok"]]
    rude.close()

    b = TcpHost(tcp_printer)
    n = 300  # b relies on a's G91: the modal state is the printer's, shared
    floods = []
    for host, axis in ((a, "X"), (b, "Y")):
        lines = [numbered(0, "M110 N0")]
        for line in move_stream(1, n, axis=axis, skip={100}):
            lines += [line, line]  # every line twice: the copy is acknowledged only
        lines += move_stream(100, n, axis=axis)  # the resend after the gap
        floods.append((host, lines, host.send_all(("\n".join(lines) + "\n").encode())))
    for host, lines, sender in floods:
        answers = host.answers(len(lines))
        sender.join()
        resends = [x for x in answers if len(x) == 3 and x[1] == "Resend: 100"]
        assert len(resends) == 2 * (n - 100)
        assert sum(1 for x in answers if x == ["ok"]) == len(lines) - len(resends)
    a.ask("M400")
    b.ask("M400")
    # Each connection's lines ran exactly once; the rude half line never ran.
    for host in (a, b):
        assert host.ask("M114")[0].endswith("Count X:%d Y:%d Z:0" % (n * 8, n * 8))
    a.close()
    b.close()


# ---------------------------------------------------------------------------------
# 4. M112 while the planner queue is full
# ---------------------------------------------------------------------------------

PAD = 16  # every line 16 bytes: the 256-byte receive ring holds exactly 16 of them


def run_m112_stream(mp, edges, lines):
    """The lines, padded, through the real firmware and simulated chip with a probe
    that prints when M112 was seen (upy/protocol_m112_probe.py): those moments, the
    answers, and the times of every STEP edge and of X's."""
    data = "".join(l.ljust(PAD - 1) + "\n" for l in lines).encode()
    COUNTS["hostile"] += len(lines)
    out = mp.script("protocol_m112_probe", edges, SIM_MAIN, stdin=data,
                    heap="2M").splitlines()
    assert out[0] == "start"
    seen = [int(l.split("=")[1]) for l in out if l.startswith("//m112 ")]
    answers, rest = group([l for l in out[1:] if not l.startswith("//")])
    assert rest == []
    t, g, v = trace.read_edges(edges)
    rises = (v == 1) & (t > 0) & np.isin(g, STEP_PINS)
    return seen, answers, t[rises], t[rises & (g == 0)]


@pytest.mark.parametrize("k", [4, 12])
def test_m112_stops_motion_at_once_with_a_full_queue(mp, tmp_path, k):
    # 5 mm moves at 100 mm/s in one direction: collinear, so the axis cruises through
    # the junctions (8000 steps/s). With every line 16 bytes the firmware takes M112
    # into its ring as the move k lines ahead of it in the queue starts, with 16 moves
    # still queued or waiting in the ring ahead of it: in order, it would run only
    # after all of those.
    move = "G1 X5 F6000"
    before = 32 + k
    lines = ["G91"] + [move] * before + ["M112"] + [move] * 5 + ["M114", "G1 X1", "M999",
                                                                   "G1 X1", "M400", "M114"]
    seen, answers, step_t, x_t = run_m112_stream(mp, tmp_path / "m112.edges", lines)
    assert len(answers) == len(lines)
    assert len(seen) >= 1
    seen_us = seen[0]
    # Steps before the final M999 + G1 X1: the halt position is where X stood then.
    halt_steps = len(x_t) - X_SPM
    halt_t = x_t[:halt_steps]
    last_step_us = int(halt_t[-1])
    stop_us = last_step_us - seen_us
    # The next step was due 125 us after the last one, so stopping after M112 was seen
    # means: no STEP edge after the moment it was seen (a 20 us tick of slack).
    assert stop_us <= 20, "steps went on %d us after M112 was seen" % stop_us
    assert seen_us - last_step_us < 1000  # and it was moving at full speed right then
    period = np.diff(halt_t[-20:])
    assert period.max() <= 140  # 100 mm/s = 125 us per step: cruising, not stopping
    # Far fewer than all queued moves ran: M112 jumped ahead of 15+ queued blocks.
    assert halt_steps < (k + 3) * 5 * X_SPM < before * 5 * X_SPM
    text = [l for a in answers for l in a]
    assert text.count(HALT_BROADCAST) == 1
    # Lines still waiting in the ring when M112 came are refused, each with one error.
    refused = [a for a in answers if a[-2:-1] == [
        "Error:printer halted (emergency stop (M112)); M999 resumes"]]
    assert len(refused) >= 16
    m114 = [a[0] for a in answers if a[0].startswith("X:")]
    # After the halt M114 shows where the axis really is, in mm and in steps ...
    assert m114[0].endswith("Count X:%d Y:0 Z:0" % halt_steps)
    assert abs(float(m114[0].split()[0][2:]) - halt_steps / X_SPM) < 0.006
    # ... moves are refused until M999, and after it the printer moves again.
    i = lines.index("M999")
    assert answers[i - 1] == ["Error:printer halted (emergency stop (M112)); M999 resumes", "ok"]
    assert answers[i] == ["ok"] and answers[i + 1] == ["ok"]
    assert m114[1].endswith("Count X:%d Y:0 Z:0" % (halt_steps + X_SPM))
    # Black-box view from the trace alone: M112 could enter the ring only once the move
    # k lines ahead of it started (its first step); motion stopped this long after.
    block_start_us = int(x_t[(halt_steps - 1) // (5 * X_SPM) * 5 * X_SPM])
    print("M112 seen at %d us (k=%d); last step at %d us, next was due ~%d us later; "
          "last step %d us after the move M112 arrived in began"
          % (seen_us, k, last_step_us, period[-1], last_step_us - block_start_us))
    COUNTS.setdefault("m112_stop_us", []).append(max(0, stop_us))


@pytest.mark.parametrize("m112", ["M112", "m112", numbered(7, "M112"), "M112 ;stop", "N7 M112"])
def test_m112_spellings_jump_the_queue(mp, tmp_path, m112):
    halt_steps = _steps_after_m112_at_full_queue(mp, tmp_path, m112)
    assert halt_steps < 10 * 5 * X_SPM


@pytest.mark.parametrize("m112", ["M 112", "\tM112"])
def test_m112_spellings_the_parser_accepts_also_jump_the_queue(mp, tmp_path, m112):
    halt_steps = _steps_after_m112_at_full_queue(mp, tmp_path, m112)
    assert halt_steps < 10 * 5 * X_SPM


def _steps_after_m112_at_full_queue(mp, tmp_path, m112):
    lines = ["G91"] + ["G1 X5 F6000"] * 36 + [m112] + ["G1 X5 F6000"] * 4
    seen, answers, step_t, x_t = run_m112_stream(mp, tmp_path / "m112.edges", lines)
    assert len(answers) == len(lines)
    # Whenever it is seen, the halt must have happened (here or in order).
    assert any(HALT_BROADCAST in a for a in answers)
    return len(x_t)


# ---------------------------------------------------------------------------------
# 5. Refuse-after-error (M932/M933) and busy: during waits
# ---------------------------------------------------------------------------------

REFUSED = "Error:refused: an earlier command failed (M933 leaves this mode)"


def test_refuse_after_error_mode():
    host = Stdio()
    assert host.ask("G91") == ["ok"]
    assert host.ask("G1 X1 F6000") == ["ok"]  # before M932: errors do not latch
    assert host.ask("G1 X999")[0].startswith("Error:move to")
    assert host.ask("G1 X1") == ["ok"]
    assert host.ask("M932") == ["ok"]  # clears the error state and arms the mode
    assert host.ask("G1 X1") == ["ok"]
    assert host.ask("G1 X999")[0].startswith("Error:move to")  # the failure
    for line in ("G1 X1", "G91", "M83", "M106 S10", "T1", "M400"):
        assert host.ask(line) == [REFUSED, "ok"], line
    # The printer keeps answering what a host needs to find out what happened.
    assert host.ask("M105")[-1].startswith("ok T:")
    assert host.ask("M114")[0].startswith("X:3.00 Y:0.00")
    # An unknown command is not run, so it is not refused either.
    assert host.ask("M9999") == ['echo:Unknown command: "M9999"', "ok"]
    # A protocol error is a transmission fault, not a failed command; a bad byte is.
    assert host.ask("M932") == ["ok"]  # M932 again: clears the state, stays armed
    assert host.ask("G1 X1") == ["ok"]
    assert host.ask(b"G1 X1\x01") == ["Error:byte 0x01 is a control character", "ok"]
    assert host.ask("G1 X1") == [REFUSED, "ok"]
    assert host.ask("M933") == ["ok"]
    assert host.ask("G1 X1") == ["ok"]
    assert host.ask("G1 X999")[0].startswith("Error:move to")
    assert host.ask("G1 X1") == ["ok"]  # mode left: errors no longer latch
    assert host.printer.finish()["steps"]["x"] == 6 * X_SPM


def test_busy_processing_during_waits():
    host = Stdio()
    # Every 2 s of a wait; the 5 s dwell hears it at 2 s and 4 s.
    assert host.ask("G4 S5") == ["busy: processing", "busy: processing", "ok"]
    host.ask("G1 X200 F3000")  # 4 s of motion
    got = host.ask("M400")
    assert got[-1] == "ok" and got[:-1] == ["busy: processing"] * len(got[:-1])
    assert len(got) - 1 == 2
    assert host.printer.finish()["steps"]["x"] == 200 * X_SPM


# ---------------------------------------------------------------------------------
# 6. Hypothesis: intake + parser + protocol, and the whole firmware
# ---------------------------------------------------------------------------------

# One micropython run per generated stream: the real Printer fed from an in-memory
# console in odd-sized chunks, with stand-in handlers (upy/protocol_fuzz_core.py).


_letters = st.sampled_from(list("GMTNXYZEFSPIV gmxyz*;()\t\r:.-+"))
_number = st.one_of(
    st.integers(-10**12, 10**12).map(str),
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.sampled_from(["", "-", "+", ".", "1.2.3", "--1", "1e5", "0x1F", "00000000000001",
                     "999999999", "1234567890", ".5", "-.5", "5.", "110", "112"]))
_word = st.tuples(_letters, _number).map(lambda t: t[0] + t[1])
_gcode = st.lists(_word, max_size=8).map(" ".join)


@st.composite
def _numbered(draw):
    n = draw(st.integers(-2, 40))
    body = "N%d %s" % (n, draw(_gcode))
    cs = checksum(body)
    if draw(st.booleans()):
        cs = draw(st.integers(0, 300))
    return "%s*%d" % (body, cs)


def _mutate(line):
    return st.tuples(st.integers(0, 100), st.binary(min_size=1, max_size=3)).map(
        lambda t: line[:t[0]] + t[1].replace(b"\n", b"?") + line[t[0]:])


# Free text after the commands that take it, and after ones we don't know (M0).
_text_line = st.tuples(
    st.sampled_from(["M117", "m117", "M118", "M118 E1", "M118 A1", "M118 A1 E1 P0", "M118 P2",
                     "M0", "M1", "M9998"]),
    # M118 sends its text back: one that reads as a reply of the protocol ("ok ...")
    # would be one to the host as well.
    # UTF-8 text as slicers write it, up to twice the line's bytes (cut, not refused).
    st.text(alphabet=[chr(c) for c in range(32, 127)] + list("äöüßé°±€✓—"),
            max_size=70).filter(
        lambda t: not any(w in t.lower() for w in ("ok", "error", "resend", "busy"))),
).map(lambda t: ("%s %s" % t).encode())
_line = st.one_of(
    _gcode.map(lambda s: s.encode("latin-1")),
    _numbered().map(lambda s: s.encode("latin-1")),
    st.binary(max_size=140).map(lambda b: b.replace(b"\n", b"")),
    _text_line,
    st.sampled_from([b"M112", b"M999", b"M932", b"M933", b"M110 N5", b"M110", b"N-1 M110 N-1*125",
                     b"M108", b"M410", b"M876 S1", b"M113 S1", b"N3 M108*0",
                     b"G1 X" + b"1" * 120, b" " * 97, b";" + b"\xff" * 200]),
).flatmap(lambda b: st.one_of(st.just(b), _mutate(b)))


def _is_text_command(line):
    """A plain M117/M118 or unknown-command line whose text no rule of the intake or
    the protocol refuses: its answer must never be Error:."""
    if intake_verdict(line) or b"*" in line.split(b";")[0]:
        return False
    stored = _cut_message(_stored(line))
    words = stored.split()
    if not words or words[0].upper() not in (b"M117", b"M118", b"M0", b"M1", b"M9998"):
        return False
    try:
        stored.decode()  # the firmware refuses text that is not UTF-8
    except UnicodeError:
        return words[0].upper() not in (b"M117", b"M118")
    return True


def _stored(line):
    """The bytes of a line the intake keeps: up to a `;`, without CR."""
    return line.split(b";")[0].replace(b"\r", b"")


_MESSAGE = re.compile(rb"[ \t]*[Mm]11[78][ \t]")


def _cut_message(stored):
    """A plain M117/M118 line longer than the buffer is cut at the last whole UTF-8
    character that fits, as Marlin cuts its messages."""
    if len(stored) <= LINE_BYTES or not _MESSAGE.match(stored):
        return stored
    cut = LINE_BYTES
    while cut > 0 and stored[cut] & 0xC0 == 0x80:  # inside a character: back to its start
        cut -= 1
    return stored[:cut]


def intake_verdict(line):
    """What the intake must say about one line, from the rules alone: control bytes
    but tab refused, every other byte kept (text is UTF-8), up to a `;`, CR ignored,
    at most 96 bytes stored unless the line is a message to cut; the first fault
    wins."""
    stored = 0
    for c in line:
        if c == 13:
            continue
        if c == 59:
            return None
        if (c < 32 and c != 9) or c == 127:
            return "Error:byte 0x%02x is a control character" % c
        if stored >= LINE_BYTES:
            if _MESSAGE.match(_stored(line)):
                return None
            return "Error:line longer than 96 bytes"
        stored += 1
    return None


def _asks_m113(line):
    """An M113 with no S word (a mutation of `M113 S1` can drop it): a report."""
    words = _stored(line).split()
    return bool(words) and words[0].upper() == b"M113" and not any(
        w[:1].upper() == b"S" for w in words[1:])


def check_answers(lines, out, reports=False):
    """One answer per line, ok last; at most one Error (plus Resend for protocol
    errors); none of them an internal error; the intake's verdict where it has one.
    reports: the full firmware, whose commands may print reports before their ok."""
    answers, rest = group(out)
    assert rest == ["//done"] or rest == [], rest
    assert len(answers) == len(lines), "%d lines, %d answers" % (len(lines), len(answers))
    for line, a in zip(lines, answers):
        body = [t for t in a[:-1] if t != HALT_BROADCAST]
        assert not any("internal error" in t for t in body), (line, a)
        errors = [t for t in body if t.startswith(("Error:", "echo:Unknown command: "))]
        assert len(errors) <= 1, (line, a)
        resend = [t for t in body if t.startswith("Resend: ")]
        if resend:
            assert body[-2:] == [errors[0], resend[0]], (line, a)
        if not reports:
            # M113 without S reports its setting, as the core's one report.
            told = [t for t in body if t.startswith("echo:M113 S") and _asks_m113(line)]
            assert len(body) == len(errors) + len(resend) + len(told), (line, a)
        verdict = intake_verdict(line)
        if verdict:
            assert body == [verdict], (line, a)
        if _is_text_command(line):
            assert not [t for t in body if t.startswith("Error:") and t != HALT_BROADCAST
                        and "halted" not in t and "refused" not in t], (line, a)


# make test fuzzes a third of the streams make test-all does.
FUZZ_SCALES = [1, pytest.param(3, marks=pytest.mark.slow)]


@pytest.mark.parametrize("scale", FUZZ_SCALES)
def test_fuzz_intake_parser_and_protocol(mp, scale):
    per_stream = 120
    streams = 30 * scale
    before = COUNTS["fuzz"]

    @settings(max_examples=streams, deadline=None, database=None,
              suppress_health_check=list(HealthCheck))
    # M997 ends serving by design (test_safety.py), so no line after it is answered.
    @given(st.lists(_line.filter(lambda b: b"997" not in b), min_size=per_stream,
                    max_size=per_stream))
    def run(lines):
        data = b"\n".join(lines) + b"\n"
        out = mp.script("protocol_fuzz_core", stdin=data).splitlines()
        assert out[0] == "start" and out[-1] == "//done"  # serve() returned: nothing escaped it
        check_answers(lines, out[1:])
        COUNTS["fuzz"] += len(lines)

    run()
    least = streams * per_stream * 9 // 10  # hypothesis may stop a few streams short
    assert COUNTS["fuzz"] - before >= least
    COUNTS["fuzz_core_least"] = COUNTS.get("fuzz_core_least", 0) + least


# The whole firmware: only commands whose virtual time is bounded (no dwell, homing,
# heating waits, configuration writes), decided by the firmware's own parser on CPython.
_SAFE = {("G", 0), ("G", 1), ("G", 90), ("G", 91), ("G", 92), ("G", 20), ("G", 21),
         ("M", 82), ("M", 83), ("M", 105), ("M", 106), ("M", 107), ("M", 110), ("M", 112),
         ("M", 114), ("M", 115), ("M", 119), ("M", 163), ("M", 164),
         ("M", 932), ("M", 933), ("M", 999), ("T", None),
         ("M", 117), ("M", 118), ("M", 108), ("M", 410), ("M", 876), ("M", 113)}


def _safe_for_full_firmware(line):
    if str(paths.FIRMWARE) not in sys.path:
        sys.path.insert(0, str(paths.FIRMWARE))
    from mixfw.gcode import Parser, GcodeError  # pure logic: imports on CPython
    if intake_verdict(line):
        return True
    # M118 sends its text back: a mutated line whose text reads as a reply of the
    # protocol ("M118ok") would be one to the host as well, as _text_line says.
    low = line.lower()
    if b"m118" in low and any(w in low for w in (b"ok", b"error", b"resend", b"busy")):
        return False
    text = line.split(b";")[0].replace(b"\r", b"")
    buf = bytearray(text.split(b"*")[0])
    try:
        ln = Parser().parse(buf, len(buf))
    except GcodeError:
        return True
    if ln.letter == "":
        return True
    if ln.letter == "T":
        return True
    if (ln.letter, ln.number) not in _SAFE:
        return False
    # Moves and G92: bounded feed and distances so no move takes minutes of virtual
    # time (E has no soft limits; M211 S0 is left out for the same reason).
    if ln.letter == "G" and ln.number in (0, 1, 92):
        for c in "XYZE":
            if ln.has_value(c) and abs(ln.float(c)) > (50 if c == "E" else 1000):
                return False
        return not ln.has_value("F") or ln.float("F") >= 600
    return True


_full_line = st.one_of(
    _line,
    st.tuples(st.sampled_from(["G1", "G0", "g1"]), st.sampled_from("XYZE"),
              st.sampled_from(["1", "-1", "0.5", "300", "-0.25", "12.5", "1.2.3", "", "251"]))
    .map(lambda t: ("%s %s%s F6000" % t).encode()),
).filter(_safe_for_full_firmware)


@pytest.mark.parametrize("scale", FUZZ_SCALES)
def test_fuzz_whole_firmware_stream(scale):
    total = 0
    streams = 13 * scale

    @settings(max_examples=streams, deadline=None, database=None,
              suppress_health_check=list(HealthCheck))
    @given(st.lists(_full_line, min_size=150, max_size=150))
    def run(lines):
        nonlocal total
        host = Stdio()
        answers, report = host.flood(b"G21\n" + b"\n".join(lines) + b"\n", count="fuzz")
        out = [t for a in answers for t in a]
        check_answers([b"G21"] + lines, out, reports=True)
        assert all(-250 * 80 - 1 <= report["steps"][k] <= 250 * 80 + 1 for k in "xy")
        total += len(lines)

    run()
    assert total >= streams * 150


def test_zz_counts():
    # Runs last (file order): how much hostile input the suite sent.
    print("hostile lines sent: %d, fuzz lines: %d, M112 stop times (us): %s"
          % (COUNTS["hostile"], COUNTS["fuzz"], COUNTS.get("m112_stop_us")))
    # Only in the worker that ran the core's fuzzing (pytest-xdist spreads the tests):
    # the whole firmware's fuzzing counts its lines too.
    if COUNTS.get("fuzz_core_least"):
        assert COUNTS["fuzz"] >= COUNTS["fuzz_core_least"]
