"""The mixer's error diffusion, run on the MicroPython unix port, against the mixing
document's rule as trace check's model writes it from the document's text
(tracemodel.mixer_picks)."""
import itertools
import json
from collections import Counter

from hypothesis import given, settings, strategies as st

from mixstep import sim, trace
from mixstep.tracemodel import mixer_picks

# Each E step's drive as the step loop's own mixer schedule picks it: upy/mixer_picks.py.
MIXER = """
from mixfw import mixer, stepper
from mixer_picks import picks
"""


def test_seed_sequence_from_fresh_start(mp):
    seq = mp.json(MIXER + """
print([d + 1 for d in picks([20, 30, 50], [10])])
""")
    assert seq == [3, 2, 1, 3, 2, 3, 3, 1, 2, 3]


def test_weights_are_any_nonnegative_numbers_normalised_to_integers(mp):
    out = mp.json(MIXER + """
import json
print(json.dumps([mixer.normalize([0.2, 0.3, 0.5], 3), mixer.normalize([20, 30, 50], 3),
                  mixer.normalize([1e-6, 1], 2), mixer.normalize([1, 1, 1], 6)]))
""")
    assert out == [[2, 3, 5], [2, 3, 5], [1, 10000], [1, 1, 1, 0, 0, 0]]


def test_all_zero_and_negative_mixes_are_refused(mp):
    out = mp.script_json("mixer_refusals")
    assert out[0].startswith("all-zero mix refused")
    assert "must be >= 0" in out[1]
    assert out[2].startswith("all-zero mix refused")


def test_proportions_over_a_period_are_exact(mp):
    counts = mp.json(MIXER + """
print(list(stepper.run_mix(mixer.normalize([1, 2, 3, 4, 5, 985], 6), [1000 * 7])))
""")
    assert counts == [7, 14, 21, 28, 35, 6895]


def _firmware_picks(mp, cases):
    """Each case [weights, moves]: the drives the step loop picks (upy/mixer_picks.py)."""
    out = mp.script("mixer_picks", stdin=json.dumps(cases).encode()).splitlines()
    assert len(out) == len(cases)
    return [[int(d) for d in line] for line in out]


def test_every_small_mix_follows_the_document_and_retraces_itself(mp):
    """Every weight vector of 2 to 4 drives with a sum up to 24: two periods forward by
    the document's rule, back over them and a period beyond the block's start, and
    forward again to the end."""
    cases = []
    for drives in (2, 3, 4):
        for w in itertools.product(range(25), repeat=drives):
            if 0 < sum(w) <= 24:
                s = sum(w)
                cases.append([list(w), [2 * s, -3 * s, 3 * s]])
    got = _firmware_picks(mp, cases)
    for (w, _), seq in zip(cases, got):
        s = sum(w)
        ahead, back, again = seq[:2 * s], seq[2 * s:5 * s], seq[5 * s:]
        period = mixer_picks(w, s)
        assert Counter(period) == {i: x for i, x in enumerate(w) if x}, w
        assert ahead == period * 2, w
        # Each step back undoes the latest step forward, and then, past the block's
        # start, meets the drives in the forward order (the rule on the mirrored
        # errors): a whole period back is exactly -w.
        assert back == ahead[::-1] + period, w
        # Forward over ground walked backwards takes the same drives again.
        assert again == back[::-1], w


@settings(max_examples=25, deadline=None)
@given(mixes=st.lists(
    st.tuples(st.lists(st.integers(0, 3000), min_size=5, max_size=6).filter(any),
              st.integers(1, 3), st.floats(0, 1)),
    min_size=1, max_size=3))
def test_large_mixes_of_five_and_six_drives_over_periods_and_mix_changes(mp, mixes):
    """Several periods and a part of one, each mix a block of its own as the planner
    gives it: every mix starts afresh, as the document's errors start at the weights."""
    moves = []
    want = []
    for w, periods, part in mixes:
        w = w + [0] * (6 - len(w))
        steps = periods * sum(w) + int(part * sum(w))
        moves.append([steps, w])
        want += mixer_picks(w, steps)
    assert _firmware_picks(mp, [[mixes[0][0] + [0] * (6 - len(mixes[0][0])), moves]])[0] \
        == want


def test_every_kind_of_pick_runs_with_the_heap_locked(mp):
    """New ground forward and backward, and the ring's picks both ways: each tick of
    the walk runs under micropython.heap_lock(), as the interrupt does."""
    counts = mp.json(MIXER + """
import micropython
step = stepper.tick

def locked(io):
    micropython.heap_lock()
    try:
        return step(io)
    finally:
        micropython.heap_unlock()

walk = stepper.run_mix((1, 2, 3, 4, 5, 6), [300, -500, 400, -100, 21])
stepper.tick = step
print([list(walk), list(stepper.run_mix((1, 2, 3, 4, 5, 6), [121]))])
""")
    assert counts[0] == counts[1]  # the walk ends at E step 121, where it had been


@settings(max_examples=40, deadline=None)
@given(weights=st.lists(st.integers(0, 1000), min_size=2, max_size=6).filter(any),
       moves=st.lists(st.integers(-150, 150), min_size=1, max_size=12))
def test_retract_then_unretract_restores_every_drive(mp, weights, moves):
    """Any walk forward and back within the mixer's ring (2,048 steps, more than a
    block's E steps) returns each drive to where it was at the same E position, and
    reverse steps undo forward steps exactly, one by one."""
    result = mp.script_json("mixer_walk", stdin=json.dumps([weights, moves]).encode())
    assert result is True


class RingModel:
    """The mixer as docs/Mixing.md states it, with a ring of `size` picks: the
    document's errors, and the picks at the positions walked, of which the ring keeps
    a stretch of at most `size` around the latest."""

    def __init__(self, weights, size):
        self.w, self.size, self.total = weights, size, sum(weights)
        self.errors = list(weights)
        self.q = self.lo = self.hi = 0
        self.known = {}

    def _top(self, values):
        return max((i for i, w in enumerate(self.w) if w), key=lambda i: (values[i], -i))

    def forward(self):
        q = self.q
        if self.lo <= q < self.hi:
            pick = self.known[q]
        else:
            pick = self._top(self.errors)
            self.known[q] = pick
            self.hi = q + 1
            self.lo = max(self.lo, self.hi - self.size)
        self.errors[pick] -= self.total
        self.errors = [e + w for e, w in zip(self.errors, self.w)]
        self.q += 1
        return pick

    def back(self):
        q = self.q - 1
        self.errors = [e - w for e, w in zip(self.errors, self.w)]
        if self.lo <= q < self.hi:
            pick = self.known[q]
        else:
            # New ground: the rule on the mirrored errors 2W - error.
            pick = self._top([2 * w - e - w for e, w in zip(self.errors, self.w)])
            self.known[q] = pick
            self.lo = q
            self.hi = min(self.hi, self.lo + self.size)
        self.errors[pick] += self.total
        self.q = q
        return pick


@settings(max_examples=40, deadline=None)
@given(weights=st.lists(st.integers(0, 60), min_size=2, max_size=6).filter(any),
       size=st.sampled_from([4, 8, 16, 64]),
       moves=st.lists(st.integers(-40, 40), min_size=1, max_size=16))
def test_walks_longer_than_a_small_ring_keep_what_it_holds(mp, weights, size, moves):
    """The firmware's step loop with a ring of 4 to 64 picks against the model: what
    the ring still holds is retraced, and past it the rules pick."""
    model = RingModel(weights, size)
    want = []
    for m in moves:
        want += [model.forward() if m > 0 else model.back() for _ in range(abs(m))]
    assert _firmware_picks(mp, [[weights, moves, size]])[0] == want


# docs/Mixing.md's table of mixes, one period each: the order of the drives' steps in
# the simulated printer's GPIO trace.
TABLE = [
    ("A1 B1 C1 D1 H1 I6", "e5 e0 e5 e1 e5 e2 e5 e3 e5 e4 e5"),
    ("A10 B1 C1 D1", "e0 e0 e0 e1 e0 e0 e2 e0 e0 e3 e0 e0 e0"),
    ("A5 B5 C1", "e0 e1 e0 e1 e2 e0 e1 e0 e1 e0 e1"),
    ("A7 B3 C2 D1", "e0 e1 e0 e2 e0 e3 e0 e1 e0 e2 e0 e1 e0"),
    ("A3 B5 C7", "e2 e1 e0 e2 e1 e2 e0 e2 e1 e2 e1 e2 e0 e1 e2"),
]


def test_the_simulated_printers_trace_steps_the_drives_in_the_documents_order(tmp_path):
    lines = ["M302 P1", "M83", "M92 E100"]  # 100 steps/mm: a period is E0.<sum>
    for letters, _ in TABLE:
        total = sum(int(word[1:]) for word in letters.split())
        lines += ["M165 " + letters, "G1 E%.2f F300" % (total / 100)]
    gcode = tmp_path / "mixes.gcode"
    gcode.write_text("\n".join(lines + ["M400", ""]))
    edges = tmp_path / "run.edges"
    report = sim.run(gcode, edges_path=edges)
    assert report["errors"] == []
    times, gpios, levels = trace.read_edges(edges)
    names = trace.signal_names("sim")
    steps = sorted((t, names[g][:2]) for t, g, v in zip(times, gpios, levels)
                   if v == 1 and names.get(g, "").endswith("_step") and names[g][0] == "e")
    order = [d for _, d in steps]
    for letters, expected in TABLE:
        w = [int(word[1:]) for word in letters.split()]
        period, order = order[:sum(w)], order[sum(w):]
        assert period == ["e%d" % d for d in mixer_picks(w, sum(w))], letters
        assert period == expected.split(), letters
    assert order == []
