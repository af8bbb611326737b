"""The mixer's error diffusion, run on the MicroPython unix port."""
import json

from hypothesis import given, settings, strategies as st

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


@settings(max_examples=40, deadline=None)
@given(weights=st.lists(st.integers(0, 1000), min_size=2, max_size=6).filter(any),
       moves=st.lists(st.integers(-400, 400), min_size=1, max_size=12))
def test_retract_then_unretract_restores_every_drive(mp, weights, moves):
    """Any walk forward and back returns each drive to where it was at the same E
    position, and reverse steps undo forward steps exactly, one by one."""
    result = mp.script_json("mixer_walk", stdin=json.dumps([weights, moves]).encode())
    assert result is True
