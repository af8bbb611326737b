# The simulated chip's ADC inputs and PWM outputs, as `machine.ADC` and `machine.PWM`.
#
# The chip knows nothing of thermistors or heaters: a model of the world (simthermal)
# tells each ADC input what it reads, with set_source(), and reads back what each PWM
# output drives, with duty_of().

# The simulated chip (simmachine.py), which binds itself here when it loads this module.
simmachine = None


def bind(machine):
    global simmachine
    simmachine = machine


_sources = {}  # gpio -> fn() returning a read_u16() value
_pwms = {}  # gpio -> the PWM driving it
_FLOATING_U16 = 32768  # an input nothing drives reads mid-scale


def _gpio(pin):
    g = pin if isinstance(pin, int) else pin.gpio
    if not 0 <= g < simmachine.GPIO_COUNT:
        raise ValueError("GPIO %d does not exist (0..%d)" % (g, simmachine.GPIO_COUNT - 1))
    return g


def set_source(gpio, fn):
    """fn() gives what the ADC on this gpio reads from now on."""
    _sources[gpio] = fn


def duty_of(gpio):
    """The duty (0..1) a PWM drives on this gpio; where none does, the pin's level (a
    heater the firmware switches itself)."""
    p = _pwms.get(gpio)
    return p._duty_u16 / 65535 if p is not None else float(simmachine._levels[gpio])


def _check_freq(hz, clock_hz):
    """Refuse a frequency as the chip's MicroPython does (ValueError)."""
    if simmachine.chip == "esp32":
        # ports/esp32/machine_pwm.c: check_freq_ranges against half the APB clock.
        if not 0 < hz <= min(clock_hz, 80000000) // 2:
            raise ValueError("frequency must be from 1Hz to %dMHz"
                             % (min(clock_hz, 80000000) // 2000000))
        return
    # ports/rp2/machine_pwm.c (the simulated chip is one too): the smallest divider in
    # 16ths that keeps TOP at most 65534; the divider register stops below 256.
    if hz <= 0:
        raise ValueError("freq too small")
    if (clock_hz + hz // 2) // hz < 65534:
        div16 = 16
    else:
        div16 = -(-16 * clock_hz // (65534 * hz))
    if div16 >= 256 * 16:
        raise ValueError("freq too small")
    # Where rp2 takes a TOP below 1 and makes another frequency, the simulated chip
    # refuses: a test then sees it.
    if hz > clock_hz // 2:
        raise ValueError("freq too large")


def pwm_of(gpio):
    return _pwms.get(gpio)


class ADC:
    def __init__(self, id):
        self.gpio = _gpio(id)

    def read_u16(self):
        fn = _sources.get(self.gpio)
        if fn is None:
            return _FLOATING_U16
        v = int(fn())
        return 0 if v < 0 else 65535 if v > 65535 else v


class PWM:
    def __init__(self, pin, freq=1000, duty_u16=0):
        self.gpio = _gpio(pin)
        self._freq = 0
        self._duty_u16 = 0
        # Virtual time of the last change to 0, so tests can measure how fast a
        # fault turned a heater off.
        self.off_since_us = simmachine.now_us
        self.freq(freq)
        self.duty_u16(duty_u16)
        _pwms[self.gpio] = self

    def freq(self, hz=None):
        if hz is None:
            return self._freq
        _check_freq(int(hz), simmachine.clock_hz)
        self._freq = int(hz)

    def duty_u16(self, d=None):
        if d is None:
            return self._duty_u16
        d = int(d)
        if not 0 <= d <= 65535:
            raise ValueError("duty_u16 %d out of range 0..65535" % d)
        if d == 0 and self._duty_u16 != 0:
            self.off_since_us = simmachine.now_us
        self._duty_u16 = d

    def deinit(self):
        self.duty_u16(0)
        if _pwms.get(self.gpio) is self:
            del _pwms[self.gpio]
