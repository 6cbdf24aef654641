"""The core's memory fixes the ward (config/ward.domain.yaml, 233,280 states) needs, checked on small models.

* ``ExplicitModel`` samples straight from the model's sparse rows and ``O`` (no cumulative copy of
  T, no ``[A, S, Z]`` observation CDF): outcomes equal an explicit inverse CDF per particle.
* ``Pomdp.create(copy=False)`` takes the arrays over; ``FactoredDomain.compile`` uses it.
* The hierarchy's abstraction refuses a subtask whose state pairs do not fit, naming it.
"""
import numpy as np
import pytest
import scipy.sparse as sp

from pearl_pomdp.model.pomdp import Pomdp
from pearl_pomdp.online.generative import ExplicitModel


def _random_sparse_model(seed=3, S=40, A=3, Z=4):
    rng = np.random.default_rng(seed)
    T = []
    for _ in range(A):
        rows = []
        for s in range(S):
            k = int(rng.integers(1, 7))                      # rows of 1..6 entries, like the ward's
            cols = rng.choice(S, size=k, replace=False)
            p = rng.random(k)
            rows.append((np.full(k, s), cols, p / p.sum()))
        r, c, p = (np.concatenate(x) for x in zip(*rows))
        T.append(sp.csr_matrix((p, (r, c)), shape=(S, S)))
    O = rng.random((A, S, Z))
    O /= O.sum(axis=2, keepdims=True)
    return Pomdp.create([f"s{i}" for i in range(S)], [f"a{i}" for i in range(A)], [f"o{i}" for i in range(Z)],
                        T, O, rng.normal(size=(S, A)), sparse=True)


def test_explicit_model_is_the_inverse_cdf_of_each_row_without_copies():
    model = _random_sparse_model()
    g = ExplicitModel(model)
    rng = np.random.default_rng(1)
    states = rng.integers(0, model.num_states, 3000)
    u = rng.random((3000, 2))
    for a in range(len(model.actions)):
        nxt, obs, rew = g.step(states, a, u)
        Ta = model.T[a].tocsr()
        for i in range(0, 3000, 37):
            s = states[i]
            cols = Ta.indices[Ta.indptr[s]:Ta.indptr[s + 1]]
            cdf = np.cumsum(Ta.data[Ta.indptr[s]:Ta.indptr[s + 1]])
            expect = cols[min(int(np.searchsorted(cdf, u[i, 0] * cdf[-1], side="right")), len(cols) - 1)]
            assert nxt[i] == expect
            ocdf = np.cumsum(model.O[a, expect])
            assert obs[i] == min(int(np.searchsorted(ocdf, u[i, 1] * ocdf[-1], side="right")), model.num_observations - 1)
            assert rew[i] == model.R[s, a]
    # The adapter holds the model's own arrays: no nnz-sized or [A, S, Z]-sized copy.
    assert g._O is model.O
    assert all(rows[1] is model.T[a].indices for a, rows in enumerate(g._rows))
    assert not any(isinstance(v, np.ndarray) and v.size >= model.O.size and v is not model.O
                   for v in vars(g).values())


def test_create_without_copy_takes_the_arrays_over_and_compile_uses_it():
    from pearl_pomdp.model.domain_yaml import parse_domain

    model = _random_sparse_model()
    again = Pomdp.create(model.states, model.actions, model.observations, model.T, model.O, model.R, sparse=True, copy=False)
    assert again.O is model.O and np.shares_memory(again.T[0].data, model.T[0].data)
    copied = Pomdp.create(model.states, model.actions, model.observations, model.T, model.O, model.R, sparse=True)
    assert copied.O is not model.O and not np.shares_memory(copied.T[0].data, model.T[0].data)
    tiny = parse_domain("""
discount: 0.9
features: {Door: [closed, open]}
modalities: {Eye: [dark, bright]}
actions: {Push: {effects: {Door: {set: open}}}, Wait: {}}
observations:
  default: {parents: [Door], table: {closed: dark, open: {bright: 0.8, dark: 0.2}}}
rewards: [{action: Push, reward: -1, why: effort}]
""")
    m = tiny.compile()
    assert m.O.shape == (2, 2, 2) and m.O[0, 1, 1] == pytest.approx(0.8) and m.O.flags.owndata


def test_belief_filter_past_the_view_limit_shares_the_models_arrays_and_agrees(monkeypatch):
    import pearl_pomdp.belief as belief

    model = _random_sparse_model(seed=5, S=80)
    exact = belief.BeliefFilter(model)
    monkeypatch.setattr(belief, "VIEW_LIMIT", 10)
    viewing = belief.BeliefFilter(model)
    assert viewing.views and not exact.views
    assert np.shares_memory(viewing._OT, model.O)
    assert all(np.shares_memory(viewing._TT[a].data, model.T[a].data) for a in range(len(model.actions)))
    b = model.b0
    rng = np.random.default_rng(2)
    for _ in range(20):
        a, o = int(rng.integers(len(model.actions))), int(rng.integers(model.num_observations))
        nb = viewing.update(b, a, o)
        np.testing.assert_allclose(nb, exact.update(b, a, o), atol=1e-12)
        b = nb


def test_a_viewing_filters_batch_update_reads_the_support_only_and_gives_the_same_bits(monkeypatch):
    """Past VIEW_LIMIT, update_batch reads the rows of T[a] and the entries of O at the beliefs' support
    only (the ward's entry beliefs hold 9,261 of its 233,280 states): the posteriors are the full
    product's bit for bit, rows of different actions and a belief on one state included."""
    import pearl_pomdp.belief as belief

    model = _random_sparse_model(seed=9, S=80)
    exact = belief.BeliefFilter(model)
    monkeypatch.setattr(belief, "VIEW_LIMIT", 10)
    viewing = belief.BeliefFilter(model)
    assert viewing.views and not exact.views
    rng = np.random.default_rng(4)
    B = rng.random((7, 80)) * (rng.random((7, 80)) < 0.15)
    B[:6, 3] += 0.1
    B[6] = np.eye(80)[17]
    B /= B.sum(axis=1, keepdims=True)
    actions, observations = np.array([0, 1, 2, 0, 1, 2, 1]), np.array([0, 1, 2, 3, 3, 0, 2])
    batch = viewing.update_batch(B, actions, observations)
    assert batch.tobytes() == exact.update_batch(B, actions, observations).tobytes()
    assert (batch > 0).sum() > (B > 0).sum()          # the predictions spread beyond the support


def test_entry_beliefs_are_every_stride_th_of_the_kept_steps_beliefs(monkeypatch):
    """The plan's entry beliefs copy only the beliefs they return: the same rows, bit for bit, as keeping
    every kept step's beliefs and taking every stride-th (what they were before; the ward's kept
    beliefs took 1.1 GB), with the filter past VIEW_LIMIT and the sampler's observations drawn
    from O's cumulative rows."""
    import importlib

    import pearl_pomdp.belief as belief
    from pearl_pomdp.simulate import EpisodeSampler
    from pearl_pomdp.solution import AlphaVectorPolicy
    from pearl_pomdp.solvers.mdp import solve_qmdp

    plan = importlib.import_module("pearl_pomdp.hierarchy.plan")
    model = _random_sparse_model(seed=11, S=80)
    episodes, steps, every, seed = 4, 10, 3, 5
    Q = solve_qmdp(model).policy.alphas.T.copy()
    policy, rng = AlphaVectorPolicy(Q.T.copy(), np.arange(model.num_actions)), np.random.default_rng(seed)
    filt, sampler = belief.BeliefFilter(model), EpisodeSampler(model)
    cum = np.cumsum(model.O, axis=2)
    states, B, kept = sampler.start(rng.random(episodes)), np.tile(model.b0, (episodes, 1)), []
    for t in range(steps):
        if t % every == 0 or (t * episodes) % every < episodes:
            kept.append(B.copy())
        actions = policy.actions_batch(B)
        u_s, u_o = rng.random(episodes), rng.random(episodes)
        nxt, obs = sampler.step(states, actions, u_s, u_o)
        c = cum[actions, nxt]
        assert (obs == np.minimum((c <= (u_o * c[:, -1])[:, None]).sum(axis=1), c.shape[1] - 1)).all()
        B, states = filt.update_batch(B, actions, obs), nxt
    flat = np.concatenate(kept)
    expected = flat[::max(1, len(flat) // max(1, (episodes * steps) // every))]
    monkeypatch.setattr(belief, "VIEW_LIMIT", 10)
    got = plan.entry_beliefs(model, seed=seed, episodes=episodes, steps=steps, every=every, qmdp=Q)
    assert len(expected) == 14 and len({tuple(np.flatnonzero(row)) for row in expected}) > 1
    assert got.tobytes() == expected.tobytes() and got.shape == expected.shape


def test_the_online_deciders_default_upper_bound_is_qmdp_past_the_fib_limit(monkeypatch):
    import pearl_pomdp.online.decider as decider

    model = _random_sparse_model(seed=7)
    assert decider.default_bounds(model).description.startswith("upper: FIB")
    monkeypatch.setattr(decider, "FIB_LIMIT", model.num_states * 3 * 4 - 1)
    assert decider.default_bounds(model).description.startswith("upper: QMDP")
    assert decider.OnlineDecider(model).bounds.description.startswith("upper: QMDP")


def test_planning_refuses_a_subtask_whose_state_pairs_do_not_fit_in_one_line_naming_it(monkeypatch):
    """A subtask that keeps too many state pairs stops planning with one line naming the hierarchy file,
    the subtask and the features kept (the ward's CareAnn kept all 233,280 states, 5.4e10 pairs, before
    separable reward terms). Checked on the reception robot with the limit lowered below its Welcome
    subtask's 18² pairs (Battery's cost is separable from Welcome: docs/hierarchy.md)."""
    import pearl_pomdp.hierarchy.abstraction as abstraction
    from pearl_pomdp.errors import PearlError
    from pearl_pomdp.hierarchy import load_hierarchy, plan
    from pearl_pomdp.model.domain_yaml import load_domain

    domain = load_domain("config/reception.domain.yaml")
    hierarchy = load_hierarchy("config/reception.hierarchy.yaml", domain)
    monkeypatch.setattr(abstraction, "MAX_PAIRS", 17 ** 2)
    with pytest.raises(PearlError) as err:
        plan(domain, hierarchy, seed=0)
    text = str(err.value)
    assert "\n" not in text
    assert text.startswith("config/reception.hierarchy.yaml: subtasks.Welcome: subtask Welcome: its abstraction keeps 18 states")
    assert "(3 features: Visitor, Wish, RobotAt)" in text and "324 state pairs > 2^31" in text


def test_a_large_compiled_model_keeps_O_as_float32_and_the_filter_and_sampler_use_it_uncopied(monkeypatch):
    """Past LARGE_O_ENTRIES (the ward: 52M) compile stores O as float32; beliefs and samples agree
    with the float64 model's to float32 precision. Checked on the reception domain with the limit lowered."""
    import pearl_pomdp.belief as belief
    import pearl_pomdp.model.factored as factored
    from pearl_pomdp.model.domain_yaml import load_domain

    exact = load_domain("config/reception.domain.yaml").compile()
    monkeypatch.setattr(factored, "LARGE_O_ENTRIES", 100)
    monkeypatch.setattr(belief, "VIEW_LIMIT", 100)
    small = load_domain("config/reception.domain.yaml").compile()
    assert exact.O.dtype == np.float64 and small.O.dtype == np.float32
    np.testing.assert_allclose(small.O, exact.O, atol=1e-7)
    f32, f64 = belief.BeliefFilter(small), belief.BeliefFilter(exact)
    assert f32.views and np.shares_memory(f32._OT, small.O)
    b32 = b64 = exact.b0
    for a, o in [(0, 0), (1, 2), (2, 1), (0, 3), (5, 4)]:
        b32, b64 = f32.update(b32, a, o), f64.update(b64, a, o)
        assert b32.dtype == np.float64
        np.testing.assert_allclose(b32, b64, atol=1e-6)
    g = ExplicitModel(small)
    assert g._O is small.O
    u = np.random.default_rng(0).random((500, 2))
    s = np.random.default_rng(1).integers(0, small.num_states, 500)
    n32, o32, _ = g.step(s, 1, u)
    n64, o64, _ = ExplicitModel(exact).step(s, 1, u)
    assert (n32 == n64).all() and (o32 != o64).sum() <= 2     # a uniform within 1e-7 of a CDF step may differ


def test_ward_hierarchy_has_an_online_root_over_per_resident_subtasks():
    """config/ward.hierarchy.yaml: the root plans online over the three residents' subtasks, the drives
    and Wait; every child is a subtask of primitives (planned offline)."""
    from pearl_pomdp.hierarchy import load_hierarchy
    from pearl_pomdp.model.domain_yaml import load_domain

    domain = load_domain("config/ward.domain.yaml")
    hierarchy = load_hierarchy("config/ward.hierarchy.yaml", domain)
    root = hierarchy.subtasks[hierarchy.root]
    assert root.solver == "online" and root.trials == 20
    assert [c for c in root.children if c in hierarchy.subtasks] == ["CareAnn", "CareBob", "CareCleo"]
    assert all(hierarchy.subtasks[c].solver == "pointbased" for c in ("CareAnn", "CareBob", "CareCleo"))


@pytest.mark.slow
def test_care_ann_keeps_her_features_and_the_robot_place_only(ward_domain):
    """Bob's and Cleo's every-action costs are separable from CareAnn (docs/hierarchy.md): its abstraction
    keeps RobotAt and Ann's three features, 5 x 36 = 180 states (compiling the ward takes ~2 s)."""
    from pearl_pomdp.hierarchy.abstraction import abstract_subtask, separable_reward_terms
    from pearl_pomdp.hierarchy.parameterize import StateFactors, parameterize
    from pearl_pomdp.hierarchy.spec import SubtaskSpec

    domain = ward_domain
    model = domain.compile()
    prims = ["RemindAnn", "AskAnn", "ServeAnn"]
    factors = StateFactors.from_domain(domain)
    sub = parameterize(model, SubtaskSpec(name="CareAnn", children=prims, solver="pointbased"), {}, factors)
    sep = separable_reward_terms(domain, prims, list(model.actions))
    assert len(sep.rules) == 6 and all("Ann" not in domain.rewards[i].why for i in sep.rules)
    sub.R = sep.apply(sub.R)
    abst = abstract_subtask(sub, factors, domain, dropped=sep.rules)
    assert abst.relevant == ["RobotAt", "AnnAt", "AnnPill", "AnnNeed"] and abst.lumped_states == 180
