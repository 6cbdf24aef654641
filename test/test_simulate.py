"""Simulation against returns computed by hand."""
import numpy as np
import pytest

from pearl_pomdp.errors import PearlError
from pearl_pomdp.model.pomdp import Pomdp
from pearl_pomdp.simulate import default_steps, simulate
from pearl_pomdp.solution import AlphaVectorPolicy
from test_belief import tiger

# Listen at the uniform belief; once a door is favoured (0.85 after one "hear"), open the other one.
LISTEN_THEN_OPEN = AlphaVectorPolicy(np.array([[-10.0, -10.0], [-100.0, 10.0], [10.0, -100.0]]), [0, 1, 2])


class ActionOnly:
    """A policy with nothing but .action(belief)."""

    def __init__(self, inner):
        self.inner = inner

    def action(self, belief):
        return self.inner.action(belief)


def test_always_listen_is_deterministic_sum():
    always_listen = AlphaVectorPolicy(np.array([[0.0, 0.0]]), [0])
    r = simulate(tiger(), always_listen, episodes=50, steps=10, seed=1)
    expected = -sum(0.95 ** t for t in range(10))  # −1 each step
    assert r["mean"] == pytest.approx(expected, abs=1e-12)
    assert r["ci95"] == pytest.approx(0.0, abs=1e-12)
    assert (r["episodes"], r["steps"]) == (50, 10)


def test_listen_then_open_matches_hand_computed_value():
    # Step 0: listen (−1). Step 1: open the door opposite to what was heard; right with
    # probability .85 (+10), wrong with .15 (−100): −1 + .95·(.85·10 − .15·100) = −7.175.
    r = simulate(tiger(), LISTEN_THEN_OPEN, episodes=20000, steps=2, seed=7)
    assert abs(r["mean"] - (-7.175)) < 2 * r["ci95"]
    assert 0.4 < r["ci95"] < 0.65  # returns are 8.5 (p=.85) or −96 (p=.15): std ≈ 37.3
    assert sorted(set(np.round(r["returns"], 9))) == [-96.0, 8.5]
    # The share of correct openings estimates the listening accuracy.
    assert np.mean(r["returns"] > 0) == pytest.approx(0.85, abs=0.01)


def test_transition_sampling_frequencies():
    # s0 → s1 with probability .3 (sparse storage); reward 1 for being in s1.
    T = [np.array([[0.7, 0.3, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])]
    model = Pomdp.create(["s0", "s1", "s2"], ["wait"], ["none"], T, np.ones((1, 3, 1)),
                         np.array([[0.0], [1.0], [5.0]]), b0=[1.0, 0.0, 0.0], discount=0.9, sparse=True)
    r = simulate(model, AlphaVectorPolicy(np.zeros((1, 3)), [0]), episodes=40000, steps=2, seed=3)
    assert abs(r["mean"] - 0.9 * 0.3) < 2 * r["ci95"]
    assert np.isin(np.round(r["returns"], 12), [0.0, 0.9]).all()  # s2 (reward 5) is never reached


def test_same_seed_same_returns_any_policy_interface():
    a = simulate(tiger(), LISTEN_THEN_OPEN, episodes=300, steps=20, seed=11)
    b = simulate(tiger(), ActionOnly(LISTEN_THEN_OPEN), episodes=300, steps=20, seed=11)
    c = simulate(tiger(), LISTEN_THEN_OPEN, episodes=300, steps=20, seed=12)
    np.testing.assert_array_equal(a["returns"], b["returns"])
    assert not np.array_equal(a["returns"], c["returns"])
    assert a["interval"] == [a["mean"] - a["ci95"], a["mean"] + a["ci95"]]


def test_default_steps_and_errors():
    assert default_steps(0.95) == 135 and 0.95 ** 135 < 1e-3 < 0.95 ** 134
    with pytest.raises(PearlError, match="undiscounted"):
        default_steps(1.0)
    with pytest.raises(ValueError, match="episodes must be ≥ 1"):
        simulate(tiger(), LISTEN_THEN_OPEN, episodes=0, steps=3)

    class Bad:
        def action(self, belief):
            return 7

    with pytest.raises(PearlError, match=r"policy Bad returned action \[7\], the model has actions 0..2"):
        simulate(tiger(), Bad(), episodes=3, steps=3)


def test_most_likely_state_policy_batched_like_its_action():
    from pearl_pomdp.policies import MostLikelyStatePolicy
    # Open the door opposite to the likelier tiger; at the uniform belief the tie goes to
    # state 0 (tiger-left), so the first action is open-right: +10 or −100, −45 on average.
    policy = MostLikelyStatePolicy([2, 1])
    fast = simulate(tiger(), policy, episodes=4000, steps=1, seed=5)
    slow = simulate(tiger(), ActionOnly(policy), episodes=4000, steps=1, seed=5)
    np.testing.assert_array_equal(fast["returns"], slow["returns"])
    assert abs(fast["mean"] - (-45.0)) < 2 * fast["ci95"]
