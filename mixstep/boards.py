"""`mixstep boards check`: catch pin-map mistakes before they reach a board.

A board's board.py is plain data: NAME, CHIP, SOURCE, PINS, SHARED_PINS, TMC_UART,
SETTINGS and, optionally, RESERVED (GPIOs the board itself uses, with why). The
checks here are the rules a wrong map breaks on real hardware: a GPIO used twice, a
pin the chip doesn't have, the ESP32's flash pins, an output on an input-only pin, a
thermistor away from the ADC, a drive without its pins, a runout input (e<n>_runout)
of a drive beyond the sixth, an unstated ENABLE polarity or TMC address, a STEP/DIR
pin the step loop can't write, and on rp2 two PWM outputs of different frequencies on
one PWM slice.
"""
import re
import sys

from mixstep import paths

AXES = ("x", "y", "z")
MAX_DRIVES = 6
ENDSTOPS = ("x_min", "y_min", "z_min")
THERMAL = ("hotend_heater", "bed_heater", "part_fan", "hotend_thermistor", "bed_thermistor")
THERMISTORS = ("hotend_thermistor", "bed_thermistor")
# Pins a board may leave out: without a part fan the firmware answers M106 with an
# error (boards/pico_6drives gives the fan's pin to a sixth drive).
OPTIONAL = ("part_fan",)
# A bed probe's input, and a BLTouch's servo (deploy and stow), where a board has pins
# for them: G29/G30 answer an error on a board without z_probe.
PROBE = ("z_probe", "probe_servo")
OUTPUT_SUFFIXES = ("_step", "_dir", "_enable", "_heater")
_MOTOR_KEY = re.compile(r"^(x|y|z|e[0-9])_(step|dir|enable)$")
# A drive's filament runout input, which a board declares where it has a pin for it.
_RUNOUT_KEY = re.compile(r"^e([0-9])_runout$")

_RP2 = {
    "gpios": frozenset(range(30)),
    # ADC0-3; on boards that keep GPIO 29 for themselves RESERVED takes it away.
    "adc": frozenset(range(26, 30)),
    "adc_name": "ADC (GPIO 26-29)",
    "step": frozenset(range(30)),
    "flash": frozenset(),
    "input_only": frozenset(),
}
CHIPS = {
    "rp2040": _RP2,
    "rp2350": _RP2,  # RP2350A: the same 30 GPIOs as the RP2040
    "esp32": {
        "gpios": frozenset(g for g in range(40) if g not in (20, 24, 28, 29, 30, 31)),
        # ADC2 stops working while WiFi runs, so only ADC1 counts.
        "adc": frozenset(range(32, 40)),
        "adc_name": "ADC1 (GPIO 32-39; ADC2 is unusable with WiFi)",
        # The step loop's masks are 30 bits wide; GPIO 32/33 ride on bits 28/29.
        "step": frozenset(g for g in range(34) if g not in (20, 24, 28, 29, 30, 31)),
        "flash": frozenset(range(6, 12)),
        "input_only": frozenset(range(34, 40)),
    },
    # The simulated chip: 48 GPIOs, an ADC on any of them, a step path on 0-29.
    "sim": {
        "gpios": frozenset(range(48)),
        "adc": frozenset(range(48)),
        "adc_name": "the simulated ADC",
        "step": frozenset(range(30)),
        "flash": frozenset(),
        "input_only": frozenset(),
    },
}
STEP_BACKENDS = {"timer": tuple(CHIPS), "pio": ("rp2040", "rp2350"),
                 "pio_dma": ("rp2040", "rp2350")}
PIN_WRITERS = ("registers", "pin")
# The fastest system clock each chip is certified for (clock_hz): the RP2040 at 200 MHz
# with its core at 1.15 V (pico-sdk 2.1.1), the RP2350 at 150 MHz, the ESP32 at 240.
MAX_CLOCK_HZ = {"rp2040": 200000000, "rp2350": 150000000, "esp32": 240000000}
TMC_ADDRESSES = range(4)  # TMC2209: MS1/MS2 straps give 0..3
TMC_SETTINGS = ("driver_microsteps", "driver_current_ma", "driver_spreadcycle")


def setting_value(text):
    """VALUE of --set KEY=VALUE, read as the simulated board reads it: a number, a
    comma-separated tuple (a trailing comma makes a tuple of one), or text."""
    if "," in text:
        return tuple(setting_value(w) for w in text.split(",") if w)
    if text[:1] not in "0123456789+-.":
        return text
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return text


def check_settings(board, settings):
    """settings ({key: VALUE text} of --set) laid over the board's, checked as the
    firmware checks its configuration; returns them as values. UsageError, naming the
    key, for one the firmware doesn't have or a value it refuses."""
    from mixfw.config import Config, ConfigError
    from mixstep.outfile import UsageError
    base = paths.load_board(board)["SETTINGS"]
    known = Config(base, None).settings
    values = {}
    for key, text in settings.items():
        if key not in known:
            raise UsageError("--set %s: the board has no setting %s (the settings are "
                             "listed in docs/Config_Reference.md)" % (key, key))
        values[key] = setting_value(text) if isinstance(text, str) else text
    try:
        Config(dict(base, **values), None)
    except ConfigError as err:
        raise UsageError("--set %s" % str(err).replace("board default ", "", 1))
    return values


def set_items(board, items):
    """The settings of --set KEY=VALUE items, checked against the board's
    (check_settings)."""
    from mixstep.outfile import UsageError
    settings = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep or not key:
            raise UsageError("--set wants KEY=VALUE, got %r" % item)
        settings[key] = value
    return check_settings(board, settings)


def board_names():
    return sorted(p.parent.name for p in paths.BOARDS.glob("*/board.py"))


def check_board(name):
    """Problems with the board's pin map and settings, as messages; empty if none."""
    try:
        board = paths.load_board(name)
    except FileNotFoundError:
        return ["%s: no board of that name (boards: %s)" % (name, ", ".join(board_names()))]
    except Exception as e:  # a board file that doesn't even run is a problem to report
        return ["%s: board.py fails to load: %s: %s" % (name, type(e).__name__, e)]
    return check(board, name)


def check(board, name):
    """Problems with one board, given as the namespace of its board.py."""
    problems = []

    def bad(text):
        problems.append("%s: %s" % (name, text))

    pins = board.get("PINS")
    settings = board.get("SETTINGS")
    if not isinstance(pins, dict) or not isinstance(settings, dict):
        bad("board.py must define PINS and SETTINGS as dicts")
        return problems
    if board.get("NAME") != name:
        bad("NAME is %r, but the board's directory is %r" % (board.get("NAME"), name))
    chip = board.get("CHIP", settings.get("chip"))
    if chip not in CHIPS:
        bad("CHIP %r is not one of %s" % (chip, ", ".join(CHIPS)))
        return problems
    if settings.get("chip") != chip:
        bad("SETTINGS chip %r differs from CHIP %r" % (settings.get("chip"), chip))
    if chip != "sim" and not board.get("SOURCE"):
        bad("SOURCE missing: say where the pin numbers come from")
    rules = CHIPS[chip]

    drives = _check_settings(settings, chip, bad)
    tmc = board.get("TMC_UART")
    _check_required(pins, drives, bad)
    if settings.get("step_backend") in ("pio", "pio_dma") and chip in STEP_BACKENDS["pio"] \
            and drives:
        _check_pio_run(pins, drives, bad)
    # Every GPIO the board uses, with the key that names it; the TMC UART counts too.
    used = [(k, g) for k, g in pins.items()]
    if isinstance(tmc, dict):
        used += [("tmc_uart_tx", tmc.get("tx")), ("tmc_uart_rx", tmc.get("rx"))]
    reserved = board.get("RESERVED", {})
    for key, gpio in used:
        _check_pin(key, gpio, chip, rules, reserved, bad)
    _check_shared(pins, used, board.get("SHARED_PINS", ()), bad)
    if chip in ("rp2040", "rp2350"):
        _check_pwm_slices(pins, settings, bad)
    _check_tmc(tmc, settings, bad)
    return problems


def _check_settings(settings, chip, bad):
    """Settings a board must state; returns the drive count (0 if unusable)."""
    for key in ("drives", "tick_us", "enable_active_low"):
        if key not in settings:
            bad("SETTINGS has no %r: the board must state it (defaults leave it out)" % key)
    if "enable_active_low" in settings and not isinstance(settings["enable_active_low"], bool):
        bad("enable_active_low must be True or False, not %r" % (settings["enable_active_low"],))
    drives = settings.get("drives", 0)
    if not isinstance(drives, int) or not 1 <= drives <= MAX_DRIVES:
        bad("drives is %r; it must be 1..%d" % (drives, MAX_DRIVES))
        drives = 0
    tick_us = settings.get("tick_us", 1)
    if not isinstance(tick_us, int) or tick_us < 1:
        bad("tick_us is %r; it must be a whole number of microseconds >= 1" % (tick_us,))
    backend = settings.get("step_backend", "timer")
    if backend not in STEP_BACKENDS:
        bad("step_backend %r is not one of %s" % (backend, ", ".join(STEP_BACKENDS)))
    elif chip not in STEP_BACKENDS[backend]:
        bad("step_backend %r needs an rp2 chip; this is %s" % (backend, chip))
    clock_hz = settings.get("clock_hz", 0)
    top_hz = MAX_CLOCK_HZ.get(chip, 0)
    if clock_hz and not (isinstance(clock_hz, int) and 48000000 <= clock_hz <= top_hz):
        allowed = ("48 MHz..%d MHz" % (top_hz // 1000000) if top_hz
                   else "0 on the simulated chip")
        bad("clock_hz is %r; it must be 0 (the clock the chip boots with) or %s"
            % (clock_hz, allowed))
    writer = settings.get("pin_writer", "pin")
    if writer not in PIN_WRITERS:
        bad("pin_writer %r is not one of %s" % (writer, ", ".join(PIN_WRITERS)))
    motors = AXES + tuple("e%d" % i for i in range(drives))
    for axis in settings.get("invert_dir", ()):
        if axis not in motors:
            bad("invert_dir names %r, which is not one of %s" % (axis, ", ".join(motors)))
    spm = settings.get("steps_per_mm")
    if not (isinstance(spm, tuple) and len(spm) == 4 and all(v > 0 for v in spm)):
        bad("steps_per_mm must be a tuple of four positive numbers (X, Y, Z, E), not %r"
            % (spm,))
    return drives


def _check_required(pins, drives, bad):
    motors = AXES + tuple("e%d" % i for i in range(drives))
    required = ["%s_%s" % (m, f) for m in motors for f in ("step", "dir", "enable")]
    required += [k for k in ENDSTOPS + THERMAL if k not in OPTIONAL]
    for key in required:
        if key not in pins:
            bad("PINS has no %r" % key)
    known = set(ENDSTOPS) | set(THERMAL) | set(PROBE)
    for key in pins:
        m = _MOTOR_KEY.match(key)
        runout = _RUNOUT_KEY.match(key)
        if runout and int(runout.group(1)) >= MAX_DRIVES:
            bad("PINS has %r, but drives go up to e%d" % (key, MAX_DRIVES - 1))
        elif key not in known and not runout and not (
                m and (m.group(1) in AXES or int(m.group(1)[1:]) < MAX_DRIVES)):
            bad("PINS has an unknown key %r" % key)


def _check_pio_run(pins, drives, bad):
    """The state machine writes one run of GPIOs: the firmware's own rule, which would
    otherwise refuse to start on the board."""
    from mixfw import pio
    try:
        pio.out_range(pins, AXES + tuple("e%d" % i for i in range(drives)))
    except KeyError:
        pass  # a missing pin is reported already
    except ValueError as e:
        bad(str(e))


def _is_output(key):
    return key.endswith(OUTPUT_SUFFIXES) or key in ("part_fan", "tmc_uart_tx", "probe_servo")


def _check_pin(key, gpio, chip, rules, reserved, bad):
    if not isinstance(gpio, int) or isinstance(gpio, bool):
        bad("%s is %r, not a GPIO number" % (key, gpio))
        return
    where = "%s on GPIO %d" % (key, gpio)
    if gpio not in rules["gpios"]:
        bad("%s: no such GPIO on the %s" % (where, chip))
        return
    if gpio in rules["flash"]:
        bad("%s: GPIO 6-11 belong to the %s's SPI flash and must never be used"
            % (where, chip))
    if gpio in reserved:
        bad("%s: the board uses this GPIO itself (%s)" % (where, reserved[gpio]))
    if _is_output(key) and gpio in rules["input_only"]:
        bad("%s: GPIO 34-39 are input only, and %s is an output" % (where, key))
    if key in THERMISTORS and (gpio not in rules["adc"] or gpio in reserved):
        bad("%s: a thermistor needs an ADC pin: %s" % (where, rules["adc_name"]))
    if key.endswith(("_step", "_dir")) and gpio not in rules["step"]:
        bad("%s: the step loop writes only GPIO %s on the %s"
            % (where, _ranges(rules["step"]), chip))


def _check_shared(pins, used, shared, bad):
    groups = {}
    for group in shared:
        for key in group:
            if key not in pins:
                bad("SHARED_PINS names %r, which is not in PINS" % key)
        gpios = {pins[k] for k in group if k in pins}
        if len(gpios) > 1:
            bad("SHARED_PINS group %s is spread over GPIOs %s; a group shares one GPIO"
                % (", ".join(group), sorted(gpios)))
        kinds = {k.rsplit("_", 1)[-1] for k in group}
        if len(kinds) > 1:
            bad("SHARED_PINS group %s mixes functions (%s); only like pins may share"
                % (", ".join(group), ", ".join(sorted(kinds))))
        for key in group:
            groups[key] = frozenset(group)
    by_gpio = {}
    for key, gpio in used:
        if isinstance(gpio, int):
            by_gpio.setdefault(gpio, []).append(key)
    for gpio, keys in sorted(by_gpio.items()):
        group = groups.get(keys[0])
        if len(keys) > 1 and (group is None or any(groups.get(k) != group for k in keys)):
            bad("GPIO %d is used by %s; only pins listed together in SHARED_PINS may "
                "share a GPIO" % (gpio, ", ".join(keys)))


# PWM outputs and the setting that gives each one's frequency.
PWM_OUTPUTS = (("hotend_heater", "hotend_pwm_hz"), ("bed_heater", "bed_pwm_hz"),
               ("part_fan", "fan_pwm_hz"))


def _check_pwm_slices(pins, settings, bad):
    """On rp2 both channels of a PWM slice run at one frequency."""
    by_slice = {}
    for key, freq_key in PWM_OUTPUTS:
        gpio = pins.get(key)
        if isinstance(gpio, int):
            by_slice.setdefault((gpio >> 1) & 7, []).append((key, gpio, settings.get(freq_key)))
    for pwm_slice, outs in sorted(by_slice.items()):
        if len({freq for _, _, freq in outs}) > 1:
            bad("%s share PWM slice %d but want different frequencies (%s Hz); put them "
                "on different slices (slice = GPIO / 2 mod 8)" % (
                    " and ".join("%s on GPIO %d" % (k, g) for k, g, _ in outs), pwm_slice,
                    "/".join(str(f) for _, _, f in outs)))


def _check_tmc(tmc, settings, bad):
    if tmc is None:
        return
    if not isinstance(tmc, dict):
        bad("TMC_UART must be None or a dict with tx, rx and addresses, not %r" % (tmc,))
        return
    for key in ("tx", "rx"):
        if key not in tmc:
            bad("TMC_UART has no %r pin" % key)
    # The firmware opens machine.UART(uart) on tx/rx and sets the drivers' current
    # from their sense resistors.
    if not isinstance(tmc.get("uart"), int) or isinstance(tmc.get("uart"), bool):
        bad("TMC_UART has no 'uart': the id of the chip's UART on its tx/rx pins")
    elif tmc["uart"] == settings.get("console_uart", -1):
        bad("TMC_UART uart %d is also console_uart" % tmc["uart"])
    if not isinstance(tmc.get("baud"), int):
        bad("TMC_UART has no 'baud'")
    sense = tmc.get("sense_mohm")
    if not isinstance(sense, int) or not 50 <= sense <= 1000:
        bad("TMC_UART sense_mohm is %r: the drivers' sense resistors in milliohms "
            "(50..1000; 110 on most boards)" % (sense,))
    for key in TMC_SETTINGS:
        value = settings.get(key)
        if not (isinstance(value, tuple) and len(value) == 4):
            bad("SETTINGS has no %s for X, Y, Z, E: a board with TMC_UART states the "
                "drivers' settings" % key)
    addresses = tmc.get("addresses")
    if not isinstance(addresses, dict) or not addresses:
        bad("TMC_UART has no addresses: state the address of every driver on the UART")
        return
    # The driver options are per axis X Y Z E: E is the board's E socket, e0.
    motors = AXES + ("e0",)
    seen = {}
    for driver, address in addresses.items():
        if driver not in motors:
            bad("TMC_UART address for %r, which is not one of %s" % (driver, ", ".join(motors)))
        if address not in TMC_ADDRESSES:
            bad("TMC_UART address of %s is %r; a TMC2209 answers on 0..3" % (driver, address))
        elif address in seen:
            bad("TMC_UART address %d is given to both %s and %s" % (address, seen[address], driver))
        else:
            seen[address] = driver


def _ranges(gpios):
    """0-19, 21-23 style text of a set of GPIOs."""
    out = []
    for g in sorted(gpios):
        if out and g == out[-1][1] + 1:
            out[-1][1] = g
        else:
            out.append([g, g])
    return ", ".join("%d" % a if a == b else "%d-%d" % (a, b) for a, b in out)


def run_check(names):
    names = names or board_names()
    failed = 0
    for name in names:
        problems = check_board(name)
        for p in problems:
            print(p, file=sys.stderr)
        print("%s: %s" % (name, "ok" if not problems else "%d problem(s)" % len(problems)))
        failed += bool(problems)
    return 1 if failed else 0


def _run(args):
    return run_check(args.names)


def add_parser(sub):
    p = sub.add_parser("boards", help="board definitions: check pin maps")
    boards_sub = p.add_subparsers(dest="boards_command", required=True)
    c = boards_sub.add_parser("check", help="check pin maps (all boards if none named)")
    c.add_argument("names", nargs="*", metavar="NAME", help="board names (boards/<NAME>)")
    c.set_defaults(run=_run)
