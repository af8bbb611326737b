"""Board definitions: every real board passes the pin-map checks, and each check
catches the mistake it is there for (broken maps built from real boards)."""
import copy

import pytest

from mixstep import boards, cli, paths

# Every board in boards/, so a new one is checked without being listed here.
REAL_BOARDS = tuple(n for n in boards.board_names() if n != "sim")


def test_the_real_boards_are_found():
    assert set(REAL_BOARDS) >= {"pico", "pico2", "pico_6drives", "esp32_devkit", "skr_pico",
                                "fysetc_e4"}


def broken(name, pins=None, settings=None, drop_settings=(), **attrs):
    """A real board's namespace with some pins, settings or attributes changed."""
    board = copy.deepcopy({k: v for k, v in paths.load_board(name).items()
                           if k != "__builtins__" and not hasattr(v, "__file__")})
    board["PINS"].update(pins or {})
    board["SETTINGS"].update(settings or {})
    for key in drop_settings:
        del board["SETTINGS"][key]
    board.update(attrs)
    return boards.check(board, name)


def assert_one(problems, *words):
    """Exactly one problem, and it names every one of words."""
    assert len(problems) == 1, problems
    for w in words:
        assert w in problems[0], (w, problems[0])


@pytest.mark.parametrize("name", REAL_BOARDS + ("sim",))
def test_board_passes(name):
    assert boards.check_board(name) == []


@pytest.mark.parametrize("name", REAL_BOARDS)
def test_board_declares_everything(name):
    b = paths.load_board(name)
    assert b["NAME"] == name
    assert b["CHIP"] == b["SETTINGS"]["chip"] in ("rp2040", "rp2350", "esp32")
    assert b["SOURCE"]
    for key in ("step_backend", "pin_writer", "invert_dir", "drives", "steps_per_mm",
                "enable_active_low", "tick_us", "console_uart"):
        assert key in b["SETTINGS"], key


def test_every_board_starts_from_the_defaults():
    from mixfw import defaults
    for name in REAL_BOARDS + ("sim",):
        settings = paths.load_board(name)["SETTINGS"]
        assert set(defaults.SETTINGS) <= set(settings), name


def test_sim_settings_unchanged_by_the_split(board):
    # Values the simulation's tests rely on.
    s = board["SETTINGS"]
    assert (s["tick_us"], s["drives"], s["steps_per_mm"]) == (20, 6, (80.0, 80.0, 400.0, 415.0))
    assert (s["chip"], s["pin_writer"], s["step_backend"], s["invert_dir"]) == (
        "sim", "pin", "timer", ())


def test_skr_pico_published_map():
    b = paths.load_board("skr_pico")
    p = b["PINS"]
    assert [p[k] for k in ("x_step", "x_dir", "x_enable")] == [11, 10, 12]
    assert [p[k] for k in ("y_step", "y_dir", "y_enable")] == [6, 5, 7]
    assert [p[k] for k in ("z_step", "z_dir", "z_enable")] == [19, 28, 2]
    assert [p[k] for k in ("e0_step", "e0_dir", "e0_enable")] == [14, 13, 15]
    assert [p[k] for k in ("x_min", "y_min", "z_min")] == [4, 3, 25]
    assert set(b["SETTINGS"]["invert_dir"]) == {"x", "y", "e0"}
    assert b["TMC_UART"]["addresses"] == {"x": 0, "y": 2, "z": 1, "e0": 3}
    assert (b["TMC_UART"]["tx"], b["TMC_UART"]["rx"]) == (8, 9)


def test_fysetc_e4_published_map():
    b = paths.load_board("fysetc_e4")
    p = b["PINS"]
    assert [p[k] for k in ("x_step", "x_dir", "y_step", "y_dir")] == [27, 26, 33, 32]
    assert [p[k] for k in ("z_step", "z_dir", "e0_step", "e0_dir")] == [14, 12, 16, 17]
    assert {p[a + "_enable"] for a in ("x", "y", "z", "e0")} == {25}
    assert (b["TMC_UART"]["rx"], b["TMC_UART"]["tx"]) == (21, 22)


# --- each rule catches its mistake -------------------------------------------------

def test_esp32_flash_pin():
    assert_one(broken("esp32_devkit", pins={"e0_step": 7}), "e0_step", "GPIO 7", "flash")


def test_esp32_output_on_input_only_pin():
    problems = broken("fysetc_e4", pins={"hotend_heater": 35, "y_min": 2})
    assert_one(problems, "hotend_heater", "GPIO 35", "input only")


def test_esp32_step_pin_beyond_the_step_path():
    # 34 is an input-only pin too, so both rules speak.
    problems = broken("esp32_devkit", pins={"x_step": 34, "x_min": 23})
    assert len(problems) == 2 and all("x_step on GPIO 34" in p for p in problems)
    assert any("step loop writes only GPIO" in p for p in problems)


def test_duplicate_pin():
    assert_one(broken("skr_pico", pins={"e2_dir": 4}), "GPIO 4", "x_min", "e2_dir",
               "SHARED_PINS")


def test_pin_shared_with_the_tmc_uart():
    assert_one(broken("skr_pico", pins={"e2_dir": 8}), "GPIO 8", "e2_dir", "tmc_uart_tx")


def test_shared_pins_must_be_declared_together():
    # The Pico's common ENABLE without its SHARED_PINS entry is a duplicate.
    problems = broken("pico", SHARED_PINS=())
    assert_one(problems, "GPIO 16", "x_enable", "e4_enable")
    # A group that mixes functions is refused even when it is declared.
    problems = broken("pico", pins={"x_min": 16},
                      SHARED_PINS=(("x_enable", "y_enable", "z_enable", "e0_enable",
                                    "e1_enable", "e2_enable", "e3_enable", "e4_enable",
                                    "x_min"),))
    assert any("mixes functions" in p for p in problems), problems


def test_pin_the_chip_lacks():
    assert_one(broken("pico", pins={"z_min": 30}), "z_min", "GPIO 30", "no such GPIO")
    assert_one(broken("esp32_devkit", pins={"z_min": 20}), "GPIO 20", "no such GPIO")


def test_pin_the_board_keeps_for_itself():
    assert_one(broken("pico", pins={"z_min": 25}), "z_min", "GPIO 25", "LED")


def test_thermistor_off_the_adc():
    # ADC2 (the probe's GPIO 28, which takes 27 instead): fine
    assert broken("pico", pins={"bed_thermistor": 28, "z_probe": 27}) == []
    assert_one(broken("pico", pins={"bed_thermistor": 22, "z_min": 27}),
               "bed_thermistor", "GPIO 22", "ADC")
    # GPIO 29 is an ADC pin of the chip, but the Pico keeps it for VSYS/3.
    problems = broken("pico", pins={"bed_thermistor": 29})
    assert any("bed_thermistor on GPIO 29" in p and "ADC" in p for p in problems), problems
    # On the ESP32 only ADC1 counts: GPIO 0 (free on the DevKit) is on ADC2.
    assert_one(broken("esp32_devkit", pins={"hotend_thermistor": 0}),
               "hotend_thermistor", "GPIO 0", "ADC1")


def test_drive_without_pins():
    b = paths.load_board("esp32_devkit")
    pins = dict(b["PINS"])
    del pins["e3_enable"]
    problems = broken("esp32_devkit", PINS=pins,
                      SHARED_PINS=(("x_enable", "y_enable", "z_enable", "e0_enable",
                                    "e1_enable", "e2_enable"),))
    assert_one(problems, "e3_enable")
    # Raising drives beyond the wired pins is caught the same way.
    problems = broken("skr_pico", settings={"drives": 4})
    assert sorted(problems) == sorted("skr_pico: PINS has no 'e3_%s'" % f
                                      for f in ("step", "dir", "enable"))


def test_enable_polarity_must_be_stated():
    assert_one(broken("fysetc_e4", drop_settings=("enable_active_low",)),
               "enable_active_low", "must state")


def test_tmc_addresses():
    bus = paths.load_board("fysetc_e4")["TMC_UART"]
    tmc = dict(bus, addresses={})
    assert_one(broken("fysetc_e4", TMC_UART=tmc), "TMC_UART has no addresses")
    tmc = dict(bus, addresses={"x": 1, "y": 1, "z": 0, "e0": 2})
    assert_one(broken("fysetc_e4", TMC_UART=tmc), "address 1", "x", "y")
    tmc = dict(bus, addresses={"x": 1, "y": 3, "z": 0, "e0": 4})
    assert_one(broken("fysetc_e4", TMC_UART=tmc), "e0", "0..3")


def test_settings_rules():
    assert_one(broken("esp32_devkit", settings={"step_backend": "pio"}), "pio", "rp2")
    assert broken("pico", settings={"step_backend": "pio"}) == []
    assert broken("pico_6drives", settings={"step_backend": "pio_dma"}) == []
    # A sixth drive's DIR away from the other STEP/DIR pins.
    assert_one(broken("pico_6drives", pins={"e5_dir": 28, "hotend_heater": 17},
                      settings={"step_backend": "pio"}), "pio", "one run of GPIOs", "16, 28")
    assert_one(broken("pico", settings={"pin_writer": "fast"}), "pin_writer")
    assert_one(broken("pico", settings={"invert_dir": ("x", "e5")}), "invert_dir", "e5")
    # The clock: up to what the chip is certified for (the RP2040's 200 MHz at 1.15 V).
    assert broken("pico", settings={"clock_hz": 0}) == []
    assert_one(broken("pico", settings={"clock_hz": 250000000}), "clock_hz", "200 MHz")
    assert_one(broken("pico2", settings={"clock_hz": 200000000}), "clock_hz", "150 MHz")
    assert_one(broken("sim", settings={"clock_hz": 125000000}), "clock_hz", "simulated")


def test_pico_6drives_trades_the_part_fan_for_a_sixth_drive():
    six, five = paths.load_board("pico_6drives"), paths.load_board("pico")
    assert six["SETTINGS"]["drives"] == 6 and "part_fan" not in six["PINS"]
    # e5 next to e4, where pico has its ENABLE and hot end; those take the fan's GPIO
    # and pico's probe input 28 (pico_6drives has no probe). The rest is wired as on
    # pico.
    assert (six["PINS"]["e5_step"], six["PINS"]["e5_dir"]) == (16, 17)
    assert six["PINS"]["x_enable"] == five["PINS"]["part_fan"]
    assert six["PINS"]["hotend_heater"] == five["PINS"]["z_probe"] == 28
    assert "z_probe" not in six["PINS"]
    moved = {"hotend_heater"} | {k for k in six["PINS"] if k.endswith("_enable")}
    assert all(five["PINS"][k] == v for k, v in six["PINS"].items()
               if k in five["PINS"] and k not in moved)
    # Every pin the Pico brings out is used.
    header = set(range(23)) | {26, 27, 28}
    assert set(six["PINS"].values()) == header
    # Without a fan the check passes; pico without its fan, too (the fan is optional).
    assert broken("pico", PINS={k: v for k, v in five["PINS"].items() if k != "part_fan"}) == []


def test_runout_inputs_are_checked_as_other_pins():
    """A drive's runout input (e<n>_runout) may go on an input-only pin, but not on a
    pin in use, nor name a drive beyond the sixth."""
    assert broken("esp32_devkit", pins={"e0_runout": 37}) == []  # input only: fine
    assert_one(broken("skr_pico", pins={"e2_runout": 4}), "GPIO 4", "x_min", "e2_runout")
    assert_one(broken("pico", pins={"e1_runout": 25}), "e1_runout", "GPIO 25", "LED")
    assert_one(broken("sim", pins={"e6_runout": 43}), "e6_runout", "up to e5")


def test_pwm_slice_shared_at_two_frequencies():
    # GPIO 16 and 17 are slice 0 A/B: the 1 kHz fan next to the 10 Hz hot end.
    problems = broken("pico", pins={"part_fan": 16, "x_enable": 21, "y_enable": 21,
                                    "z_enable": 21, "e0_enable": 21, "e1_enable": 21,
                                    "e2_enable": 21, "e3_enable": 21, "e4_enable": 21})
    assert_one(problems, "slice 0", "hotend_heater", "part_fan")


def test_cli_exit_status(capsys):
    assert cli.main(["boards", "check"]) == 0
    out = capsys.readouterr().out
    for name in REAL_BOARDS:
        assert "%s: ok" % name in out
    assert cli.main(["boards", "check", "no_such_board"]) == 1
    assert "no board of that name" in capsys.readouterr().err
