# The simulated chip: stands in for `machine` so the firmware runs unchanged on the
# MicroPython unix port. Time is virtual: timers fire only when the firmware idles
# (machine.idle), and every output edge is recorded with its virtual time.
#
# It also models the printer around the chip: STEP/DIR edges move the axes, and the
# min endstops read triggered at or below position 0, where the axes start. With
# set_bounce (sim-only M7105, simswitch.py) a switch bounces as a mechanical one does:
# for bounce_us after the step that reaches it (or leaves it), its level flips at a
# few irregular points (_BOUNCE_64THS) before it settles.
#
# Edge records are 64-bit words: time_us << 8 | gpio << 1 | level, flushed to a file
# in native (little-endian) byte order outside the step loop. Recording never
# allocates, so the step loop can run with the heap locked, on a 32-bit port too: no
# value the step loop's callbacks compute reaches 2**30, where a 31-bit small int
# would become a heap-allocated big int. For that, the loops keep the time modulo
# 2**30 (_now_w) beside now_us (which outgrows 2**30 after 18 simulated minutes), and
# records are built from 16-bit pieces.
from array import array
import gc
import micropython
import sys
import time as walltime  # the real clock; firmware sees simtime instead

GPIO_COUNT = 48  # 0..29 like an RP2040 for the step path, more for heaters, fans, inputs
# The chip being simulated (set_chip): which GPIOs exist and which can drive a pin.
# "sim" is the simulated board's own chip: every GPIO 0..47 exists.
_CHIP_GPIOS = {
    "rp2040": tuple(range(30)), "rp2350": tuple(range(30)),
    "esp32": tuple(g for g in range(40) if g not in (20, 24, 28, 29, 30, 31)),
}
_INPUT_ONLY = {"esp32": (34, 35, 36, 37, 38, 39)}
chip = "sim"
# The system clock each chip boots with (machine.freq() changes it, as boot code may).
_BOOT_CLOCK_HZ = {"rp2040": 125000000, "rp2350": 150000000, "esp32": 160000000}
clock_hz = 125000000


def set_chip(name):
    global chip, clock_hz
    chip = name
    clock_hz = _BOOT_CLOCK_HZ.get(name, 125000000)


def freq(hz=None):
    """machine.freq(): the system clock, which the simulated PWM divides."""
    global clock_hz
    if hz is None:
        return clock_hz
    clock_hz = int(hz)


class _Mem32:
    """machine.mem32 for the one register boot.py writes: the RP2040's core regulator
    (VREG: VSEL 1.10 V and enabled, as at reset). Other words read 0."""

    def __init__(self):
        self.words = {0x40064000: 0xB1}

    def __getitem__(self, address):
        return self.words.get(address, 0)

    def __setitem__(self, address, value):
        self.words[address] = value & 0xFFFFFFFF


mem32 = _Mem32()

_CAPACITY = 8192
_FLUSH_AT = _CAPACITY - 256  # one tick writes far fewer edges than this

now_us = 0
quantum_us = 1000  # virtual time one idle() call advances; below 2**24
_W30 = 0x3FFFFFFF  # times modulo 2**30: small ints on every port
_now_w = 0  # now_us & _W30, kept by whatever sets now_us
# now_us at the start of the idle quantum, as (now_us >> 24, now_us & 0xFFFFFF): every
# edge until the next quantum falls less than 2**24 us after it, so a record's time
# is this plus at most one carry.
_base_hi = 0
_base_lo = 0
heap_lock_ticks = False  # lock the heap around every timer callback

_edges = array("H", bytes(8 * _CAPACITY))  # 4 pieces per record, low first
_n = 0
_out = None
_levels = bytearray(GPIO_COUNT)
_timers = []
# Live heap, sampled after a collection once per _HEAP_EVERY idle calls.
_HEAP_EVERY = 500
_idle_calls = 0
heap_peak_bytes = 0
# Models of the world around the chip (thermal, ...), called once per idle quantum.
_world_hooks = []
# Interrupt latency (set_jitter): each timer callback runs up to _jitter_max_us after
# its due time, by a seeded pseudo-random amount, and never before the callback
# before it. 0, the default, keeps idle()'s loop free of any per-tick cost.
_jitter_max_us = 0
_jitter_state = 0
# Virtual seconds allowed per wall second; 0 runs as fast as it can. Interactive
# consoles (TCP, PTY) pace the simulation so hosts see a printer in real time.
realtime_factor = 0
_wall_start_us = walltime.ticks_us()
_virtual_start_us = 0


# Devices that run on the chip's clock beside the CPU (rp2.py's DMA-fed state machine):
# fn(end_us) does what the device does up to end_us, inside the idle quantum.
_devices = []


def add_device(fn):
    if fn not in _devices:
        _devices.append(fn)


def add_world_hook(fn):
    """fn(now_us) runs after every idle quantum, outside the step loop."""
    _world_hooks.append(fn)


def pace(factor):
    global realtime_factor, _wall_start_us, _virtual_start_us
    realtime_factor = factor
    _wall_start_us = walltime.ticks_us()
    _virtual_start_us = now_us
# Printer model: what each pin is to the mechanics.
_role = bytearray(GPIO_COUNT)  # 1 + index for STEP pins, 0 otherwise
_dir_of = bytearray(GPIO_COUNT)  # STEP pin -> its DIR pin
_endstop_axis = bytearray(GPIO_COUNT)  # 1 + axis for endstop inputs
_inputs = [None] * GPIO_COUNT  # fn() -> level, for inputs a model drives (model_input)
positions = array("i", bytes(4 * 16))  # steps per STEP pin index
step_names = []


_dir_forward = bytearray(GPIO_COUNT)  # STEP pin -> DIR level that moves it forward


def attach_world(pin_map, step_names_in_order, inverted=()):
    """Tell the model which pins are STEP, DIR and endstops (names as in board.PINS);
    inverted: motors wired the other way round, moving forward with DIR low."""
    for i, name in enumerate(step_names_in_order):
        step_names.append(name)
        g = pin_map[name + "_step"]
        _role[g] = 1 + i
        _dir_of[g] = pin_map[name + "_dir"]
        _dir_forward[g] = 0 if name in inverted else 1
    for axis, name in enumerate(("x", "y", "z")):
        _endstop_axis[pin_map[name + "_min"]] = 1 + axis


# Switch bounce (set_bounce): per axis, whether its switch is still bouncing and the
# time (modulo 2**30, as the step loop keeps it) of the step that reached or left it.
bounce_us = 0
_BOUNCE_64THS = (5, 13, 22, 31, 45, 50)  # flips, in 64ths of bounce_us: irregular
_bouncing = bytearray(3)
_bounce_from_w = array("i", bytes(4 * 3))


def model_input(gpio, fn):
    """An input whose level a model of the printer gives: fn() -> 0 or 1, read when
    the firmware reads the pin (simbed.py's bed probe)."""
    _inputs[gpio] = fn


def _model_level(fn):
    """fn(), a model of the world outside the chip (simbed's floats are the bed's
    physics, not the firmware's). The firmware's step path reads the pin under
    --heap-lock, and what the model allocates there is no fault of the firmware's:
    it runs again with the heap open (the lock is a depth, so only where it is held)."""
    try:
        return fn()
    except MemoryError:
        if not heap_lock_ticks:
            raise
    micropython.heap_unlock()
    try:
        return fn()
    finally:
        micropython.heap_lock()


def set_bounce(us):
    """Bounce every min endstop for `us` after each contact and release (0: never)."""
    global bounce_us
    bounce_us = us
    for axis in range(3):
        _bouncing[axis] = 0
    if _settle_switches not in _world_hooks:
        add_world_hook(_settle_switches)


def set_input(gpio, level):
    """What the world outside drives an input to (a runout sensor, simswitch.py's
    M7107): the level its Pin reads. An input's level is no edge of the trace."""
    _levels[gpio] = 1 if level else 0


def _switch_level(axis):
    """The min endstop of `axis`: 1 at or below position 0, but for the flips of its
    bounce. Called in the step loop (timer backends): small ints only."""
    closed = 1 if positions[axis] <= 0 else 0
    if not _bouncing[axis]:
        return closed
    since_us = (_now_w - _bounce_from_w[axis]) & _W30
    if since_us >= bounce_us:
        _bouncing[axis] = 0
        return closed
    at = (since_us << 6) // bounce_us
    for flip in _BOUNCE_64THS:
        if at >= flip:
            closed ^= 1
    return closed


def _settle_switches(end_us):
    # A bounce nobody read for 2**30 us would wrap: settle them here (world hook).
    for axis in range(3):
        if _bouncing[axis]:
            _switch_level(axis)


def buffer_bytes():
    return len(_edges) * 2


def record_to(path):
    global _out
    _out = open(path, "wb")


def flush():
    global _n
    if _out is not None and _n:
        _out.write(memoryview(_edges)[0:4 * _n])
    _n = 0


def close():
    flush()
    if _out is not None:
        _out.close()


# The chip's GPIO set/clear registers, as a RAM bank the firmware writes with ptr32
# (pin_writer "registers"). After every timer callback the bank's writes become pin
# levels, in the same order and at the same virtual time as Pin.value writes would.
_bank = None
_bank_words = array("i", [0, 0, 0, 0])  # set, clear, hi set, hi clear word offsets


def register_bank(chip):
    """A bank laid out like the chip's registers; the firmware gets its address."""
    global _bank
    from mixfw.pins import REGISTERS
    _, set_at, clr_at, hi_set_at, hi_clr_at = REGISTERS[chip]
    for i, at in enumerate((set_at, clr_at, hi_set_at, hi_clr_at)):
        _bank_words[i] = at // 4
    _bank = array("I", bytes(4 * 16))
    return _bank


def _apply_bank():
    bank = _bank
    w = _bank_words
    for k in (0, 2):
        if k and not w[2]:
            break
        s = bank[w[k]]
        c = bank[w[k + 1]]
        if s | c:
            bank[w[k]] = 0
            bank[w[k + 1]] = 0
            first = 32 if k else 0
            m = s | c
            bit = 0
            while m:
                if m & 1:
                    _set_level(first + bit, (s >> bit) & 1)
                m >>= 1
                bit += 1


# The PIO state machine (boards/sim/rp2.py): words of pin levels waiting for their
# output time, in a ring; the real FIFO holds 8. Times are kept modulo 2**30 (_W30),
# as pio_put runs in the step loop, under the heap lock.
_PIO_SLOTS = 64
_HALF = 0x20000000  # a wrapped difference at or above this is negative
_pio_time = array("i", bytes(4 * _PIO_SLOTS))
_pio_word = array("i", bytes(4 * _PIO_SLOTS))
_pio_head = 0
_pio_tail = 0
_pio_base = 0  # first GPIO
_pio_count = 0  # GPIOs
_pio_period_us = 0  # one word's time
_pio_next_w = 0  # earliest time the next word can come out, modulo 2**30
pio_overflows = 0


def attach_pio(base_gpio, count, period_us):
    global _pio_base, _pio_count, _pio_period_us
    _pio_base = base_gpio
    _pio_count = count
    _pio_period_us = period_us


def pio_put(word):
    global _pio_head, _pio_next_w, pio_overflows
    head = _pio_head
    nxt = head + 1 if head + 1 < _PIO_SLOTS else 0
    if nxt == _pio_tail:
        pio_overflows += 1
        return
    at = _pio_next_w if ((_pio_next_w - _now_w) & _W30) < _HALF else _now_w
    _pio_time[head] = at
    _pio_word[head] = word
    _pio_next_w = (at + _pio_period_us) & _W30
    _pio_head = nxt


def _pio_output(until_us):
    """Output every word due by until_us, at its own time."""
    global now_us, _now_w, _pio_tail
    tail = _pio_tail
    if tail == _pio_head:
        return
    keep = now_us
    while tail != _pio_head:
        late = (until_us - _pio_time[tail]) & _W30
        if late >= _HALF:  # not due yet
            break
        now_us = until_us - late
        _now_w = now_us & _W30
        word = _pio_word[tail]
        bit = 0
        while bit < _pio_count:
            _set_level(_pio_base + bit, (word >> bit) & 1)
            bit += 1
        tail = tail + 1 if tail + 1 < _PIO_SLOTS else 0
    _pio_tail = tail
    now_us = keep
    _now_w = now_us & _W30


def _set_now(t_us):
    """Move virtual time to t_us outside the tick loops."""
    global now_us, _now_w, _base_hi, _base_lo
    now_us = t_us
    _now_w = t_us & _W30
    _base_hi = t_us >> 24
    _base_lo = t_us & 0xFFFFFF


def drain_pio():
    """Let the state machine output everything it holds (end of a run)."""
    if _pio_head != _pio_tail:
        ahead_us = (_pio_next_w - _now_w) & _W30
        end = now_us + (ahead_us if ahead_us < _HALF else 0)
        _pio_output(end)
        _set_now(end)


def _record(gpio, level):
    global _n
    lo = _now_w & 0xFFFFFF
    hi = _base_hi + 1 if lo < _base_lo else _base_hi
    i = 4 * _n
    _edges[i] = ((lo & 0xFF) << 8) | (gpio << 1) | level
    _edges[i + 1] = lo >> 8
    _edges[i + 2] = hi & 0xFFFF
    _edges[i + 3] = hi >> 16
    _n += 1
    if _n >= _CAPACITY:  # a flush outside idle() would be a bug: drop nothing, stop
        raise RuntimeError("edge buffer overflow")


def _set_level(g, v):
    if _levels[g] != v:
        _levels[g] = v
        _record(g, v)
        idx = _role[g]
        if idx and v:
            if _levels[_dir_of[g]] == _dir_forward[g]:
                positions[idx - 1] += 1
                touched = positions[idx - 1] == 1  # left the switch
            else:
                positions[idx - 1] -= 1
                touched = positions[idx - 1] == 0  # reached it
            if touched and idx <= 3 and bounce_us:
                _bouncing[idx - 1] = 1
                _bounce_from_w[idx - 1] = _now_w
    elif now_us == 0:
        _record(g, v)  # every signal gets a value at #0


class Pin:
    IN = 0
    OUT = 1
    OPEN_DRAIN = 2
    PULL_UP = 1
    PULL_DOWN = 2

    # As on the chips, Pin(n) is the one object of GPIO n, made before the firmware
    # runs: on rp2 and ESP32 the pin objects are a table in flash, so they cost the
    # firmware no heap, and here their heap is the simulation's.
    def __new__(cls, gpio, *args, **kw):
        if not 0 <= gpio < GPIO_COUNT or gpio not in _CHIP_GPIOS.get(chip, range(GPIO_COUNT)):
            raise ValueError("GPIO %d does not exist on the %s" % (gpio, chip))
        return _pin_table[gpio]

    def __init__(self, gpio, mode=-1, pull=-1, value=None):
        if mode == Pin.OUT and gpio in _INPUT_ONLY.get(chip, ()):
            raise ValueError("GPIO %d of the %s is input-only" % (gpio, chip))
        self.gpio = gpio
        self.mode = mode
        if value is not None:
            self.value(value)
        elif mode == Pin.OUT and now_us == 0:
            _record(gpio, _levels[gpio])
        elif mode == Pin.IN and pull in (Pin.PULL_UP, Pin.PULL_DOWN):
            # An input nothing drives reads its pull (until set_input drives it).
            _levels[gpio] = 1 if pull == Pin.PULL_UP else 0

    def value(self, v=None):
        g = self.gpio
        if v is None:
            axis = _endstop_axis[g]
            if axis:
                return _switch_level(axis - 1)
            fn = _inputs[g]
            if fn is not None:
                return _model_level(fn)
            return _levels[g]
        _set_level(g, 1 if v else 0)

    def on(self):
        self.value(1)

    def off(self):
        self.value(0)

    def __call__(self, v=None):
        return self.value(v)


_pin_table = []
for _g in range(GPIO_COUNT):
    _pin = object.__new__(Pin)
    _pin.gpio = _g
    _pin.mode = -1
    _pin_table.append(_pin)


def set_jitter(max_us, seed=1):
    """Fire every timer callback late by 0..max_us (0: on time, the default)."""
    global _jitter_max_us, _jitter_state
    _jitter_max_us = max_us
    _jitter_state = seed & 0x7FFFFFFF


def _draw_late_us():
    global _jitter_state
    # The C library's LCG: repeatable, and small ints only (no allocation).
    _jitter_state = (_jitter_state * 1103515245 + 12345) & 0x7FFFFFFF
    return (_jitter_state >> 8) % (_jitter_max_us + 1)


class Timer:
    ONE_SHOT = 0
    PERIODIC = 1

    def __init__(self, id=-1, **kw):
        self._cb = None
        if kw:
            self.init(**kw)

    def init(self, mode=1, freq=None, period=None, callback=None, hard=False):
        if freq:
            self.period_us = 1000000 // freq
        else:
            self.period_us = int(period * 1000)
        if self.period_us < 1:
            raise ValueError("timer period below 1 us")
        self._cb = callback
        self._next = now_us + self.period_us
        self._late_us = 0  # how late the callback due at _next will run
        if self not in _timers:
            _timers.append(self)

    def deinit(self):
        if self in _timers:
            _timers.remove(self)


def idle():
    """Advance virtual time by quantum_us, firing due timer callbacks."""
    global now_us, _now_w, _idle_calls, heap_peak_bytes
    _set_now(now_us)  # the quantum's base for the records
    _idle_calls += 1
    if _idle_calls >= _HEAP_EVERY:
        _idle_calls = 0
        gc.collect()
        used = gc.mem_alloc()
        if used > heap_peak_bytes:
            heap_peak_bytes = used
    end = now_us + quantum_us
    _fire_timers(end)
    for dev in _devices:
        dev(end)
    _pio_output(end)
    _set_now(end)
    for hook in _world_hooks:
        hook(end)
    for w in _watchdogs:
        if end - w.fed_us > w.timeout_us:
            _watchdog_reset(w)
    if realtime_factor:
        ahead_us = (end - _virtual_start_us) / realtime_factor - walltime.ticks_diff(
            walltime.ticks_us(), _wall_start_us)
        if ahead_us > 2000:
            walltime.sleep_us(int(ahead_us))


def _fire_timers(end):
    """Every timer callback due up to end."""
    for t in _timers:
        try:
            if _jitter_max_us:
                _fire_late(t, end)
            else:
                _fire_on_time(t, end)
        except Exception as e:
            # As MicroPython does with an interrupt handler that raised: report it and
            # disable the handler. The timer never fires again.
            _timers.remove(t)
            sys.stderr.write("simmachine: uncaught exception in timer callback, timer "
                             "disabled: %r\n" % (e,))
            break


# A flash write (hold_irqs): until this time every interrupt is held. rp2.py's DMA
# raises its IRQs meanwhile as pending.
irqs_off_until_us = 0


def hold_irqs(us):
    """Every interrupt held for `us` of virtual time, as the rp2 port holds them while
    it erases and programs flash; the main loop waits too, as it runs the write. The
    PIO and the DMA go on with the words they have. When the interrupts are back on,
    what became pending runs at once: the DMA IRQs, and each timer's callback once
    (the ticks it missed are lost: the step loop's time stood still)."""
    global irqs_off_until_us
    end = now_us + us
    irqs_off_until_us = end
    _set_now(now_us)
    for t in _timers:
        if t._next < end:
            t._next = end
    for dev in _devices:
        dev(end)
    _pio_output(end)
    _set_now(end)
    _fire_timers(end)


def _fire_on_time(t, end):
    """idle()'s timer loop: every callback due up to end, at its due time."""
    global now_us, _now_w
    cb = t._cb
    per = t.period_us
    nxt = t._next
    if heap_lock_ticks:
        while nxt <= end:
            if _pio_head != _pio_tail:  # a call per tick would cost more than the tick
                _pio_output(nxt)
            now_us = nxt
            _now_w = nxt & _W30
            micropython.heap_lock()
            try:  # an error must reach the firmware's handlers with the heap open
                cb(t)
                if _bank is not None:
                    _apply_bank()
            finally:
                micropython.heap_unlock()
            nxt += per
            if _n > _FLUSH_AT:
                flush()
    else:
        while nxt <= end:
            if _pio_head != _pio_tail:
                _pio_output(nxt)
            now_us = nxt
            _now_w = nxt & _W30
            cb(t)
            if _bank is not None:
                _apply_bank()
            nxt += per
            if _n > _FLUSH_AT:
                flush()
    t._next = nxt


# The chip's watchdog (machine.WDT): a reset when the firmware stops feeding it. Like
# a real reset it stops everything at once: the run ends with status 3 after one
# `//sim watchdog reset` line.
_watchdogs = []


class WDT:
    def __init__(self, id=0, timeout=5000):
        if timeout < 1:
            raise ValueError("watchdog timeout below 1 ms")
        self.timeout_us = timeout * 1000
        self.fed_us = now_us
        _watchdogs.append(self)

    def feed(self):
        self.fed_us = now_us


def release_watchdogs():
    del _watchdogs[:]


def _watchdog_reset(w):
    flush()
    sys.stdout.write("//sim watchdog reset at_us=%d fed_us=%d\n" % (now_us, w.fed_us))
    sys.exit(3)


def _fire_late(t, end):
    """idle()'s timer loop with interrupt latency: the callback due at nxt runs at
    nxt + late. Each one's lateness is drawn when the one before it has run, and
    raised if need be so it runs at least 1 us after that one: callbacks keep their
    order, as a late interrupt delays the next. A callback whose time falls after end
    waits for the next quantum."""
    global now_us, _now_w
    cb = t._cb
    per = t.period_us
    nxt = t._next
    late = t._late_us
    while nxt + late <= end:
        at = nxt + late
        _pio_output(at)
        now_us = at
        _now_w = at & _W30
        if heap_lock_ticks:
            micropython.heap_lock()
        try:
            cb(t)
            if _bank is not None:
                _apply_bank()
        finally:
            if heap_lock_ticks:
                micropython.heap_unlock()
        if _n > _FLUSH_AT:
            flush()
        nxt += per
        late = max(_draw_late_us(), late - per + 1)
    t._next = nxt
    t._late_us = late


def disable_irq():
    return 0


def enable_irq(state=0):
    pass


def unique_id():
    return b"mixstep-sim"


# The chip's peripherals in modules of their own, which reach this one through bind():
# they are its parts, so they don't import it.
_this = sys.modules[__name__]
try:  # heaters, fans and thermistors of the simulated board
    import simanalog
    simanalog.bind(_this)
    ADC, PWM = simanalog.ADC, simanalog.PWM
except ImportError:
    pass


def UART(*args, **kw):
    """The board's TMC2209 bus (simtmc.py), loaded only by a board that opens it."""
    import simtmc
    simtmc.bind(_this)
    return simtmc.UART(*args, **kw)
