"""State/observation abstraction (eq. 18): the abstract model's value function equals the full one.

For every subtask of the Pearl hierarchy, the finite-horizon optimal value is computed two
independent ways at random full beliefs (Dirichlet, so features are correlated):

* on the **full** subtask (576 states, 18 observations), by exact expectimax over the
  state-pair kernel ``Σ_s b(s) T(s, π(s), s') O(s', π(s), o)`` written out here from the
  flat model's arrays (no code of the abstraction module), and
* on the **abstract** standard-form model SOLVE gets, at the projected belief, by the same
  expectimax and by incremental pruning's α-vectors.

They must agree to 1e-6. Abstract actions use a stand-in child policy π_j(s) = the child's
myopically best primitive (the abstraction must be exact for *any* π, as it only reads
the arrays).
"""
from pathlib import Path

import numpy as np
import pytest

from pearl_pomdp.hierarchy import load_hierarchy, parse_hierarchy
from pearl_pomdp.hierarchy.abstraction import abstract_subtask
from pearl_pomdp.hierarchy.parameterize import StateFactors, parameterize
from pearl_pomdp.model.domain_yaml import load_domain
from pearl_pomdp.solvers.incremental_pruning import solve_incremental_pruning

CONFIG = Path(__file__).resolve().parents[1] / "config"


@pytest.fixture(scope="module")
def pearl():
    domain = load_domain(CONFIG / "pearl.domain.yaml")
    return domain, domain.compile(), load_hierarchy(CONFIG / "pearl.hierarchy.yaml", domain)


_DENSE = {}


def dense_T(model):
    key = id(model)
    if key not in _DENSE:
        _DENSE[key] = (model, [Ta.toarray() if hasattr(Ta, "toarray") else np.asarray(Ta) for Ta in model.T])
    return _DENSE[key][1]


def full_value(model, source, R, b, horizon):
    """Expectimax on the full subtask: actions k execute primitive source[k, s] in state s."""
    if horizon == 0:
        return 0.0
    best = -np.inf
    Tm = dense_T(model)
    for k in range(source.shape[0]):
        value = float(b @ R[:, k])
        joint = np.zeros((model.num_observations, model.num_states))  # [o, s'] unnormalised
        for p in np.unique(source[k]):
            pred = (b * (source[k] == p)) @ Tm[p]
            joint += pred[None, :] * model.O[p].T
        if horizon > 1:
            for o in range(model.num_observations):
                po = joint[o].sum()
                if po > 1e-15:
                    value += model.discount * po * full_value(model, source, R, joint[o] / po, horizon - 1)
        best = max(best, value)
    return best


def standard_value(model, b, horizon):
    """Expectimax on a standard-form Pomdp (T[a][s, s'], O[a, s', o])."""
    if horizon == 0:
        return 0.0
    best = -np.inf
    for a in range(model.num_actions):
        value = float(b @ model.R[:, a])
        if horizon > 1:
            pred = b @ dense_T(model)[a]
            for o in range(model.num_observations):
                joint = pred * model.O[a][:, o]
                po = joint.sum()
                if po > 1e-15:
                    value += model.discount * po * standard_value(model, joint / po, horizon - 1)
        best = max(best, value)
    return best


def stand_in_effective(model, hierarchy, child):
    """π_child(s): the child's primitive descendant with the best immediate reward in s."""
    prims = [model.actions.index(p) for p in hierarchy.descendants(child)]
    return np.asarray(prims)[np.argmax(model.R[:, prims], axis=1)]


SUBTASKS = ["Act", "Remind", "Contact", "Assist", "Move", "Inform", "Rest"]


@pytest.mark.parametrize("name", SUBTASKS)
def test_abstract_value_equals_full_value(pearl, name):
    domain, model, h = pearl
    spec = h.subtasks[name]
    effective = {c: stand_in_effective(model, h, c) for c in spec.children if h.is_abstract(c)}
    sub = parameterize(model, spec, effective, StateFactors.from_domain(domain))
    ab = abstract_subtask(sub, StateFactors.from_domain(domain), domain)
    assert all(ab.checks.values()), ab.checks
    rng = np.random.default_rng(7)
    horizon = 2
    # Incremental pruning on the abstract model too where it is small enough to be quick.
    policy = solve_incremental_pruning(ab.model, horizon=horizon).policy if ab.model.num_states <= 100 else None
    for _ in range(3):
        b = rng.dirichlet(np.full(model.num_states, 0.3))
        full = full_value(model, sub.source, sub.R, b, horizon)
        proj = ab.project(b)
        assert standard_value(ab.model, proj, horizon) == pytest.approx(full, abs=1e-6)
        if policy is not None:
            assert policy.value(proj) == pytest.approx(full, abs=1e-6)


def test_inform_keeps_only_user_info_goal_exact_to_horizon_3(pearl):
    """The paper: Inform 'required only the UserInfoGoal state feature' (+ speech/touch symbols).
    Ours also reads UserPresent (nobody answers an absent resident): 3 × 2 states."""
    domain, model, h = pearl
    sub = parameterize(model, h.subtasks["Inform"], {}, StateFactors.from_domain(domain))
    ab = abstract_subtask(sub, StateFactors.from_domain(domain), domain)
    assert ab.relevant == ["UserPresent", "UserInfoGoal"]
    assert ab.model.num_states == 6
    assert not any(o.startswith(("at", "g_")) for o in ab.model.observations)  # laser/reminder dropped
    assert ab.model.num_observations < model.num_observations
    rng = np.random.default_rng(3)
    for _ in range(2):
        b = rng.dirichlet(np.full(model.num_states, 0.3))
        assert standard_value(ab.model, ab.project(b), 3) == pytest.approx(
            full_value(model, sub.source, sub.R, b, 3), abs=1e-6)


def test_check_adds_observed_features_the_seed_missed():
    """A feature only the observations read (not reward, not transition) must join X+,
    or the abstract value would differ on correlated beliefs."""
    from pearl_pomdp.model.domain_yaml import parse_domain

    text = """
name: probe
discount: 0.9
features:
  Goal: [a, b]
  Noise: [lo, hi]
start: {Goal: {a: 0.5, b: 0.5}, Noise: {lo: 0.5, hi: 0.5}}
modalities:
  Speech: [sa, sb]
actions:
  Ask: {}
  DoA: {}
  DoB: {}
observations:
  Ask:
    parents: [Goal, Noise]
    table:
      "a,lo": {sa: 0.9, sb: 0.1}
      "a,hi": {sa: 0.6, sb: 0.4}
      "b,lo": {sa: 0.1, sb: 0.9}
      "b,hi": {sa: 0.4, sb: 0.6}
  default:
    parents: [Goal]
    table:
      a: {sa: 0.5, sb: 0.5}
      b: {sa: 0.5, sb: 0.5}
rewards:
  - {action: DoA, when: {Goal: a}, reward: 10, why: probe}
  - {action: DoA, when: {Goal: b}, reward: -10, why: probe}
  - {action: DoB, when: {Goal: b}, reward: 10, why: probe}
  - {action: DoB, when: {Goal: a}, reward: -10, why: probe}
  - {action: Ask, reward: -1, why: probe}
"""
    domain = parse_domain(text, "probe.yaml")
    model = domain.compile()
    h = parse_hierarchy("root: R\nsubtasks:\n  R: {actions: [Ask, DoA, DoB]}\n", model.actions)
    sub = parameterize(model, h.subtasks["R"], {}, StateFactors.from_domain(domain))
    ab = abstract_subtask(sub, StateFactors.from_domain(domain), domain)
    assert ab.seeded == ["Goal"]
    assert ab.added_by_check == ["Noise"] and ab.added_reasons == {"Noise": ["observation"]}
    rng = np.random.default_rng(0)
    for _ in range(5):
        b = rng.dirichlet(np.ones(4))
        assert standard_value(ab.model, ab.project(b), 3) == pytest.approx(
            full_value(model, sub.source, sub.R, b, 3), abs=1e-9)
