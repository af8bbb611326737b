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
    out = mp.script("mixer_picks", stdin=json.dumps(cases).encode()).split()
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


@settings(max_examples=40, deadline=None)
@given(weights=st.lists(st.integers(0, 1000), min_size=2, max_size=6).filter(any),
       moves=st.lists(st.integers(-150, 150), min_size=1, max_size=12))
def test_retract_then_unretract_restores_every_drive(mp, weights, moves):
    """Any walk forward and back within the mixer's ring (2,048 steps, more than a
    block's E steps) returns each drive to where it was at the same E position, and
    reverse steps undo forward steps exactly, one by one."""
    result = mp.script_json("mixer_walk", stdin=json.dumps([weights, moves]).encode())
    assert result is True


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
