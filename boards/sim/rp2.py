# The simulated chip's PIO and DMA, for step_backends "pio" and "pio_dma". The PIO
# program text is not interpreted; the behaviour of mixstep's two programs is:
# - step_levels (mixfw/pio.py) outputs one word of pin levels per tick: each word comes
#   out when the previous one has had its tick, or when it arrives if the FIFO ran empty;
# - step_events (mixfw/piodma.py) takes words of levels (low bits, one per pin) and a
#   count above them: the levels come out one cycle after the pull, the next pull is
#   count + 4 cycles after this one;
# - step_events_hold_high / _hold_low (homing) look at the jmp pin first: no word is
#   pulled while it reads high / low, and each word takes a cycle more.
# The DMA: channels whose registers are a RAM bank laid out as the RP2040's (the
# firmware writes it with ptr32), reading words from one RAM array (address 0 is its
# first byte), paced by the state machine's 8-word TX FIFO, with CHAIN_TO and an IRQ
# per finished channel, run by a hook of simmachine.idle on the PIO's clock.
from array import array
import micropython
import sys
import simmachine


class PIO:
    IN_LOW = 0
    IN_HIGH = 1
    OUT_LOW = 2
    OUT_HIGH = 3
    SHIFT_LEFT = 0
    SHIFT_RIGHT = 1
    JOIN_NONE = 0
    JOIN_TX = 1
    JOIN_RX = 2


def asm_pio(**options):
    def assemble(program):
        return dict(options, name=program.__name__)
    return assemble


class StateMachine:
    def __init__(self, sm_id, program, freq, out_base, jmp_pin=None):
        name = program["name"]
        if name.startswith("step_events"):
            hold = None
            if name != "step_events":
                hold = (jmp_pin, 1 if name == "step_events_hold_high" else 0)
            _engine.attach(out_base.gpio, len(program["out_init"]), freq, hold)
            self.put = _engine.put
            self.active = _engine.active
            self.tx_fifo = _engine.tx_fifo
            return
        cycles_per_word = 20  # mixfw/pio.py: pull, then out with 18 cycles of delay
        simmachine.attach_pio(out_base.gpio, len(program["out_init"]),
                              cycles_per_word * 1000000 // freq)
        self.put = simmachine.pio_put

    def active(self, on=None):
        return 1


# RP2040 DMA registers: word offsets in a channel's block, and the shared ones.
_CH_WORDS = 16
_READ_ADDR = 0
_WRITE_ADDR = 1
_TRANS_COUNT = 2
_CTRL_TRIG = 3
_AL1_CTRL = 4
_MULTI_CHAN_TRIGGER = 0x430 // 4
_CHANNELS = 12
_BUSY = 1 << 24
_FIFO_WORDS = 8


def dma_register_bank(ram):
    """The DMA's registers and PIO0's as RAM banks; ram: the one array the DMA's
    addresses point into."""
    _engine.ram = ram
    return _engine.bank, _engine.pio_bank


class DMA:
    def __init__(self):
        self.channel = _engine.claim(self)
        self.handler = None

    def pack_ctrl(self, default=None, **fields):
        value = default if default is not None else (
            (1 << 21) | (0x3F << 15) | (1 << 5) | (1 << 4) | (2 << 2) | 1 | (self.channel << 11))
        for name, (shift, bits) in _CTRL_FIELDS.items():
            if name in fields:
                value = (value & ~(((1 << bits) - 1) << shift)) | (int(fields[name]) << shift)
        return value

    def config(self, read=None, write=None, count=None, ctrl=None, trigger=False):
        b = _engine.bank
        r = self.channel * _CH_WORDS
        if read is not None:
            b[r + _READ_ADDR] = read
        if write is not None:
            b[r + _WRITE_ADDR] = write
        if count is not None:
            b[r + _TRANS_COUNT] = count
        if ctrl is not None:
            b[r + _AL1_CTRL] = ctrl
            b[r + _CTRL_TRIG] = ctrl | (b[r + _CTRL_TRIG] & _BUSY)
        if trigger:
            _engine.trigger(self.channel)

    def irq(self, handler=None, hard=False):
        self.handler = handler

    def active(self, on=None):
        if on is not None:
            if on:
                _engine.trigger(self.channel)
            else:
                _engine.abort(self.channel)
        return bool(_engine.bank[self.channel * _CH_WORDS + _CTRL_TRIG] & _BUSY)

    def close(self):
        _engine.dmas[self.channel] = None


_CTRL_FIELDS = {"enable": (0, 1), "high_pri": (1, 1), "size": (2, 2), "inc_read": (4, 1),
                "inc_write": (5, 1), "ring_size": (6, 4), "ring_sel": (10, 1),
                "chain_to": (11, 4), "treq_sel": (15, 6), "irq_quiet": (21, 1),
                "bswap": (22, 1), "sniff_en": (23, 1)}


class _Engine:
    """The DMA channels and the step_events state machine, in PIO cycles."""

    def __init__(self):
        self.bank = array("I", bytes(4 * (0x450 // 4)))
        self.pio_bank = array("I", bytes(4 * 16))  # FLEVEL (word 3) is kept
        self.ram = None
        self.dmas = [None] * _CHANNELS
        self.left = [0] * _CHANNELS  # transfers still to do per channel
        self.order = []  # busy channels, first triggered first
        self.fifo = []
        self.on = False
        self.base = 0
        self.count = 0
        self.per_us = 8
        self.hold = None
        self.word_cycles = 4
        self.t = 0  # cycles: the time of the last thing done
        self.ready = 0  # cycle of the state machine's next pull
        self.pending = []  # (cycle, channel) of IRQs held back (set_irq_delay)
        self.irq_delay_cycles = 0
        self.irq_delay_every = 0
        self.irqs = 0
        self.late_irqs = 0

    def claim(self, dma):
        ch = self.dmas.index(None)
        self.dmas[ch] = dma
        return ch

    def attach(self, base, count, freq, hold=None):
        self.base = base
        self.count = count
        self.hold = hold  # (jmp pin, level that holds the pins), or None
        self.word_cycles = 4 if hold is None else 5
        self.per_us = freq // 1000000
        self.fifo = []
        self.on = False
        simmachine.add_device(self.run)

    def put(self, word):
        if len(self.fifo) < _FIFO_WORDS:
            self.fifo.append(word)

    def tx_fifo(self):
        return len(self.fifo)

    def active(self, on=None):
        if on is not None:
            if on and not self.on:
                self.t = self.ready = simmachine.now_us * self.per_us
            self.on = bool(on)
            if not on:
                self.pending = []
        return self.on

    def trigger(self, ch):
        r = ch * _CH_WORDS
        if self.bank[r + _CTRL_TRIG] & _BUSY:
            return
        self.bank[r + _CTRL_TRIG] = self.bank[r + _AL1_CTRL] | _BUSY
        self.left[ch] = self.bank[r + _TRANS_COUNT]
        self.order.append(ch)

    def abort(self, ch):
        r = ch * _CH_WORDS
        self.bank[r + _CTRL_TRIG] = self.bank[r + _AL1_CTRL]
        if ch in self.order:
            self.order.remove(ch)

    def _transfer(self):
        """The DMA fills the FIFO from the first busy channel; finished channels chain
        and raise their IRQ."""
        b = self.bank
        while self.order and len(self.fifo) < _FIFO_WORDS:
            ch = self.order[0]
            r = ch * _CH_WORDS
            if self.left[ch] > 0:
                self.fifo.append(self.ram[b[r + _READ_ADDR] // 4])
                b[r + _READ_ADDR] += 4
                self.left[ch] -= 1
            if self.left[ch] == 0:
                self.order.pop(0)
                ctrl = b[r + _AL1_CTRL]
                b[r + _CTRL_TRIG] = ctrl
                chain = (ctrl >> 11) & 15
                if chain != ch:
                    self.trigger(chain)
                if not (ctrl >> 21) & 1:
                    self._raise(ch)

    def _raise(self, ch):
        self.irqs += 1
        if self.irq_delay_every and self.irqs % self.irq_delay_every == 0:
            self.late_irqs += 1
            self.pending.append((self.t + self.irq_delay_cycles, ch))
        else:
            self._handle(ch)

    def _handle(self, ch):
        dma = self.dmas[ch]
        if dma is None or dma.handler is None:
            return
        keep = simmachine.now_us
        simmachine.now_us = self.t // self.per_us
        simmachine._now_w = simmachine.now_us & simmachine._W30
        self.pio_bank[3] = len(self.fifo)  # state machine 0's TX level
        try:
            if simmachine.heap_lock_ticks:
                micropython.heap_lock()
                try:
                    dma.handler(dma)
                finally:
                    micropython.heap_unlock()
            else:
                dma.handler(dma)
        except Exception as e:
            dma.handler = None  # as MicroPython disables a handler that raised
            sys.stderr.write("rp2 (sim): uncaught exception in DMA IRQ handler, "
                             "disabled: %r\n" % (e,))
        simmachine.now_us = keep
        simmachine._now_w = keep & simmachine._W30
        m = self.bank[_MULTI_CHAN_TRIGGER]
        if m:
            self.bank[_MULTI_CHAN_TRIGGER] = 0
            for c in range(_CHANNELS):
                if m >> c & 1:
                    self.trigger(c)

    def run(self, end_us):
        """Everything the DMA and the state machine do up to end_us."""
        if not self.on:
            return
        until = end_us * self.per_us
        while True:
            self._transfer()
            pull = self.ready if self.ready > self.t else self.t
            if self.pending:
                at, ch = min(self.pending)
                if at <= until and (not self.fifo or at <= pull):
                    self.pending.remove((at, ch))
                    self.t = max(self.t, at)
                    self._handle(ch)
                    continue
            if not self.fifo or pull > until:
                break
            if self.hold and self.hold[0].value() == self.hold[1]:
                self.t = until  # held at the jmp pin (nothing moves, so it stays)
                return
            word = self.fifo.pop(0) & 0xFFFFFFFF
            self.t = pull
            self._output(word & ((1 << self.count) - 1), pull + 1)
            self.ready = pull + self.word_cycles + (word >> self.count)
        if self.t < until and not self.fifo:
            self.t = until  # stalled on an empty FIFO until then

    def _output(self, word, cycle):
        keep = simmachine.now_us
        simmachine.now_us = cycle // self.per_us
        simmachine._now_w = simmachine.now_us & simmachine._W30
        for bit in range(self.count):
            simmachine._set_level(self.base + bit, (word >> bit) & 1)
        simmachine.now_us = keep
        simmachine._now_w = keep & simmachine._W30
        if simmachine._n > simmachine._FLUSH_AT:
            simmachine.flush()


_engine = _Engine()


def set_irq_delay(us, every=1):
    """Hold back every `every`-th DMA IRQ by `us` (a main loop with interrupts off, a
    flash write): the refills it does come late."""
    _engine.irq_delay_cycles = us * _engine.per_us
    _engine.irq_delay_every = every if us else 0


def dma_stats():
    return {"irqs": _engine.irqs, "held_back": _engine.late_irqs}
