"""pearl_pomdp.policies.lookahead: the one-step values a parent ranks its children's offers by."""
import numpy as np
import pytest

from pearl_pomdp.hierarchy import load_hierarchical_policy
from pearl_pomdp.model.domain_yaml import load_domain
from ros_helpers import DOMAIN


@pytest.fixture(scope="module")
def pearl_subtasks(pearl_policy):
    return load_hierarchical_policy(pearl_policy, load_domain(DOMAIN)).subtasks


def _beliefs(size, count, seed):
    rng = np.random.default_rng(seed)
    for _ in range(count):
        b = np.zeros(size)
        support = rng.choice(size, size=int(rng.integers(1, min(size, 200) + 1)), replace=False)
        b[support] = rng.dirichlet(np.ones(support.size))
        yield b


@pytest.mark.parametrize("name", ["Act", "Assist", "Rest", "Contact"])
def test_the_values_of_some_actions_are_those_of_all_actions_bit_for_bit(pearl_subtasks, name):
    """A parent asks only for its offers' values (Pearl's root: 6 of its 19 actions); each must be
    exactly the value it gets among all actions, or a pick could differ from the planner's, and the
    actions not asked for are NaN, so reading one is an error that shows."""
    one_step = pearl_subtasks[name].one_step
    rng = np.random.default_rng(7)
    for b in _beliefs(one_step.S, 40, seed=len(name)):
        full = one_step.q(b)
        wanted = sorted(set(rng.choice(one_step.A, size=int(rng.integers(1, one_step.A + 1))).tolist()))
        some = one_step.q(b, wanted)
        assert some[wanted].tobytes() == full[wanted].tobytes()
        others = np.setdiff1d(np.arange(one_step.A), wanted)
        assert np.isnan(some[others]).all()
        assert np.isfinite(full).all()


def test_a_pick_values_only_the_offered_actions(pearl_subtasks, pearl_policy):
    """The root's pick at Pearl's start belief asks the kernel for its offers alone, and picks what
    ranking every action's value restricted to the offers picks."""
    domain = load_domain(DOMAIN)
    hp = load_hierarchical_policy(pearl_policy, domain)
    asked = []
    one_step = hp.subtasks[hp.root].one_step
    full_q = one_step.q

    def spy(b, actions=None):
        asked.append(None if actions is None else list(actions))
        return full_q(b, actions)

    one_step.q = spy
    b0 = domain.compile().b0
    memo: dict = {}
    prim, _, value, path = hp.pick(hp.root, b0, memo)
    offers = hp.offers(hp.subtasks[hp.root].actions, b0, {})
    table = hp._to_model[hp.root]
    assert asked and asked[0] is not None and sorted(asked[0]) == sorted({int(table[p]) for p, _ in offers})
    assert len(asked[0]) < one_step.A
    values = full_q(hp.subtasks[hp.root].project(b0)[0])
    best = max(offers, key=lambda offer: values[table[offer[0]]])
    assert prim == best[0] and value == values[table[prim]]
