"""DESPOT's expansion in C (``pearl_pomdp/online/_step_kernel.c``: ``group_outcomes``, ``group_max_means``,
``rock_tours``).

* ``group_outcomes`` equals, bit for bit, the numpy grouping the search did before it: one stable
  sort of an expansion's ``[A, N]`` outcomes by (action, observation), the children in action then
  observation order with their particles in the node's order. Both of its sorts are checked (a
  counting sort over a narrow range of observations, a merge sort over a wide one, negative and
  int64-extreme observations included).
* ``group_max_means`` equals ``np.add.reduceat`` of the gathered rows over each set's size, then the
  largest column, bit for bit (the α-vector bounds DESPOT asks for at every expansion:
  ``AlphaBounds.grouped``).
* ``rock_tours`` (RockSample's tour lower bounds) is checked against tours stepped through the model
  in ``test_online.py``; here, its refusals.
* Bad input is a ValueError naming the argument.

The search built on them builds the trees it built before, to the bit of the root's bounds: the
recorded trees of ``test_online.py`` (tiger, reception, RockSample(7,8)).
"""
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pearl_pomdp.online import _step_kernel
from pearl_pomdp.online.generative import AlphaBounds


def numpy_grouping(nxt, obs, scenarios):
    """The search's grouping before the kernel: ``(states, scenarios, actions, observations, starts)``."""
    A, N = obs.shape
    keys = [(a, int(o), i) for a in range(A) for i, o in enumerate(obs[a])]
    order = sorted(range(A * N), key=lambda k: keys[k][:2])          # Python's sort is stable
    states = nxt.ravel()[order]
    scen = scenarios[[keys[k][2] for k in order]]
    pairs = [keys[k][:2] for k in order]
    firsts = [i for i in range(A * N) if i == 0 or pairs[i] != pairs[i - 1]]
    return (states, scen, np.array([pairs[i][0] for i in firsts]), np.array([pairs[i][1] for i in firsts]),
            np.array(firsts + [A * N]))


def kernel_grouping(nxt, obs, scenarios):
    A, N = obs.shape
    out = [np.empty(A * N, dtype=np.int64) for _ in range(4)] + [np.empty(A * N + 1, dtype=np.int64)]
    G = _step_kernel.group_outcomes(nxt, obs, scenarios, *out)
    states, scen, actions, observations, starts = out
    return states, scen, actions[:G], observations[:G], starts[:G + 1]


@settings(max_examples=120, deadline=None)
@given(seed=st.integers(0, 2 ** 32 - 1), A=st.integers(1, 9), N=st.integers(1, 300),
       observations=st.sampled_from(["narrow", "negative", "wide", "extreme"]))
def test_group_outcomes_equals_the_stable_sort_by_action_and_observation(seed, A, N, observations):
    rng = np.random.default_rng(seed)
    if observations == "narrow":          # counting sort
        obs = rng.integers(0, 6, (A, N))
    elif observations == "negative":
        obs = rng.integers(-40, 3, (A, N))
    elif observations == "wide":          # a span over 65,536 values: merge sort
        obs = rng.choice(np.array([-10 ** 9, 3, 7, 10 ** 9]), (A, N))
    else:
        obs = rng.choice(np.array([np.iinfo(np.int64).min, -1, 0, np.iinfo(np.int64).max]), (A, N))
    nxt = rng.integers(0, 10 ** 6, (A, N))
    scenarios = rng.permutation(3 * N)[:N].astype(np.int64)
    got = kernel_grouping(nxt, obs, scenarios)
    want = numpy_grouping(nxt, obs, scenarios)
    for name, g, w in zip(("states", "scenarios", "actions", "observations", "starts"), got, want):
        assert np.array_equal(g, w), name


def test_group_outcomes_by_hand():
    # Two actions, four particles (scenarios 10..13): action 0 sees 5, 2, 5, 2; action 1 sees 7 for all.
    nxt = np.array([[100, 101, 102, 103], [200, 201, 202, 203]])
    obs = np.array([[5, 2, 5, 2], [7, 7, 7, 7]])
    states, scen, actions, observations, starts = kernel_grouping(nxt, obs, np.arange(10, 14))
    assert states.tolist() == [101, 103, 100, 102, 200, 201, 202, 203]
    assert scen.tolist() == [11, 13, 10, 12, 10, 11, 12, 13]
    assert actions.tolist() == [0, 0, 1] and observations.tolist() == [2, 5, 7] and starts.tolist() == [0, 2, 4, 8]


def numpy_max_means(states, starts, table):
    sizes = np.diff(starts)
    return (np.add.reduceat(np.take(table, states, axis=0), starts[:-1], axis=0) / sizes[:, None]).max(axis=1)


@settings(max_examples=120, deadline=None)
@given(seed=st.integers(0, 2 ** 32 - 1), S=st.integers(1, 200), C=st.integers(1, 17),
       sizes=st.lists(st.integers(1, 700), min_size=1, max_size=12))
def test_group_max_means_equals_numpy_reduceat_bit_for_bit(seed, S, C, sizes):
    rng = np.random.default_rng(seed)
    # Magnitudes over six orders, so a different order of the additions would show in the last bits.
    table = rng.standard_normal((S, C)) * 10.0 ** rng.uniform(-3, 3, (S, 1))
    states = rng.integers(0, S, sum(sizes))
    starts = np.concatenate(([0], np.cumsum(sizes))).astype(np.int64)
    out = np.empty(len(sizes))
    _step_kernel.group_max_means(states, starts, table, out)
    assert np.array_equal(out, numpy_max_means(states, starts, table))


def test_alpha_bounds_grouped_is_each_sets_lower_and_upper():
    rng = np.random.default_rng(4)
    Q, alphas = rng.normal(size=(30, 4)), rng.normal(size=(6, 30))
    bounds = AlphaBounds(Q, alphas, "test")
    sets = [rng.integers(0, 30, n) for n in (1, 9, 130, 2)]
    starts = np.concatenate(([0], np.cumsum([len(s) for s in sets])))
    lowers, uppers = bounds.grouped(np.concatenate(sets), starts, None)
    for s, lower, upper in zip(sets, lowers, uppers):
        assert lower == pytest.approx(bounds.lower(s, None), rel=1e-12)
        assert upper == pytest.approx(bounds.upper(s), rel=1e-12)
    # By hand: Q's column means over {0, 0, 1}.
    means = (2 * Q[0] + Q[1]) / 3
    assert bounds.grouped(np.array([0, 0, 1]), np.array([0, 3]), None)[1][0] == pytest.approx(means.max())


def _grouping_args(**override):
    args = dict(next_states=np.zeros((2, 3), dtype=np.int64), observations=np.zeros((2, 3), dtype=np.int64),
                scenarios=np.arange(3), states_out=np.empty(6, dtype=np.int64), scenarios_out=np.empty(6, dtype=np.int64),
                group_action_out=np.empty(6, dtype=np.int64), group_obs_out=np.empty(6, dtype=np.int64),
                group_start_out=np.empty(7, dtype=np.int64))
    args.update(override)
    return list(args.values())


@pytest.mark.parametrize("override,msg", [
    (dict(observations=np.zeros((2, 4), dtype=np.int64)), r"observations have shape \(2, 4\), next_states \(2, 3\)"),
    (dict(observations=np.zeros((2, 3))), "observations must hold int64"),
    (dict(scenarios=np.arange(4)), "scenarios has 4 entries, expected N = 3"),
    (dict(group_start_out=np.empty(6, dtype=np.int64)), "group_start_out have .* 6 entries"),
    (dict(states_out=np.empty(6, dtype=np.int64)[::-1][::-1].reshape(2, 3)), "states_out must be 1-D"),
    (dict(next_states=np.zeros((0, 3), dtype=np.int64), observations=np.zeros((0, 3), dtype=np.int64)),
     "neither empty"),
])
def test_group_outcomes_rejects_bad_input_naming_the_argument(override, msg):
    with pytest.raises(ValueError, match=msg):
        _step_kernel.group_outcomes(*_grouping_args(**override))


@pytest.mark.parametrize("states,starts,out,msg", [
    ([0, 5], [0, 2], 1, r"states\[1\] = 5 is not a row of table \(0..3\)"),
    ([0, 1], [0, 1, 1, 2], 3, r"set 1 is empty or reversed"),
    ([0, 1], [0, 1], 1, r"starts must run from 0 to len\(states\) = 2, got 0 .. 1"),
    ([0, 1], [0, 2], 2, "out has 2 entries, starts 2: expected one fewer"),
])
def test_group_max_means_rejects_bad_input_naming_the_argument(states, starts, out, msg):
    with pytest.raises(ValueError, match=msg):
        _step_kernel.group_max_means(np.array(states, dtype=np.int64), np.array(starts, dtype=np.int64),
                                     np.zeros((4, 2)), np.empty(out))


def _rock_tour_args(**override):
    """A valid ``rock_tours`` call on RockSample(4,1)-like input (one rock at (2, 1)), then ``override``."""
    k, n = 1, 4
    args = dict(states=np.array([(5 << k) | 1, (5 << k)], dtype=np.int64), starts=np.array([0, 2], dtype=np.int64),
                k=k, n=n, rocks=np.array([[2, 1]], dtype=np.int64), visit=np.array([[0, 1]], dtype=np.int64),
                blind=np.array([[0, 0]], dtype=np.int64), powers=0.95 ** np.arange(40.0), out=np.empty(1))
    args.update(override)
    return args


def test_rock_tours_values_a_checking_tour_by_hand():
    """The rover at cell 5 = (1, 1), the rock at (2, 1): one particle has it good, one bad. The checking
    tour moves East (step 0), checks (step 1), samples the good one (+10 at step 2) and drives East
    from x = 2 (+10 at step 3 + 1 = 4 after the sample, at step 3 without); East at once: +10 at step 2."""
    args = _rock_tour_args()
    _step_kernel.rock_tours(*args.values())
    good, bad = 10 * 0.95 ** 2 + 10 * 0.95 ** 4, 10 * 0.95 ** 3
    assert args["out"][0] == pytest.approx((good + bad) / 2, abs=1e-12)
    args = _rock_tour_args(visit=np.array([[0]], dtype=np.int64), blind=np.array([[0]], dtype=np.int64))
    _step_kernel.rock_tours(*args.values())
    assert args["out"][0] == pytest.approx(10 * 0.95 ** 2, abs=1e-12)


@pytest.mark.parametrize("override,msg", [
    (dict(starts=np.array([0, 1], dtype=np.int64)), r"starts must run from 0 to len\(states\) = 2, got 0 .. 1"),
    (dict(starts=np.array([0, 2, 2], dtype=np.int64)), "out has 1 entries, visit"),
    (dict(rocks=np.array([[4, 1]], dtype=np.int64)), r"rock 0 at \(4, 1\) is off the 4 x 4 grid"),
    (dict(states=np.array([16 << 1, 0], dtype=np.int64)), "set 0's first state 32 is not on the grid"),
    (dict(powers=0.95 ** np.arange(3.0)), "powers has 3 entries, too few for set 0's tour"),
    (dict(blind=np.array([[0]], dtype=np.int64)), r"blind \(1, 1\)"),
    (dict(visit=np.array([[0, 1]], dtype=np.int32)), "visit must hold int64"),
])
def test_rock_tours_rejects_bad_input_naming_the_argument(override, msg):
    with pytest.raises(ValueError, match=msg):
        _step_kernel.rock_tours(*_rock_tour_args(**override).values())
