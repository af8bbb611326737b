"""Where a setting comes from, in one order: the board's, then the saved configuration
(M500), then --set on the command line. A key the firmware doesn't have, or a value it
refuses, is an error naming it."""
import json

import pytest

from mixstep import cli, paths
from mixstep.simprinter import SimPrinter

EXCERPT = paths.ROOT / "testdata" / "part_3tool_emu_excerpt.gcode"


def _option(printer, name):
    return [l for l in printer.send("M503") if (" I%s " % name) in l]


def test_set_goes_over_a_saved_configuration(tmp_path):
    cfg = tmp_path / "mixstep.cfg"
    p = SimPrinter(config_path=cfg)
    assert p.send("M500") == ["ok"]  # every option saved, trace_records at the board's
    p.finish()
    p = SimPrinter(config_path=cfg, settings={"trace_records": 60000})
    assert "V60000 " in _option(p, "trace_records")[0]
    p.finish()
    p = SimPrinter(config_path=cfg)  # without --set, the saved value again
    assert "V60000 " not in _option(p, "trace_records")[0]
    p.finish()


@pytest.mark.parametrize("command", [["sim", str(EXCERPT)], ["serve", "--pty"],
                                     ["emu", "print"]])
@pytest.mark.parametrize("item,words", [("bogus_key=5", "no setting bogus_key"),
                                        ("tool_mixes_2=1,0", "no setting tool_mixes_2"),
                                        ("tick_us=abc", "not a whole number"),
                                        ("trace_records", "KEY=VALUE")])
def test_a_setting_the_firmware_would_not_take_is_refused(capsys, command, item, words):
    assert cli.main(command + ["--set", item]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and words in err, err


def test_sim_reads_a_saved_configuration_only_when_asked_and_set_goes_over_it(tmp_path):
    cfg = tmp_path / "mixstep.cfg"
    p = SimPrinter(config_path=cfg)
    assert p.send("M92 X100")[-1] == "ok" and p.send("M500") == ["ok"]
    p.finish()
    board_spm = paths.load_board("sim")["SETTINGS"]["steps_per_mm"]

    def x_steps(*argv):
        report = tmp_path / "r.json"
        assert cli.main(["sim", str(EXCERPT), "--report", str(report)] + list(argv)) == 0
        return json.loads(report.read_text())["steps"]["x"]
    plain = x_steps()
    assert x_steps("--config", str(cfg)) == round(plain * 100 / board_spm[0])
    assert x_steps("--config", str(cfg), "--set",
                   "steps_per_mm=" + ",".join(map(str, board_spm))) == plain
