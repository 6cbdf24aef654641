"""execute_without: a decision with actions forbidden (an operator's veto), checked against the
policy's own values recomputed here from its vectors and models."""
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
from test_contingent import HIERARCHY as PROBE_HIERARCHY, PROBE_DOMAIN  # noqa: E402
from test_parameterize import ACTIONS, HIERARCHY, meds_domain  # noqa: E402

from pearl_pomdp.errors import PolicyError
from pearl_pomdp.hierarchy import parse_hierarchy, plan
from pearl_pomdp.interfaces import MaskingDecider
from pearl_pomdp.model.domain_yaml import parse_domain
from pearl_pomdp.model.pomdp import Pomdp
from pearl_pomdp.policies import FlatPolicyDecider
from pearl_pomdp.solution import AlphaVectorPolicy
from pearl_pomdp.solvers.registry import solve

#: Beliefs over (wantMeds, wantMove, done) for the meds domain (corner, the paper's eq. 15-17) and
#: over (Goal=a, Goal=b, Goal=done) for the probe domain (policy-contingent, plan's default).
BELIEFS = [[0.4, 0.4, 0.2], [0.7, 0.2, 0.1], [0.1, 0.8, 0.1], [0.05, 0.05, 0.9], [1 / 3, 1 / 3, 1 / 3],
           [0.97, 0.03, 0.0], [0.02, 0.98, 0.0], [0.5, 0.5, 0.0]]


def planned(kind):
    if kind == "corner":
        return plan(meds_domain(), parse_hierarchy(HIERARCHY, ACTIONS))
    domain = parse_domain(PROBE_DOMAIN)
    return plan(domain, parse_hierarchy(PROBE_HIERARCHY, domain.actions))


def tiger() -> Pomdp:
    T = [np.eye(2), np.full((2, 2), 0.5), np.full((2, 2), 0.5)]
    O = np.array([[[0.85, 0.15], [0.15, 0.85]], [[0.5, 0.5], [0.5, 0.5]], [[0.5, 0.5], [0.5, 0.5]]])
    R = np.array([[-1.0, -100.0, 10.0], [-1.0, 10.0, -100.0]])
    return Pomdp.create(["tiger-left", "tiger-right"], ["listen", "open-left", "open-right"],
                        ["hear-left", "hear-right"], T, O, R, discount=0.95, name="tiger")


def one_step_q(model, alphas, b, a):
    """b·R_a + γ Σ_o max_k α_k·(b T_a diag O_{a,o}), by loops."""
    T = np.asarray(model.T[a].todense() if hasattr(model.T[a], "todense") else model.T[a])
    q = float(b @ model.R[:, a])
    for o in range(model.num_observations):
        successor = (b @ T) * model.O[a][:, o]
        q += model.discount * max(float(alpha @ successor) for alpha in alphas)
    return q


@pytest.fixture(scope="module")
def tiger_policy():
    model = tiger()
    return model, solve(model, "incprune", horizon=8).policy


def test_flat_veto_takes_the_best_vector_left(tiger_policy):
    model, policy = tiger_policy
    decider = FlatPolicyDecider(policy, model)
    assert isinstance(decider, MaskingDecider)
    b = np.array([0.85, 0.15])
    assert decider.execute(b).action_name == "listen"
    assert decider.execute_without(b, []).action_name == "listen"
    masked = decider.execute_without(b, ["listen"])
    # The best vector whose label is not listen, found by hand.
    best = max((float(alpha @ b), model.actions[int(a)]) for alpha, a in zip(policy.alphas, policy.actions)
               if model.actions[int(a)] != "listen")
    assert masked.action_name == best[1] == "open-right"
    assert masked.trace[0].value == pytest.approx(best[0], abs=1e-12)
    # Nothing remembered: the next decision may take the vetoed action again.
    assert decider.execute(b).action_name == "listen"


def test_flat_veto_without_a_vector_left_uses_the_one_step_values(tiger_policy):
    model, policy = tiger_policy
    listen = policy.actions == 0
    only_listen = AlphaVectorPolicy(policy.alphas[listen], policy.actions[listen])
    decider = FlatPolicyDecider(only_listen, model)
    b = np.array([0.6, 0.4])
    masked = decider.execute_without(b, ["listen"])
    q = {a: one_step_q(model, only_listen.alphas, b, i) for i, a in enumerate(model.actions) if a != "listen"}
    assert masked.action_name == max(q, key=q.get) == "open-right"
    assert masked.trace[0].value == pytest.approx(q["open-right"], abs=1e-9)


def test_flat_veto_errors_name_what_is_wrong(tiger_policy):
    model, policy = tiger_policy
    decider = FlatPolicyDecider(policy, model)
    with pytest.raises(PolicyError, match="'jump': not an action"):
        decider.execute_without([0.5, 0.5], ["jump"])
    with pytest.raises(PolicyError, match="every action is forbidden"):
        decider.execute_without([0.5, 0.5], model.actions)


def contingent_offer(hp, name, b, banned):
    """The primitive subtask ``name`` offers at ``b`` with ``banned`` masked, and its value: each
    child's offer valued by the subtask's one-step Q over its own model (recomputed here)."""
    sub = hp.subtasks[name]
    q = sub.one_step.q(sub.project(b)[0])
    offers = []
    for k, child in enumerate(sub.actions):
        if sub.abstract[k]:
            got = contingent_offer(hp, child, b, banned)
            if got is None:
                continue
            prim = got[0]
        elif child in banned:
            continue
        else:
            prim = child
        offers.append((float(q[sub.model_actions.index(prim)]), -k, prim))
    if not offers:
        return None
    value, _, prim = max(offers)   # first child on ties, as EXECUTE
    return prim, value


@pytest.mark.parametrize("kind", ["contingent", "corner"])
def test_hierarchical_veto_takes_the_best_action_left(kind):
    hp = planned(kind)
    assert isinstance(hp, MaskingDecider) and hp.contingent == (kind == "contingent")
    ACTIONS = hp.action_names
    chosen_ever = set()
    changed = 0
    for b in map(np.array, BELIEFS):
        chosen = hp.execute(b).action_name
        chosen_ever.add(chosen)
        # Vetoing an action the policy did not choose changes nothing.
        for other in set(ACTIONS) - {chosen}:
            assert hp.execute_without(b, [other]).action_name == chosen
        masked = hp.execute_without(b, [chosen])
        assert masked.action_name != chosen
        changed += 1
        if hp.contingent:
            expected = contingent_offer(hp, hp.root, b, {chosen})
            assert masked.action_name == expected[0]
            assert masked.trace[0].value == pytest.approx(expected[1], abs=1e-12)
        else:
            # Corner: at each level the best vector among the children left.
            node, left = hp.root, set(ACTIONS) - {chosen}
            while True:
                sub = hp.subtasks[node]
                ok = [k for k, c in enumerate(sub.actions)
                      if (c in left) or (sub.abstract[k] and left & below(hp, c))]
                values = [(float(alpha @ b), int(k)) for alpha, k in zip(sub.alphas_full, sub.alpha_actions) if k in ok]
                child = sub.actions[max(values)[1]]
                if not sub.abstract[sub.actions.index(child)]:
                    break
                node = child
            assert masked.action_name == child
        # The mask is for one decision: the cache still gives the unmasked choice.
        assert hp.execute(b).action_name == chosen
    assert changed == len(BELIEFS) and len(chosen_ever) >= 2
    with pytest.raises(PolicyError, match="every action is forbidden"):
        hp.execute_without(BELIEFS[0], ACTIONS)


def below(hp, name):
    sub = hp.subtasks[name]
    out = set()
    for k, c in enumerate(sub.actions):
        out |= below(hp, c) if sub.abstract[k] else {c}
    return out


def test_a_deeper_root_search_masks_the_first_step_only():
    """lookahead: 1 at a policy-contingent root: two steps of search over the offers. The veto
    removes the offer at the first step; later steps may take the action again. The masked
    value is recomputed here: first-step offers as contingent_offer gives them, successors
    valued by the unmasked one-step choice (the vectors after it)."""
    domain = parse_domain(PROBE_DOMAIN)
    deep = plan(domain, parse_hierarchy(PROBE_HIERARCHY.replace(
        "Top: {actions: [Ask, Do]}", "Top: {actions: [Ask, Do], lookahead: 1, expansions: 500}"), domain.actions))
    top = deep.subtasks["Top"]
    la = top.lookahead
    assert top.search_depth == 2

    def offer_value(bf, prim, depth):
        bh = top.project(bf)[0]
        a = top.model_actions.index(prim)
        pred = np.asarray(la._Tt[a] @ bh)
        total = float(bh @ la.R[:, a])
        for o in la._live_obs[a]:
            succ = pred * la.O[a, :, o]
            m = succ.sum()
            if m <= 1e-300:
                continue
            if depth == 1:
                total += la.discount * float((top.alphas @ succ).max())
            else:
                nxt = top.lift(succ / m)
                offers = {contingent_offer(deep, c, nxt, set())[0] if top.abstract[k] else c
                          for k, c in enumerate(top.actions)}
                total += la.discount * m * max(offer_value(nxt, p, depth - 1) for p in offers)
        return total

    for mass in (0.5, 0.9, 0.995):
        b = np.array([mass, 1 - mass, 0.0])
        chosen = deep.execute(b).action_name
        masked = deep.execute_without(b, [chosen])
        offers = {contingent_offer(deep, c, b, {chosen})[0] if top.abstract[k] else c
                  for k, c in enumerate(top.actions) if top.abstract[k] or c != chosen}
        values = {p: offer_value(b, p, 2) for p in offers}
        best = max(values, key=values.get)
        assert masked.action_name == best != chosen, (mass, chosen, values)
        assert masked.trace[0].value == pytest.approx(values[best], abs=1e-9)
        assert masked.expansions > 0
