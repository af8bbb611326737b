# The mixer: which filament drive gets each extrusion step.
#
# Weights are integers that never change inside a block. The choice is an exact
# divisor (Sainte-Lague) schedule: drive i takes its k-th step of a period at the
# "due time" (2k+1)/(2*w_i), and the step goes to the drive with the earliest due
# time, ties to the lowest index. From a fresh start 20/30/50 gives the mixing
# document's sequence 3,2,1,3,2,3,3,1,2,3. Unlike a largest-error rule this schedule
# has an exact inverse: stepping back takes the drive with the latest previous due
# time, ties to the highest index, so n steps back and n forward restore every
# count and every drive position, however lopsided the weights.
#
# This module holds the weights, their normalisation and the schedule's state: one
# preallocated array('i') section (see the M_ offsets). The pick itself runs inline
# in the step loop (stepper.tick), which has no viper call to spare;
# stepper.run_mix runs it on a scratch block for the planner's forecasts and tests.

MAX_DRIVES = const(6)
# Normalised weights sum to at most this before the gcd is taken out, so products
# in the schedule stay below 2**30 (the chips' small-int limit).
WEIGHT_SCALE = const(10000)

# Offsets inside the mixer section. M_ID..M_W has the same shape as a block's mix
# words, so starting a block is one copy (mix_load).
M_ID = const(0)  # id of the mix loaded, -1 for none
M_W = const(1)  # weights, MAX_DRIVES words
M_N = const(7)  # number of drives fitted
M_SUM = const(8)  # sum of weights: the period of the schedule
M_Q = const(9)  # steps taken in the current period
M_C = const(10)  # per-drive steps in the current period, MAX_DRIVES words
M_WORDS = const(16)


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
def mix_load(mem: ptr32, base: int, src: int):
    """Copy a mix (id and weights at mem[src:]) into the mixer and restart its schedule."""
    mem[base + M_ID] = mem[src]
    total = 0
    i = 0
    while i < MAX_DRIVES:
        w = mem[src + 1 + i]
        mem[base + M_W + i] = w
        mem[base + M_C + i] = 0
        total += w
        i += 1
    mem[base + M_SUM] = total
    mem[base + M_Q] = 0


def load(mem, base, mix_id, weights):
    """Load a normalised mix from the main loop (tests, start-up)."""
    mem[base + M_ID] = mix_id
    for i in range(MAX_DRIVES):
        mem[base + M_W + i] = weights[i] if i < len(weights) else 0
    mix_load(mem, base, base)


def default_tool_mixes(drives, count=16):
    """T<n> is 100 % drive n below the drive count, an equal mix of all drives above."""
    return tuple(tuple(1 if i == t else 0 for i in range(drives)) if t < drives
                 else (1,) * drives for t in range(count))
