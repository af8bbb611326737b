"""The TMC2209 drivers of boards that share a UART (skr_pico, fysetc_e4): datagrams and
register values (mixfw/tmc.py, on CPython), and on the simulated board's bus
(boards/sim/simtmc.py) what the firmware sets up at start and what M906, M569 and
M122 do."""
import re

import pytest

from mixstep import boards, paths
from mixfw import tmc

TMC_BOARDS = ("skr_pico", "fysetc_e4")


# The datasheet's CRC example code, run by hand on read requests to node 0: GCONF
# (0x00) gives 0x48 and IOIN (0x06) 0x6F, values a real TMC2209 was seen to answer.
def test_crc_of_read_requests_matches_the_datasheets_code():
    assert tmc.read_datagram(0, 0x00) == bytes((0x05, 0x00, 0x00, 0x48))
    assert tmc.read_datagram(0, 0x06) == bytes((0x05, 0x00, 0x06, 0x6F))


def test_write_datagram_sets_bit_7_and_sends_the_value_msb_first():
    d = tmc.write_datagram(3, tmc.CHOPCONF, 0x14030053)
    assert d[:7] == bytes((0x05, 0x03, 0xEC, 0x14, 0x03, 0x00, 0x53))
    assert d[7] == tmc.crc8(d[:7]) and len(d) == 8


def test_a_reply_with_a_bad_crc_or_another_register_is_not_taken():
    reply = bytearray((0x05, 0xFF, 0x02, 0, 0, 0, 7, 0))
    reply[7] = tmc.crc8(reply, 7)
    assert tmc.parse_reply(bytes(reply), tmc.IFCNT) == 7
    assert tmc.parse_reply(bytes(reply), tmc.GCONF) is None
    reply[6] = 8
    assert tmc.parse_reply(bytes(reply), tmc.IFCNT) is None


def test_straps_give_8_32_64_16_microsteps_by_address():
    # MS2 MS1: 00 8, 01 32, 10 64, 11 16; the address is MS1 + 2 * MS2.
    assert [tmc.strap_microsteps(a) for a in range(4)] == [8, 32, 64, 16]
    assert [tmc.mres(m) for m in (256, 16, 8, 1)] == [0, 4, 5, 8]
    with pytest.raises(tmc.TmcError, match="20 microsteps"):
        tmc.mres(20)


def test_run_current_from_the_datasheet_formula():
    # 0.11 ohm + 20 mOhm: IRUN 31 with vsense 0 gives 0.325 V / 0.13 / sqrt(2) = 1767 mA.
    assert tmc.max_current_ma(110) == 1767
    # 800 mA: vsense 1 (0.18 V) reaches it; 32 * sqrt(2) * 0.13 * 0.8 / 0.18 = 26.1,
    # so CS 25, which gives 26 / 32 * 0.18 / 0.13 / sqrt(2) = 795 mA.
    assert tmc.current_fields(800, 110) == (1, 25, 12)
    assert tmc.current_ma(25, 110, 1) == 795
    # 1200 mA is beyond vsense 1's 979 mA: vsense 0, CS round(21.7) - 1 = 21.
    assert tmc.current_fields(1200, 110)[:2] == (0, 21)
    with pytest.raises(tmc.TmcError, match="1800 mA is above the 1767 mA"):
        tmc.current_fields(1800, 110)


def test_each_board_with_a_tmc_uart_states_its_drivers_settings_at_16_microsteps():
    for name in TMC_BOARDS:
        b = paths.load_board(name)
        assert b["TMC_UART"]["sense_mohm"] == 110
        assert b["SETTINGS"]["driver_microsteps"] == (16, 16, 16, 16)
        # steps_per_mm assume 16 microsteps: 200-step motors, 40 mm per turn on X/Y
        # (GT2 belt, 20 teeth) and 8 mm on Z.
        assert b["SETTINGS"]["steps_per_mm"][:3] == (200 * 16 / 40, 200 * 16 / 40,
                                                     200 * 16 / 8)
    b = paths.load_board("skr_pico")
    del b["SETTINGS"]["driver_current_ma"]
    b["TMC_UART"] = dict(b["TMC_UART"], sense_mohm=None)
    problems = boards.check(b, "skr_pico")
    assert any("sense_mohm is None" in p for p in problems)
    assert any("no driver_current_ma" in p for p in problems)


def registers(printer):
    """{driver name: {register: value}} from the simulated bus (M7106)."""
    out = {}
    for line in printer.send("M7106")[:-1]:
        words = line.split()
        out[words[1]] = {k: (int(v, 16) if v.startswith("0x") else int(v))
                         for k, v in (w.split("=") for w in words[2:])}
    return out


def check_driver(regs, microsteps, irun, spreadcycle=False):
    gconf = regs["GCONF"]
    assert gconf & tmc.MSTEP_REG_SELECT and gconf & tmc.PDN_DISABLE
    assert not gconf & tmc.I_SCALE_ANALOG
    assert bool(gconf & tmc.EN_SPREADCYCLE) == spreadcycle
    assert regs["CHOPCONF"] >> 24 & 15 == tmc.mres(microsteps)
    assert regs["IHOLD_IRUN"] >> 8 & 31 == irun


@pytest.mark.parametrize("board", TMC_BOARDS)
def test_every_driver_is_set_up_at_start(sim_printer, board):
    p = sim_printer(board=board)
    regs = registers(p)
    assert sorted(regs) == ["e0", "x", "y", "z"]
    for name in "xyz":  # 580 mA: CS round(19.06) - 1
        check_driver(regs[name], 16, 18)
    check_driver(regs["e0"], 16, tmc.current_fields(650, 110)[1])
    assert all(r["GSTAT"] == 0 and r["IFCNT"] == 4 for r in regs.values())
    p.finish()


def test_m906_and_m569_set_the_drivers_and_report_them(sim_printer):
    p = sim_printer(board="skr_pico")
    assert p.send("M906 X800 E1200") == ["ok"]
    assert p.send("M569 S1 X Y") == ["ok"]
    regs = registers(p)
    check_driver(regs["x"], 16, 25, spreadcycle=True)
    check_driver(regs["y"], 16, 18, spreadcycle=True)
    check_driver(regs["z"], 16, 18)
    assert regs["e0"]["IHOLD_IRUN"] >> 8 & 31 == 21
    assert not regs["e0"]["CHOPCONF"] & tmc.VSENSE
    assert p.send("M906") == ["echo:M906 X800 Y580 Z580 E1200", "ok"]
    assert p.send("M569") == ["echo:M569 S0 Z E", "echo:M569 S1 X Y", "ok"]
    assert "echo:x driver (TMC2209 address 0): 16 microsteps, run 795 mA, spreadCycle" \
        in p.send("M122")
    # Microsteps through the configuration: the driver counts 32, steps_per_mm is the user's.
    assert p.send("M926 Idriver_microsteps_z V32") == ["ok"]
    assert p.send("M930") == ["ok"]
    assert registers(p)["z"]["CHOPCONF"] >> 24 & 15 == tmc.mres(32)
    p.finish()


def test_a_change_of_microsteps_waits_for_the_queued_moves(sim_printer):
    p = sim_printer(board="skr_pico")
    for line in ("G28", "G1 X50 F600", "M926 Idriver_microsteps_x V32", "M930"):
        assert p.send(line)[-1] == "ok"  # M930 sends busy: lines while it waits
    # Written mid-move, it would have shifted every step after it.
    assert registers(p)["x"]["steps_at_chopconf"] == 50 * 80
    assert p.send("M906 X600") == ["ok"]  # a current needn't wait
    p.finish()


def test_bad_driver_values_get_an_error_and_change_nothing(sim_printer):
    p = sim_printer(board="skr_pico")
    before = registers(p)
    assert p.send("M906 X1700")[0] == "Error:driver_current_ma_x = 1700 is above the maximum 1600"
    assert p.send("M906 Y20")[0] == "Error:driver_current_ma_y = 20 is below the minimum 50"
    assert p.send("M569 S2 X")[0].startswith("Error:S2 out of range")
    assert p.send("M926 Idriver_microsteps_x V20")[0] == (
        "Error:driver_microsteps_x = 20 is not a power of two (1, 2, 4, ...)")
    assert p.send("M906") == ["echo:M906 X580 Y580 Z580 E650", "ok"]
    assert registers(p) == before
    p.finish()


def test_a_driver_without_motor_power_warns_at_start_and_the_printer_still_prints(
        sim_printer, monkeypatch):
    monkeypatch.setenv("MIXSTEP_SIM_TMC_OFF", "y")
    p = sim_printer(board="skr_pico")
    assert p.send("M906") == [
        "echo:Warning: y driver (TMC2209 address 2) does not answer on the UART (is the "
        "motor power on?); it steps on its MS1/MS2 straps until M122 sets it up",
        "echo:M906 X580 Y580 Z580 E650", "ok"]
    regs = registers(p)
    check_driver(regs["x"], 16, 18)
    check_driver(regs["e0"], 16, tmc.current_fields(650, 110)[1])  # the one after it
    assert regs["y"]["IFCNT"] == 0 and regs["y"]["GCONF"] == 0x41
    assert ("echo:y driver (TMC2209 address 2) does not answer on the UART (is the motor "
            "power on?); without UART set-up it steps 64 microsteps") in p.send("M122")
    # A change for it is an error that says so; the others take theirs.
    reply = p.send("M906 X800 Y800")
    assert reply[0].startswith("Error:y driver (TMC2209 address 2) does not answer")
    assert registers(p)["x"]["IHOLD_IRUN"] >> 8 & 31 == 25
    for line in ("G28", "G1 X10 Y10 F3000", "M400"):
        assert p.send(line)[-1] == "ok"
    # Power on: M122 sets it up with what was asked meanwhile.
    assert p.send("M7106 P2 S1") == ["ok"]
    assert "echo:y driver (TMC2209 address 2): 16 microsteps, run 795 mA, stealthChop" \
        in p.send("M122")
    check_driver(registers(p)["y"], 16, 25)
    report = p.finish()
    assert report["steps"]["x"] == 800 and report["steps"]["y"] == 800


def test_a_driver_whose_motor_power_was_cycled_is_set_up_again_by_m122(sim_printer):
    p = sim_printer(board="skr_pico")
    assert p.send("M7106 P1 S0") == ["ok"]
    assert p.send("M7106 P1 S1") == ["ok"]
    assert registers(p)["z"]["GSTAT"] == 1  # back at its reset values
    report = p.send("M122")
    assert report[0].startswith("echo:underruns:")  # the printer's diagnostics first
    assert any(re.match(r"echo:z driver \(TMC2209 address 1\): 16 microsteps", line)
               for line in report), report
    check_driver(registers(p)["z"], 16, 18)
    p.finish()
