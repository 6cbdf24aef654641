"""Monte-Carlo evaluation with control variates against exact policy values."""
import numpy as np
import pytest

from pearl_pomdp.evaluation import evaluate_policies, feature_controls, steps_for_truncation
from pearl_pomdp.policies import FlatPolicyDecider, LookaheadPolicy
from pearl_pomdp.simulate import simulate
from pearl_pomdp.solution import AlphaVectorPolicy
from test_belief import tiger

LISTEN, OPEN_LEFT, OPEN_RIGHT = 0, 1, 2


class OpenAfterTwoMore:
    """Tiger: listen until one side was heard twice more than the other (b(left) ≥ 0.9 or ≤ 0.1),
    then open the other door; opening resets the belief to uniform."""

    def actions_batch(self, beliefs):
        left = np.asarray(beliefs)[:, 0]
        return np.where(left >= 0.9, OPEN_RIGHT, np.where(left <= 0.1, OPEN_LEFT, LISTEN))

    def action(self, belief):
        return int(self.actions_batch(np.asarray(belief)[None, :])[0])


def exact_value_open_after_two_more(g=0.95, p=0.85):
    """The controller's value at b0 by solving its linear Bellman system over
    (count difference n ∈ {−2..2}, tiger side s): n = ±2 opens, every other n listens."""
    nodes = [-2, -1, 0, 1, 2]
    idx = {(n, s): i for i, (n, s) in enumerate((n, s) for n in nodes for s in (0, 1))}
    M = np.eye(len(idx))
    r = np.zeros(len(idx))
    for n in nodes:
        for s in (0, 1):
            i = idx[(n, s)]
            if abs(n) == 2:
                # n = +2: "left" heard twice more → open right: +10 if the tiger is left (s = 0).
                good = (n == 2) == (s == 0)
                r[i] = 10.0 if good else -100.0
                for s2 in (0, 1):
                    M[i, idx[(0, s2)]] -= g * 0.5
            else:
                r[i] = -1.0
                hear_left = p if s == 0 else 1 - p
                M[i, idx[(n + 1, s)]] -= g * hear_left
                M[i, idx[(n - 1, s)]] -= g * (1 - hear_left)
    v = np.linalg.solve(M, r)
    return 0.5 * (v[idx[(0, 0)]] + v[idx[(0, 1)]])


def test_plain_returns_are_simulates_returns():
    policy = AlphaVectorPolicy(np.array([[-10.0, -10.0], [-100.0, 10.0], [10.0, -100.0]]), [0, 1, 2])
    sim = simulate(tiger(), policy, episodes=300, steps=30, seed=5)
    ev = evaluate_policies(tiger(), {"p": policy}, episodes=300, steps=30, seed=5)["p"]
    np.testing.assert_array_equal(ev["returns"], sim["returns"])
    assert ev["plain"]["mean"] == pytest.approx(sim["mean"], abs=1e-12)


def test_estimate_matches_the_exact_controller_value_within_its_ci():
    exact = exact_value_open_after_two_more()
    m = tiger()
    r = evaluate_policies(m, {"c": OpenAfterTwoMore()}, episodes=20000, seed=3)["c"]
    assert steps_for_truncation(m, 0.01) == r["steps"]
    assert abs(r["truncation"][0]) <= 0.01 and abs(r["truncation"][1]) <= 0.01
    # Both the plain and the control-variate means hold the exact value within their 95 % CIs
    # (the CV one is unbiased: its coefficients come from the other half of the episodes).
    assert abs(r["plain"]["mean"] - exact) <= r["plain"]["ci95"] + 0.01
    assert abs(r["mean"] - exact) <= r["ci95"] + 0.01
    assert r["lower"] <= exact <= r["upper"]
    assert r["ci95"] < 0.5


def test_control_variates_have_zero_mean_and_cut_variance_where_the_state_drives_reward():
    # One state variable that flips at random and pays while "on": the whole spread of the
    # return is the state process, so a control on that state removes most of it.
    from pearl_pomdp.model.pomdp import Pomdp

    T = [np.array([[0.9, 0.1], [0.2, 0.8]])]
    m = Pomdp.create(["off", "on"], ["wait"], ["none"], T, np.ones((1, 2, 1)), np.array([[0.0], [1.0]]),
                     b0=[1.0, 0.0], discount=0.9)
    # Exact: V = (I − γT)^{-1} R.
    exact = float(np.linalg.solve(np.eye(2) - 0.9 * T[0], np.array([0.0, 1.0]))[0])
    r = evaluate_policies(m, {"wait": AlphaVectorPolicy(np.zeros((1, 2)), [0])}, episodes=4000, seed=1,
                          controls=np.array([[0.0], [1.0]]))["wait"]
    assert abs(r["mean"] - exact) <= r["ci95"] + 0.01
    assert r["variance_reduction"] > 5.0
    assert r["ci95"] < r["plain"]["ci95"] / 2


def test_feature_controls_follow_the_compiled_state_order():
    from pathlib import Path

    from pearl_pomdp.model.domain_yaml import load_domain

    domain = load_domain(Path(__file__).resolve().parents[1] / "config" / "pearl.domain.yaml")
    model = domain.compile()
    C = feature_controls(model)
    features = model.metadata["features"]
    assert C.shape == (model.num_states, sum(len(v) - 1 for v in features.values()))
    # Column of UserPresent=no is 1 exactly on the states whose name says so.
    names = list(features)
    col = sum(len(features[f]) - 1 for f in names[: names.index("UserPresent")])  # its only column ('no')
    says_no = np.array(["UserPresent=no" in s for s in model.states])
    np.testing.assert_array_equal(C[:, col] == 1.0, says_no)


def test_lookahead_policy_batches_the_deciders_choice():
    m = tiger()
    policy = AlphaVectorPolicy(np.array([[-10.0, -10.0], [-100.0, 10.0], [10.0, -100.0]]), [0, 1, 2])
    batched = LookaheadPolicy(policy, m)
    decider = FlatPolicyDecider(policy, m, lookahead=1)
    B = np.array([[p, 1 - p] for p in np.linspace(0.0, 1.0, 41)])
    np.testing.assert_array_equal(batched.actions_batch(B), [decider.action(b) for b in B])
    q = np.array([decider.execute(b).trace[0].value for b in B])
    np.testing.assert_allclose(batched.q_values(B).max(axis=1), q, rtol=0, atol=1e-9)
