"""The Executive: step protocol, hand-computed beliefs, speech text, counters, deciders."""
import math
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
from test_parameterize import ACTIONS, HIERARCHY, meds_domain  # noqa: E402

from pearl_pomdp.errors import BeliefError
from pearl_pomdp.executive import Executive
from pearl_pomdp.hierarchy import parse_hierarchy, plan
from pearl_pomdp.policies import FlatPolicyDecider
from pearl_pomdp.solution import AlphaVectorPolicy
from pearl_pomdp.speech import KeywordFilter
from pearl_pomdp.tracking import StepSettings

#: The meds domain has no 'unknown' symbol for a timeout: scripted dialogs need none.
UNTIMED = StepSettings(step_timeout=0.0)


@pytest.fixture(scope="module")
def hp():
    return plan(meds_domain(), parse_hierarchy(HIERARCHY, ACTIONS))


def test_observe_is_eq5_by_hand(hp):
    """b0 = (0.4, 0.4, 0.2), ClarifyTask (identity), hear o_meds (0.8 / 0.1 / 0.1):
    b' = (0.32, 0.04, 0.02) / 0.38."""
    ex = Executive(meds_domain(), hp, settings=UNTIMED)
    b = ex.observe("ClarifyTask", "o_meds")
    np.testing.assert_allclose(b, [0.32 / 0.38, 0.04 / 0.38, 0.02 / 0.38], atol=1e-12)
    assert ex.updates == 1 and ex.zero_likelihood == 0


def test_decide_follows_the_belief(hp):
    """Hearing o_meds twice makes wantMeds near certain: Act → Help → CheckMeds."""
    model = meds_domain()
    ex = Executive(model, hp, settings=UNTIMED)
    ex.observe("ClarifyTask", "o_meds")
    ex.observe("ClarifyTask", "o_meds")
    d = ex.decide()
    assert [(t.subtask, t.choice) for t in d.trace] == [("Act", "Help"), ("Help", "CheckMeds")]
    assert d.action_name == "CheckMeds" and ex.last_decision is d
    ex.reset()
    np.testing.assert_array_equal(ex.belief, model.b0)
    assert ex.updates == 0


def test_speech_text_goes_through_keyword_filter(hp):
    kf = KeywordFilter({"o_meds": ["pills", "medication"], "o_move": ["walk"]}, unknown_symbol="o_none")
    ex = Executive(meds_domain(), hp, keyword_filter=kf, settings=UNTIMED)
    b_text = ex.observe("ClarifyTask", "where are my pills")
    np.testing.assert_allclose(b_text, [0.32 / 0.38, 0.04 / 0.38, 0.02 / 0.38], atol=1e-12)
    ex.observe("ClarifyTask", "blah blah")  # no keyword → o_none, counted
    ex.observe("ClarifyTask", "o_move")     # a symbol is used as is
    assert ex.unknown_inputs == 1 and ex.updates == 3


def test_unknown_inputs_are_errors_without_a_filter(hp):
    ex = Executive(meds_domain(), hp, settings=UNTIMED)
    with pytest.raises(BeliefError, match="unknown observation 'hello'"):
        ex.observe("ClarifyTask", "hello")
    with pytest.raises(BeliefError, match="unknown action 'Dance'"):
        ex.observe("Dance", "o_meds")
    with pytest.raises(BeliefError, match="needs a previous decide"):
        ex.step("o_meds")


def test_zero_likelihood_is_counted_not_nan():
    """Only 'done' can emit o_none under this O; after a certain wantMeds belief hearing it is impossible."""
    model = meds_domain()
    model.O[0] = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    model.b0 = np.array([1.0, 0.0, 0.0])
    ex = Executive(model, FlatPolicyDecider(AlphaVectorPolicy(np.zeros((1, 3)), [0]), model), settings=UNTIMED)
    b = ex.observe("ClarifyTask", "o_none")
    assert ex.zero_likelihood == 1 and np.isfinite(b).all() and b.sum() == pytest.approx(1.0)


def test_flat_decider_value_and_mls():
    from pearl_pomdp.policies import MostLikelyStatePolicy

    model = meds_domain()
    alphas = np.array([[10.0, -5.0, -3.0], [-5.0, 10.0, -5.0]])
    d = FlatPolicyDecider(AlphaVectorPolicy(alphas, [1, 2]), model).execute(np.array([0.2, 0.7, 0.1]))
    assert (d.action_name, d.trace[0].subtask) == ("Move", "flat")
    assert d.trace[0].value == pytest.approx(-1.0 + 7.0 - 0.5)
    mls = FlatPolicyDecider(MostLikelyStatePolicy(np.array([1, 2, 0])), model).execute(np.array([0.2, 0.7, 0.1]))
    assert mls.action_name == "Move" and math.isnan(mls.trace[0].value)
    assert mls.as_dict()["trace"][0]["value"] is None


def test_flat_decider_lookahead_is_one_bellman_step_over_the_vectors(benchmarks_dir):
    """FlatPolicyDecider(lookahead=1): argmax_a b·R_a + γ Σ_o max_k α_k·(b T_a diag O_{a,o}),
    computed here by hand on tiger with horizon-2 vectors."""
    import numpy as np

    from pearl_pomdp.model import load_model
    from pearl_pomdp.solvers.incremental_pruning import solve_incremental_pruning

    m = load_model(benchmarks_dir / "tiger.95.POMDP")
    policy = solve_incremental_pruning(m, horizon=2).policy
    greedy, search = FlatPolicyDecider(policy, m), FlatPolicyDecider(policy, m, lookahead=1)
    T, O, R = m.T_dense(), m.O, m.R
    for p in np.linspace(0.0, 1.0, 21):
        b = np.array([p, 1.0 - p])
        q = [b @ R[:, a] + m.discount * sum(float(np.max(policy.alphas @ ((b @ T[a]) * O[a, :, o])))
                                            for o in range(m.num_observations)) for a in range(m.num_actions)]
        d = search.execute(b)
        assert d.trace[0].value == pytest.approx(max(q), abs=1e-9)
        assert q[d.action] == pytest.approx(max(q), abs=1e-9)
        assert greedy.execute(b).action == int(policy.actions[np.argmax(policy.alphas @ b)])
    with pytest.raises(ValueError, match="α-vector policy"):
        from pearl_pomdp.solvers.mdp import most_likely_state_policy

        FlatPolicyDecider(most_likely_state_policy(m), m, lookahead=1)
