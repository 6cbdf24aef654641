"""pearl_pomdp.online.lasertag: LaserTag's dynamics, laser and belief against values worked by hand."""
import math

import numpy as np
import pytest

from pearl_pomdp.online.lasertag import (EAST, LAYOUT, NORTH, SAME_CELL, TAG, WEST, LaserTag, LaserTagBounds,
                                         lasertag, random_lasertag)

SIGMA = 2.5


def phi(x):
    return 0.5 * (1.0 + math.erf(x / (SIGMA * math.sqrt(2.0))))


@pytest.fixture(scope="module")
def model():
    return lasertag()


def state(m, robot, opponent):
    return m.index[robot] * m.n + m.index[opponent]


def test_the_fixed_map_is_the_draw_of_seed_8_and_connected(model):
    assert random_lasertag(np.random.default_rng(8)).obstacles == LAYOUT
    assert model.n == 77 - 8 and model.num_states == 69 * 69 + 1
    with pytest.raises(ValueError, match="distinct cells"):
        LaserTag(((0, 0), (0, 0)))


def test_the_opponent_moves_away_as_worked_by_hand(model):
    """Robot (0, 0), opponent (3, 0), level in y: away in x with 0.4, either way in y with 0.2 each
    (y − 1 is off the grid: it stays), 0.2 stay; the robot's own move does not change it."""
    m = model
    s = state(m, (0, 0), (3, 0))
    T = m.transition_matrix(NORTH)[s].toarray().ravel()
    robot = m.index[(0, 1)]
    expected = {robot * m.n + m.index[(4, 0)]: 0.4, robot * m.n + m.index[(3, 1)]: 0.2,
                robot * m.n + m.index[(3, 0)]: 0.4}
    assert {int(k): round(float(T[k]), 12) for k in np.flatnonzero(T)} == expected


def test_a_move_into_the_wall_stays_and_a_tag_ends_only_on_the_same_cell(model):
    m = model
    s = state(m, (0, 0), (0, 0))
    nxt, obs, rew = m.step(np.array([s, s]), WEST, np.full((2, m.uniforms_per_step), 0.99))
    assert rew.tolist() == [-1.0, -1.0] and (nxt // m.n == m.index[(0, 0)]).all()
    nxt, obs, rew = m.step(np.array([s]), TAG, np.full((1, m.uniforms_per_step), 0.5))
    assert nxt.tolist() == [m.terminal] and rew.tolist() == [10.0] and obs.tolist() == [SAME_CELL]
    other = state(m, (0, 0), (2, 0))
    nxt, _, rew = m.step(np.array([other]), TAG, np.full((1, m.uniforms_per_step), 0.5))
    assert rew.tolist() == [-10.0] and nxt[0] != m.terminal and nxt[0] // m.n == m.index[(0, 0)]
    assert m.step(np.array([m.terminal]), EAST, np.zeros((1, m.uniforms_per_step)))[2].tolist() == [0.0]


def test_the_laser_reads_half_normal_buckets_below_the_true_distance(model):
    """Robot (0, 0), opponent (3, 0): East the beam stops at the opponent, 3 cells: readings 0, 1, 2
    with 2(Φ(−2) − 0), 2(Φ(−1) − Φ(−2)), 2(Φ(0) − Φ(−1)); North-East a diagonal beam √2 a cell."""
    m = model
    s = state(m, (0, 0), (3, 0))
    assert m.laser_range[s, EAST] == 3.0
    expected = [2 * phi(-2.0), 2 * (phi(-1.0) - phi(-2.0)), 2 * (phi(0.0) - phi(-1.0))]
    assert m._reading_p[s, EAST, :3] == pytest.approx(expected, abs=1e-12)
    assert m._reading_p[s, EAST, 3:].sum() == 0.0 and m._reading_p[s].sum(axis=1) == pytest.approx(1.0, abs=1e-12)
    x, y, d = 0, 0, 1
    while (x + d, y + d) in m.index and (x + d, y + d) != (3, 0):
        d += 1
    assert m.laser_range[s, 4] == pytest.approx(d * math.sqrt(2.0))


def test_step_draws_what_the_likelihood_says(model):
    """20,000 draws of one step: the readings' frequencies per beam match the distribution, and every
    drawn observation has the likelihood of its beams' product at the state it was drawn in."""
    m = model
    rng = np.random.default_rng(1)
    s = state(m, (0, 0), (3, 0))
    count = 20_000
    nxt, obs, _ = m.step(np.full(count, s), EAST, rng.random((count, m.uniforms_per_step)))
    for beam in range(8):
        readings = (obs >> (7 * beam)) & 127
        for dest in np.unique(nxt)[:2]:
            seen = np.bincount(readings[nxt == dest], minlength=m._reading_p.shape[2]) / (nxt == dest).sum()
            assert np.abs(seen - m._reading_p[dest, beam]).max() < 0.03
    for o, n_ in zip(obs[:200], nxt[:200]):
        like = m.observation_likelihood(int(o))
        readings = [(int(o) >> (7 * b)) & 127 for b in range(8)]
        assert like[n_] == pytest.approx(np.prod([m._reading_p[n_, b, r] for b, r in enumerate(readings)]),
                                         rel=1e-12)
        assert like[n_] > 0


def test_the_belief_follows_bayes_rule_and_finds_the_robot(model):
    """From the uniform start, the exact belief after a step is T then the laser's likelihood; after a
    few steps of an episode the true state keeps positive mass and becomes likely."""
    m = model
    rng = np.random.default_rng(3)
    belief = m.initial_belief()
    truth = state(m, (2, 3), (8, 2))
    b0 = belief.b.copy()
    nxt, obs, _ = m.step(np.array([truth]), EAST, rng.random((1, m.uniforms_per_step)))
    belief.update(EAST, int(obs[0]))
    expected = (m.transition_matrix(EAST).T @ b0) * m.observation_likelihood(int(obs[0]))
    np.testing.assert_allclose(belief.b, expected / expected.sum(), atol=1e-15)
    current = int(nxt[0])
    for action in (NORTH, EAST, EAST, NORTH, WEST, EAST):
        nxt, obs, _ = m.step(np.array([current]), action, rng.random((1, m.uniforms_per_step)))
        belief.update(action, int(obs[0]))
        current = int(nxt[0])
        assert belief.b[current] > 0
    assert belief.b[current] > 20.0 / m.num_states     # far above the uniform start's 1/4762


def test_bounds_by_hand_and_in_order(model):
    m = model
    bounds = LaserTagBounds(m)
    g = m.discount
    s = state(m, (0, 0), (2, 0))
    manhattan = LaserTagBounds(m, upper="manhattan")
    assert manhattan.upper(np.array([s])) == pytest.approx(-(1 - g ** 2) / (1 - g) + 10 * g ** 2)
    same = state(m, (3, 3), (3, 3))
    assert bounds.upper(np.array([same])) == 10.0
    assert bounds.lower(np.array([same] * 5), np.random.default_rng(0)) == pytest.approx(10.0, abs=1e-9)  # tag at once
    rng = np.random.default_rng(2)
    particles = m.initial_belief().sample(300, rng)
    assert bounds.lower(particles, rng) <= bounds.upper(particles)


def test_despot_plans_lasertag_within_its_budget():
    """A short episode through the search with the trial budget the tests afford: legal actions,
    rewards from the model's set, the belief never empties."""
    from pearl_pomdp.online.despot import Despot, DespotSettings

    m = lasertag()
    planner = Despot(m, LaserTagBounds(m), DespotSettings(trials=20, scenarios=100))
    rng = np.random.default_rng(5)
    belief = m.initial_belief()
    current = int(belief.sample(1, rng)[0])
    for t in range(6):
        result = planner.search(belief.sample(100, np.random.default_rng([5, t])), seed=t)
        assert 0 <= result.action < 5
        nxt, obs, rew = m.step(np.array([current]), result.action, rng.random((1, m.uniforms_per_step)))
        assert rew[0] in (-1.0, -10.0, 10.0)
        if nxt[0] == m.terminal:
            break
        belief.update(result.action, int(obs[0]))
        current = int(nxt[0])


def _chase_by_hand(model, bounds, particles, plan, rng, walk_steps=0):
    """The chase simulated with ``transition`` one action at a time (the particles that take it):
    tag on "same cell", else the plan's move; then the walk's table value, or ``walk_steps`` random
    moves simulated (tag on "same cell") and −1/(1−γ) discounted past them where not tagged."""
    g = model.discount
    current = np.array(particles, dtype=np.int64)
    total = np.zeros(current.size)
    steps = list(plan) + [None] * walk_steps
    for t, move in enumerate(steps):
        wanted = np.full(current.size, move if move is not None else -1)
        if move is None:
            wanted = rng.integers(4, size=current.size)
        wanted = np.where(bounds.same[current], TAG, wanted)
        uniform = rng.random(current.size)
        for action in range(5):
            chosen = wanted == action
            if chosen.any():
                nxt, reward = model.transition(current[chosen], action, uniform[chosen])
                current[chosen] = nxt
                total[chosen] += g ** t * reward
    alive = current != model.terminal
    if walk_steps == 0:
        total += g ** len(plan) * bounds.walk_values[current]
    else:
        total += np.where(alive, -(g ** len(steps)) / (1 - g), 0.0)
    return float(total.mean())


def test_the_random_walk_and_one_states_chase_are_their_simulations(model):
    """The walk's exact value (tag on "same cell", else a random move) against 4,000 walks of 150
    steps; a state's own chase from the table against 4,000 simulations; ``lower`` of a set of one
    state is the table's; ``grouped`` gives every set what ``lower``/``upper`` give it."""
    bounds = LaserTagBounds(model, lower="chase")
    rng = np.random.default_rng(4)
    for s in (5, 4000):
        walked = _chase_by_hand(model, bounds, [s] * 4000, [], rng, walk_steps=150)
        assert walked == pytest.approx(bounds.walk_values[s], abs=0.5)
    for s in (2000, 4000):
        chased = _chase_by_hand(model, bounds, [s] * 4000, bounds._plan(s), rng)
        assert chased == pytest.approx(bounds.chase_value(s), abs=0.3)
        assert bounds.lower(np.array([s, s]), rng) == bounds.chase_value(s)
    sets = [np.array([5]), np.array([2000, 2000, 2000]), model.initial_belief().sample(50, rng), np.array([4000])]
    states = np.concatenate(sets)
    starts = np.concatenate(([0], np.cumsum([len(x) for x in sets])))
    lowers, uppers = bounds.grouped(states, starts, np.random.default_rng(9))
    assert uppers == pytest.approx([bounds.upper(x) for x in sets], abs=1e-12)
    assert lowers[[0, 1, 3]].tolist() == [bounds.chase_value(5), bounds.chase_value(2000), bounds.chase_value(4000)]
    assert lowers[2] == bounds.lower(sets[2], np.random.default_rng(9))


def test_a_step_with_an_action_per_particle_is_the_step_of_each(model):
    """The bounds simulate many plans at once with ``transition_each``: with one action for all it is
    ``transition`` bit for bit; −1 leaves a particle where it is, reward 0."""
    m = model
    rng = np.random.default_rng(6)
    states = np.concatenate([m.initial_belief().sample(400, rng), [m.terminal, state(m, (3, 3), (3, 3))]])
    uniform = rng.random(states.shape[0])
    for action in range(5):
        nxt, rew = m.transition(states, action, uniform)
        each = m.transition_each(states, np.full(states.shape[0], action), uniform)
        assert np.array_equal(each[0], nxt) and np.array_equal(each[1], rew)
    nxt, rew = m.transition_each(states, np.full(states.shape[0], -1), uniform)
    assert np.array_equal(nxt, states) and not rew.any()


def test_the_lower_bound_of_a_mixed_set_is_its_best_plan_simulated(model):
    """A set of two states, 200 particles each: its bound is the best of the two modes' chases run on
    all 400 particles (checked against each chase simulated particle by particle), below the upper."""
    bounds = LaserTagBounds(model, lower="chase")
    a, b = state(model, (0, 0), (2, 0)), state(model, (9, 5), (1, 0))
    particles = np.array([a] * 200 + [b] * 200)
    got = bounds.lower(particles, np.random.default_rng(7))
    rng = np.random.default_rng(8)
    reference = max(_chase_by_hand(model, bounds, np.repeat(particles, 10), bounds._plan(s), rng) for s in (a, b))
    assert got == pytest.approx(reference, abs=0.8)
    assert got <= bounds.upper(particles)


def test_the_mdp_upper_bound_lies_between_every_chase_and_the_manhattan_bound(model):
    """The fully observed MDP's value (it sees both cells) is at least the value of every policy of
    the laser, each state's own chase among them, and at most the Manhattan chase's (the opponent
    never comes closer); at the start belief it is lower than Manhattan's, so tighter."""
    mdp, manhattan = LaserTagBounds(model, lower="chase"), LaserTagBounds(model, upper="manhattan")
    assert (mdp.upper_values <= manhattan.upper_values + 1e-12).all()
    assert (mdp.chase_values <= mdp.upper_values + 1e-9).all()
    particles = model.initial_belief().sample(500, np.random.default_rng(1))
    assert mdp.upper(particles) < manhattan.upper(particles) - 1.0
    with pytest.raises(ValueError, match="upper bound 'sp'"):
        LaserTagBounds(model, upper="sp")
    with pytest.raises(ValueError, match="lower bound 'mode'"):
        LaserTagBounds(model, lower="mode")


def test_the_walk_lower_bound_is_each_sets_mean_walk_value_whatever_its_particles_know(model):
    """The default lower bound: per set the mean of the walk's exact values, so a set of one state
    gets the walk's value there, not the chase that walks straight to that state's opponent."""
    walk, chase = LaserTagBounds(model), LaserTagBounds(model, lower="chase")
    assert walk.walk_values == pytest.approx(chase.walk_values, abs=0.0)
    rng = np.random.default_rng(11)
    sets = [np.array([2000]), model.initial_belief().sample(60, rng), np.array([4000, 4000, 5])]
    states = np.concatenate(sets)
    starts = np.concatenate(([0], np.cumsum([len(x) for x in sets])))
    lowers, uppers = walk.grouped(states, starts, rng)
    assert lowers.tolist() == pytest.approx([walk.walk_values[x].mean() for x in sets], abs=1e-12)
    assert uppers.tolist() == pytest.approx([walk.upper(x) for x in sets], abs=1e-12)
    # One state's chase knows where its opponent is: it is worth more than the walk there.
    assert chase.chase_value(2000) > walk.lower(np.array([2000]), rng) + 1.0


def test_target_bounds_head_for_the_opponent_cells_the_planned_belief_favours(model):
    """``lower="target"``: the search tells the bounds its root particles first (``begin_search``);
    the targets are the opponent's most common cells there, and a set's bound is the best over them
    of "tag on same cell, else a shortest move towards the target, then the walk" on its particles."""
    from pearl_pomdp.online.despot import Despot, DespotSettings

    bounds = LaserTagBounds(model, lower="target")
    cells = [state(model, (0, 0), opp) for opp in [(3, 3)] * 5 + [(9, 5)] * 3 + [(1, 0)] * 2 + [(10, 6)]]
    bounds.begin_search(np.array(cells))
    assert bounds.targets == [model.index[c] for c in [(3, 3), (9, 5), (1, 0)]]
    s = state(model, (0, 0), (3, 5))
    for target in ((9, 5), (0, 6)):
        bounds.targets = [model.index[target]]
        got = bounds._toward_targets(np.array([s] * 4000), np.array([0, 4000]), np.random.default_rng(3))
        plan = bounds._path(model.index[(0, 0)], model.index[target])
        assert got[0] == pytest.approx(_chase_by_hand(model, bounds, [s] * 4000, plan, np.random.default_rng(4)), abs=0.3)
    seen = []

    class Recording(LaserTagBounds):
        def begin_search(self, root_states):
            seen.append(root_states.copy())
            super().begin_search(root_states)

    roots = model.initial_belief().sample(100, np.random.default_rng(5))
    Despot(model, Recording(model, lower="target"), DespotSettings(trials=3, scenarios=100)).search(roots, seed=1)
    assert len(seen) == 1 and np.array_equal(seen[0], roots)
