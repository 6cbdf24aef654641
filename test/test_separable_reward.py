"""Separable reward terms (docs/hierarchy.md, "Separable reward terms"): a rule every action of a
subtask pays alike, over features no action of the subtask moves, is left out of its local reward
and of its relevance closure — and that changes no choice of the subtask.

The toy: two residents A and B, each wanting something now and then (``ANeed``, ``BNeed``); the
robot's subtask ``CareA`` asks A (a noisy answer) or serves A; every step either resident waits
costs 1 (rules for every action, ``"*"``). ``BNeed`` moves the same way whatever ``CareA`` does,
so its waiting cost is separable from ``CareA``: the abstraction keeps ``ANeed`` alone, and the
subtask's exact finite-horizon Q-values with and without the term differ by the same amount for
every action — the term's expected discounted sum, computed here from B's chain alone.

In the variants the question disturbs B (directly, or through a noise feature B reacts to): the
term is then *not* separable, and leaving it out would change the subtask's choice.
"""
import numpy as np
import pytest

from pearl_pomdp.hierarchy import parse_hierarchy, plan
from pearl_pomdp.hierarchy.abstraction import abstract_subtask, separable_reward_terms
from pearl_pomdp.hierarchy.parameterize import StateFactors, parameterize
from pearl_pomdp.hierarchy.spec import SubtaskSpec
from pearl_pomdp.model.domain_yaml import parse_domain

GAMMA = 0.9


def toy(ask_disturbs_b: str = "no") -> str:
    """The two-resident domain; ``ask_disturbs_b``: ``"no"``, ``"direct"`` (AskA sets BNeed to want
    half the time) or ``"noise"`` (AskA makes the room loud; B wants something when it is loud)."""
    noise = ask_disturbs_b == "noise"
    features = "  ANeed: [none, want]\n  BNeed: [none, want]\n" + ("  Noise: [quiet, loud]\n" if noise else "")
    start = "  ANeed: {none: 0.5, want: 0.5}\n  BNeed: {none: 0.7, want: 0.3}\n" + ("  Noise: quiet\n" if noise else "")
    b_default = ("    BNeed:\n      parents: [BNeed, Noise]\n      table:\n"
                 "        \"none,quiet\": {none: 0.9, want: 0.1}\n        \"none,loud\": want\n        \"want,*\": keep\n"
                 "    Noise: {set: quiet}\n") if noise else (
                 "    BNeed:\n      parents: [BNeed]\n      table:\n"
                 "        none: {none: 0.9, want: 0.1}\n        want: {none: 0.2, want: 0.8}\n")
    ask_effects = {"no": "", "direct": "    effects:\n      BNeed:\n        parents: [BNeed]\n        table:\n"
                                       "          none: {none: 0.5, want: 0.5}\n          want: keep\n",
                   "noise": "    effects: {Noise: {set: loud}}\n"}[ask_disturbs_b]
    return f"""
name: toy
discount: {GAMMA}
features:
{features}start:
{start}modalities:
  Voice: {{symbols: ["yes", "no", quiet]}}
defaults:
  effects:
    ANeed:
      parents: [ANeed]
      table:
        none: {{none: 0.8, want: 0.2}}
        want: keep
{b_default}observations:
  default:
    parents: [ANeed]
    table:
      want: {{"yes": 0.2, quiet: 0.8}}
      none: quiet
  AskA:
    parents: [ANeed]
    table:
      want: {{"yes": 0.8, "no": 0.2}}
      none: {{"yes": 0.2, "no": 0.8}}
actions:
  Wait: {{}}
  AskA:
{ask_effects or '    {}'}
  ServeA:
    effects: {{ANeed: {{set: none}}}}
  ServeB:
    effects: {{BNeed: {{set: none}}}}
rewards:
  - {{action: ServeA, when: {{ANeed: want}}, reward: 10, why: A is served}}
  - {{action: ServeA, when: {{ANeed: none}}, reward: -6, why: serving nothing}}
  - {{action: ServeB, when: {{BNeed: want}}, reward: 10, why: B is served}}
  - {{action: ServeB, when: {{BNeed: none}}, reward: -6, why: serving nothing}}
  - {{action: AskA, reward: -1, why: a question}}
  - {{action: "*", when: {{ANeed: want}}, reward: -1, why: A waits}}
  - {{action: "*", when: {{BNeed: want}}, reward: -2, why: B waits}}
"""


HIERARCHY = """
root: Care
defaults: {solver: pointbased, trials: 30}
subtasks:
  Care: {actions: [CareA, ServeB, Wait]}
  CareA: {actions: [AskA, ServeA]}
"""
CARE_A = ["AskA", "ServeA"]


def _parts(variant: str):
    domain = parse_domain(toy(variant))
    model = domain.compile()
    factors = StateFactors.from_domain(domain)
    sub = parameterize(model, SubtaskSpec(name="CareA", children=CARE_A, solver="incprune"), {}, factors)
    return domain, model, factors, sub


def _q(T, O, R, b, horizon, gamma):
    """Exact horizon-``horizon`` Q-values ``[A]`` at ``b`` by expectimax (``T[a][s, s']``, ``O[a][s', o]``)."""
    q = np.empty(len(T))
    for a in range(len(T)):
        q[a] = b @ R[:, a]
        if horizon > 1:
            pred = b @ T[a]
            for o in range(O[a].shape[1]):
                joint = pred * O[a][:, o]
                p = joint.sum()
                if p > 1e-15:
                    q[a] += gamma * p * _q(T, O, R, joint / p, horizon - 1, gamma).max()
    return q


def _dense(model, prims):
    idx = [model.actions.index(p) for p in prims]
    T = [np.asarray(model.T[a].toarray() if hasattr(model.T[a], "toarray") else model.T[a]) for a in idx]
    O = [np.asarray(model.O[a]) for a in idx]
    return T, O


def test_waiting_cost_of_the_other_resident_is_separable():
    domain, model, factors, sub = _parts("no")
    # Charged under every action of the domain (the option's condition) and B moves alone: dropped.
    sep = separable_reward_terms(domain, CARE_A, list(model.actions))
    assert [domain.rewards[i].why for i in sep.rules] == ["B waits"]
    assert "B waits" in sep.described[0]
    # A's own waiting cost is not: ServeA moves ANeed.
    assert all(domain.rewards[i].why != "A waits" for i in sep.rules)
    sub.R = sep.apply(sub.R)
    abst = abstract_subtask(sub, factors, domain, dropped=sep.rules)
    assert abst.relevant == ["ANeed"] and abst.irrelevant == ["BNeed"]
    # Without the rule taken out, BNeed's cost keeps B in the subtask.
    _, _, _, whole = _parts("no")
    assert abstract_subtask(whole, factors, domain).relevant == ["ANeed", "BNeed"]


def test_dropped_term_shifts_every_action_alike_exactly():
    """Horizon-4 Q-values of the full subtask (term included, every state) minus those of the abstract
    model without the term, at random beliefs: one number for both actions, equal to the term's expected
    discounted sum over B's own chain (so the choice is the same)."""
    domain, model, factors, sub = _parts("no")
    R_full = sub.R.copy()
    sep = separable_reward_terms(domain, CARE_A, list(model.actions))
    sub.R = sep.apply(sub.R)
    abst = abstract_subtask(sub, factors, domain, dropped=sep.rules)
    T_full, O_full = _dense(model, CARE_A)
    am = abst.model
    T_abs = [np.asarray(t.toarray() if hasattr(t, "toarray") else t) for t in am.T]
    O_abs = [np.asarray(am.O[a]) for a in range(am.num_actions)]
    H = 4
    b_feature = factors.names.index("BNeed")
    P_b = np.array([[0.9, 0.1], [0.2, 0.8]])        # B's chain, written from the toy above
    cost = np.array([0.0, -2.0])
    rng = np.random.default_rng(7)
    checked = 0
    for _ in range(25):
        b = rng.dirichlet(np.ones(model.num_states) * 0.7)
        q_full = _q(T_full, O_full, R_full, b, H, GAMMA)
        q_abs = _q(T_abs, O_abs, am.R, abst.project(b), H, GAMMA)
        shift = q_full - q_abs
        assert abs(shift[0] - shift[1]) < 1e-9
        marginal = np.bincount(factors.state_values[:, b_feature], weights=b, minlength=2)
        expected = sum(GAMMA ** t * marginal @ np.linalg.matrix_power(P_b, t) @ cost for t in range(H))
        assert shift[0] == pytest.approx(expected, abs=1e-9)
        assert int(np.argmax(q_full)) == int(np.argmax(q_abs))
        checked += 1
    assert checked == 25


@pytest.mark.parametrize("variant", ["direct", "noise"])
def test_cost_the_subtask_influences_is_kept_and_matters(variant):
    """AskA disturbs B (directly, or through the noise B reacts to): the rule is kept, B's features stay
    relevant, and leaving the term out would flip the subtask's choice at some belief."""
    domain, model, factors, sub = _parts(variant)
    sep = separable_reward_terms(domain, CARE_A, list(model.actions))
    assert all(domain.rewards[i].why != "B waits" for i in sep.rules)
    assert "BNeed" in abstract_subtask(sub, factors, domain, dropped=sep.rules).relevant
    b_rule = next(i for i, r in enumerate(domain.rewards) if r.why == "B waits")
    mask = np.isin(factors.state_values[:, factors.names.index("BNeed")], domain.rewards[b_rule].when["BNeed"])
    R_without = sub.R - np.where(mask, domain.rewards[b_rule].reward, 0.0)[:, None]
    T, O = _dense(model, CARE_A)
    flips = 0
    for pa in np.linspace(0.05, 0.95, 19):
        b = np.zeros(model.num_states)
        for s in range(model.num_states):
            v = dict(zip(factors.names, factors.state_values[s]))
            if v.get("Noise", 0) == 0 and v["BNeed"] == 0:
                b[s] = pa if v["ANeed"] == 1 else 1 - pa
        flips += int(np.argmax(_q(T, O, sub.R, b, 3, GAMMA)) != np.argmax(_q(T, O, R_without, b, 3, GAMMA)))
    assert flips > 0


def test_option_needs_the_rule_charged_under_every_action():
    """A rule only the subtask's actions pay is separable from a subtask that never stops, but not from an
    option: stopping would escape it in the option's model, and the parent's actions do not pay it."""
    text = toy("no").replace('{action: "*", when: {BNeed: want}, reward: -2, why: B waits}',
                             '{action: [AskA, ServeA], when: {BNeed: want}, reward: -2, why: B waits}')
    domain = parse_domain(text)
    actions = list(domain.actions)
    assert [domain.rewards[i].why for i in separable_reward_terms(domain, CARE_A, CARE_A).rules] == ["B waits"]
    assert separable_reward_terms(domain, CARE_A, actions).rules == []


def test_plan_reports_the_separable_terms():
    domain = parse_domain(toy("no"))
    hierarchy = parse_hierarchy(HIERARCHY, domain.actions, {f.name: list(f.values) for f in domain.features})
    policy = plan(domain, hierarchy)
    care_a = next(s for s in policy.report["subtasks"] if s["name"] == "CareA")
    assert care_a["relevant_features"] == ["ANeed"]
    assert len(care_a["separable_reward_terms"]) == 1 and "B waits" in care_a["separable_reward_terms"][0]
    root = next(s for s in policy.report["subtasks"] if s["name"] == "Care")
    assert root["separable_reward_terms"] == []     # ServeB moves BNeed; the root keeps every rule
    # --no-abstraction solves the subtask as it is.
    flat = plan(domain, hierarchy, abstraction=False)
    assert next(s for s in flat.report["subtasks"] if s["name"] == "CareA")["separable_reward_terms"] == []
