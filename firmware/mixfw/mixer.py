# The mixer: which filament drive gets each extrusion step.
#
# The mixing document's integer error diffusion: every drive's error starts at its
# weight W; each step goes to the drive with the highest error (ties to the lowest
# drive), which then loses S (the sum of the weights), and every error gains its
# weight. From a fresh start 20/30/50 gives 3,2,1,3,2,3,3,1,2,3; after S steps every
# drive has made exactly W steps and the errors are back where they started.
#
# Stepping back has no rule of its own that undoes the forward one (a state has
# several possible predecessors, and telling them apart can take a dozen steps), so
# the mixer keeps its picks in a ring of _RING_STEPS bytes, by E position, with the
# span of positions it knows: a step back over known positions takes the recorded
# drive, and a step forward over positions first walked backwards replays them. Only
# new ground is picked: forward by the rule above, backward by the same rule run on
# the mirrored errors 2W - error, so a block run backwards from a fresh start meets
# the drives in the forward order and also gives exactly W steps each a period. Any
# walk within _RING_STEPS positions retraces itself exactly, anywhere in a block.
#
# The errors are kept less their weights (a fresh start is all zeros): the step loop
# adds each weight as it scans for the highest, one pass over the drives. They and
# the positions are stored plus _MIX_BIAS, so that every word the step loop compares
# is positive: a 64-bit port's ptr32 reads a negative word as a large positive one.
#
# This module holds the weights, their normalisation and the mixer's state: one
# preallocated array('i') section (see the M_ offsets), whose ring lies at the end of
# the step loop's memory (stepper.mem_words). The pick itself runs inline in the step
# loop (stepper.tick), which has no viper call to spare; stepper.run_mix runs it on a
# scratch block for the planner's forecasts and tests.

MAX_DRIVES = const(6)
# Normalised weights sum to at most this before the gcd is taken out, so products
# and errors stay below 2**30 (the chips' small-int limit).
WEIGHT_SCALE = const(10000)
_RING_STEPS = const(2048)  # picks remembered, a power of 2
_MIX_BIAS = const(0x20000000)  # a multiple of _RING_STEPS

# Offsets inside the mixer section. M_ID..M_W has the same shape as a block's mix
# words, so starting a block is one copy (mix_load). The step loop has its own copies
# of the private ones (stepper._MIX_*): names a chip would keep in RAM else.
M_ID = const(0)  # id of the mix loaded, -1 for none
M_W = const(1)  # weights, MAX_DRIVES words
_M_SUM = const(7)  # sum of weights: the period
_M_Q = const(8)  # E position in steps since the mix was loaded
# The ring knows the picks at positions _M_QMIN .. _M_Q + _M_AHEAD - 1, the last
# _RING_STEPS of them at most: forward steps on new ground change neither word.
_M_QMIN = const(9)
_M_AHEAD = const(10)  # known positions ahead of _M_Q
_M_E = const(11)  # each drive's error less its weight, MAX_DRIVES words
_M_RING = const(17)  # the ring's byte offset from the memory's start
_M_RING_MASK = const(18)  # its length less 1 (a power of 2 less 1)
M_WORDS = const(19)


class MixError(ValueError):
    pass


def gcd(a, b):
    while b:
        a, b = b, a % b
    return a


def normalize(weights, drives):
    """Non-negative numbers -> integer weights (tuple of `drives`) with the gcd taken out.

    Every positive weight keeps at least 1, so no drive asked for is dropped. An all-zero
    or negative mix is refused: the step loop would have no drive to step."""
    if len(weights) > drives:
        raise MixError("mix has %d weights but only %d drives" % (len(weights), drives))
    vals = [float(w) for w in weights] + [0.0] * (drives - len(weights))
    for i, v in enumerate(vals):
        if v < 0 or v != v:
            raise MixError("weight for drive %d is %s; weights must be >= 0" % (i, v))
    total = sum(vals)
    if total <= 0:
        raise MixError("all-zero mix refused: at least one drive needs a weight > 0")
    if total <= WEIGHT_SCALE and all(v == int(v) for v in vals):
        ints = [int(v) for v in vals]  # already exact: 1:1:1 stays 1:1:1
    else:
        # Largest remainder, so the scaled weights sum to exactly WEIGHT_SCALE.
        exact = [v * WEIGHT_SCALE / total for v in vals]
        ints = [int(x) for x in exact]
        order = sorted(range(drives), key=lambda i: ints[i] - exact[i])
        short = WEIGHT_SCALE - sum(ints)
        for i in order[:short]:
            ints[i] += 1
        for i in range(drives):
            if vals[i] > 0 and ints[i] == 0:
                ints[i] = 1
    g = 0
    for w in ints:
        g = gcd(g, w)
    return tuple(w // g for w in ints)


@micropython.viper
def mix_load(mem: ptr32, base: int, src: int, ring: int):
    """Copy a mix (id and weights at mem[src:]) into the mixer and start it afresh;
    with ring, where the position stands, its ring of picks kept: pressure
    advance's follower (stepper.py) walks from one block's picks on into the next
    block's as one path, and back over them, which a fresh start would forget. The
    picks ahead are the new mix's from there, as they would be from a fresh start."""
    mem[base + M_ID] = mem[src]
    total = 0
    i = 0
    while i < MAX_DRIVES:
        w = mem[src + 1 + i]
        mem[base + M_W + i] = w
        mem[base + _M_E + i] = _MIX_BIAS
        total += w
        i += 1
    mem[base + _M_SUM] = total
    mem[base + _M_AHEAD] = 0
    if not ring:
        mem[base + _M_Q] = _MIX_BIAS
        mem[base + _M_QMIN] = _MIX_BIAS


def default_tool_mixes(drives, count=16):
    """T<n> is 100 % drive n below the drive count, an equal mix of all drives above."""
    return tuple(tuple(1 if i == t else 0 for i in range(drives)) if t < drives
                 else (1,) * drives for t in range(count))
