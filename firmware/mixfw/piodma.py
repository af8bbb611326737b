# step_backend "pio_dma" for RP2040/RP2350: the step loop runs ahead in batches and
# writes the pin levels between edges, a word each (levels, and above them the PIO
# cycles they hold), into a ring in RAM. Two DMA channels, chained to each other, move
# the ring into a state machine's FIFO paced by its TX DREQ; the state machine writes
# each word's levels to the pins and counts its cycles down.
# The CPU takes one interrupt per batch (_BATCH_US), not one per tick, and an edge lands
# at its own time inside its tick, not on the tick.
#
# The ring has 3 segments: one the running channel reads, one armed on the other
# channel, one filled and ready. When a channel ends, its IRQ (hard) arms it with the
# ready segment, points the running channel's CHAIN_TO at it, and fills the segment it
# had just read with the next batch.
#
# A late refill (the running channel ended before the IRQ re-armed the other) must
# never replay stale words: a channel is armed without a trigger and chained to only
# once it is armed; if the running one has already ended, the chain has passed and the
# IRQ triggers the armed channel itself. A late refill then stalls the pins (steps
# late, never wrong); R_LATE counts them (M122).
#
# What can hold the DMA IRQ back is whatever masks interrupts or holds the CPU in
# another handler: machine.disable_irq() sections (the planner's queue hand-over, a
# few us), other interrupt handlers of the same priority (USB, a few us), and flash
# erase/program, which the rp2 port runs with interrupts off (a 4 kB erase takes tens
# of ms, many batches): so every flash write waits for the moves to end first
# (config.FileStorage), and its late refills come at a standstill, where they stall
# nothing. gc.collect() runs with interrupts on (a hard handler that allocated would
# fail during it; refill allocates nothing), so it delays nothing: the emulated prints
# run M122, which collects, without a late refill.
import sys
from array import array
from mixfw import heap, stepper as st
from mixfw.stepper import tick
from mixfw.pio import out_range

_PIO_HZ = const(8000000)
_CYCLES_PER_US = const(8)
_BATCH_US = const(2000)  # 1 ms is too short: the emulated chip's refills come late
_SEGMENTS = const(3)
_FIFO_WORDS = const(8)  # the TX FIFO, joined
_DMA_BASE = const(0x50000000)
_PIO0_BASE = const(0x50200000)
_PIO0_TXF0 = const(0x50200010)
_FLEVEL = const(3)  # PIO register word: each state machine's FIFO levels, a byte each
# Word offsets: in a channel's block of 16 registers, and of the shared registers.
_READ_ADDR = const(0)
_TRANS_COUNT = const(2)
_CTRL_TRIG = const(3)
_AL1_CTRL = const(4)
_CH_WORDS = const(16)
_INTR = const(0x400 // 4)
_INTS0 = const(0x40C // 4)
_EN = const(1)  # CTRL's enable bit, bit 0 on both chips
# What differs between the chips' DMAs (RP2040 and RP2350 datasheets, DMA register
# lists): the word offsets of MULTI_CHAN_TRIGGER and CHAN_ABORT, the lowest bit of
# CHAIN_TO and the BUSY bit in a channel's CTRL, and the NVIC number of DMA_IRQ_0 (the
# one MicroPython's rp2.DMA raises). One is chosen at start from settings["chip"].
# A tuple per chip, read by the indices below: string keys would each be interned.
_MULTI_CHAN_TRIGGER = const(0)
_CHAN_ABORT = const(1)
_CHAIN_TO_LSB = const(2)
_BUSY_BIT = const(3)
_DMA_IRQ_0 = const(4)
DMA_CHIPS = {
    "rp2040": (0x430 // 4, 0x444 // 4, 11, 24, 11),
    "rp2350": (0x450 // 4, 0x464 // 4, 13, 26, 10),
}
_ABORT_POLLS = const(1000)  # an abort ends within a few bus cycles
# Where rp2.asm_pio's program (a list) keeps out_init: third from its end, before
# set_init and sideset_init (MicroPython 1.28 has an offset per PIO before it, 3 on
# any chip).
_PROG_OUT_PINS = const(-3)

# stepper.py's layout: the step loop's words refill uses, as constants viper folds
# (copies).
_R_BATCHES = const(98)
_R_BUSY_BIT = const(104)
_R_CH = const(105)
_R_CHAIN_SHIFT = const(103)
_R_CH_SEG = const(107)
_R_CTRL = const(102)
_R_FIRED = const(109)
_R_LATE = const(97)
_R_READY = const(100)
_R_RING_ADDR = const(101)
_R_SEG_LV = const(111)
_R_SEG_N = const(85)
_R_SEG_SEQ = const(88)
_R_SEG_WORDS = const(99)
_R_W = const(95)
_R_SM = const(110)
_S_LEVELS = const(45)
_TAIL_WORDS = const(9)  # the FIFO's words and the one before them


def seg_words(batch_ticks):
    """Ring words a batch can need. A step tick has two edges (the step and its fall)
    and is never followed by another (the pulse and its low time take a tick at
    least); any other tick one at most (DIR). So 3 edges in 2 ticks, a word each, and
    the word that holds the last levels to the batch's end; an idle batch is padded
    to stepper.BATCH_MIN_WORDS."""
    return (3 * batch_ticks) // 2 + 3 + st.BATCH_MIN_WORDS


def batch_ticks(tick_us, batch_us, pins):
    """Ticks a batch runs: batch_us, or less where a word's hold, in the bits the pins
    leave, could not count that long (a hold lasts a batch and a tick at most)."""
    ticks = min(batch_us // tick_us,
                ((1 << (32 - pins)) - 1) // (tick_us * _CYCLES_PER_US) - 1)
    return max(1, ticks)


def ring_words(tick_us, batch_us=_BATCH_US):
    """The ring's words at most, whatever the pins."""
    return _SEGMENTS * seg_words(max(1, batch_us // tick_us))


def make_ring(ticks):
    """The ring for batches of this many ticks, to be allocated early: a few kB in one
    block, which the heap may not have in one piece once the firmware is built."""
    return heap.zeros(_SEGMENTS * seg_words(ticks))


@micropython.viper
def refill(mem_buf, io, done: int):
    """Channel `done` (0 or 1) has read its segment: arm it with the ready one, chain
    the running channel to it, and fill the freed segment with the next batch. io:
    (DMA registers, PIO registers, ring, step loop's io, tail, the chip's
    MULTI_CHAN_TRIGGER word, stepper.tick), one tuple because a viper call with more
    arguments allocates."""
    mem = ptr32(mem_buf)
    regs = ptr32(io[0])
    pio = ptr32(io[1])
    ch = mem[_R_CH + done]
    r = ch * _CH_WORDS
    o = mem[_R_CH + 1 - done] * _CH_WORDS
    seg = mem[_R_READY]
    start = mem[_R_RING_ADDR] + seg * mem[_R_SEG_WORDS] * 4
    regs[r + _READ_ADDR] = start
    regs[r + _TRANS_COUNT] = mem[_R_SEG_N + seg]
    own = mem[_R_CTRL] | (ch << mem[_R_CHAIN_SHIFT])  # chained to itself: no chain
    regs[r + _AL1_CTRL] = own
    regs[o + _AL1_CTRL] = own
    busy = 1 << mem[_R_BUSY_BIT]
    if (regs[o + _CTRL_TRIG] & busy) == 0:
        # The running channel may have ended before its CHAIN_TO pointed here: then
        # nothing triggered this one (it neither runs nor has read a word).
        if (regs[r + _CTRL_TRIG] & busy) == 0 and regs[r + _READ_ADDR] == start:
            regs[int(io[5])] = 1 << ch
            # Late only if the FIFO had run dry: idle batches are 2 words, so with
            # words enough in the FIFO both channels may end before the IRQ runs.
            if (pio[_FLEVEL] >> (mem[_R_SM] << 3)) & 15 == 0:
                mem[_R_LATE] += 1
    freed = mem[_R_CH_SEG + done]
    mem[_R_CH_SEG + done] = seg
    mem[_R_FIRED] += 1
    base = freed * mem[_R_SEG_WORDS]
    # The FIFO may still hold the freed segment's last words (up to its 8): kept, with
    # the word before them, for a stop to take back what they never put on the pins.
    ring = ptr32(io[2])
    tail = ptr32(io[4])
    i = 0
    k = base + mem[_R_SEG_N + freed] - _TAIL_WORDS
    while i < _TAIL_WORDS:
        tail[i] = ring[k + i]
        i += 1
    mem[_R_W] = base
    mem[_R_SEG_LV + freed] = mem[_S_LEVELS]
    w = int(io[6](io[3]))
    mem[_R_SEG_N + freed] = w - base
    mem[_R_SEG_SEQ + freed] = mem[_R_BATCHES]
    mem[_R_READY] = freed


def chain_to_lsb(dma):
    """Where this MicroPython's rp2.DMA.pack_ctrl puts CHAIN_TO's lowest bit: the
    chip it was built for."""
    diff = dma.pack_ctrl(chain_to=1) ^ dma.pack_ctrl(chain_to=0)
    lsb = 0
    while diff >> lsb > 1:
        lsb += 1
    return lsb


def check_chip(chip, cpu, lsb):
    """Refuse to run with DMA_CHIPS[chip] where it would be wrong: on the RP2350's
    RISC-V cores (cpu: sys.implementation._machine), which have no NVIC for the
    planner to mask the DMA IRQ in, and on a MicroPython built for the other chip
    (lsb: chain_to_lsb), whose registers lie elsewhere."""
    if "RISCV" in cpu:
        raise ValueError("step_backend pio_dma needs the RP2350's Arm cores; this "
                         "MicroPython runs on its RISC-V cores (%s): flash the Arm build"
                         % cpu)
    if lsb != DMA_CHIPS[chip][_CHAIN_TO_LSB]:
        raise ValueError("step_backend pio_dma: chip is %r, but this MicroPython's DMA has "
                         "CHAIN_TO at bit %d (the %s's is at bit %d): flash the MicroPython "
                         "for the board's chip" % (chip, lsb, chip,
                                                   DMA_CHIPS[chip][_CHAIN_TO_LSB]))


class Feed:
    """The ring, the state machine and the two channels of one printer's steps. Made
    right after the step loop's memory (its ring is the next largest block), set up
    by the first start(), once the pins and their masks are there."""

    def __init__(self, machine, mem, settings, pin_map, sm_id=0, batch_us=_BATCH_US):
        chip = settings.get("chip")
        if chip not in DMA_CHIPS:
            raise ValueError("step_backend pio_dma needs an RP2040 or RP2350, not %r" % chip)
        import rp2
        self.rp2 = rp2
        self.machine = machine
        self.mem = mem
        self.settings = settings
        self.sm_id = sm_id
        self.names = ["x", "y", "z"] + ["e%d" % i for i in range(settings["drives"])]
        self.first, self.count = out_range(pin_map, self.names)
        self.ticks = batch_ticks(settings["tick_us"], batch_us, self.count)
        hold_cycles = (self.ticks + 1) * settings["tick_us"] * _CYCLES_PER_US
        if hold_cycles >> (32 - self.count):
            raise ValueError("step_backend pio_dma: %d STEP/DIR pins leave %d bits, too "
                             "few for a hold of %d cycles" % (self.count, 32 - self.count,
                                                                hold_cycles))
        self.ring = make_ring(self.ticks)
        # The last words of the segment refilled last (see refill): the FIFO may still
        # hold them when the ring no longer does.
        self.tail = array("i", bytes(4 * _TAIL_WORDS))
        self.dmas = [rp2.DMA(), rp2.DMA()]
        self.chip = DMA_CHIPS[chip]
        check_chip(chip, getattr(sys.implementation, "_machine", ""),
                   chain_to_lsb(self.dmas[0]))
        # What the planner needs to hold the refill back while it rewrites a queued
        # block's record (lookahead.recalculate): (ICER, ISER, bit) of the DMA's IRQ in
        # the NVIC, as words of an array 'i'; None on the simulated chip (no NVIC: the
        # planner then masks every interrupt, as for the timer). Masking only the IRQ
        # that runs the step loop is enough: it is the only code besides the main loop
        # that reads the block records. A refill it holds back runs as soon as the
        # mask is lifted, tens of us later, and the ring is two batches (4 ms) ahead
        # of the pins, so no step is late or lost. It costs the chip about 1 us, where
        # machine.disable_irq() and enable_irq() cost 6 us a record (up to 13 records
        # a line on curves). ICER and ISER are at 0xE000E180 and 0xE000E100 on ARMv6-M
        # and ARMv8-M alike: above 2**31, so stored as negative words.
        self.irq = None if getattr(rp2, "dma_register_bank", None) else array(
            "i", [0xE000E180 - (1 << 32), 0xE000E100 - (1 << 32),
                  1 << self.chip[_DMA_IRQ_0]])
        self.pins = None
        self.sm = None
        self.running = False
        self.watch = None  # (endstop Pin, level it reads when triggered) while homing

    def _setup(self, pins):
        """The step loop's words for the ring, and the IRQ handlers."""
        mem, settings, rp2 = self.mem, self.settings, self.rp2
        self.pins = pins
        self.out_base = self.machine.Pin(self.first)
        tick_us = settings["tick_us"]
        ticks = self.ticks
        mem[st.S_PIO] = 2
        mem[st.S_PIO_SHIFT] = self.first
        mem[st.R_TC] = tick_us * _CYCLES_PER_US
        mem[st.R_BATCH_TICKS] = ticks
        mem[st.R_PULSE_CYC] = settings["step_pulse_us"] * _CYCLES_PER_US
        mem[st.R_SEG_WORDS] = seg_words(ticks)
        mem[st.R_LEVEL_BITS] = self.count
        # Steps land anywhere in their tick and a DIR change at its start, after the
        # fall of a pulse that may reach into it: the setup counts from there.
        mem[st.S_DIR_TICKS] = max(1, -(-(settings["dir_setup_us"] + settings["step_pulse_us"])
                                       // tick_us))
        self.motors = []  # (step mask, dir mask, position word, drive word or -1)
        for i in range(len(self.names)):
            axis = i if i < 3 else st.E
            drive = st.S_DRIVE_POS + i - 3 if i >= 3 else -1
            self.motors.append((mem[st.MASK_BASE + i], mem[st.DIR_MASK_BASE + i],
                                st.S_POS + axis, drive))
        self.dir_invert_mask = pins.dir_invert_mask
        bank = getattr(rp2, "dma_register_bank", None)
        if bank:  # the simulated chip: registers in RAM, ring addresses from 0
            self.regs, self.pio_regs = bank(self.ring)
            mem[st.R_RING_ADDR] = 0
        else:
            import uctypes
            self.regs = _DMA_BASE
            self.pio_regs = _PIO0_BASE
            mem[st.R_RING_ADDR] = uctypes.addressof(self.ring)
        d = self.dmas[0]
        sm_id = self.sm_id
        self.ctrl = d.pack_ctrl(size=2, inc_read=True, inc_write=False, chain_to=0,
                                treq_sel=sm_id, irq_quiet=False)
        mem[st.R_CTRL] = self.ctrl
        mem[st.R_CHAIN_SHIFT] = self.chip[_CHAIN_TO_LSB]
        mem[st.R_BUSY_BIT] = self.chip[_BUSY_BIT]
        for i, dma in enumerate(self.dmas):
            mem[st.R_CH + i] = dma.channel
        mem[st.R_SM] = sm_id
        # The step loop's own io (stepper.tick) is io[3].
        io = self.io = (self.regs, self.pio_regs, self.ring, (mem, self.ring, pins.endstops),
                        self.tail, self.chip[_MULTI_CHAN_TRIGGER], tick)
        fill = refill

        # Bound once: the interrupt looks up no name and allocates nothing. A global's
        # lookup goes through the VM's lookup cache, which the main loop's names share:
        # its cost would depend on which names the main loop used last.
        def irq0(_dma):
            fill(mem, io, 0)

        def irq1(_dma):
            fill(mem, io, 1)

        self.handlers = (irq0, irq1)
        # Assembled once: it takes ms on the chip. The homing ones first look at the
        # endstop (the state machine's jmp pin) and hold every pin where it is from the
        # word after it reads triggered (high, or low) until the next start().
        self.programs = self._programs()

    def _programs(self):
        rp2 = self.rp2
        pins_n = self.count
        hold_n = 32 - pins_n
        options = dict(out_init=(rp2.PIO.OUT_LOW,) * self.count,
                       out_shiftdir=rp2.PIO.SHIFT_RIGHT, fifo_join=rp2.PIO.JOIN_TX)

        # The assembler swaps the module's globals for its own names while it runs:
        # the counts and the shared part come in as closure variables (that part
        # reads the same swapped globals). noqa: F821 below: the assembler's names.
        def word():
            # A word: its levels to the pins, then its count of cycles down.
            pull(block)  # noqa: F821
            out(pins, pins_n)  # noqa: F821
            out(x, hold_n)  # noqa: F821
            label("wait")  # noqa: F821
            jmp(x_dec, "wait")  # noqa: F821

        @rp2.asm_pio(**options)
        def step_events():
            wrap_target()  # noqa: F821
            word()
            wrap()  # noqa: F821

        # Homing: one look at the endstop (the jmp pin) before each word. From the
        # first look that finds it triggered, the state machine loops in place until
        # it is made again (start()): the first closure of a switch is home, and its
        # bounces open let no word through. One cycle more per word than step_events
        # (the simulated chip counts it too).
        @rp2.asm_pio(**options)
        def step_events_latch_high():
            wrap_target()  # noqa: F821
            jmp(pin, "hold")  # noqa: F821
            word()
            wrap()  # noqa: F821
            label("hold")  # noqa: F821
            jmp("hold")  # noqa: F821

        @rp2.asm_pio(**options)
        def step_events_latch_low():
            wrap_target()  # noqa: F821
            jmp(pin, "go")  # noqa: F821
            label("hold")  # noqa: F821
            jmp("hold")  # noqa: F821
            label("go")  # noqa: F821
            word()
            wrap()  # noqa: F821

        return {None: step_events, 1: step_events_latch_high, 0: step_events_latch_low}

    def _fill(self, seg):
        mem = self.mem
        base = seg * mem[st.R_SEG_WORDS]
        mem[st.R_W] = base
        mem[st.R_SEG_LV + seg] = mem[st.S_LEVELS]
        mem[st.R_SEG_N + seg] = tick(self.io[3]) - base
        mem[st.R_SEG_SEQ + seg] = mem[st.R_BATCHES]

    def start(self, pins=None):
        """Prime the ring with three batches and let the channels run."""
        if self.pins is None:
            self._setup(pins)
        mem = self.mem
        rp2 = self.rp2
        # A StateMachine drives its out pins to its program's out_init as it is made:
        # the levels they have now, so a restart (each homed axis, each resume) moves
        # no DIR pin. STEP pins are low between words.
        levels = mem[st.S_LEVELS] >> self.first
        init = tuple(rp2.PIO.OUT_HIGH if levels >> i & 1 else rp2.PIO.OUT_LOW
                     for i in range(self.count))
        for program in self.programs.values():
            program[_PROG_OUT_PINS] = init
        if self.watch:
            pin, level = self.watch
            self.sm = rp2.StateMachine(self.sm_id, self.programs[level], freq=_PIO_HZ,
                                       out_base=self.out_base, jmp_pin=pin)
        else:
            self.sm = rp2.StateMachine(self.sm_id, self.programs[None], freq=_PIO_HZ,
                                       out_base=self.out_base)
        mem[st.R_LAST] = 0
        for seg in range(_SEGMENTS):
            self._fill(seg)
        mem[st.R_READY] = 2
        a, b = self.dmas
        words = mem[st.R_SEG_WORDS]
        txf = _PIO0_TXF0 + 4 * self.sm_id
        shift = mem[st.R_CHAIN_SHIFT]
        # The first word goes into the FIFO by hand: a state machine made again
        # after a stop with a full FIFO raises no DREQ on the emulated chip until its
        # first pull.
        self.sm.put(self.ring[0])
        for i, dma in enumerate(self.dmas):
            mem[st.R_CH_SEG + i] = i
            first = 1 if i == 0 else 0
            # The first chains to the second; the second to itself (no chain) until
            # its IRQ has armed the first again.
            dma.config(read=mem[st.R_RING_ADDR] + 4 * (i * words + first), write=txf,
                       count=mem[st.R_SEG_N + i] - first,
                       ctrl=self.ctrl | (b.channel << shift))
        # A flag left from a stop would run a refill on channels not yet running.
        self._clear_flags()
        for i, dma in enumerate(self.dmas):
            dma.irq(self.handlers[i], hard=True)
        self.sm.active(1)
        a.active(1)
        self.running = True

    def stop(self):
        """Stop the state machine, then the channels: what was read from the ring and
        what the FIFO still holds then say which words reached the pins. Returns the
        stream order of the segments, and the segment and word the pins stopped at.
        An abort can raise the channel's IRQ (RP2040-E13): the handlers go first, and
        the flags are cleared after, so no refill runs on a stopped ring."""
        self.sm.active(0)
        # The channels go on until the FIFO is full or their segments end; read their
        # addresses once they have (a word in flight when a channel is aborted counts
        # as read but never reaches the FIFO).
        a, b = self.dmas
        for _ in range(200):
            if self.sm.tx_fifo() >= _FIFO_WORDS or not (a.active() or b.active()):
                break
        where = self._first_unsent()
        for dma in self.dmas:
            dma.irq(None)
        self._abort()
        self.running = False
        self._clear_flags()
        return where

    def _abort(self):
        """Abort both channels in the datasheet's order, as RP2350-E5 needs it (a
        channel aborted with EN set can start again and feed the FIFO stale words):
        EN off and no CHAIN_TO on both, one abort of both, then wait until neither
        channel is BUSY: BUSY, not CHAN_ABORT, says the transfers in flight are done
        (RP2040-E13), as pico-sdk's dma_channel_abort waits."""
        regs = self._regs_view()
        off = self.ctrl & ~_EN
        shift = self.chip[_CHAIN_TO_LSB]
        mask = 0
        for dma in self.dmas:
            regs[dma.channel * _CH_WORDS + _AL1_CTRL] = off | (dma.channel << shift)
            mask |= 1 << dma.channel
        regs[self.chip[_CHAN_ABORT]] = mask
        a, b = self.dmas
        for _ in range(_ABORT_POLLS):
            if not (a.active() or b.active()):
                return
        raise RuntimeError("DMA channels %d and %d did not stop" % (a.channel, b.channel))

    def _clear_flags(self):
        """Both channels' raw interrupt flags (INTR; INTS0 is INTR masked)."""
        mask = (1 << self.dmas[0].channel) | (1 << self.dmas[1].channel)
        regs = self._regs_view()
        regs[_INTR] = mask
        regs[_INTS0] = mask

    def _first_unsent(self):
        mem = self.mem
        words = mem[st.R_SEG_WORDS]
        base = mem[st.R_RING_ADDR]
        regs = self._regs_view()
        order = sorted(range(_SEGMENTS), key=lambda s: mem[st.R_SEG_SEQ + s])
        # Words read from the ring: up to where the later started channel got.
        read = 0
        for i in range(2):
            seg = mem[st.R_CH_SEG + i]
            ch = mem[st.R_CH + i]
            done = (regs[ch * _CH_WORDS + _READ_ADDR] - base) // 4 - seg * words
            if 0 < done <= mem[st.R_SEG_N + seg]:
                at = sum(mem[st.R_SEG_N + s] for s in order[:order.index(seg)]) + done
                read = max(read, at)
        unsent = read - self.sm.tx_fifo()
        for s in order:
            n = mem[st.R_SEG_N + s]
            if unsent < n:
                # Negative: that many words the FIFO holds of the segment refilled
                # before order[0] (its tail).
                return order, s, unsent
            unsent -= n
        return order, order[-1], mem[st.R_SEG_N + order[-1]]

    def _regs_view(self):
        return _Mem32(self.machine, self.regs) if isinstance(self.regs, int) else self.regs

    def stop_and_take_back(self):
        """M112 / quick stop: stop the pins where they are and take every step the pins
        never got out of the step loop's positions, so they hold where the axes are.
        The feed starts again (resume) once the queue has been dropped."""
        if not self.running:
            return
        state = self.machine.disable_irq()
        try:
            order, seg, at = self.stop()
            self._take_back(order, seg, at)
        finally:
            self.machine.enable_irq(state)

    def resume(self):
        if not self.running:
            self.start()

    def watch_endstop(self, pin=None, level=1):
        """Homing: from now on the pins hold from the first word after `pin` reads
        `level` (the endstop triggered), and go on holding whatever it reads after,
        so no step the ring held past the switch gets out; the homing code then takes
        them back (stop_and_take_back). None: stop watching. Called with the queue run
        out (the ring holds no step)."""
        self.stop_and_take_back()
        self.watch = (pin, level) if pin is not None else None
        self.start()

    def _take_back(self, order, seg, at):
        mem = self.mem
        ring = self.ring
        words = mem[st.R_SEG_WORDS]
        shift = self.first
        level_mask = (1 << self.count) - 1
        # The words the pins never got, in stream order: (array, first, end).
        spans = []
        if at < 0:
            # The FIFO still held -at words of the segment refilled last: its tail.
            tail = self.tail
            prev = tail[_TAIL_WORDS - 1 + at] & level_mask
            spans.append((tail, _TAIL_WORDS + at, _TAIL_WORDS))
            at = 0
        else:
            # Levels on the pins: the last word sent's, or those the segment starts from.
            prev = mem[st.R_SEG_LV + seg] >> shift
            if at > 0:
                prev = ring[seg * words + at - 1] & level_mask
        started = False
        for s in order:
            started = started or s == seg
            if started:
                spans.append((ring, s * words + (at if s == seg else 0),
                              s * words + mem[st.R_SEG_N + s]))
        sent = prev << shift
        taken = 0
        for words_of, k, end in spans:
            while k < end:
                lv = words_of[k] & level_mask
                rising = (lv & ~prev) << shift
                dirs = lv << shift
                for step, dmask, pos, drive in self.motors:
                    if rising & step:
                        # A DIR pin high is forward, unless the motor is wired inverted.
                        forward = bool(dirs & dmask) != bool(self.dir_invert_mask & dmask)
                        back = 1 if forward else -1
                        mem[pos] -= back
                        taken += 1
                        if drive >= 0:
                            mem[drive] -= back
                prev = lv
                k += 1
        steps = 0
        dir_mask = 0
        for step, dmask, _, _ in self.motors:
            steps |= step
            dir_mask |= dmask
        mem[st.S_LEVELS] = sent & ~steps
        mem[st.S_DIR] = sent & dir_mask
        mem[st.S_PULSE_LEFT] = 0
        mem[st.S_WAIT] = 0
        mem[st.R_PENDING] = 0
        # The mixer's schedule went on past the steps taken back: start it afresh. (A
        # ring with no step left, as when homing changes program, leaves it as it is.)
        if taken:
            mem[st.MIX_BASE] = -1

    def deinit(self):
        if self.running:
            self.stop()


class _Mem32:
    def __init__(self, machine, base):
        self.base = base
        self.mem32 = machine.mem32  # main loop only: an address above 2**30 is a big int

    def __getitem__(self, i):
        return self.mem32[self.base + 4 * i]

    def __setitem__(self, i, value):
        self.mem32[self.base + 4 * i] = value
