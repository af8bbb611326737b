# The simulated chip's PIO and DMA, for step_backends "pio" and "pio_dma". The PIO
# program text is not interpreted; the behaviour of mixstep's two programs is:
# - step_levels (mixfw/pio.py) outputs one word of pin levels per tick: each word comes
#   out when the previous one has had its tick, or when it arrives if the FIFO ran empty;
# - step_events (mixfw/piodma.py) takes words of levels (low bits, one per pin) and a
#   count above them: the levels come out one cycle after the pull, the next pull is
#   count + 4 cycles after this one;
# - step_events_latch_high / _latch_low (homing) run a jmp on the jmp pin a cycle
#   before each pull, so each word takes a cycle more; the first jmp that reads it high
#   / low latches: no word is pulled after it until the state machine is made again,
#   whatever the pin reads then. A pull that waits on an empty FIFO does not look again.
# A StateMachine drives its out pins to the program's out_init as it is made, as
# MicroPython's StateMachine.init does on the chip: the trace shows the glitch a
# restart gives pins whose levels out_init does not keep.
# The DMA: channels whose registers are a RAM bank laid out as the simulated chip's,
# RP2040 or RP2350 (simmachine.set_chip; the firmware writes it with ptr32), reading
# words from one RAM array (address 0 is its first byte), paced by the state
# machine's 8-word TX FIFO, with CHAIN_TO and an IRQ per finished channel, run by a
# hook of simmachine.idle on the PIO's clock. A write to MULTI_CHAN_TRIGGER or
# CHAN_ABORT acts when the firmware's IRQ handler returns or when it next asks a
# channel whether it is busy; one at another chip's offset does nothing. On the
# RP2350 a channel aborted with EN set starts again (RP2350-E5), from where it had
# read to.
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


# rp2.asm_pio's program as MicroPython 1.28 makes it: [instructions, its offset in
# PIO0, PIO1 and PIO2, EXECCTRL, SHIFTCTRL, out_init, set_init, sideset_init], a list
# the firmware may change. The program's name stands in for its instructions.
_PROG_DATA = 0
_PROG_OUT_PINS = 6


def asm_pio(out_init=None, set_init=None, sideset_init=None, **options):
    def assemble(program):
        return [program.__name__, -1, -1, -1, 0, 0, out_init, set_init, sideset_init]
    return assemble


class StateMachine:
    def __init__(self, sm_id, program, freq, out_base, jmp_pin=None):
        name = program[_PROG_DATA]
        out_init = program[_PROG_OUT_PINS]
        if name.startswith("step_events"):
            hold = None
            if name != "step_events":
                hold = (jmp_pin, 1 if name == "step_events_latch_high" else 0)
            _engine.attach(out_base.gpio, len(out_init), freq, hold)
            self.put = _engine.put
            self.active = _engine.active
            self.tx_fifo = _engine.tx_fifo
        else:
            cycles_per_word = 20  # mixfw/pio.py: pull, then out with 18 cycles of delay
            simmachine.attach_pio(out_base.gpio, len(out_init),
                                  cycles_per_word * 1000000 // freq)
            self.put = simmachine.pio_put
        for i, init in enumerate(out_init):
            level = init & 1  # PIO.OUT_LOW, OUT_HIGH
            if simmachine._levels[out_base.gpio + i] != level:
                simmachine._set_level(out_base.gpio + i, level)

    def active(self, on=None):
        return 1


# DMA registers: word offsets in a channel's block, the same on both chips.
_CH_WORDS = 16
_READ_ADDR = 0
_WRITE_ADDR = 1
_TRANS_COUNT = 2
_CTRL_TRIG = 3
_AL1_CTRL = 4
_CHANNELS = 16  # the RP2350's; the RP2040 has 12
_BANK_WORDS = 0x480 // 4
_FIFO_WORDS = 8
# What differs, from each chip's datasheet (DMA register list), kept apart from the
# firmware's table so that a wrong constant there shows here: the shared registers'
# word offsets, and CTRL's fields as (lowest bit, bits).
_CHIPS = {
    "rp2040": {
        "multi_chan_trigger": 0x430 // 4, "chan_abort": 0x444 // 4, "e5": False,
        "fields": {"enable": (0, 1), "high_pri": (1, 1), "size": (2, 2), "inc_read": (4, 1),
                   "inc_write": (5, 1), "ring_size": (6, 4), "ring_sel": (10, 1),
                   "chain_to": (11, 4), "treq_sel": (15, 6), "irq_quiet": (21, 1),
                   "bswap": (22, 1), "sniff_en": (23, 1), "busy": (24, 1)}},
    "rp2350": {
        "multi_chan_trigger": 0x450 // 4, "chan_abort": 0x464 // 4, "e5": True,
        "fields": {"enable": (0, 1), "high_pri": (1, 1), "size": (2, 2), "inc_read": (4, 1),
                   "inc_read_rev": (5, 1), "inc_write": (6, 1), "inc_write_rev": (7, 1),
                   "ring_size": (8, 4), "ring_sel": (12, 1), "chain_to": (13, 4),
                   "treq_sel": (17, 6), "irq_quiet": (23, 1), "bswap": (24, 1),
                   "sniff_en": (25, 1), "busy": (26, 1)}},
}


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
        layout = _engine.fields
        if default is None:
            # MicroPython's default: quiet, unpaced, reads and writes incrementing,
            # words, enabled, chained to itself.
            default = self.pack_ctrl(0, irq_quiet=1, treq_sel=0x3F, inc_write=1, inc_read=1,
                                     size=2, enable=1, chain_to=self.channel)
        value = default
        for name, (shift, bits) in layout.items():
            if name in fields and name != "busy":
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
            b[r + _CTRL_TRIG] = ctrl | (b[r + _CTRL_TRIG] & _engine.busy)
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
        _engine.registers_written()
        return bool(_engine.bank[self.channel * _CH_WORDS + _CTRL_TRIG] & _engine.busy)

    def close(self):
        _engine.dmas[self.channel] = None


class _Engine:
    """The DMA channels and the step_events state machine, in PIO cycles."""

    def __init__(self):
        self.bank = array("I", bytes(4 * _BANK_WORDS))
        self.set_chip("rp2040")
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

    def set_chip(self, name):
        chip = _CHIPS[name]
        self.fields = chip["fields"]
        self.busy = 1 << self.fields["busy"][0]
        self.chain_lsb = self.fields["chain_to"][0]
        self.quiet_bit = self.fields["irq_quiet"][0]
        self.multi_chan_trigger = chip["multi_chan_trigger"]
        self.chan_abort = chip["chan_abort"]
        self.e5 = chip["e5"]

    def claim(self, dma):
        # The chip is the simulated board's, set before the firmware makes a channel.
        self.set_chip(simmachine.chip if simmachine.chip in _CHIPS else "rp2040")
        ch = self.dmas.index(None)
        self.dmas[ch] = dma
        return ch

    def attach(self, base, count, freq, hold=None):
        self.base = base
        self.count = count
        self.hold = hold  # (jmp pin, level that latches), or None
        self.word_cycles = 4 if hold is None else 5
        self.looked = False  # the jmp before the next pull has run
        self.latched = False
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
                self.t = simmachine.now_us * self.per_us
                # A latching program starts at its jmp: the pull is a cycle later.
                self.ready = self.t + (1 if self.hold else 0)
            self.on = bool(on)
            if not on:
                self.pending = []
        return self.on

    def trigger(self, ch):
        r = ch * _CH_WORDS
        ctrl = self.bank[r + _AL1_CTRL]
        if self.bank[r + _CTRL_TRIG] & self.busy or not ctrl & 1:  # busy, or EN off
            return
        self.bank[r + _CTRL_TRIG] = ctrl | self.busy
        self.left[ch] = self.bank[r + _TRANS_COUNT]
        self.order.append(ch)

    def abort(self, ch):
        r = ch * _CH_WORDS
        busy = self.bank[r + _CTRL_TRIG] & self.busy
        self.bank[r + _CTRL_TRIG] = self.bank[r + _AL1_CTRL]
        self.left[ch] = 0
        if ch in self.order:
            self.order.remove(ch)
        if busy and self.e5:
            self.trigger(ch)  # RP2350-E5, unless EN was cleared first

    def registers_written(self):
        """What the firmware's writes to MULTI_CHAN_TRIGGER and CHAN_ABORT do."""
        b = self.bank
        for word, act in ((self.chan_abort, self.abort),
                          (self.multi_chan_trigger, self.trigger)):
            m = b[word]
            if m:
                b[word] = 0
                for c in range(_CHANNELS):
                    if m >> c & 1:
                        act(c)

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
                chain = (ctrl >> self.chain_lsb) & 15
                if chain != ch:
                    self.trigger(chain)
                if not (ctrl >> self.quiet_bit) & 1:
                    self._raise(ch)

    def _raise(self, ch):
        self.irqs += 1
        if self.irq_delay_every and self.irqs % self.irq_delay_every == 0:
            self.late_irqs += 1
            self.pending.append((self.t + self.irq_delay_cycles, ch))
        elif self.t < simmachine.irqs_off_until_us * self.per_us:
            self.pending.append((self.t, ch))  # a flash write: run() holds it
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
        self.registers_written()

    def run(self, end_us):
        """Everything the DMA and the state machine do up to end_us."""
        if not self.on:
            return
        until = end_us * self.per_us
        while True:
            self._transfer()
            pull = until + 1 if self.latched else max(self.ready, self.t)
            if self.pending:
                due, ch = min(self.pending)
                # Not before interrupts are back on after a flash write (hold_irqs).
                at = max(due, simmachine.irqs_off_until_us * self.per_us)
                if at <= until and (not self.fifo or at <= pull):
                    self.pending.remove((due, ch))
                    self.t = max(self.t, at)
                    self._handle(ch)
                    continue
            if self.hold and not (self.looked or self.latched):
                jmp_at = self.ready - 1
                if jmp_at > until:
                    break
                self.looked = True
                self.latched = self._pin_at(jmp_at) == self.hold[1]
                continue
            if not self.fifo or pull > until:
                break
            word = self.fifo.pop(0) & 0xFFFFFFFF
            self.looked = False
            self.t = pull
            self._output(word & ((1 << self.count) - 1), pull + 1)
            self.ready = pull + self.word_cycles + (word >> self.count)
        if self.t < until and (self.latched or not self.fifo):
            self.t = until  # stalled on an empty FIFO, or latched, until then

    def _pin_at(self, cycle):
        """The jmp pin's level at this PIO cycle."""
        keep = simmachine.now_us
        simmachine.now_us = cycle // self.per_us
        simmachine._now_w = simmachine.now_us & simmachine._W30
        level = self.hold[0].value()
        simmachine.now_us = keep
        simmachine._now_w = keep & simmachine._W30
        return level

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
