"""The online planner (pearl_pomdp/online): RockSample's dynamics against the explicit file and by
hand, the bounds bracket the optimum, DESPOT on tiger, and budget determinism."""
from __future__ import annotations

import math
import re

import numpy as np
import pytest

from pearl_pomdp.model import load_model
from pearl_pomdp.online.decider import OnlineDecider
from pearl_pomdp.online.despot import Despot, DespotSettings
from pearl_pomdp.online.generative import AlphaBounds, ExplicitModel, alpha_bounds
from pearl_pomdp.online.rocksample import RockSampleBounds, mdp_upper_values, random_rocksample, rocksample


@pytest.fixture(scope="module")
def tiger(benchmarks_dir):
    return load_model(str(benchmarks_dir / "tiger.95.POMDP"))


@pytest.fixture(scope="module")
def rs44_file(benchmarks_dir):
    return load_model(str(benchmarks_dir / "RockSample_4_4.pomdp"))


def _state_index(rs, name: str) -> int:
    """The generative model's state for the file's name ``xXyY_B`` (B: rock 1 first)."""
    if name == "exit":
        return rs.exit_state
    x, y, b = re.fullmatch(r"x(\d+)y(\d+)_([01]+)", name).groups()
    return rs.encode(int(x), int(y), sum(1 << i for i, c in enumerate(b) if c == "1"))


def test_rocksample_4_4_matches_the_explicit_file_state_by_state(rs44_file):
    """Every state and action: the generative step's next state, reward and P(good) equal the
    project's generated RockSample_4_4.pomdp (an independent writer of the same model)."""
    rs = rocksample("4_4")
    m = rs44_file
    assert rs.num_states == m.num_states == 257
    T = [Ta.toarray() if hasattr(Ta, "toarray") else np.asarray(Ta) for Ta in m.T]
    ours = np.array([_state_index(rs, n) for n in m.states])
    for a, name in enumerate(m.actions):
        assert rs.actions[a] == name
        for u in (0.1, 0.9):   # a check's outcome depends on the uniform; moves do not
            nxt, obs, rew = rs.step(ours, a, np.full((ours.size, 1), u))
            expected_next = ours[T[a].argmax(axis=1)]
            assert np.array_equal(nxt, expected_next), name
            np.testing.assert_allclose(rew, m.R[:, a], err_msg=name)
        # P(good | s', a): the share of uniforms in [0, 1) that report good, on a fine grid.
        grid = (np.arange(2000) + 0.5) / 2000
        live = ours != rs.exit_state
        for s_file, s in zip(np.flatnonzero(live)[:40], ours[live][:40]):
            _, o, _ = rs.step(np.full(grid.size, s), a, grid[:, None])
            s_next = int(T[a][s_file].argmax())
            assert abs(float(np.mean(o == 0)) - m.O[a, s_next, 0]) < 1e-3, (name, m.states[s_file])


def test_rocksample_dynamics_by_hand():
    """A tiny instance worked by hand: RockSample(4,4) from the start cell (0, 2)."""
    rs = rocksample("4_4")
    s = rs.encode(0, 2, 0b0101)                # rocks 1 and 3 good
    u = np.array([[0.5]])
    # Check_1: rock 1 at (3, 1), distance sqrt(10); η = e^(-sqrt 10); P(correct) = (1 + η)/2.
    p = 0.5 * (1 + math.exp(-math.sqrt(10)))
    assert rs.accuracy[2 * 4 + 0, 0] == pytest.approx(p)
    assert p == pytest.approx(0.5211646, abs=1e-7)   # e^-3.16228 = 0.0423292
    nxt, o, r = rs.step(np.array([s]), 5, np.array([[p - 1e-9]]))
    assert (nxt[0], o[0], r[0]) == (s, 0, 0.0)          # correct: rock 1 is good → "good"
    nxt, o, r = rs.step(np.array([s]), 5, np.array([[p + 1e-9]]))
    assert (nxt[0], o[0], r[0]) == (s, 1, 0.0)          # wrong → "bad"
    # W off the grid: -100 and exit; E moves to (1, 2); N to (0, 3).
    assert rs.step(np.array([s]), 3, u)[0][0] == rs.exit_state
    assert rs.step(np.array([s]), 3, u)[2][0] == -100.0
    assert rs.decode(int(rs.step(np.array([s]), 2, u)[0][0])) == (1, 2, 0b0101)
    assert rs.decode(int(rs.step(np.array([s]), 0, u)[0][0])) == (0, 3, 0b0101)
    # Rock 3 sits at (1, 3): go there and sample it: +10, then its bit is cleared; again: -10.
    on3 = rs.encode(1, 3, 0b0101)
    nxt, _, r = rs.step(np.array([on3]), 4, u)
    assert r[0] == 10.0 and rs.decode(int(nxt[0])) == (1, 3, 0b0001)
    assert rs.step(nxt, 4, u)[2][0] == -10.0
    # Sample off a rock: -100 and exit; East off the grid at x = 3: +10 and exit.
    assert rs.step(np.array([s]), 4, u)[2][0] == -100.0
    east = rs.step(np.array([rs.encode(3, 0, 0)]), 2, u)
    assert (east[0][0], east[2][0]) == (rs.exit_state, 10.0)
    assert rs.step(np.array([rs.exit_state]), 2, u)[2][0] == 0.0   # the exit is absorbing, reward 0


def test_rocksample_exact_belief_is_bayes():
    rs = rocksample("4_4")
    b = rs.initial_belief()
    b.update(5, 0)                                  # Check_1 says good at accuracy p
    p = 0.5 * (1 + math.exp(-math.sqrt(10)))
    assert b.p_good[0] == pytest.approx(p)          # prior ½: posterior = p
    b.update(2, 0)                                  # E: the rover moves to (1, 2)
    assert (b.x, b.y) == (1, 2)
    samples = b.sample(20000, np.random.default_rng(0))
    assert {rs.decode(int(s))[:2] for s in samples} == {(1, 2)}
    bits = samples & 0xF
    assert np.mean(bits & 1) == pytest.approx(p, abs=0.01)


def test_rocksample_mdp_bound_equals_value_iteration_on_the_explicit_file(rs44_file):
    """The generative MDP upper bound is the fully observed MDP's value: the project's own value
    iteration on the explicit file gives the same numbers (up to the bound's safety margin)."""
    from pearl_pomdp.solvers.mdp import mdp_value_iteration

    rs = rocksample("4_4")
    V_file, _ = mdp_value_iteration(rs44_file, epsilon=1e-8)
    ours = mdp_upper_values(rs, dtype=np.float64, tolerance=1e-9).reshape(-1)
    idx = np.array([_state_index(rs, n) for n in rs44_file.states])
    live = idx != rs.exit_state
    np.testing.assert_allclose(ours[idx[live]], V_file[live], atol=1e-6)


def test_rocksample_bounds_bracket_the_optimum(rs44_file):
    """At b0 (all 16 rock configurations as particles) the tour lower bound ≤ V* ≤ the MDP upper
    bound, with V* bracketed by the point-based solver run to a 1e-3 gap on the explicit file."""
    from pearl_pomdp.solvers.registry import solve

    result = solve(rs44_file, "pointbased", epsilon=1e-3, time_limit=30)
    rs = rocksample("4_4")
    b0 = np.array([rs.encode(0, 2, bits) for bits in range(16)])
    bounds = RockSampleBounds(rs)
    low, up = bounds.lower(b0, None), bounds.upper(b0)
    assert low <= result.value_at_start + 1e-6
    assert up >= result.upper_bound - 1e-6
    assert low > 0.0                       # better than nothing: the tour earns something at b0
    distance = RockSampleBounds(rs, upper="distance").upper(b0)
    assert up <= distance + 1e-6           # the MDP bound is never looser than the distance bound


def test_alpha_bounds_bracket_tiger_optimum(tiger):
    """FIB above and the blind policies below bracket tiger's optimum at every belief we try."""
    from pearl_pomdp.solvers.registry import solve

    exact = solve(tiger, "pointbased", epsilon=1e-4, time_limit=30)
    bounds = alpha_bounds(tiger)
    rng = np.random.default_rng(0)
    for p_left in (0.5, 0.15, 0.85, 0.97):
        b = np.array([p_left, 1 - p_left])
        states = (rng.random(4000) >= p_left).astype(np.int64)
        v_star = exact.policy.value(b)
        # The bounds of the particle belief; the particles' share is within 0.02 of p_left.
        share = 1 - states.mean()
        b_particles = np.array([share, 1 - share])
        assert bounds.lower(states, rng) <= exact.policy.value(b_particles) + 1e-6
        assert bounds.upper(states) >= exact.policy.value(b_particles) - 1e-6
        assert bounds.lower(states, rng) < v_star < bounds.upper(states)


def test_despot_on_tiger_acts_as_the_optimal_policy_and_brackets_its_value(tiger):
    """At b0 DESPOT listens, after strong evidence it opens the other door — the converged
    point-based policy's choices — and its root bounds bracket V*(b0) = 19.37 closely."""
    from pearl_pomdp.solvers.registry import solve

    exact = solve(tiger, "pointbased", epsilon=1e-4, time_limit=30)
    v_star = exact.value_at_start
    assert v_star == pytest.approx(19.37, abs=0.01)
    decider = OnlineDecider(tiger, settings=DespotSettings(trials=100, scenarios=300, depth=40))
    for p_left in (0.5, 0.85, 0.03, 0.97):
        b = np.array([p_left, 1 - p_left])
        assert decider.execute(b).action == exact.policy.action(b), p_left
    d = decider.execute(tiger.b0)
    assert d.action_name == "listen"
    search = d.search
    assert search is not None
    # The root's bounds are over 300 sampled scenarios: they bracket V* within sampling noise.
    assert search["lower"] <= v_star + 2.0
    assert search["upper"] >= v_star - 2.0
    # The search lifted the root's lower bound far above its heuristic start (always listen: -20).
    blind_start = alpha_bounds(tiger).lower(np.array([0, 1] * 150), None)
    assert blind_start == pytest.approx(-20.0, abs=1e-3)
    assert search["lower"] > blind_start + 15.0
    assert search["trials"] == 100 and search["nodes"] > 100 and search["seconds"] > 0


def test_despot_tiger_return_is_near_the_optimum(tiger):
    """Episodes on tiger (common random numbers for the world): the online planner's mean
    discounted return over 20 steps is within the CI of the optimal policy's on the same seeds."""
    from pearl_pomdp.belief import BeliefFilter
    from pearl_pomdp.solvers.registry import solve

    exact = solve(tiger, "pointbased", epsilon=1e-4, time_limit=30)
    decider = OnlineDecider(tiger, settings=DespotSettings(trials=5, scenarios=100, depth=8))
    world, filt = ExplicitModel(tiger), BeliefFilter(tiger)

    def run(choose, episodes=20, steps=20):
        out = []
        for ep in range(episodes):
            rng = np.random.default_rng(ep)
            b, s, total = filt.initial(), int(rng.integers(2)), 0.0
            for t in range(steps):
                a = choose(b)
                s2, o, r = world.step(np.array([s]), a, rng.random((1, 2)))
                total += tiger.discount ** t * float(r[0])
                b, s = filt.update(b, a, int(o[0])), int(s2[0])
            out.append(total)
        return np.array(out)

    ours = run(lambda b: decider.execute(b).action)
    best = run(exact.policy.action)
    half = 1.96 * best.std(ddof=1) / math.sqrt(best.size)
    assert ours.mean() >= best.mean() - half, (ours.mean(), best.mean(), half)


def test_same_seed_same_actions_under_a_trial_budget():
    """The trial budget is deterministic: the same particles and seed give the same tree and action;
    another seed may differ but is reported with the same fields."""
    rs = rocksample("7_8")
    planner = Despot(rs, RockSampleBounds(rs), DespotSettings(trials=8, scenarios=200))
    roots = rs.initial_belief().sample(200, np.random.default_rng(3))
    first, second = planner.search(roots, seed=11), planner.search(roots, seed=11)
    assert (first.action, first.trials, first.nodes, first.expansions) == \
        (second.action, second.trials, second.nodes, second.expansions)
    assert first.lower == second.lower and first.upper == second.upper
    assert first.action_bounds == second.action_bounds
    assert first.stop == "trials" and first.trials == 8
    assert first.lower <= first.upper


class _OneAtATime:
    """The model or bounds with their batched methods hidden: the search falls back to per-action
    steps and per-node bounds."""

    def __init__(self, inner):
        self._inner = inner

    def __getattr__(self, name):
        if name in ("step_many", "many"):
            raise AttributeError(name)
        return getattr(self._inner, name)


@pytest.mark.parametrize("layout", ["7_8", "11_11"])
def test_rocksample_batched_step_and_bounds_equal_the_one_at_a_time_ones(layout):
    """``step_many`` row a is ``step(states, a)`` exactly, the exit state included; ``many`` gives
    each group's ``both``."""
    rs = rocksample(layout)
    rng = np.random.default_rng(5)
    states = np.append(rng.integers(0, rs.exit_state, 300), rs.exit_state)
    uniforms = rng.random((states.shape[0], 1))
    nxt, obs, rew = rs.step_many(states, uniforms)
    for a in range(len(rs.actions)):
        one = rs.step(states, a, uniforms)
        assert np.array_equal(nxt[a], one[0]) and np.array_equal(obs[a], one[1]) and np.array_equal(rew[a], one[2]), a
    bounds = RockSampleBounds(rs)
    cells = rng.integers(0, rs.n * rs.n, 6)
    groups = [(c << rs.k) + rng.integers(0, 1 << rs.k, size) for c, size in zip(cells, (1, 7, 40, 3, 200, 2))]
    lowers, uppers = bounds.many(groups, rng)
    for g, lower, upper in zip(groups, lowers, uppers):
        assert (lower, upper) == pytest.approx(bounds.both(g, rng), abs=1e-9)


def test_alpha_bounds_many_equals_each_sets_bounds(tiger):
    bounds = alpha_bounds(tiger)
    groups = [np.array([0]), np.array([0, 1, 1]), np.array([1] * 5 + [0] * 2)]
    lowers, uppers = bounds.many(groups, None)
    for g, lower, upper in zip(groups, lowers, uppers):
        assert lower == pytest.approx(bounds.lower(g, None), abs=1e-12)
        assert upper == pytest.approx(bounds.upper(g), abs=1e-12)


def test_the_batched_search_builds_the_tree_the_one_at_a_time_search_builds():
    rs = rocksample("11_11")
    roots = rs.initial_belief().sample(500, np.random.default_rng(2))
    settings = DespotSettings(trials=25)
    fast = Despot(rs, RockSampleBounds(rs), settings).search(roots, seed=9)
    slow = Despot(_OneAtATime(rs), _OneAtATime(RockSampleBounds(rs)), settings).search(roots, seed=9)
    assert (fast.action, fast.trials, fast.nodes, fast.expansions) == (slow.action, slow.trials, slow.nodes, slow.expansions)
    assert fast.lower == pytest.approx(slow.lower, abs=1e-9) and fast.upper == pytest.approx(slow.upper, abs=1e-9)
    assert fast.nodes > 1000


def test_online_decider_seed_depends_on_the_belief_only(tiger):
    decider = OnlineDecider(tiger, settings=DespotSettings(trials=10, scenarios=50, depth=10), seed=4)
    b = np.array([0.7, 0.3])
    a = decider.execute(b)
    decider.execute(np.array([0.2, 0.8]))          # whatever came between
    again = decider.execute(b)
    assert a.action == again.action
    assert {k: v for k, v in a.search.items() if k != "seconds"} == \
        {k: v for k, v in again.search.items() if k != "seconds"}
    assert a.search["top"]["actions"][0]["action"] == a.action_name


def test_time_guard_stops_the_search_near_its_limit():
    rs = rocksample("11_11")
    planner = Despot(rs, RockSampleBounds(rs, upper="distance"), DespotSettings(trials=None, time_limit=0.05))
    result = planner.search(rs.initial_belief().sample(500, np.random.default_rng(0)), seed=0)
    assert result.stop == "time_limit"
    assert result.seconds < 0.05 + 0.04   # the guard trips between expansions


def test_a_process_clock_budget_counts_this_process_cpu_seconds():
    """``clock="process"`` (DESPOT's own code's measure): the guard and ``seconds`` read CPU time, so
    a search whose process sleeps in a bound call still runs its CPU budget (a wall clock would stop
    it after the sleep)."""
    import time as _time

    rs = rocksample("11_11")

    class SleepyBounds(RockSampleBounds):
        def many(self, groups, rng):
            _time.sleep(0.02)                       # wall time passes, CPU time does not
            return super().many(groups, rng)

    roots = rs.initial_belief().sample(500, np.random.default_rng(0))
    cpu = Despot(rs, SleepyBounds(rs), DespotSettings(trials=None, time_limit=0.1, clock="process"))
    wall = Despot(rs, SleepyBounds(rs), DespotSettings(trials=None, time_limit=0.1))
    t0 = _time.process_time()
    by_cpu = cpu.search(roots, seed=0)
    spent = _time.process_time() - t0
    by_wall = wall.search(roots, seed=0)
    assert by_cpu.stop == by_wall.stop == "time_limit"
    assert by_cpu.seconds == pytest.approx(spent, abs=0.03)
    assert by_cpu.expansions > by_wall.expansions
    with pytest.raises(ValueError, match="clock: 'cpu' is not one of wall, process"):
        DespotSettings(clock="cpu")


def test_explicit_model_samples_the_rows(tiger):
    """Inverse-CDF sampling: listening in tiger-left hears tiger-left 85 % of the time."""
    g = ExplicitModel(tiger)
    u = np.random.default_rng(0).random((20000, 2))
    nxt, obs, rew = g.step(np.zeros(20000, dtype=np.int64), 0, u)
    assert (nxt == 0).all() and (rew == -1.0).all()
    assert np.mean(obs == 0) == pytest.approx(0.85, abs=0.01)
    nxt, _, rew = g.step(np.zeros(20000, dtype=np.int64), 1, u)     # open-left with the tiger left
    assert np.mean(nxt == 0) == pytest.approx(0.5, abs=0.02) and (rew == -100.0).all()


def test_settings_reject_what_cannot_stop():
    with pytest.raises(ValueError, match="never stop"):
        DespotSettings(trials=None, time_limit=None)
    with pytest.raises(ValueError, match="xi"):
        DespotSettings(xi=0.0)


def test_policy_online_wires_the_decider_and_decision_messages_carry_the_search(tiger):
    """``policy:=online:TRIALS`` loads the online decider; /pearl/decision carries its search record,
    and ``pearl replay --explain`` prints the search's size and the top of its tree."""
    import json

    from pearl_pomdp.cli.replay import search_lines
    from pearl_pomdp.nodes.common import NodeSetupError
    from pearl_pomdp.nodes.conversions import decision_to_msg
    from pearl_pomdp.nodes.hierarchical_policy import load_decider

    decider = load_decider(tiger, None, "online:7", "")
    assert isinstance(decider, OnlineDecider) and decider.settings.trials == 7
    with pytest.raises(NodeSetupError, match="parameter policy: 'online:0'"):
        load_decider(tiger, None, "online:0", "")
    d = decider.execute(tiger.b0)
    from pearl_pomdp.nodes.conversions import msg_to_decision

    msg = decision_to_msg(0, d.action_name, d.trace, 0.01, d.expansions, search=d.search)
    assert msg.has_search and msg.search.trials == 7 and msg.search.top[0].children
    body = msg_to_decision(msg)
    json.dumps(body)   # the plain form stays JSON-ready (the live view sends it)
    search = body["search"]
    assert search["action_bounds"] == [{"action": a["action"], "lower": a["lower"], "upper": a["upper"]}
                                       for a in d.search["action_bounds"]]
    assert search["bounds"] == d.search["bounds"] and search["top"]["scenarios"] == d.search["top"]["scenarios"]
    assert search["trials"] == 7 and search["nodes"] >= 7 and search["gap"] == pytest.approx(
        search["upper"] - search["lower"])
    assert search["seconds"] > 0 and search["top"]["actions"][0]["action"] == d.action_name
    text = "\n".join(search_lines(search))
    assert "7 trials" in text and f"{d.action_name}: [" in text and "o0 " in text


def test_the_nodes_time_guard_cuts_a_search_that_its_trials_would_make_too_long(tiger):
    """``online_time_guard`` (the policy node's parameter) stops a search at its next expansion:
    a million trials on tiger end within about the guard, and the decision says why it stopped;
    0 means no guard; a negative guard is a one-line error naming the parameter."""
    import time

    from pearl_pomdp.nodes.common import NodeSetupError
    from pearl_pomdp.nodes.hierarchical_policy import HierarchicalPolicyNode, load_decider
    from pearl_pomdp.online.decider import DEFAULT_TIME_GUARD

    default = {p.name: p.default for p in HierarchicalPolicyNode.PARAMETERS}["online_time_guard"]
    assert default == DEFAULT_TIME_GUARD > 0
    guarded = load_decider(tiger, None, "online:1000000", "", time_guard=0.2)
    assert guarded.settings.time_limit == 0.2 and guarded.settings.trials == 1000000
    start = time.monotonic()
    d = guarded.execute(tiger.b0)
    assert time.monotonic() - start < 0.2 + 1.0              # the guard, plus the scenarios' draw and slack
    assert d.search["stop"] == "time_limit" and 0 < d.search["trials"] < 1000000
    assert load_decider(tiger, None, "online:7", "", time_guard=0).settings.time_limit is None
    with pytest.raises(NodeSetupError, match="parameter online_time_guard: -1.0"):
        load_decider(tiger, None, "online:7", "", time_guard=-1.0)


def test_particle_belief_follows_bayes_and_reinvigorates_when_deprived(tiger):
    """Weighted resampling tracks the exact posterior; when no particle explains the observation
    (a perfect sensor contradicting every particle) the filter reinvigorates instead of starving."""
    from pearl_pomdp.belief import BeliefFilter
    from pearl_pomdp.model.pomdp import Pomdp
    from pearl_pomdp.online.beliefs import ParticleBelief

    rng = np.random.default_rng(0)
    g = ExplicitModel(tiger)
    pf = ParticleBelief(g, np.repeat([0, 1], 2000), reinvigorate=lambda a, o, n, r: np.full(n, o))
    exact = BeliefFilter(tiger)
    b = exact.initial()
    for o in (0, 0, 1):                                      # listen: left, left, right
        pf.update(0, o, rng)
        b = exact.update(b, 0, o)
    assert np.mean(pf.particles == 0) == pytest.approx(b[0], abs=0.03)   # 0.85 after left, left, right
    assert pf.reinvigorations == 0

    eye = np.eye(2)
    sensor = Pomdp.create(["a", "b"], ["stay"], ["see-a", "see-b"], [eye], [eye], np.zeros((2, 1)), discount=0.9)
    deprived = ParticleBelief(ExplicitModel(sensor), np.zeros(100, dtype=np.int64),
                              reinvigorate=lambda a, o, n, r: np.full(n, o))
    deprived.update(0, 1, rng)                               # every particle says "a", the sensor sees "b"
    assert deprived.reinvigorations == 1
    assert (deprived.particles == 1).all() and deprived.particles.shape == (100,)


def test_random_rocksample_lays_out_as_despots_code_does():
    """DESPOT's ``InitGeneral``: the rover at (0, n//2), k rocks at distinct cells of the grid."""
    a = random_rocksample(15, 15, np.random.default_rng(4))
    b = random_rocksample(15, 15, np.random.default_rng(4))
    assert a.rocks == b.rocks and a.start == (0, 7) and len(set(a.rocks)) == 15
    assert all(0 <= x < 15 and 0 <= y < 15 for x, y in a.rocks)
    assert a.rocks != random_rocksample(15, 15, np.random.default_rng(5)).rocks
    assert a.num_states == 15 * 15 * 2 ** 15 + 1


# (action, nodes, lower, upper) of 30-trial searches, recorded with the search as it was before its
# expansion grouped every action's children in one sort and its trials backed up only the action
# they took (same tree: the full trees' states, scenarios, bounds and rewards hashed equal on these
# and on the ward, docs/online.md "Speed"). Explicit models step through _step_kernel.c; their
# bounds are _plain_bounds (this file's arithmetic, so the record does not move with the solvers').
_RECORDED = {
    ("rs7_8", 1): (6, 3041, 12.82736801302025, 26.26842381611665),
    ("rs7_8", 7): (6, 2996, 13.376687636790763, 26.462771164902048),
    ("tiger", 1): (0, 468, -9.397683822513516, 142.8045699934929),
    ("tiger", 7): (0, 450, -10.044701027751165, 142.5278970600568),
    ("reception", 1): (0, 1898, -9.353217731163186, 30.2944539178281),
    ("reception", 7): (0, 2147, -8.644312359651211, 28.93759418097821),
}


def _plain_bounds(model):
    """Bounds by a fixed number of plain sweeps: Q of 60 QMDP sweeps from 0 above, the blind policies'
    values after 60 sweeps from 0 below (not bounds of anything: only a fixed input for the record)."""
    from pearl_pomdp.model.pomdp import issparse

    T = [t.toarray() if issparse(t) else np.asarray(t, dtype=float) for t in model.T]
    R, g = np.asarray(model.R, dtype=float), float(model.discount)
    V, blind = np.zeros(R.shape[0]), np.zeros(R.shape[::-1])
    for _ in range(60):
        Q = R + g * np.stack([Ta @ V for Ta in T], axis=1)
        V = Q.max(axis=1)
        blind = np.stack([R[:, a] + g * (T[a] @ blind[a]) for a in range(len(T))])
    return AlphaBounds(Q, blind, "plain sweeps (test)")


def _recorded_case(problem, tiger):
    from pearl_pomdp.model.domain_yaml import load_domain
    from pearl_pomdp.online.beliefs import sample_belief

    if problem == "rs7_8":
        rs = rocksample("7_8")
        return rs, RockSampleBounds(rs, lower="tour"), rs.initial_belief().sample(300, np.random.default_rng(3))
    m = tiger if problem == "tiger" else load_domain("config/reception.domain.yaml").compile()
    return ExplicitModel(m), _plain_bounds(m), sample_belief(m.b0, 500, np.random.default_rng(1 if problem == "tiger" else 2))


@pytest.mark.parametrize("problem,seed", sorted(_RECORDED))
def test_the_search_builds_the_tree_it_built_before_its_bookkeeping_was_batched(problem, seed, tiger):
    model, bounds, roots = _recorded_case(problem, tiger)
    res = Despot(model, bounds, DespotSettings(trials=30)).search(roots, seed)
    action, nodes, lower, upper = _RECORDED[problem, seed]
    assert (res.action, res.nodes) == (action, nodes)
    if problem == "rs7_8":
        # The open-loop tour (lower="tour", the bound of the record) has been summed particle by particle
        # in C since the checking tours came (_step_kernel.rock_tours), not from the shares: the same
        # tree, its root's lower bound moved in the last bit.
        assert res.lower == pytest.approx(lower, rel=1e-14) and res.upper == upper
    else:
        assert res.lower == lower and res.upper == upper


def test_a_search_pauses_the_garbage_collector_and_frees_its_tree(tiger):
    """The collector is paused during a search (its tree of ~10^3 nodes would start collections in
    the middle of a decision) and restored after; the tree is freed by reference counting."""
    import gc

    from pearl_pomdp.online import despot as despot_module

    bounds = alpha_bounds(tiger)
    seen = []

    class Watching:
        description = bounds.description

        def many(self, groups, rng):
            seen.append(gc.isenabled())
            return bounds.many(groups, rng)

    planner = Despot(ExplicitModel(tiger), Watching(), DespotSettings(trials=200))
    roots = np.random.default_rng(0).integers(0, 2, 500)
    try:
        result = planner.search(roots, seed=3)
        assert gc.isenabled()
        alive = sum(isinstance(o, despot_module._Belief) for o in gc.get_objects())
        gc.disable()
        planner.search(roots, seed=3)
        assert not gc.isenabled()      # (a caller's paused collector stays paused)
    finally:
        gc.enable()
    assert result.nodes > 2000 and len(seen) > 100 and not any(seen) and alive == 0


def _simulated_tour(rs, cell, particles, visit, checking):
    """What a tour earns on each particle, stepped through ``rs.step``: visit the rocks ``visit``
    nearest first (moving along x, then y), ``Check`` each on arrival when ``checking`` and some particle
    calls it bad, ``Sample`` when the check said good (every time when not checking), then East."""
    states = particles.copy()
    total = np.zeros(states.shape[0])
    t = np.zeros(states.shape[0], dtype=np.int64)        # each particle's step: a sample takes one
    bits = particles & ((1 << rs.k) - 1)
    x, y = cell % rs.n, cell // rs.n

    def act(a, mask=None):
        nonlocal states
        nxt, obs, rew = rs.step(states, a, np.zeros((states.shape[0], 1)))
        mask = np.ones(states.shape[0], dtype=bool) if mask is None else mask
        total[mask] += rs.discount ** t[mask] * rew[mask]
        states = np.where(mask, nxt, states)
        return obs

    todo = list(visit)
    while todo:
        i = min(todo, key=lambda r: abs(rs.rocks[r][0] - x) + abs(rs.rocks[r][1] - y))
        todo.remove(i)
        rx, ry = rs.rocks[i]
        while (x, y) != (rx, ry):
            a = 2 if rx > x else 3 if rx < x else 0 if ry > y else 1
            act(a)
            t += 1
            x, y = x + (a == 2) - (a == 3), y + (a == 0) - (a == 1)
        if checking and not ((bits >> i) & 1).all():
            obs = act(5 + i)
            t += 1
            sample = obs == 0
        else:
            sample = np.ones(states.shape[0], dtype=bool)
        act(4, sample)
        t += sample
    while not rs.is_terminal(states).all():
        act(2)
        t += 1
    return total


@pytest.mark.parametrize("layout", ["7_8", "11_11"])
def test_rocksample_lower_bound_is_the_best_of_east_the_tour_and_the_checking_tours_as_simulated(layout):
    """The lower bound of a set is the best of four policies (RockSampleBounds' doc), each stepped here
    through the model on every particle: driving East, the open-loop tour of the rocks most particles
    call good, and the tours that check on arrival over the rocks some / half the particles call good.
    ``many`` gives the same numbers as ``lower`` set by set; the bound before the checking tours
    (``lower="tour"``) is the best of the first two."""
    rs = rocksample(layout)
    rng = np.random.default_rng(11)
    checking, touring = RockSampleBounds(rs), RockSampleBounds(rs, lower="tour")
    groups = []
    for size in (1, 3, 25, 200):
        cell = int(rng.integers(0, rs.n * rs.n))
        bits = rng.integers(0, 1 << rs.k, size)
        bits &= rng.integers(0, 1 << rs.k) | rng.integers(0, 1 << rs.k)     # some rocks bad in every particle
        groups.append((cell << rs.k) + bits)
    lowers, _ = checking.many(groups, rng)
    for group, lower in zip(groups, lowers):
        cell = int(group[0] >> rs.k)
        share = ((group[:, None] >> np.arange(rs.k)) & 1).mean(axis=0)
        east = _simulated_tour(rs, cell, group, [], False).mean()
        tour = _simulated_tour(rs, cell, group, np.flatnonzero(share > 0.5), False).mean()
        some = _simulated_tour(rs, cell, group, np.flatnonzero(share > 0), True).mean()
        half = _simulated_tour(rs, cell, group, np.flatnonzero(share >= 0.5), True).mean()
        assert lower == pytest.approx(max(east, tour, some, half), abs=1e-9)
        assert checking.lower(group, rng) == pytest.approx(lower, abs=1e-12)
        assert touring.lower(group, rng) == pytest.approx(max(east, tour), abs=1e-9)
    b0 = rs.initial_belief().sample(2000, np.random.default_rng(0))
    assert checking.lower(b0, rng) > touring.lower(b0, rng) + 10.0       # at the start, by far the tighter
