"""Runtime configuration: APrinter's M503 M925 M926 M502 M501 M500 M930, Marlin's M92
M201 M203 M204 M205, and the configuration file on flash, on the firmware running on
the MicroPython unix port."""
import json
import zlib

import pytest

from hypothesis import given, settings, strategies as st, HealthCheck

from mixstep import paths
from mixfw.options_help import HELP


class Session:
    """One boot of the whole simulated printer (upy/config_machine.py) with its
    configuration file at cfg_path: the warnings it printed right after `start`,
    the replies to each command (the `ok` dropped), and what it reported at the end."""

    # Sent first, replies dropped: these tests extrude without heating.
    PRELUDE = ["M302 P1"]

    def __init__(self, mp, cfg_path, commands):
        commands = self.PRELUDE + list(commands)
        out = mp.script("config_machine", cfg_path,
                        stdin=("\n".join(commands) + "\n").encode()).splitlines()
        start = out.index("start") + 1
        self.boot = []
        while out[start].startswith("echo:config"):
            self.boot.append(out[start])
            start += 1
        self.end = json.loads(out[-1][len("//end "):])
        self.replies = []
        reply = []
        for text in out[start:-1]:
            if text == "ok" or text.startswith("ok "):
                self.replies.append(reply)
                reply = []
            else:
                reply.append(text)
        assert len(self.replies) == len(commands)
        self.replies = self.replies[len(self.PRELUDE):]

    def of(self, i):
        return self.replies[i]


def m503_lines(replies):
    return [r[len("echo:"):] for r in replies]


def value_of(line):
    """'echo:M926 Idrives V6 ; ...' -> '6'"""
    return line.split(";")[0].split()[2][1:]


# --- configuration inside one MicroPython process: a test double for the printer
# that dispatches through the real parser, and a flash that can lose power
# (upy/config_unit.py). Short snippets run with these names. ---
UNIT_NAMES = """import json, sys, board
from mixfw.config import Config, ConfigError, crc32
from config_unit import Commands, Flash, PATH, PowerLoss, boot_each, sweep
"""


def run_unit(mp, body, data=None, heap="32M", lines=False):
    """Run body with UNIT_NAMES; data, if given, arrives as DATA (JSON on stdin). Returns
    its last output line decoded from JSON, or with lines=True every line."""
    if data is not None:
        body = "DATA = json.loads(sys.stdin.read())\n" + body
    out = mp.run(UNIT_NAMES + body, stdin=json.dumps(data).encode(), heap=heap).splitlines()
    return [json.loads(line) for line in out] if lines else json.loads(out[-1])


def run_unit_script(mp, name, data=None):
    """Run upy/<name>.py, data (if given) as JSON on its stdin; its last line decoded."""
    return mp.script_json(name, stdin=json.dumps(data).encode(), heap="32M")


def test_crc32_is_zlibs(mp):
    payloads = [b"", b"a", b"123456789", bytes(range(256)) * 3]
    got = run_unit(mp, "print(json.dumps([crc32(bytes.fromhex(h)) for h in %r]))"
                   % [p.hex() for p in payloads])
    assert got == [zlib.crc32(p) for p in payloads]


def test_options_are_the_boards_settings_one_per_axis(mp, board):
    got = run_unit_script(mp, "config_options")
    names = got["names"]
    axes = {"steps_per_mm": "xyze", "max_feed_mm_s": "xyze", "max_accel_mm_s2": "xyze",
            "travel_mm": "xyz", "homing_feed_mm_s": "xyz", "change_park_mm": "xyz"}
    expected = [k + "_" + a for k, ax in axes.items() for a in ax] + [
        "acceleration_mm_s2", "retract_acceleration_mm_s2", "junction_deviation_mm",
        "min_segment_time_us", "min_arc_segment_mm", "max_arc_segment_mm", "min_circle_segments",
        "default_feed_mm_s", "soft_limits", "max_extrude_mm", "retract_policy", "retract_mm", "trace_records",
        "watchdog_ms", "step_stall_ms",
        "retract_feed_mm_s", "unretract_feed_mm_s", "transition_l1_mm", "transition_l2_mm",
        "drives", "virtual_tools", "queue_blocks",
        "line_buffer_bytes", "tick_us", "step_pulse_us", "dir_setup_us",
        "enable_active_low", "endstop_active_high", "endstop_pullup",
        "change_unload_mm", "change_load_mm", "change_purge_mm", "change_feed_mm_s",
        "change_heater_timeout_s", "runout_enabled", "runout_active_high", "runout_pullup"]
    heater = ["beta", "r25_ohm", "pullup_ohm", "sh_a", "sh_b", "sh_c", "kp", "ki", "kd",
              "pwm_hz", "min_c", "max_c", "watch_s", "watch_rise_c", "runaway_c",
              "runaway_s"]
    optional = ["%s_%s" % (h, k) for h in ("hotend", "bed") for k in heater] + [
        "min_extrude_c", "fan_pwm_hz", "thermal_period_ms", "console_uart", "console_baud", "tcp_port",
        "tcp_max_clients", "net_password", "net_idle_timeout_s", "web_page_port"]
    expected += [n for n in optional if n in board["SETTINGS"]]
    expected += ["%s_%d" % (k, t) for t in range(board["SETTINGS"]["virtual_tools"])
                 for k in ("tool_mixes", "tool_advance_k")]
    expected += ["transition_pairs_%d" % k for k in range(8)]
    # The bed probe and the mesh (defaults.py): 5 x 5 heights at most.
    expected += ["probe_active_high", "probe_feed_mm_s", "probe_travel_feed_mm_s",
                 "probe_clearance_mm", "probe_dive_mm", "mesh_fade_mm", "mesh_probed",
                 "mesh_enabled"]
    expected += ["probe_offset_mm_" + a for a in "xyz"]
    expected += ["mesh_%s_%s" % (k, a) for k in ("points", "min_mm", "max_mm") for a in "xy"]
    expected += ["mesh_z_nm_%d" % k for k in range(25)]
    expected += ["%s_%d" % (k, d) for d in range(board["SETTINGS"]["drives"])
                 for k in ("drive_steps_per_mm", "filament_used_mm")
                 + (("drive_colour_rgb",) if "drive_colour_rgb" in board["SETTINGS"] else ())]
    assert sorted(names) == sorted(expected)
    assert len(names) == len(set(names))
    assert got["soft_limits"] is True  # the firmware's default; the board names none
    assert {"drives", "queue_blocks", "tick_us"} <= set(got["restart"])
    assert "steps_per_mm_x" not in got["restart"]
    assert got["no_bed"] == [n for n in names if not n.startswith("bed_")]
    assert got["bad"] == "board default drives = 9 is above the maximum 6"


def test_m503_pasted_back_gives_the_same_configuration(mp, tmp_path):
    changes = ["M926 Isteps_per_mm_e V93.3", "M926 Ijunction_deviation_mm V0.30000000000000004",
               "M926 Isoft_limits V0", "M926 Iqueue_blocks V32", "M926 ITRAVEL_MM_Z V180.5"]
    first = Session(mp, tmp_path / "a.cfg", changes + ["M503"])
    printed = first.of(len(changes))
    # Each an M926 line, but the password's: a comment that never shows it.
    assert all(r.startswith("echo:M926 I") for r in printed if "Inet_password" not in r)
    assert [r for r in printed if "Inet_password" in r] == [
        "echo:; M926 Inet_password V... ; " + HELP["net_password"] + " (none set yet)"]
    by_name = {line.split()[1][1:]: value_of(line) for line in printed
               if "Inet_password" not in line}
    assert by_name["steps_per_mm_e"] == "93.3"
    assert by_name["junction_deviation_mm"] == "0.30000000000000004"
    assert by_name["soft_limits"] == "0"
    assert by_name["queue_blocks"] == "32"
    assert by_name["travel_mm_z"] == "180.5"
    assert by_name["steps_per_mm_x"] == "80.0"

    pasted = m503_lines(printed)
    second = Session(mp, tmp_path / "b.cfg", ["M503"] + pasted + ["M503"])
    assert second.of(0) != printed  # a fresh printer starts from the defaults
    assert all(r == [] for r in second.replies[1:-1]), [r for r in second.replies[1:-1] if r]
    assert second.of(len(pasted) + 1) == printed


_UNIT_SCHEMA = None


def schema(mp):
    """(name, kind, lo, hi) of every option, as the firmware on the unix port has them."""
    global _UNIT_SCHEMA
    if _UNIT_SCHEMA is None:
        _UNIT_SCHEMA = run_unit(mp, """
c = Config(board.SETTINGS, PATH, Flash())
print(json.dumps([(o.name, o.kind, o.lo, o.hi) for o in c.options]))
""")
    return _UNIT_SCHEMA


@st.composite
def configurations(draw, options):
    """Some options set to valid values, as (name, value text) pairs."""
    chosen = draw(st.lists(st.sampled_from(options), unique_by=lambda o: o[0], max_size=12))
    pairs = []
    for name, kind, lo, hi in chosen:
        if kind == "float":
            v = repr(draw(st.floats(lo, hi, allow_nan=False)))
        elif kind == "int":
            v = str(draw(st.integers(lo, hi)))
        elif kind == "mix":
            weights = draw(st.lists(st.integers(0, 50), min_size=1, max_size=6).filter(any))
            v = ":".join(str(w) for w in weights)
        elif kind == "pair":
            v = "%d:%d:%r:%r" % (draw(st.integers(0, 15)), draw(st.integers(0, 15)),
                                 draw(st.floats(lo, hi)), draw(st.floats(lo, hi)))
        else:
            v = str(draw(st.integers(0, 1)))
        pairs.append((name, v))
    return pairs


def test_random_configurations_round_trip_through_m926_and_m503(mp):
    # Not the password: M503 never shows it (test_netconsole.py).
    options = [o for o in schema(mp) if o[0] != "net_password"]

    @settings(max_examples=5, deadline=None,
              suppress_health_check=[HealthCheck.function_scoped_fixture])
    @given(st.lists(configurations(options), min_size=20, max_size=20))
    def check(batch):
        got = run_unit_script(mp, "config_round_trip", batch)
        for pairs, (printed, printed_again) in zip(batch, got):
            assert printed == printed_again
            shown = {line.split()[1][1:]: value_of(line) for line in printed
                     if "Inet_password" not in line}
            for name, text in pairs:
                if name.startswith("tool_mixes_"):  # shown normalised: same ratios
                    a = [float(w) for w in text.split(":")]
                    b = [float(w) for w in shown[name].split(":")]
                    ratio = sum(b) / sum(a)
                    assert all(abs(x * ratio - y) < 1e-9 for x, y in zip(a, b)), name
                elif name.startswith("transition_pairs_"):
                    a = [float(w) for w in text.split(":")]
                    b = [float(w) for w in shown[name].split(":")]
                    assert b == pytest.approx(a, rel=4e-16), name
                else:
                    # MicroPython's text-to-float is not correctly rounded for 17-digit
                    # numbers, so its parse may be the neighbouring double of CPython's.
                    assert float(shown[name]) == pytest.approx(float(text), rel=4e-16), name

    check()


def test_bad_values_are_refused_naming_option_value_and_limit(mp, tmp_path):
    bad = {
        "M926 Isteps_per_mm_x V-5": "Error:steps_per_mm_x = -5.0 is below the minimum 0.001",
        "M926 Idrives V7": "Error:drives = 7 is above the maximum 6",
        "M926 Idrives V2.5": "Error:drives: '2.5' is not a whole number",
        "M926 Isoft_limits V2": "Error:soft_limits: 2 is not 0 or 1",
        "M926 Ihotend_kp Vfast": "Error:hotend_kp: 'fast' is not a number",
        "M926 Ijunction_deviation_mm Vnan": "Error:junction_deviation_mm = nan is below "
                                            "the minimum 0.001",
        "M926 Ibogus V1": "Error:unknown option 'bogus' (M503 lists them)",
        "M925 Ibogus": "Error:unknown option 'bogus' (M503 lists them)",
        "M926 V1": "Error:missing option name: I<option>, M503 lists them",
        "M926 Idrives X3": "Error:unexpected 'X3': expected I<option> V<value>",
        "M926 Idrives V3 V4": "Error:parameter V given twice",
        "M92 X0": "Error:steps_per_mm_x = 0.0 is below the minimum 0.001",
        "M92 X100 Y-1": "Error:steps_per_mm_y = -1.0 is below the minimum 0.001",
        "M203 Z": "Error:parameter Z needs a number",
        "M204 R0": "Error:retract_acceleration_mm_s2 = 0.0 is below the minimum 0.1",
        "M205 J20": "Error:junction_deviation_mm = 20.0 is above the maximum 10.0",
    }
    s = Session(mp, tmp_path / "c.cfg", ["M503"] + list(bad) + ["M503", "M501"])
    for i, (command, error) in enumerate(bad.items()):
        assert s.of(i + 1) == [error], command
    # Nothing was changed, not even X of "M92 X100 Y-1": a command sets all or nothing.
    assert s.of(len(bad) + 1) == s.of(0)
    assert s.of(len(bad) + 2) == ["Error:no saved configuration in %s" % (tmp_path / "c.cfg")]


def test_a_failed_save_is_an_error_and_the_printer_goes_on(mp, tmp_path):
    cfg = tmp_path / "missing-dir" / "mixstep.cfg"
    s = Session(mp, cfg, ["M926 Idrives V2", "M500", "M925 Idrives"])
    assert len(s.of(1)) == 1
    assert s.of(1)[0].startswith("Error:could not save %s: " % cfg)
    assert value_of(s.of(2)[0]) == "2"


def test_saved_configuration_is_loaded_and_used_after_a_reboot(mp, tmp_path):
    cfg = tmp_path / "mixstep.cfg"
    s = Session(mp, cfg, [
        "M926 Isteps_per_mm_x V100", "M926 Idrives V3", "M926 Itravel_mm_x V5",
        "M500",
        "M926 Isteps_per_mm_x V50", "M925 Isteps_per_mm_x",
        "M501", "M925 Isteps_per_mm_x",
        "M502", "M925 Isteps_per_mm_x",
        "M501", "M925 Isteps_per_mm_x", "M930"])
    assert s.boot == []  # no file yet: a first boot, defaults without a warning
    shown = [value_of(s.of(i)[0]) for i in (5, 7, 9, 11)]
    assert shown == ["50.0", "100.0", "80.0", "100.0"]
    assert s.of(12) == ["echo:takes effect after a restart (M500 saves it): drives"]

    data = cfg.read_bytes()
    cut = data.rindex(b"\n", 0, -1) + 1
    body, crc_line = data[:cut], data[cut:]
    assert body.startswith(b"# mixstep configuration, version 1\n")
    assert crc_line == b"crc32 = %08x\n" % zlib.crc32(body)
    assert b"\nsteps_per_mm_x = 100.0\n" in body and b"\ndrives = 3\n" in body
    assert not (tmp_path / "mixstep.cfg.tmp").exists()

    # The next boot assembles the machine from the saved values.
    s = Session(mp, cfg, ["M925 Isteps_per_mm_x", "M163 S3 P1", "M930",
                          "G1 X2 F600", "G1 X6", "M400"])
    assert s.boot == []
    assert value_of(s.of(0)[0]) == "100.0"
    assert s.of(1) == ["Error:S3 out of range 0..2"]  # three drives
    assert s.of(2) == []  # built with drives 3: nothing waits for a restart
    assert s.of(4)[0].startswith("Error:") and "X6" in s.of(4)[0]  # beyond 5 mm travel
    assert s.end["steps"]["x"] == 2 * 100


def test_marlin_aliases_set_options_and_apply_at_once(mp, tmp_path):
    s = Session(mp, tmp_path / "d.cfg", [
        "M92", "M83", "M92 X100 E100", "G1 X1 F600", "T0", "G1 E1", "T1", "G1 E1",
        "M92", "M201 X1000 E2000", "M925 Imax_accel_mm_s2_x", "M203 Z5",
        "M925 Imax_feed_mm_s_z", "M204 P1200 R2500", "M204", "M204 T900", "M204",
        "M205 X10 J0.02", "M205", "M926 Itick_us V25", "M930", "M926 Itick_us", "M930"])
    assert s.of(0) == ["echo:M92 X80.0 Y80.0 Z400.0 E415.0"]
    assert s.of(8) == ["echo:M92 X100.0 Y80.0 Z400.0 E100.0"]
    assert value_of(s.of(10)[0]) == "1000.0"
    assert value_of(s.of(12)[0]) == "5.0"
    assert s.of(14) == ["echo:M204 P1200.0 R2500.0"]
    assert s.of(16) == ["echo:M204 P900.0 R2500.0"]
    assert s.of(17) == ["echo:M205 ignored X: mixstep uses junction deviation J"]
    assert s.of(18) == ["echo:M205 J0.02 B20000"]
    assert s.of(20) == ["echo:takes effect after a restart (M500 saves it): tick_us"]
    assert s.of(22) == []
    # M92, M201, M203, M204 (twice), M205 and two M930 each applied once.
    assert s.end["applied"] == 8
    steps = s.end["steps"]
    assert steps["x"] == 100  # the new steps per mm, for the move queued after M92
    assert steps["e0"] == 100 and steps["e1"] == 100  # M92 E is every drive's


GOOD_CHANGES = (("steps_per_mm_x", "100.0"), ("drives", "3"), ("soft_limits", "0"))


def good_file(mp):
    return bytes.fromhex(run_unit(mp, """
c = Config(board.SETTINGS, PATH, Flash())
c.update(%r)
print(json.dumps(c.text().hex()))
""" % (GOOD_CHANGES,)))


def with_crc(body):
    return body + b"crc32 = %08x\n" % zlib.crc32(body)


def damaged_files(good):
    body = good[:good.rindex(b"\n", 0, -1) + 1]
    # A body whose checksum has hex letters, so that capitals make a different line.
    lettered = body
    while b"%08x" % zlib.crc32(lettered) == b"%08X" % zlib.crc32(lettered):
        lettered += b"# \n"
    flipped = bytearray(good)
    flipped[60] ^= 0x04
    return {
        "empty": (b"", "truncated (no final newline)"),
        "truncated mid-line": (good[:good.index(b"\n", 700) - 2], "truncated (no final newline)"),
        "cut at a line end": (good[:good.index(b"\n", 700) + 1], "truncated (no checksum line)"),
        "flipped bit": (bytes(flipped), "checksum mismatch (file corrupt)"),
        "other version": (with_crc(body.replace(b"version 1", b"version 2")),
                          "unsupported header '# mixstep configuration, version 2'"),
        "no separator": (with_crc(body + b"drives 3\n"),
                         "line %d: expected name = value" % (body.count(b"\n") + 1)),
        "too large": (b"#" * 20000 + b"\n", "20001 bytes is too large for a configuration"),
        # Same number, other text: only the exact line counts.
        "checksum in capitals": (lettered + b"crc32 = %08X\n" % zlib.crc32(lettered),
                                 "checksum mismatch (file corrupt)"),
        "checksum with a leading zero": (body + b"crc32 = 0%08x\n" % zlib.crc32(body),
                                         "checksum mismatch (file corrupt)"),
    }


def test_damaged_file_gives_defaults_and_a_warning_at_boot(mp, tmp_path):
    good = good_file(mp)
    cfg = tmp_path / "mixstep.cfg"
    cases = damaged_files(good)
    for label, (data, problem) in cases.items():
        cfg.write_bytes(data)
        s = Session(mp, cfg, ["M925 Isteps_per_mm_x", "M925 Idrives", "M501"])
        assert s.boot == ["echo:config %s: %s; using defaults" % (cfg, problem)], label
        assert [value_of(s.of(i)[0]) for i in (0, 1)] == ["80.0", "6"], label
        assert s.of(2) == ["Error:%s: %s" % (cfg, problem)], label
    cfg.write_bytes(good)
    s = Session(mp, cfg, ["M925 Isteps_per_mm_x"])
    assert s.boot == [] and value_of(s.of(0)[0]) == "100.0"


def test_a_value_this_firmware_no_longer_takes_keeps_its_default_alone(mp, tmp_path):
    # The checksum says the file is as saved: an option this firmware doesn't have, or
    # a value past a limit that changed, leaves that option at its default and keeps
    # every other saved value.
    good = good_file(mp)
    body = good[:good.rindex(b"\n", 0, -1) + 1]
    cfg = tmp_path / "mixstep.cfg"
    drives_line = body[:body.index(b"drives = 3")].count(b"\n") + 1
    cfg.write_bytes(with_crc(body.replace(b"drives = 3", b"drives = 8")
                             + b"warp_drive = 1\n"))
    s = Session(mp, cfg, ["M925 Isteps_per_mm_x", "M925 Idrives", "M501"])
    note = ("%s: line %d: drives = 8 is above the maximum 6; line %d: unknown option "
            "'warp_drive' (M503 lists them); kept the defaults"
            % (cfg, drives_line, body.count(b"\n") + 1))
    assert s.boot == ["echo:config " + note]
    assert [value_of(s.of(i)[0]) for i in (0, 1)] == ["100.0", "6"]
    assert s.of(2) == ["echo:config " + note]


def assert_defaults_and_one_warning(results, count):
    assert len(results) == count
    for i, (is_default, warnings) in enumerate(results):
        assert is_default, i
        assert len(warnings) == 1 and warnings[0].startswith("echo:config /mixstep.cfg: ")
        assert warnings[0].endswith("; using defaults")


def test_corrupt_file_with_a_complete_tmp_from_an_interrupted_save_takes_the_tmp(mp):
    got = run_unit_script(mp, "config_interrupted_tmp")
    assert got["same"]
    assert got["warnings"] == ["echo:config /mixstep.cfg: truncated (no checksum line); "
                               "took the complete /mixstep.cfg.tmp"]
    assert got["files"] == ["/mixstep.cfg"] and got["moved"]  # the save was finished


def test_the_file_is_the_same_written_on_cpython(mp, board):
    """Pure logic: host tools import the same module and write the same file."""
    import sys
    sys.path.insert(0, str(paths.FIRMWARE))
    try:
        from mixfw.config import Config
    finally:
        sys.path.remove(str(paths.FIRMWARE))
    host = Config(board["SETTINGS"], "/unused")
    host.update(GOOD_CHANGES)
    assert host.text() == good_file(mp)


def test_every_truncation_is_detected(mp):
    good = good_file(mp)
    got = run_unit(mp, """
good = bytes.fromhex(DATA)
boot_each(good[:n] for n in range(len(good)))
""", good.hex(), lines=True)
    assert_defaults_and_one_warning(got, len(good))


def test_random_damage_is_detected(mp):
    good = good_file(mp)

    @settings(max_examples=5, deadline=None,
              suppress_health_check=[HealthCheck.function_scoped_fixture])
    @given(st.lists(st.tuples(st.integers(0, len(good) - 1), st.integers(1, 255),
                              st.sampled_from(["xor", "insert", "delete"])),
                    min_size=200, max_size=200))
    def check(edits):
        damaged = []
        for at, byte, how in edits:
            d = bytearray(good)
            if how == "xor":
                d[at] ^= byte
            elif how == "insert":
                d[at:at] = bytes([byte])
            else:
                del d[at]
            damaged.append(bytes(d).hex())
        got = run_unit(mp, """
boot_each(bytes.fromhex(h) for h in DATA)
""", damaged, lines=True)
        assert_defaults_and_one_warning(got, len(edits))

    check()


# (fat, start, every byte): each start from both kinds of rename at every byte; a stale
# .tmp left by an earlier interrupted save only matters around the operations.
SWEEPS = [(fat, start, True) for fat in (False, True) for start in ("old file", "no file")] + [
    (fat, start, False) for fat in (False, True)
    for start in ("stale partial tmp", "stale complete tmp")]


# The configuration saved before (OLD) and the one being saved when power fails (NEW).
OLD = [("steps_per_mm_x", 100.0), ("drives", 3), ("hotend_kp", 0.07)]
NEW = [("steps_per_mm_x", 90.0), ("soft_limits", False), ("tick_us", 25)]


def test_a_save_interrupted_around_its_file_operations_loads_old_or_new(mp):
    """The quick run's power loss (the sweeps below are slow): one start, the old file
    on a FAT-like file system (rename removes the old file first, the case with most
    steps to lose), cut at the seven points around open, the last bytes, close, remove
    and rename, each boot after it cut too; then a save completes."""
    r = run_unit(mp, """
print(json.dumps(sweep(%r, %r, True, "old file", every_byte=False)))
""" % (OLD, NEW))
    # open + every byte + close + remove + rename
    assert r["save_steps"] == r["file_bytes"] + 4
    # Cut before the old file is removed: the old; after it: the new (the boot finishes
    # the rename), never neither (sweep raises). Over 7 tries: the boot that finishes
    # the rename was cut as well.
    assert r["old"] == 5 and r["new"] == 2 and r["tried"] > 7, r


@pytest.mark.slow
def test_save_interrupted_at_every_point_loads_old_or_new(mp):
    # A run each: a sweep's time grows with the square of the file's size.
    got = [run_unit(mp, """
print(json.dumps(sweep(%r, %r, %r, %r, %r)))
""" % (OLD, NEW, fat, start, every)) for fat, start, every in SWEEPS]
    total = 0
    for (fat, start, every), r in zip(SWEEPS, got):
        # open + every byte + close + rename (FAT: + the remove inside rename)
        assert r["save_steps"] == r["file_bytes"] + 3 + (fat and start != "no file"), start
        if every:
            assert r["tried"] >= r["save_steps"] + 1
            assert r["old"] > r["file_bytes"] and r["new"] >= 1
        else:
            assert r["tried"] >= 7 and r["old"] >= 4 and r["new"] >= 1
        total += r["tried"]
    print("interruption points tried:", total, got)
    assert total > 4 * 1400


@pytest.mark.slow
def test_random_configurations_survive_interrupted_saves(mp):
    options = schema(mp)

    @settings(max_examples=2, deadline=None,
              suppress_health_check=[HealthCheck.function_scoped_fixture])
    @given(configurations(options), configurations(options), st.booleans())
    def check(old, new, fat):
        got = run_unit(mp, """
print(json.dumps(sweep(%r, %r, %r, "old file")))
""" % (old, new, fat))
        assert got["tried"] >= got["save_steps"] + 1

    check()


def test_the_beds_option_rows_are_the_hot_ends():
    """options.py spells out both heaters' rows in literals (so they stay in flash on a
    frozen board); they must not drift apart."""
    from mixfw.options import SCHEMA
    hotend = [row for row in SCHEMA if row[0].startswith("hotend_")]
    bed = [row for row in SCHEMA if row[0].startswith("bed_")]
    assert len(hotend) == 16
    assert bed == [("bed_" + r[0][len("hotend_"):],) + r[1:] for r in hotend]
    for r in hotend:
        assert HELP["bed_" + r[0][len("hotend_"):]] == "bed " + HELP[r[0]][len("hotend "):]
    from mixfw.options_net import NETWORK_ROWS
    assert sorted(HELP) == sorted(row[0] for row in SCHEMA + NETWORK_ROWS)


def test_the_option_table_is_a_constant():
    """Its rows are literals, so importing options.py builds almost nothing in RAM (a
    row naming FLOAT or LIVE would be built at import: 11 KB on this port)."""
    from mixstep import sim
    assert sim.code_heap(["mixfw.options"])["module_body_bytes"] < 1024
    assert sim.code_heap(["mixfw.options_net"])["module_body_bytes"] < 1024


def test_a_refused_file_is_told_to_every_host_until_a_save_replaces_it(mp, tmp_path):
    """A host on USB connects after the board has started and never sees the boot's
    lines: M115, which hosts send when they connect, repeats the warning, and so does
    every network connection and the simulation's report. M500 ends it."""
    good = good_file(mp)
    cfg = tmp_path / "mixstep.cfg"
    data, problem = damaged_files(good)["flipped bit"]
    cfg.write_bytes(data)
    warning = "echo:config %s: %s; using defaults" % (cfg, problem)
    s = Session(mp, cfg, ["M115", "M500", "M115"])
    assert s.boot == [warning]
    assert s.of(0)[-1] == warning and s.of(0)[0].startswith("FIRMWARE_NAME:mixstep")
    assert warning not in s.of(2)

    from mixstep import serve, sim
    from net import free_port, wait_for_port
    import socket
    cfg.write_bytes(data)
    address = "127.0.0.1:%d" % free_port()
    proc = serve.serve_tcp(address, realtime=0, announce=lambda text: None, config=cfg,
                           files=tmp_path / "files")
    try:
        wait_for_port(address)
        host, port = address.rsplit(":", 1)
        with socket.create_connection((host, int(port)), timeout=60) as c, \
                c.makefile("rb") as console:
            assert console.readline() == b"start\n"
            assert console.readline().decode().rstrip("\n") == warning
    finally:
        serve.stop(proc)
    gcode = tmp_path / "short.gcode"
    gcode.write_bytes(b"".join(paths.EXAMPLE_GCODE.read_bytes().splitlines(True)[:20]))
    report = sim.run(gcode, config_path=cfg, files_dir=tmp_path / "files")
    assert report["warnings"] == [warning]
