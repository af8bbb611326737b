# The step loop: one viper function, run from machine.Timer on a board and from the
# virtual clock in the simulation. It reads the integer block records the planner
# prepared, walks a fixed-point velocity ramp per tick, spreads minor-axis steps
# with Bresenham, hands E steps to the mixer, and writes STEP/DIR edges in
# GPIO-number space: straight into the chip's set/clear registers (out is then the
# register block's address), or through `out(set_mask, clr_mask)` (Pin.value).
# While recording, every write is also kept in a ring with its tick (M7300/M7301).
#
# Every word the loop compares is kept non-negative: ptr32 loads zero-extend on the
# 64-bit unix port, so a stored -1 would read back as 4294967295 there.
#
# Rules, as it runs in an interrupt (docs/Step_Timing.md: which, on each chip): no
# allocation, no floats, nothing that can raise. All state lives in one preallocated
# array('i') whose layout is defined here (the modules that read it in viper keep
# copies of the words they use, which host_tests/test_layouts.py checks); the planner
# writes only block records and S_HEAD, the step loop writes everything else, and a
# record's ramp schedule as it starts the block (F_SCHEDULE).
from mixfw import mixer
from mixfw.mixer import mix_load
from mixfw import ramp
from mixfw.ramp import isqrt_limbs, ramp_into

# Fixed point for rates: lead-axis steps per tick times 2**28. A rate is at most
# half a step per tick, so rate + phase stays below 2**30 (the chips' small ints).
RATE_SHIFT = const(28)
ONE = const(0x10000000)

AXES = const(4)  # X Y Z E; E is split over the drives by the mixer
X = const(0)
Y = const(1)
Z = const(2)
E = const(3)

# Step-loop state words.
S_HEAD = const(0)  # next free block slot (written by the planner)
S_TAIL = const(1)  # block being run or next to run
S_ACTIVE = const(2)  # 1 while the tail block has started
_S_EVENT = const(3)  # lead-axis steps done in the block
S_PHASE = const(4)
_S_RATE = const(5)
_S_ERR = const(6)  # Bresenham counters, one per axis (4 words), kept in 1..n
_S_PULSE_MASK = const(10)  # STEP pins raised by the last step
S_PULSE_LEFT = const(11)  # ticks until they fall
S_WAIT = const(12)  # ticks of DIR setup or dwell still to wait
S_DIR = const(13)  # current DIR pin levels
S_POS = const(14)  # position in steps per axis (4 words)
S_DRIVE_POS = const(18)  # position in steps per mixing drive (6 words)
S_PULSE_TICKS = const(24)
S_DIR_TICKS = const(25)
S_QUEUE = const(26)  # block slots
S_HOME_STOP = const(27)  # axes stopped by their endstop in this homing block
S_TICKS = const(28)  # tick counter, wraps at 2**30
S_BLOCKS_DONE = const(29)  # blocks finished, wraps at 2**30
# Register writes: word offsets of the set and clear registers from the address
# passed as out; 0 for the Pin.value path. The HI pair is ESP32's register for
# GPIO 32..39, whose pins 32 and 33 use mask bits 28 and 29 (ESP32 has no GPIO 28-31).
S_REG_SET = const(30)
S_REG_CLR = const(31)
_S_REG_HI_SET = const(32)
_S_REG_HI_CLR = const(33)
# Trace capture: a ring of (tick since start, set mask, clear mask) records after the
# block ring. The interrupt writes at HEAD while there is room and counts what it had
# to drop in LOST; the main loop reads from TAIL (M7301).
S_CAP_ON = const(34)
S_CAP_BASE = const(35)
S_CAP_SIZE = const(36)  # records
S_CAP_HEAD = const(37)
S_CAP_TAIL = const(38)
S_CAP_LOST = const(39)
S_CAP_T0 = const(40)  # S_TICKS when recording started
# PIO output (see pio.py): out is the state machine's put; words are pin levels
# shifted down by S_PIO_SHIFT. _S_PIO_LEFT: ticks the current burst still runs.
S_PIO = const(41)  # 1 for the PIO path
S_PIO_SHIFT = const(42)
_S_PIO_LEFT = const(43)
S_PIO_LATENCY = const(44)
S_LEVELS = const(45)  # STEP/DIR levels written so far
_S_PIO_DRAIN = const(46)  # tick by which the state machine will have output every word
_S_RAMP_TICKS = const(47)  # ticks of velocity ramp run in the block
_S_WORDS = const(48)

MIX_BASE = const(48)  # mixer section, mixer.M_WORDS long
# The mixer words the step loop reads: copies of mixer.py's M_ offsets plus MIX_BASE
# (viper folds only this module's constants).
_MIX_W = const(49)
_MIX_SUM = const(55)
_MIX_Q = const(56)
_MIX_QMIN = const(57)
_MIX_AHEAD = const(58)
_MIX_E = const(59)
_MIX_RING = const(65)
_MIX_RING_MASK = const(66)
_MIX_BIAS = const(0x20000000)
_RING_STEPS = const(2048)  # the mixer's
MASK_BASE = const(67)  # STEP pin masks: X Y Z then the drives (9 words)
DIR_MASK_BASE = const(76)  # DIR pin masks in the same order (9 words)
# Event ring (step_backend "pio_dma", S_PIO == 2; see piodma.py): one call of tick runs
# a batch of ticks and writes the pin levels between its edges into the ring passed as
# out, a word each: the levels in the low bits, above R_LEVEL_BITS the PIO cycles they
# hold (a word is written when the edge that ends it is known). Times are PIO cycles
# from the batch's start.
R_SEG_N = const(85)  # words in each of the 3 ring segments
R_SEG_SEQ = const(88)  # batch number each segment holds (3 words)
R_TC = const(91)  # PIO cycles per tick
R_BATCH_TICKS = const(92)
R_PULSE_CYC = const(93)  # STEP high time
R_LAST = const(94)  # time of the last event written, from the batch's start (>= 0)
R_W = const(95)  # next ring word to write
R_PENDING = const(96)  # batches still to run before the pins have output every step
R_LATE = const(97)  # refills that came after the running segment had ended
R_BATCHES = const(98)  # batches filled, wraps at 2**30
R_SEG_WORDS = const(99)  # ring words per segment
R_READY = const(100)  # the segment filled and not yet handed to a channel
R_RING_ADDR = const(101)  # byte address of ring word 0 as the DMA sees it
R_CTRL = const(102)  # channel control word with CHAIN_TO 0
R_CHAIN_SHIFT = const(103)  # where CHAIN_TO sits in a control word
R_BUSY_BIT = const(104)
R_CH = const(105)  # the two DMA channels (2 words)
R_CH_SEG = const(107)  # segment each channel was last given (2 words)
R_FIRED = const(109)  # channel completions handled
R_SM = const(110)  # the state machine's number
R_SEG_LV = const(111)  # pin levels before each segment's first event (3 words)
R_LEVEL_BITS = const(114)  # the state machine's pins
# Pressure advance (blocks with _F_ADVANCE): the drives follow a target, the block's
# filament as Bresenham gives it plus the advance, K times the filament's speed (from
# the rate); at most one E step each lead-axis step (or each tick while a block waits
# for them), each through the mixer, forward or back. The picks are those of the
# blocks without advance, position by position: the follower loads a block's mix where
# its picks begin (mix_load keeping the ring), and walks back over the picks it made.
_S_ADV_OWED = const(115)  # E steps the drives owe the target, plus _ADV_BIAS
_S_ADV_NOW = const(116)  # the advance in the target, E steps
# The slot of the block whose mix the follower has loaded, plus 1; _ADV_OFF (0, as a
# memory made afresh is): the follower is off.
_S_ADV_SLOT = const(117)
_S_ADV_END = const(118)  # the mixer's position where that block's picks end
_S_ADV_DIR_AT = const(119)  # S_TICKS when the follower last changed the drives' DIR
_S_ADV_BACK = const(120)  # 1 while the drives' DIR pins are set backward
_S_ADV_FWD_SET = const(121)  # the drives' DIR pins raised for forward (the planner's)
_S_ADV_FWD_CLR = const(122)  # and lowered
BLOCK_BASE = const(123)

# Block record words.
B_N = const(0)  # lead-axis steps (step events)
B_STEPS = const(1)  # steps per axis X Y Z E, absolute (4 words)
_B_DIR_SET = const(5)  # DIR pins to raise at block start
_B_DIR_CLR = const(6)
B_FLAGS = const(7)
B_RATE_INIT = const(8)
B_RATE_NOM = const(9)
B_RATE_FINAL = const(10)
B_ACCEL = const(11)  # rate change per tick
# The ramp is scheduled in ramp ticks (counted from 1 in the block), not in steps: the
# planner knows the times of the trapezoid's corners, while the step at which a corner
# falls depends on the phase the block inherits. Accelerating ends at tick ACCEL_UNTIL;
# at tick DECEL_AFTER the rate is set to RATE_DECEL, the planned decelerating line at
# the next tick (the corner falls between ticks), and falls by ACCEL per tick after
# (ramp.ramp_into works them out).
B_ACCEL_UNTIL = const(12)
B_DECEL_AFTER = const(13)
B_DWELL = const(14)  # ticks, for dwell blocks
B_MIX = const(15)  # mix id then 6 weights: same shape as the mixer's M_ID..M_W
B_RATE_DECEL = const(22)
_B_ADV = const(23)  # _F_ADVANCE: E steps of advance per rate, times 2**23 over 2**13
B_WORDS = const(24)
# A PIO event takes this many cycles besides its delay (piodma.py's program): a pull,
# two outs and the last pass of the delay loop.
_EV_MIN_CYCLES = const(4)
# A ramp's ticks with no step are passed over in closed form up to this many at once,
# where the acceleration (rate per tick) is below _RAMP_SKIP_ACC: its products then
# stay below 2**30.
_RAMP_SKIP_MAX = const(1024)
_RAMP_SKIP_ACC = const(0x80000)
# Every batch has at least this many words, one more than the state machine's FIFO
# holds: a channel then never ends the moment it starts (several could end before
# their IRQs ran), and the FIFO never holds a whole batch.
BATCH_MIN_WORDS = const(9)
# A batch filled now has reached the pins once this many more have been filled: two
# segments are ahead of it in the ring, and the batch after it has pushed it out of
# the FIFO.
_PENDING_BATCHES = const(4)

# Flag bits.
F_DWELL = const(1)
F_HOMING = const(2)
_F_NEG = const(4)  # shifted by axis: _F_NEG << X .. _F_NEG << E are negative moves
_F_HOME_SHIFT = const(8)  # homing axis mask (X=1, Y=2, Z=4) << _F_HOME_SHIFT
# The record's ramp schedule (ACCEL_UNTIL, DECEL_AFTER, RATE_DECEL) is still to be
# worked out from its rates: the look-ahead changes a waiting block's entry and exit
# as more blocks come (on curves a dozen times a line), and a schedule worked out at
# each change would be most of its time. The step loop works it out once, as the
# block starts (schedule).
F_SCHEDULE = const(2048)
# And its rates too (with F_SCHEDULE): RATE_INIT and RATE_FINAL hold the entry's and
# the exit's V2 (lookahead.py; V2_AT_NOMINAL: the nominal rate's), and the schedule's
# words ACCEL_UNTIL, DECEL_AFTER and RATE_DECEL what a rate comes from: K2, K_SHIFT
# plus SHIFT_BIAS, and FLOOR. The look-ahead rewrites a waiting block's entry and exit
# a dozen times a line on curves, and a root or two for each would cost the chip most
# of a rewrite.
F_RATES = const(4096)
# The block's drives run by pressure advance's follower (see _S_ADV_OWED): its DIR words
# leave the drives' pins to it.
_F_ADVANCE = const(8192)
_ADV_OFF = const(0)
_ADV_BIAS = const(0x20000000)
# The most advance the target takes, E steps: the mixer's ring walks back twice that.
_ADV_MOST_STEPS = const(1024)
V2_AT_NOMINAL = const(0x20000000)  # above any V2 the look-ahead keeps
SHIFT_BIAS = const(64)
# ramp.py's io words, which schedule() stores and reads (copies).
_IO_N = const(0)
_IO_R0 = const(1)
_IO_RNOM = const(2)
_IO_R1 = const(3)
_IO_ACC = const(4)
_IO_ACCEL_UNTIL = const(5)
_IO_DECEL_AFTER = const(6)
_IO_RATE_DECEL = const(7)
_IO_HI = const(8)
_IO_LO = const(9)
_MASK30 = const(0x3FFFFFFF)  # compat.MASK30: the tick and block counters wrap at 2**30


CAP_WORDS = const(3)  # per capture record
_HI_SHIFT = const(28)  # ESP32: GPIO 32, 33 travel as mask bits 28, 29
_LO_MASK = const(0x0FFFFFFF)


def mem_words(queue_blocks, capture_records=0, ring_steps=_RING_STEPS):
    """The step loop's memory: its words, the block ring, the trace capture's records
    and the mixer's ring of picks (bytes, a power of 2), in that order."""
    return (BLOCK_BASE + queue_blocks * B_WORDS + capture_records * CAP_WORDS
            + ring_steps // 4)


def init_mem(mem, queue_blocks, capture_records=0, ring_steps=_RING_STEPS):
    """Where the capture and the mixer's ring lie in mem (mem_words' order)."""
    mem[S_CAP_BASE] = BLOCK_BASE + queue_blocks * B_WORDS
    mem[S_CAP_SIZE] = capture_records
    mem[_MIX_RING] = 4 * (mem[S_CAP_BASE] + capture_records * CAP_WORDS)
    mem[_MIX_RING_MASK] = ring_steps - 1
    mem[MIX_BASE + mixer.M_ID] = -1
    # Pressure advance's follower off, owing nothing (as planner.abort leaves it).
    mem[_S_ADV_SLOT] = _ADV_OFF
    mem[_S_ADV_OWED] = _ADV_BIAS


@micropython.viper
def _pio_ahead(mem: ptr32) -> int:
    """Ticks of words the state machine still holds."""
    ahead = (mem[_S_PIO_DRAIN] - mem[S_TICKS]) & _MASK30
    return 0 if ahead > 0x1FFFFFFF else ahead


@micropython.viper
def _pio_put(mem_buf, out, count: int):
    """Hand the state machine count words of the current levels, one tick each."""
    mem = ptr32(mem_buf)
    word = mem[S_LEVELS] >> mem[S_PIO_SHIFT]
    mem[_S_PIO_DRAIN] = (mem[S_TICKS] + int(_pio_ahead(mem_buf)) + count) & _MASK30
    while count > 0:
        out(word)
        count -= 1


@micropython.viper
def _finish(mem: ptr32):
    mem[S_ACTIVE] = 0
    tail = mem[S_TAIL] + 1
    if tail >= mem[S_QUEUE]:
        tail = 0
    mem[S_TAIL] = tail
    mem[S_BLOCKS_DONE] = (mem[S_BLOCKS_DONE] + 1) & _MASK30


@micropython.viper
def schedule(mem_buf, b: int, io_buf):
    """The ramp schedule of the record at word b, if it has none yet (F_SCHEDULE),
    by ramp.ramp_into in io_buf (ramp.IO_WORDS words of scratch of the caller's own:
    the step loop's interrupt may come in between the main loop's); first its rates,
    if it has none yet either (F_RATES)."""
    # The record's words through a pointer of their own: an index into mem costs viper
    # an addition and a shift at every use.
    blk = ptr32(int(ptr32(mem_buf)) + 4 * b)
    flags = blk[B_FLAGS]
    if flags & F_SCHEDULE:
        io = ptr32(io_buf)
        r_nom = blk[B_RATE_NOM]
        if flags & F_RATES:
            # rate = isqrt(V2 * K2) scaled by 2**K_SHIFT, within FLOOR and the nominal
            # rate: k sqrt(V2 / 64), k the speed's scale lookahead.plan_words works out.
            # The top rate is the nominal one: where the ramps meet below it (on
            # curves, most blocks), ramp_into finds their peak in the rates themselves.
            k2 = blk[B_ACCEL_UNTIL]
            shift = blk[B_DECEL_AFTER] - SHIFT_BIAS
            floor = blk[B_RATE_DECEL]
            w = B_RATE_INIT
            for _ in range(2):
                x = blk[w]
                if x >= V2_AT_NOMINAL:
                    r = r_nom
                elif x <= 0:
                    r = floor  # a stop: the root below would take 30 turns to say 0
                else:
                    # x * K2 (below 2**29 and 2**26) in two 30-bit limbs, in
                    # ramp.product's form, written out: this runs twice a block.
                    a1 = x >> 15
                    a0 = x & 0x7FFF
                    b1 = k2 >> 15
                    b0 = k2 & 0x7FFF
                    mid = a1 * b0 + a0 * b1
                    lo = ((mid & 0x7FFF) << 15) + a0 * b0
                    io[_IO_HI] = a1 * b1 + (mid >> 15) + (lo >> 30)
                    io[_IO_LO] = lo & _MASK30
                    r = int(isqrt_limbs(int(io) >> 2))  # its address over 4
                    if shift >= 0:
                        r = r << shift
                    else:
                        r = r >> (0 - shift)
                    if r > r_nom:
                        r = r_nom
                    if r < floor:
                        r = floor
                blk[w] = r
                w = B_RATE_FINAL
        io[_IO_N] = blk[B_N]
        io[_IO_R0] = blk[B_RATE_INIT]
        io[_IO_RNOM] = r_nom
        io[_IO_R1] = blk[B_RATE_FINAL]
        io[_IO_ACC] = blk[B_ACCEL]
        ramp_into(io_buf)
        blk[B_ACCEL_UNTIL] = io[_IO_ACCEL_UNTIL]
        blk[B_DECEL_AFTER] = io[_IO_DECEL_AFTER]
        blk[B_RATE_DECEL] = io[_IO_RATE_DECEL]
        blk[B_FLAGS] = flags & (0 - 1 - (F_SCHEDULE | F_RATES))


def ramp_scratch():
    """Scratch words for schedule(): one array for each context that calls it."""
    from array import array
    return array("i", bytes(4 * ramp.IO_WORDS))


# The step loop's own scratch: its interrupts do not nest.
_TICK_RAMP_IO = ramp_scratch()


@micropython.viper
def _start(mem_buf, b: int) -> int:
    """Begin the block at word b. Returns the DIR pins whose level changed."""
    mem = ptr32(mem_buf)
    blk = ptr32(int(mem) + 4 * b)  # as in schedule()
    mem[S_ACTIVE] = 1
    mem[_S_EVENT] = 0
    mem[S_HOME_STOP] = 0
    flags = blk[B_FLAGS]
    if flags & F_DWELL:
        mem[S_WAIT] = blk[B_DWELL]
        return 0
    if flags & F_SCHEDULE:
        schedule(mem_buf, b, _TICK_RAMP_IO)
    n = blk[B_N]
    half = n - (n >> 1)
    mem[_S_ERR + 0] = half
    mem[_S_ERR + 1] = half
    mem[_S_ERR + 2] = half
    mem[_S_ERR + 3] = half
    # A tick moves by its rate, so the rate must be the mean speed over the tick
    # (trapezoidal integration): half a tick of acceleration above the entry speed.
    mem[_S_RATE] = blk[B_RATE_INIT] + (blk[B_ACCEL] >> 1)
    mem[_S_RAMP_TICKS] = 0
    if flags & _F_ADVANCE:
        if mem[_S_ADV_SLOT] == _ADV_OFF:
            # The follower starts: the picks from here are new ground, as after a
            # fresh start (which a block without advance makes), and its first step
            # loads the mix of the first block with filament (_adv).
            slot = mem[S_TAIL] - 1
            if slot < 0:
                slot = mem[S_QUEUE] - 1
            mem[_S_ADV_SLOT] = slot + 1
            mem[_MIX_Q] = _MIX_BIAS
            mem[_MIX_QMIN] = _MIX_BIAS
            mem[_MIX_AHEAD] = 0
            mem[_S_ADV_END] = _MIX_BIAS
            fwd = mem[_S_ADV_FWD_SET]
            mem[_S_ADV_BACK] = 0 if (mem[S_DIR] & (fwd | mem[_S_ADV_FWD_CLR])) == fwd else 1
            mem[_S_ADV_DIR_AT] = (mem[S_TICKS] - mem[S_DIR_TICKS] - 1) & _MASK30
    elif blk[B_STEPS + E] != 0 and blk[B_MIX] != mem[MIX_BASE]:
        mix_load(mem_buf, MIX_BASE, b + B_MIX, 0)
    old = mem[S_DIR]
    new = (old & (0 - 1 - blk[_B_DIR_CLR])) | blk[_B_DIR_SET]
    changed = old ^ new
    if changed:
        mem[S_DIR] = new
        # The tick that writes DIR is the first tick of the setup time.
        mem[S_WAIT] = mem[S_DIR_TICKS] - 1
    return changed


# _adv's jobs.
_ADV_NEXT = const(0)
_ADV_DONE = const(1)
_ADV_STOP = const(2)


@micropython.viper
def _adv(mem_buf, job: int) -> int:
    """Pressure advance's follower, one function for its three jobs (a name each would
    take the chip's table of names past its sixth block).

    _ADV_NEXT, at the end of the picks it has loaded: the next block's mix with
    filament, loaded where its picks begin; blocks with none passed over. 0, and the
    follower waits, while that block is not queued yet or runs without advance (the
    follower gives its advance back first).

    _ADV_DONE: 1 if the tail block, its lead-axis steps all made, may end: the
    follower has made its picks (a record may be written over once its block ends, so
    the follower never stays behind one), and the last block queued, which ends at
    rest, has its advance back and owes nothing. Else the block waits, and the
    follower steps each tick.

    _ADV_STOP, before a block without advance: the target without the advance; 1, and
    the follower off, once the drives owe it nothing."""
    mem = ptr32(mem_buf)
    queue = mem[S_QUEUE]
    if job == _ADV_NEXT:
        slot = mem[_S_ADV_SLOT] - 1
        while True:
            slot += 1
            if slot >= queue:
                slot = 0
            if slot == mem[S_HEAD]:
                return 0
            b = BLOCK_BASE + slot * B_WORDS
            if not (mem[b + B_FLAGS] & _F_ADVANCE):
                return 0
            mem[_S_ADV_SLOT] = slot + 1
            e = mem[b + B_STEPS + E]
            if e > 0:
                mix_load(mem_buf, MIX_BASE, b + B_MIX, 1)
                mem[_S_ADV_END] = mem[_MIX_Q] + e
                return 1
    owed = mem[_S_ADV_OWED]
    if job == _ADV_STOP:
        owed -= mem[_S_ADV_NOW]
        mem[_S_ADV_NOW] = 0
        mem[_S_ADV_OWED] = owed
        if owed != _ADV_BIAS:
            return 0
        mem[_S_ADV_SLOT] = _ADV_OFF
        return 1
    tail = mem[S_TAIL]
    slot = mem[_S_ADV_SLOT] - 1
    if slot == tail:
        if mem[_MIX_Q] < mem[_S_ADV_END]:
            return 0
    else:
        ahead = slot - tail
        if ahead < 0:
            ahead += queue
        queued = mem[S_HEAD] - tail
        if queued < 0:
            queued += queue
        if ahead >= queued:  # behind: the follower has not reached this block's picks
            if mem[BLOCK_BASE + tail * B_WORDS + B_STEPS + E] > 0:
                return 0
            mem[_S_ADV_SLOT] = tail + 1
    nxt = tail + 1
    if nxt >= queue:
        nxt = 0
    if nxt == mem[S_HEAD]:
        owed -= mem[_S_ADV_NOW]
        mem[_S_ADV_NOW] = 0
        mem[_S_ADV_OWED] = owed
        return 1 if owed == _ADV_BIAS else 0
    return 1


@micropython.viper
def tick(io) -> int:
    """One timer tick. Returns 1 if a step was taken. io: (mem, out, endstops), made
    once: the step loop's array, where it writes (see the module's comment),
    and the endstops' reader.

    A stepping tick has the mixer and the pin writes inline, because a viper call
    costs as much as a whole idle tick: the tick works out the levels (set_mask,
    clr_mask) first and writes them at one place, the end.

    On ARMv6-M viper keeps a function's first locals (its arguments first) in
    registers, and the rest on the stack: one argument, so that mem, the most used,
    is in a register. The disassembly shows two there, io and mem; every other local
    costs a load or a store at each use.

    The helpers it calls get the array object (io[0]), never the ptr32: viper boxes
    a pointer it passes on as an int, and an address above 2**30 (any RAM of a 32-bit
    unix port, some chips' too) would be a big int allocated in the interrupt."""
    mem = ptr32(io[0])
    # The tail block's record: a pointer of its own, as an index into mem costs viper
    # an addition and a shift at every word read; worked out again as a block starts
    # (the tail moves on only as one ends).
    blk = ptr32(int(mem) + 4 * (BLOCK_BASE + mem[S_TAIL] * B_WORDS))
    # The ring's loop costs the timer path a compare of a register per tick: where the
    # timer path returns, the ring goes on with the batch's next tick.
    # Locals only the ring reads are set only for it (each is a store per tick).
    ring = 0
    if mem[S_PIO] == 2:
        ring = 1
        evr = ptr32(io[1])
        tc = mem[R_TC]
        ticks_left = mem[R_BATCH_TICKS]
        t0 = 0 - tc  # start of this tick, PIO cycles from the batch's start
        # The ring's words in locals for the batch, stored at its end.
        at = mem[R_W]  # the next ring word
        at_first = at
        last = mem[R_LAST]
        lv = mem[S_LEVELS]
        shift = mem[S_PIO_SHIFT]
        bits = mem[R_LEVEL_BITS]
        pulse_cyc = mem[R_PULSE_CYC]
        if mem[R_PENDING] > 0:
            mem[R_PENDING] -= 1
    cruise = 0
    while True:
        if ring:
            if cruise:
                # Cruise: straight on to the tick before the next step, or the
                # batch's end; the ticks between only add the same rate.
                cruise = 0
                rate = mem[_S_RATE]
                ramp = mem[_S_RAMP_TICKS]
                if rate > 0 and rate == blk[B_RATE_NOM] and \
                        ramp + 1 >= blk[B_ACCEL_UNTIL]:
                    phase = mem[S_PHASE]
                    skip = (ONE - 1 - phase) // rate
                    if skip > blk[B_DECEL_AFTER] - 1 - ramp:
                        skip = blk[B_DECEL_AFTER] - 1 - ramp
                    if skip > ticks_left:
                        skip = ticks_left
                    if skip > 0:
                        mem[S_PHASE] = phase + skip * rate
                        mem[_S_RAMP_TICKS] = ramp + skip
                        mem[S_TICKS] = (mem[S_TICKS] + skip) & _MASK30
                        ticks_left -= skip
                        t0 += skip * tc
                        left = mem[S_PULSE_LEFT]
                        if left > 0:  # a pulse's hold ends within the skip
                            mem[S_PULSE_LEFT] = left - skip if left > skip else 0
            if ticks_left <= 0:
                break
            ticks_left -= 1
            t0 += tc
        mem[S_TICKS] = (mem[S_TICKS] + 1) & _MASK30
        if ring == 0 and mem[S_PIO] == 1:
            # The levels the last tick left, for the state machine; the burst goes on
            # while there is work.
            left = mem[_S_PIO_LEFT]
            if left > 0:
                _pio_put(io[0], io[1], 1)
                if mem[S_ACTIVE] or mem[S_TAIL] != mem[S_HEAD] or mem[S_PULSE_LEFT]:
                    left = mem[S_PIO_LATENCY] + 2
                mem[_S_PIO_LEFT] = left - 1
        set_mask = 0
        clr_mask = 0
        stepped = 0
        # 1 to 3: the follower's step only: before a block, at its end, between steps
        drain = 0
        left = mem[S_PULSE_LEFT]
        if left > 0:
            left -= 1
            mem[S_PULSE_LEFT] = left
            # The ring has the fall written with its step: its pulse only holds the
            # next step back a tick longer (as the fall tick does here), and the tick
            # goes the cheap way.
            if left == 0 and ring == 0:
                clr_mask = mem[_S_PULSE_MASK]
        run = 1
        if mem[S_ACTIVE] == 0:
            blk = ptr32(int(mem) + 4 * (BLOCK_BASE + mem[S_TAIL] * B_WORDS))
            if mem[S_TAIL] == mem[S_HEAD]:
                # The axes have stopped (the planner ends the queue at rest): the next
                # move's first step comes a whole step after its start, as the ideal
                # trapezoid has it, not after what was left of the last move's step.
                mem[S_PHASE] = 0
                if clr_mask == 0:
                    if ring == 0:
                        return 0  # idle
                    if left == 0:  # nothing to do until the batch's end
                        mem[S_TICKS] = (mem[S_TICKS] + ticks_left) & _MASK30
                        ticks_left = 0
                    continue
                run = 0
            elif mem[_S_ADV_SLOT] != _ADV_OFF and not (blk[B_FLAGS] & _F_ADVANCE) and \
                    not int(_adv(io[0], _ADV_STOP)):
                drain = 1  # the advance goes back before a block that has none
                run = 0
            else:
                changed = int(_start(io[0], BLOCK_BASE + mem[S_TAIL] * B_WORDS))
                if changed:
                    dirs = mem[S_DIR]
                    set_mask = dirs & changed
                    clr_mask |= changed & (0 - 1 - dirs)
                    run = 0
        flags = blk[B_FLAGS]
        if run:
            wait = mem[S_WAIT]
            if wait > 0:
                mem[S_WAIT] = wait - 1
                if wait == 1 and (flags & F_DWELL):
                    _finish(io[0])
                run = 0
            elif flags & F_DWELL:  # a zero-length dwell
                _finish(io[0])
                run = 0
        # Homing looks at the endstops every tick, not only when a step is due: the
        # first closure of a bouncing switch can be shorter than a step, and it is
        # home. S_HOME_STOP latches: an axis stopped stays stopped for the rest of the
        # block, whatever the switch reads as it bounces.
        stopped = 0
        if run and (flags & F_HOMING):
            homing = (flags >> _F_HOME_SHIFT) & 7
            stopped = mem[S_HOME_STOP] | (int(io[2]()) & homing)
            mem[S_HOME_STOP] = stopped
            if stopped == homing:
                _finish(io[0])
                run = 0
        if run and (flags & _F_ADVANCE) and mem[_S_EVENT] >= blk[B_N]:
            drain = 2  # its lead-axis steps are made: it ends once _adv says so
            run = 0
        while run:
            # Velocity ramp, per tick so speed is linear in time.
            ramp = mem[_S_RAMP_TICKS] + 1
            mem[_S_RAMP_TICKS] = ramp
            rate = mem[_S_RATE]
            step_rate = rate
            phase = mem[S_PHASE] + rate
            if ramp < blk[B_ACCEL_UNTIL]:
                rate += blk[B_ACCEL]
                if rate > blk[B_RATE_NOM]:
                    rate = blk[B_RATE_NOM]
            elif ramp >= blk[B_DECEL_AFTER]:
                if ramp == blk[B_DECEL_AFTER]:
                    rate = blk[B_RATE_DECEL]
                else:
                    rate -= blk[B_ACCEL]
                    if rate < blk[B_RATE_FINAL]:
                        rate = blk[B_RATE_FINAL]
            else:
                rate = blk[B_RATE_NOM]
            mem[_S_RATE] = rate
            # A step waits while a STEP pin is still high or has just fallen (its low time).
            if phase >= ONE and left == 0 and clr_mask == 0:
                mem[S_PHASE] = phase - ONE
                break
            mem[S_PHASE] = phase
            run = 0
            if clr_mask == 0:
                if (flags & _F_ADVANCE) and left == 0 and mem[_S_ADV_OWED] != _ADV_BIAS and \
                        phase + (rate << 2) < ONE:
                    # The follower steps between lead-axis steps too, where its pulse
                    # ends well before the next of them: the advance keeps up with a
                    # ramp that asks more than a step of it each.
                    drain = 3
                    break
                if ring == 0:
                    return 0  # the most common tick while moving: no step due, no pin to write
                if ticks_left <= 0 or (rate == blk[B_RATE_NOM] and
                                       ramp + 1 >= blk[B_ACCEL_UNTIL]):
                    cruise = 1  # the loop's top skips a cruise's ticks at once
                    break
                # A ramp: the next tick has nothing else to do (no pin, no block to
                # start or end before a step), so it comes round here, past the
                # ticks that surely end below a step at once (_RAMP_SKIP_MAX at
                # most, so that every product below stays in a machine word): a
                # tick each costs the chip about 1.7 us, a sixth of its time at 10 us
                # ticks on curves, which never stop ramping.
                gap = ONE - 1 - phase
                acc = blk[B_ACCEL]
                skip = 0
                da = 0  # the rate's change a tick over the ticks passed over
                if gap > 0 and rate > 0 and acc > 0 and acc < _RAMP_SKIP_ACC:
                    most = gap // rate  # no more at the fastest rate of a deceleration
                    if most > _RAMP_SKIP_MAX:
                        most = _RAMP_SKIP_MAX
                    x = 0
                    if most > 2:
                        if ramp + 1 < blk[B_ACCEL_UNTIL]:
                            # Accelerating: rate + acc (j - 1) at the j-th, so k ticks
                            # add k rate + acc k (k - 1) / 2, below gap while
                            # k (rate + acc most) is, for k <= most; short of the
                            # nominal rate and of ACCEL_UNTIL.
                            da = acc
                            skip = gap // (rate + acc * most)
                            if skip > most:
                                skip = most
                            x = blk[B_ACCEL_UNTIL] - 1 - ramp
                            if skip > x:
                                skip = x
                            x = (blk[B_RATE_NOM] - rate) // acc
                        elif ramp >= blk[B_DECEL_AFTER]:
                            # Decelerating: short of the final rate.
                            da = 0 - acc
                            skip = most
                            x = (rate - blk[B_RATE_FINAL]) // acc
                    if skip > x:
                        skip = x
                    if skip > ticks_left - 1:
                        skip = ticks_left - 1
                if skip > 0:
                    # Each term below gap (see above), so in a machine word.
                    phase += skip * rate + ((skip * (skip - 1)) >> 1) * da
                    rate += skip * da
                    ramp += skip
                    mem[S_PHASE] = phase
                    mem[_S_RATE] = rate
                    mem[_S_RAMP_TICKS] = ramp
                    ticks_left -= skip
                    t0 += skip * tc
                    mem[S_TICKS] = (mem[S_TICKS] + skip) & _MASK30
                    if left > 0:
                        left = left - skip if left > skip else 0
                        mem[S_PULSE_LEFT] = left
                ticks_left -= 1
                t0 += tc
                mem[S_TICKS] = (mem[S_TICKS] + 1) & _MASK30
                if left > 0:
                    left -= 1
                    mem[S_PULSE_LEFT] = left
                run = 1
        if cruise:
            continue
        if run or drain:
            n = blk[B_N]
            dset = 0  # the drives' DIR pins the follower changes
            dclr = 0
            if run:
                stepped = 1
                # Bresenham for X, Y, Z, written out: constant offsets cost nothing.
                err = mem[_S_ERR + X] + blk[B_STEPS + X]
                if err > n:
                    err -= n
                    if (stopped & 1) == 0:
                        set_mask = mem[MASK_BASE + X]
                        if flags & (_F_NEG << X):
                            mem[S_POS + X] -= 1
                        else:
                            mem[S_POS + X] += 1
                mem[_S_ERR + X] = err
                err = mem[_S_ERR + Y] + blk[B_STEPS + Y]
                if err > n:
                    err -= n
                    if (stopped & 2) == 0:
                        set_mask |= mem[MASK_BASE + Y]
                        if flags & (_F_NEG << Y):
                            mem[S_POS + Y] -= 1
                        else:
                            mem[S_POS + Y] += 1
                mem[_S_ERR + Y] = err
                err = mem[_S_ERR + Z] + blk[B_STEPS + Z]
                if err > n:
                    err -= n
                    if (stopped & 4) == 0:
                        set_mask |= mem[MASK_BASE + Z]
                        if flags & (_F_NEG << Z):
                            mem[S_POS + Z] -= 1
                        else:
                            mem[S_POS + Z] += 1
                mem[_S_ERR + Z] = err
            e_step = 0  # 1 forward, 2 back
            if drain or (flags & _F_ADVANCE):
                owed = mem[_S_ADV_OWED]
                if run:
                    # The target: the block's filament by Bresenham, and the advance
                    # at the step's rate, at most _ADV_MOST_STEPS.
                    err = mem[_S_ERR + E] + blk[B_STEPS + E]
                    if err > n:
                        err -= n
                        owed += 1
                    mem[_S_ERR + E] = err
                    a = blk[_B_ADV]
                    adv = 0
                    if a:
                        r = step_rate >> 13
                        adv = ((r * (a >> 8)) >> 15) + ((r * (a & 255)) >> 23)
                        if adv > _ADV_MOST_STEPS:
                            adv = _ADV_MOST_STEPS
                    owed += adv - mem[_S_ADV_NOW]
                    mem[_S_ADV_NOW] = adv
                # A step as the target is ahead or behind, once the drives' DIR pins
                # point that way and have been set up; a step each lead-axis step, or
                # a tick while no STEP pin is held.
                if owed != _ADV_BIAS and (run or (left == 0 and clr_mask == 0)):
                    back = 1 if owed < _ADV_BIAS else 0
                    if back != mem[_S_ADV_BACK]:
                        mem[_S_ADV_BACK] = back
                        mem[_S_ADV_DIR_AT] = mem[S_TICKS]
                        dset = mem[_S_ADV_FWD_SET]
                        dclr = mem[_S_ADV_FWD_CLR]
                        if back:
                            dset = dclr
                            dclr = mem[_S_ADV_FWD_SET]
                        mem[S_DIR] = (mem[S_DIR] & (0 - 1 - dclr)) | dset
                    elif ((mem[S_TICKS] - mem[_S_ADV_DIR_AT]) & _MASK30) > mem[S_DIR_TICKS]:
                        if back:
                            e_step = 2
                            owed += 1
                        elif mem[_MIX_AHEAD] or mem[_MIX_Q] < mem[_S_ADV_END] or \
                                int(_adv(io[0], _ADV_NEXT)):
                            e_step = 1
                            owed -= 1
                mem[_S_ADV_OWED] = owed
            else:
                err = mem[_S_ERR + E] + blk[B_STEPS + E]
                if err > n:
                    err -= n
                    e_step = 1
                    if flags & (_F_NEG << E):
                        e_step = 2
                mem[_S_ERR + E] = err
            if e_step:
                # The mixer (see mixer.py): on new ground the highest error, ties to
                # the lowest drive (backward: the lowest error less twice the weight,
                # the rule on the mirrored errors); where the ring knows the pick, the
                # pick again. A drive without a weight never wins: the top error of
                # a mix with weights is above 0, the bottom one backward below 0 (the
                # words hold them plus _MIX_BIAS). No mix (no weight at all): no drive
                # steps.
                q = mem[_MIX_Q]
                picks = ptr8(int(mem) + mem[_MIX_RING])
                best = -1
                if e_step == 2:
                    q -= 1
                    ahead = mem[_MIX_AHEAD] + 1
                    # Known if walked and not yet written over: forward steps on new
                    # ground store nothing of the ring's reach (one store fewer
                    # there), so this tells how far back it still reaches.
                    known = 0
                    if q >= mem[_MIX_QMIN]:
                        if ahead <= mem[_MIX_RING_MASK] + 1:
                            known = 1
                    if known:
                        best = picks[q & mem[_MIX_RING_MASK]]
                        mem[_MIX_E] -= mem[_MIX_W]
                        mem[_MIX_E + 1] -= mem[_MIX_W + 1]
                        mem[_MIX_E + 2] -= mem[_MIX_W + 2]
                        mem[_MIX_E + 3] -= mem[_MIX_W + 3]
                        mem[_MIX_E + 4] -= mem[_MIX_W + 4]
                        mem[_MIX_E + 5] -= mem[_MIX_W + 5]
                    else:
                        # Written out as forward, as are the ring's cases (a
                        # retraction block runs here).
                        top = _MIX_BIAS
                        v = mem[_MIX_E] - mem[_MIX_W]
                        mem[_MIX_E] = v
                        if v < top:
                            top = v
                            best = 0
                        v = mem[_MIX_E + 1] - mem[_MIX_W + 1]
                        mem[_MIX_E + 1] = v
                        if v < top:
                            top = v
                            best = 1
                        v = mem[_MIX_E + 2] - mem[_MIX_W + 2]
                        mem[_MIX_E + 2] = v
                        if v < top:
                            top = v
                            best = 2
                        v = mem[_MIX_E + 3] - mem[_MIX_W + 3]
                        mem[_MIX_E + 3] = v
                        if v < top:
                            top = v
                            best = 3
                        v = mem[_MIX_E + 4] - mem[_MIX_W + 4]
                        mem[_MIX_E + 4] = v
                        if v < top:
                            top = v
                            best = 4
                        v = mem[_MIX_E + 5] - mem[_MIX_W + 5]
                        mem[_MIX_E + 5] = v
                        if v < top:
                            best = 5
                        if best >= 0:
                            picks[q & mem[_MIX_RING_MASK]] = best
                            mem[_MIX_QMIN] = q
                            if ahead > mem[_MIX_RING_MASK] + 1:
                                ahead = mem[_MIX_RING_MASK] + 1
                    if best >= 0:
                        mem[_MIX_AHEAD] = ahead
                        mem[_MIX_E + best] += mem[_MIX_SUM]
                        mem[_MIX_Q] = q
                        set_mask |= mem[MASK_BASE + 3 + best]
                        mem[S_DRIVE_POS + best] -= 1
                    mem[S_POS + E] -= 1
                else:
                    ahead = mem[_MIX_AHEAD]
                    if ahead:
                        best = picks[q & mem[_MIX_RING_MASK]]
                        mem[_MIX_AHEAD] = ahead - 1
                        mem[_MIX_E] += mem[_MIX_W]
                        mem[_MIX_E + 1] += mem[_MIX_W + 1]
                        mem[_MIX_E + 2] += mem[_MIX_W + 2]
                        mem[_MIX_E + 3] += mem[_MIX_W + 3]
                        mem[_MIX_E + 4] += mem[_MIX_W + 4]
                        mem[_MIX_E + 5] += mem[_MIX_W + 5]
                    else:
                        # Every drive's words, written out: the loop's counter and
                        # indexes cost viper as much again on the emulated Pico, and
                        # forward on new ground is how a print runs.
                        top = _MIX_BIAS
                        v = mem[_MIX_E] + mem[_MIX_W]
                        mem[_MIX_E] = v
                        if v > top:
                            top = v
                            best = 0
                        v = mem[_MIX_E + 1] + mem[_MIX_W + 1]
                        mem[_MIX_E + 1] = v
                        if v > top:
                            top = v
                            best = 1
                        v = mem[_MIX_E + 2] + mem[_MIX_W + 2]
                        mem[_MIX_E + 2] = v
                        if v > top:
                            top = v
                            best = 2
                        v = mem[_MIX_E + 3] + mem[_MIX_W + 3]
                        mem[_MIX_E + 3] = v
                        if v > top:
                            top = v
                            best = 3
                        v = mem[_MIX_E + 4] + mem[_MIX_W + 4]
                        mem[_MIX_E + 4] = v
                        if v > top:
                            top = v
                            best = 4
                        v = mem[_MIX_E + 5] + mem[_MIX_W + 5]
                        mem[_MIX_E + 5] = v
                        if v > top:
                            best = 5
                        # (With no mix, best is -1 and nothing below moves: the byte
                        # written is never read, as the position is not walked.)
                        picks[q & mem[_MIX_RING_MASK]] = best
                    if best >= 0:
                        mem[_MIX_E + best] -= mem[_MIX_SUM]
                        mem[_MIX_Q] = q + 1
                        set_mask |= mem[MASK_BASE + 3 + best]
                        mem[S_DRIVE_POS + best] += 1
                    mem[S_POS + E] += 1
            if set_mask:
                stepped = 1
                mem[_S_PULSE_MASK] = set_mask
                mem[S_PULSE_LEFT] = mem[S_PULSE_TICKS] + ring
            # The follower's DIR pins, after the pulse's: they don't fall with it.
            set_mask |= dset
            clr_mask |= dclr
            if run:
                event = mem[_S_EVENT] + 1
                mem[_S_EVENT] = event
                if event >= n:
                    if not (flags & _F_ADVANCE) or int(_adv(io[0], _ADV_DONE)):
                        _finish(io[0])
            elif drain == 2 and int(_adv(io[0], _ADV_DONE)):
                _finish(io[0])
        if (set_mask | clr_mask) == 0:
            if ring == 0:
                return stepped
            continue
        # The writes: set_mask pins high, clr_mask pins low, by one of three outputs
        # (S_PIO, then S_REG_SET, says which), recorded first while tracing.
        # --- output: the trace (M7300) ---
        if mem[S_CAP_ON]:
            # One record of the writes; with the ring, a step's second: its fall, a
            # pulse later (the ring has no fall tick).
            cap_set = set_mask
            cap_clr = clr_mask
            cap_t = mem[S_TICKS]
            records = 2 if ring and stepped else 1
            while records > 0:
                records -= 1
                head = mem[S_CAP_HEAD]
                nxt = head + 1
                if nxt >= mem[S_CAP_SIZE]:
                    nxt = 0
                if nxt == mem[S_CAP_TAIL]:
                    mem[S_CAP_LOST] += 1
                else:
                    r = mem[S_CAP_BASE] + head * CAP_WORDS
                    mem[r] = (cap_t - mem[S_CAP_T0]) & _MASK30
                    mem[r + 1] = cap_set
                    mem[r + 2] = cap_clr
                    mem[S_CAP_HEAD] = nxt
                cap_clr = mem[_S_PULSE_MASK]
                cap_set = 0
                cap_t += mem[S_PULSE_TICKS]
        # --- output: PIO/DMA words (pio_dma's ring here, and the batch's end below
        # the loop; pio's state machine) ---
        if mem[S_PIO]:
            if ring:
                # A step at the time the phase crossed ONE inside the tick (the rate
                # is the tick's mean speed), its fall a pulse later; DIR at the tick's
                # start. Events are never closer than the program's own cycles.
                nxt = (lv | set_mask) & ~clr_mask
                if nxt != lv:  # else a pulse whose fall is written already
                    t = t0
                    if run:
                        over = phase - ONE  # phase left over at the tick's end
                        if over < step_rate:
                            t = t0 + tc - (((over // ((step_rate >> 10) + 1)) * tc) >> 10)
                    # The levels before, held to the edge; with a step, its levels
                    # too, held to its fall a pulse later (written out: a loop's
                    # counter costs viper more than the second copy).
                    if t < last + _EV_MIN_CYCLES:
                        t = last + _EV_MIN_CYCLES
                    evr[at] = (lv >> shift) | ((t - last - _EV_MIN_CYCLES) << bits)
                    at += 1
                    last = t
                    lv = nxt
                    if stepped:
                        t += pulse_cyc
                        if t < last + _EV_MIN_CYCLES:
                            t = last + _EV_MIN_CYCLES
                        evr[at] = (lv >> shift) | ((t - last - _EV_MIN_CYCLES) << bits)
                        at += 1
                        last = t
                        lv = lv & ~mem[_S_PULSE_MASK]
                if drain == 0 and mem[_S_ADV_OWED] == _ADV_BIAS:
                    cruise = stepped & mem[S_ACTIVE]
                continue
            if mem[_S_PIO_LEFT] == 0:
                # A burst starts: old levels until the latency is queued, so this
                # tick's levels come out exactly LATENCY ticks from now.
                fill = mem[S_PIO_LATENCY] - int(_pio_ahead(io[0]))
                if fill > 0:
                    _pio_put(io[0], io[1], fill)
            mem[S_LEVELS] = (mem[S_LEVELS] | set_mask) & ~clr_mask
            mem[_S_PIO_LEFT] = mem[S_PIO_LATENCY] + 2
            return stepped
        # --- output: pin writes (pin_writer "pin", S_REG_SET 0): out(set, clear) ---
        at = mem[S_REG_SET]
        if at == 0:
            io[1](set_mask, clr_mask)
            return stepped
        # --- output: register writes (pin_writer "registers") ---
        regs = ptr32(io[1])
        hi = mem[_S_REG_HI_SET]
        if hi:
            if set_mask >> _HI_SHIFT:
                regs[hi] = set_mask >> _HI_SHIFT
            if clr_mask >> _HI_SHIFT:
                regs[mem[_S_REG_HI_CLR]] = clr_mask >> _HI_SHIFT
            set_mask = set_mask & _LO_MASK
            clr_mask = clr_mask & _LO_MASK
        if set_mask:
            regs[at] = set_mask
        if clr_mask:
            regs[mem[S_REG_CLR]] = clr_mask
        return stepped

    # --- output: PIO/DMA words, the batch's end (pio_dma) ---
    # The levels since the last edge hold to the batch's last cycle, in as many
    # pieces as make up BATCH_MIN_WORDS, and the next batch counts from there.
    end = mem[R_BATCH_TICKS] * tc
    mem[S_LEVELS] = lv
    lv = lv >> shift
    edges = at - at_first
    pieces = BATCH_MIN_WORDS - edges
    if pieces < 1 or end - last < pieces * _EV_MIN_CYCLES:
        pieces = 1
    while pieces > 1:
        piece = (end - last) // pieces
        evr[at] = lv | ((piece - _EV_MIN_CYCLES) << bits)
        at += 1
        last += piece
        pieces -= 1
    t = end if end >= last + _EV_MIN_CYCLES else last + _EV_MIN_CYCLES
    evr[at] = lv | ((t - last - _EV_MIN_CYCLES) << bits)
    at += 1
    mem[R_W] = at
    mem[R_LAST] = t - end
    if edges or mem[S_ACTIVE] or mem[S_TAIL] != mem[S_HEAD] or mem[S_PULSE_LEFT]:
        mem[R_PENDING] = _PENDING_BATCHES
    mem[R_BATCHES] = (mem[R_BATCHES] + 1) & _MASK30
    return at


def run_mix(weights, moves, out=None, ring_steps=_RING_STEPS):
    """Runs this step loop on E-only moves of moves[k] steps each (negative: back) from
    a fresh start of the mix `weights`, and returns each drive's net steps: the
    mixer exactly as the interrupt runs it, for the planner's forecasts and for
    tests. A move (steps, weights) changes the mix there: a block with a new mix id,
    as the planner gives every extruding block. out(set_mask, clr_mask), if given,
    sees every step (drive d is bit d). ring_steps: the mixer's ring (a power of 2,
    at least 4), the firmware's unless a walk needs no stepping back
    (schedule_counts)."""
    from array import array
    drives = len(weights)
    mem = array("i", bytes(4 * mem_words(2, 0, ring_steps)))
    init_mem(mem, 2, 0, ring_steps)
    mem[S_QUEUE] = 2
    for d in range(drives):
        mem[MASK_BASE + 3 + d] = 1 << d
    if out is None:
        out = array("i", bytes(12))  # scratch set/clear registers at words 1, 2
        mem[S_REG_SET] = 1
        mem[S_REG_CLR] = 2
    io = (mem, out, None)
    mix_id = 1
    for steps in moves:
        if not isinstance(steps, int):
            steps, weights = steps
            mix_id += 1
        if steps == 0:
            continue
        b = BLOCK_BASE + mem[S_HEAD] * B_WORDS
        n = abs(steps)
        mem[b + B_N] = mem[b + B_STEPS + E] = n
        mem[b + B_DECEL_AFTER] = n + 1  # a step per tick: done before it decelerates
        mem[b + B_FLAGS] = (_F_NEG << E) if steps < 0 else 0
        mem[b + B_RATE_INIT] = mem[b + B_RATE_NOM] = mem[b + B_RATE_FINAL] = ONE
        mem[b + B_MIX] = mix_id
        for d in range(drives):
            mem[b + B_MIX + 1 + d] = weights[d]
        mem[S_HEAD] = 1 - mem[S_HEAD]
        done = mem[S_BLOCKS_DONE]
        while mem[S_BLOCKS_DONE] == done:
            tick(io)
    return tuple(mem[S_DRIVE_POS + d] for d in range(drives))


def schedule_counts(weights, steps):
    """Steps per drive the mixer gives in `steps` steps from a fresh start (forward
    only, so a ring of 4 picks will do: no big array in the main loop)."""
    return run_mix(weights, (steps,), None, 4)


def make_irq(mem, out, endstops):
    """The timer callback, bound once so the interrupt looks up no name (see
    piodma's handlers): the step loop and its io as default arguments, which hold
    less heap than a closure's cells."""
    def irq(_timer, step=tick, io=(mem, out, endstops)):
        step(io)

    return irq
