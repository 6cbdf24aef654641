"""The online planner's step kernel (``pearl_pomdp/online/_step_kernel.c``, ``ExplicitModel.step``).

* It equals, bit for bit, :func:`reference_step`: numpy on the definition (each row's entries
  summed left to right in float64, the first entry whose running sum exceeds ``u · mass``, the
  last entry of positive mass when rounding leaves none), on random CSR rows (short ones, and ones
  of many of the kernel's blocks) and observation rows with zero entries, entries just below zero,
  empty rows and rows without mass, int32 and int64 indices, float32 and float64 data and O,
  uniforms on the rows' exact CDF steps and next to 1.
* Its draws have the model's frequencies on a small hand-made model (zero-probability entries never drawn).
* Bad input is a ValueError naming the argument; nothing is copied from the model.

``bench/ward_decision.py --engines model,numpy`` times :func:`reference_step` against the kernel on the ward.
"""
import numpy as np
import pytest
import scipy.sparse as sp
from hypothesis import given, settings
from hypothesis import strategies as st

from pearl_pomdp.model.pomdp import Pomdp
from pearl_pomdp.online import _step_kernel
from pearl_pomdp.online.generative import ExplicitModel


def _draw_rows(P: np.ndarray, lengths: np.ndarray, u: np.ndarray) -> np.ndarray:
    """The definition's draw in each row of ``P`` ``[N, L]`` (its first ``lengths[i]`` entries; zeros
    after them): the position drawn. Raises ValueError for a row without positive finite mass."""
    N, L = P.shape
    valid = np.arange(L)[None, :] < lengths[:, None]
    c = np.cumsum(P, axis=1, dtype=np.float64)              # left to right, in float64
    mass = np.where(lengths > 0, c[np.arange(N), np.maximum(lengths, 1) - 1], 0.0)
    bad = ~((mass > 0) & np.isfinite(mass))
    if bad.any():
        raise ValueError(f"row {int(np.argmax(bad))} has no positive finite mass")
    hit = (c > (u * mass)[:, None]) & valid
    first = np.argmax(hit, axis=1)
    positive = (P > 0) & valid
    last = L - 1 - np.argmax(positive[:, ::-1], axis=1)      # the rounding residue's entry
    return np.where(hit.any(axis=1), first, last)


def reference_draws(indptr, indices, data, O, R, action, states, uniforms):
    """``(next_states, observations, rewards)`` by the definition, in numpy (the kernel's contract)."""
    s = np.asarray(states, dtype=np.int64)
    u = np.asarray(uniforms, dtype=np.float64)
    lo = np.asarray(indptr, dtype=np.int64)[s]
    lengths = np.asarray(indptr, dtype=np.int64)[s + 1] - lo
    L = max(int(lengths.max(initial=0)), 1)
    cols = lo[:, None] + np.arange(L)[None, :]
    inside = np.arange(L)[None, :] < lengths[:, None]
    P = np.where(inside, np.asarray(data)[np.where(inside, cols, 0)] if data.size else 0.0, 0.0)
    k = _draw_rows(P, lengths, u[:, 0])
    nxt = np.asarray(indices, dtype=np.int64)[lo + k]
    rows = O[action][nxt]                                     # [N, Z], float32 or float64
    obs = _draw_rows(rows, np.full(s.shape[0], rows.shape[1]), u[:, 1]).astype(np.int64)
    return nxt, obs, np.asarray(R, dtype=np.float64)[s, action].copy()


def reference_step(g: ExplicitModel, states, action: int, uniforms):
    """:meth:`ExplicitModel.step` by :func:`reference_draws` on the model's own rows (bench/ward_decision.py)."""
    indptr, indices, data = g._rows[action]
    return reference_draws(indptr, indices, data, g._O, g.R, action, states, uniforms)


def _tables(indptr, data):
    blocks = data.shape[0] // _step_kernel.BLOCK + 1
    mass, ends, peaks = np.empty(indptr.shape[0] - 1), np.empty(blocks), np.empty(blocks)
    _step_kernel.row_tables(indptr, data, mass, ends, peaks)
    return mass, ends, peaks


def _masses(indptr, data):
    return _tables(indptr, data)[0]


def _kernel(indptr, indices, data, O, R, a, s, u):
    n = s.shape[0]
    out = np.empty(n, dtype=np.int64), np.empty(n, dtype=np.int64), np.empty(n)
    _step_kernel.step(indptr, indices, data, *_tables(indptr, data), O, R, a, s, u, *out)
    return out


def _random_case(seed, index_types, data_type, o_type):
    """A random CSR T[a] per action (rows of 0-5 entries, some of probability 0, some rows without
    mass, some of subnormal mass: the rounding-residue case), O with zero entries, states in rows with
    mass, and uniforms on exact CDF steps, at 0 and next to 1."""
    rng = np.random.default_rng(seed)
    S, A, Z = int(rng.integers(1, 9)), int(rng.integers(1, 4)), int(rng.integers(1, 6))
    T = []
    for _ in range(A):
        # rows of 0-5 entries, and in half the cases some of up to 150 (several of the kernel's blocks)
        lengths = rng.integers(0, 6, S) if rng.random() < 0.5 else rng.integers(0, 150, S)
        indptr = np.concatenate(([0], np.cumsum(lengths))).astype(index_types[0])
        indices = rng.integers(0, S, int(lengths.sum())).astype(index_types[1])
        data = rng.random(int(lengths.sum())) * (rng.random(int(lengths.sum())) < 0.7)
        if rng.random() < 0.3:      # entries a little below zero, as a model within Pomdp's tolerance may hold
            data[rng.random(data.shape[0]) < 0.1] = -1e-7
        # by the largest magnitude: a row of only the small negatives must not be blown up to ±inf
        scale = rng.choice([1.0, 3e-9, 7.0, 1e-320]) / max(np.abs(data).max(initial=0), 1e-300)
        T.append((indptr, indices, (data * scale).astype(data_type)))
    O = (rng.random((A, S, Z)) * (rng.random((A, S, Z)) < 0.6)).astype(o_type)
    O[..., int(rng.integers(Z))] += o_type(0.01)          # every observation row has mass
    R = rng.normal(size=(S, A))
    return rng, S, A, Z, T, O, R


def _uniforms_on_steps(rng, rows_mass, n):
    """``n`` uniforms: random, 0, the largest double below 1, and exact steps ``c_k / M`` of the given rows."""
    u = rng.random(n)
    pick = rng.random(n)
    u[pick < 0.1] = 0.0
    u[(pick >= 0.1) & (pick < 0.2)] = np.nextafter(1.0, 0.0)
    steps = [c / m for c, m in rows_mass if m > 0]
    if steps:
        on = np.flatnonzero(pick >= 0.6)
        for i in on:
            row = steps[int(rng.integers(len(steps)))]
            u[i] = min(max(float(row[int(rng.integers(row.shape[0]))]), 0.0), np.nextafter(1.0, 0.0))
    return u


@settings(max_examples=150, deadline=None)
@given(seed=st.integers(0, 2 ** 32 - 1),
       index_types=st.sampled_from([(np.int32, np.int32), (np.int64, np.int64), (np.int32, np.int64), (np.int64, np.int32)]),
       data_type=st.sampled_from([np.float64, np.float32]), o_type=st.sampled_from([np.float64, np.float32]))
def test_kernel_equals_the_numpy_definition_bit_for_bit(seed, index_types, data_type, o_type):
    rng, S, A, Z, T, O, R = _random_case(seed, index_types, data_type, o_type)
    checked = 0
    for a, (indptr, indices, data) in enumerate(T):
        rows = [data[indptr[s]:indptr[s + 1]].astype(np.float64) for s in range(S)]
        live = [s for s in range(S) if rows[s].size and np.cumsum(rows[s])[-1] > 0]
        if not live:
            continue
        n = int(rng.integers(1, 60))
        states = rng.choice(live, n).astype(np.int64)
        u = np.column_stack([_uniforms_on_steps(rng, [(np.cumsum(r), np.cumsum(r)[-1]) for r in rows if r.size], n),
                             _uniforms_on_steps(rng, [(np.cumsum(O[a, s].astype(np.float64)),
                                                       np.cumsum(O[a, s].astype(np.float64))[-1]) for s in range(S)], n)])
        got = _kernel(indptr, indices, data, O, R, a, states, u)
        want = reference_draws(indptr, indices, data, O, R, a, states, u)
        for g_, w_ in zip(got, want):
            assert g_.dtype == w_.dtype and np.array_equal(g_, w_)
        # never an entry of probability zero
        pos = [np.flatnonzero((indices[indptr[s]:indptr[s + 1]] == t)
                              & (data[indptr[s]:indptr[s + 1]] > 0)).size for s, t in zip(states, got[0])]
        if (data >= 0).all():
            assert all(p > 0 for p in pos)
        assert (O[a, got[0], got[1]] > 0).all()
        checked += 1
    # A particle in a row without mass (no entries, or only zeros) is an error for both.
    for a, (indptr, indices, data) in enumerate(T):
        mass = _masses(indptr, data)
        dead = [s for s in range(S) if not mass[s] > 0]
        if dead:
            s = np.array([dead[0]], dtype=np.int64)
            u = np.full((1, 2), 0.5)
            with pytest.raises(ValueError, match=f"T\\[{a}\\] row {dead[0]} .* has no positive finite mass"):
                _kernel(indptr, indices, data, O, R, a, s, u)
            with pytest.raises(ValueError, match="no positive finite mass"):
                reference_draws(indptr, indices, data, O, R, a, s, u)


def test_boundaries_and_the_rounding_residue_by_hand():
    """Row [0, 0.25, 0, 0.75, 0] (columns 10..14): u·M on a step goes to the next entry, u next to 1 to the
    last entry of positive mass (column 13); zero entries are never drawn."""
    indptr = np.array([0, 5] + [5] * 14, dtype=np.int32)
    indices = np.arange(10, 15, dtype=np.int32)
    data = np.array([0.0, 0.25, 0.0, 0.75, 0.0])
    O = np.zeros((1, 15, 3))
    O[0, :, :] = [0.5, 0.0, 0.5]
    R = np.arange(15.0)[:, None]
    u = np.array([[0.0, 0.0], [0.25, 0.5], [0.2499999, 0.4999999], [np.nextafter(1.0, 0.0)] * 2, [0.9, 0.75]])
    s = np.zeros(5, dtype=np.int64)
    nxt, obs, rew = _kernel(indptr, indices, data, O, R, 0, s, u)
    assert nxt.tolist() == [11, 13, 11, 13, 13]
    assert obs.tolist() == [0, 2, 0, 2, 2]
    assert rew.tolist() == [0.0] * 5
    # The mass is the row's own running sum, so for u < 1 some c_k > u·M exists unless u·M rounds up to M,
    # which only a subnormal mass allows: row [5e-324, 0] with u = 0.7 (0.7 · 5e-324 rounds to 5e-324).
    # The residue then goes to the last entry of positive mass, never to the trailing zero.
    tiny = np.array([5e-324, 0.0])
    ptr = np.array([0, 2, 2], dtype=np.int64)
    args = (ptr, np.array([0, 1], dtype=np.int64), tiny, np.ones((1, 2, 1)), np.zeros((2, 1)), 0,
            np.zeros(1, dtype=np.int64), np.array([[0.7, 0.5]]))
    assert 0.7 * 5e-324 == 5e-324
    got, want = _kernel(*args), reference_draws(*args)
    assert got[0].tolist() == want[0].tolist() == [0]


def _hand_model(o_dtype):
    """3 states, 2 actions; T[Go][0] = [0.2, 0, 0.8] with the 0 stored; O float32 or float64."""
    T = [sp.identity(3, format="csr"),
         sp.csr_matrix((np.array([0.2, 0.0, 0.8, 1.0, 1.0]), np.array([0, 1, 2, 1, 2], dtype=np.int32),
                        np.array([0, 3, 4, 5], dtype=np.int32)), shape=(3, 3))]
    O = np.array([[[1.0, 0.0], [1.0, 0.0], [1.0, 0.0]], [[0.9, 0.1], [0.5, 0.5], [0.25, 0.75]]])
    m = Pomdp.create(["s0", "s1", "s2"], ["Stay", "Go"], ["dark", "bright"], T, O, np.array([[0.0, -1.0]] * 3),
                     sparse=True)
    m.O = m.O.astype(o_dtype)
    return m


@pytest.mark.parametrize("o_dtype", [np.float64, np.float32])
def test_draws_have_the_models_frequencies(o_dtype):
    model = _hand_model(o_dtype)
    g = ExplicitModel(model)
    assert g._O is model.O and g._rows[1][1] is model.T[1].indices and g._rows[1][2] is model.T[1].data
    n = 200_000
    u = np.random.default_rng(4).random((n, 2))
    nxt, obs, rew = g.step(np.zeros(n, dtype=np.int64), 1, u)
    assert (rew == -1.0).all()
    counts = np.zeros((3, 2))
    np.add.at(counts, (nxt, obs), 1)
    want = np.array([0.2, 0.0, 0.8])[:, None] * np.asarray(model.O[1], dtype=float)
    assert counts[1].sum() == 0                              # the stored zero is never drawn
    sigma = np.sqrt(n * want * (1 - want))
    assert (np.abs(counts - n * want) <= 5 * sigma + 1e-9).all(), (counts / n, want)
    assert np.array_equal(np.stack(g.step(np.zeros(n, dtype=np.int64), 1, u)), np.stack((nxt, obs, rew)))


def test_step_many_is_step_under_every_action():
    model = _hand_model(np.float32)
    g = ExplicitModel(model)
    s = np.array([0, 1, 2, 0, 2], dtype=np.int64)
    u = np.random.default_rng(0).random((5, 2))
    many = g.step_many(s, u)
    for a in range(2):
        for got, want in zip(many, g.step(s, a, u)):
            assert np.array_equal(got[a], want)


def test_step_actions_repeats_and_orders_rows_as_asked():
    model = _hand_model(np.float32)
    g = ExplicitModel(model)
    s = np.array([0, 1, 2, 0, 2], dtype=np.int64)
    u = np.random.default_rng(1).random((5, 2))
    got = g.step_actions(s, [1, 0, 1], u)
    for row, a in enumerate([1, 0, 1]):
        for part, want in zip(got, g.step(s, a, u)):
            assert np.array_equal(part[row], want)
    with pytest.raises(ValueError, match="action 2 is not an action index"):
        g.step_actions(s, [0, 2], u)


def _args(**override):
    args = dict(indptr=np.array([0, 1, 2], dtype=np.int32), indices=np.array([1, 0], dtype=np.int32),
                data=np.array([1.0, 1.0]), mass=np.array([1.0, 1.0]), ends=np.zeros(1), peaks=np.full(1, 1.0),
                O=np.full((1, 2, 2), 0.5), R=np.zeros((2, 1)), action=0,
                states=np.array([0, 1], dtype=np.int64), uniforms=np.full((2, 2), 0.5),
                next_out=np.empty(2, dtype=np.int64), obs_out=np.empty(2, dtype=np.int64), reward_out=np.empty(2))
    args.update(override)
    return list(args.values())


@pytest.mark.parametrize("override,msg", [
    (dict(indptr=np.array([0, 1, 2], dtype=np.uint32)), "indptr must hold int32 or int64, got format 'I'"),
    (dict(indices=np.array([1.0, 0.0])), "indices must hold int32 or int64, got format 'd'"),
    (dict(data=np.array([1, 1])), "data must hold float32 or float64"),
    (dict(O=np.full((1, 2, 2), 1, dtype=np.int64)), "O must hold float32 or float64"),
    (dict(O=np.full((2, 2), 0.5)), "O must be 3-D, got 2-D"),
    (dict(O=np.full((1, 2, 4), 0.5)[:, :, ::2]), "O must be a C-contiguous array"),
    (dict(R=np.zeros((2, 1), dtype=np.float32)), "R must hold float64"),
    (dict(R=np.zeros((2, 2))), r"R has shape \(2, 2\), expected \[S, A\] = \(2, 1\)"),
    (dict(states=np.array([0, 1], dtype=np.int32)), "states must hold int64"),
    (dict(states=np.array([0, 2], dtype=np.int64)), r"states\[1\] = 2 is not a state \(0..1\)"),
    (dict(states=np.array([-1, 0], dtype=np.int64)), r"states\[0\] = -1 is not a state"),
    (dict(action=1), r"action 1 is not in 0..0"),
    (dict(action=-1), r"action -1 is not in 0..0"),
    (dict(indptr=np.array([0, 1], dtype=np.int32)), "indptr has 2 entries, expected S \\+ 1 = 3"),
    (dict(indptr=np.array([0, 1, 5], dtype=np.int32)), r"the row of state 1, indptr\[1:1 \+ 2\] = \[1, 5\]"),
    (dict(indptr=np.array([0, 2, 1], dtype=np.int64)), r"the row of state 1"),
    (dict(indices=np.array([1, 7], dtype=np.int64)), r"indices\[1\] = 7 \(row 1\) is not a state"),
    (dict(data=np.array([1.0])), "data has 1 entries, indices 2"),
    (dict(mass=np.array([1.0, np.nan])), r"T\[0\] row 1 \(1 entries\) has no positive finite mass \(sum nan\)"),
    (dict(mass=np.array([1.0, 0.0])), r"T\[0\] row 1 \(1 entries\) has no positive finite mass \(sum 0.0\)"),
    (dict(mass=np.array([1.0])), r"mass has 1 entries, expected S = 2"),
    (dict(mass=np.array([1.0, 1.0], dtype=np.float32)), r"mass must hold float64"),
    (dict(ends=np.zeros(2)), r"ends and peaks have 2 and 1 entries, expected len\(data\) // BLOCK \+ 1 = 1"),
    (dict(peaks=np.zeros((1, 1))), r"peaks must be 1-D, got 2-D"),
    (dict(O=np.array([[[0.5, 0.5], [0.0, 0.0]]])), r"O\[0, 1, :\] \(reached from state 0\) has no positive finite mass"),
    (dict(uniforms=np.array([[0.5, 0.5], [0.5, 1.0]])), r"uniforms\[1, 1\] \(particle in state 1\) = 1.0 is not in \[0, 1\)"),
    (dict(uniforms=np.array([[np.nan, 0.5], [0.5, 0.5]])), r"uniforms\[0, 0\] .* = nan"),
    (dict(uniforms=np.full((2, 1), 0.5)), r"uniforms has shape \(2, 1\), expected \[N, >= 2\]"),
    (dict(uniforms=np.full((3, 2), 0.5)), r"uniforms has shape \(3, 2\)"),
    (dict(next_out=np.empty(1, dtype=np.int64)), "next_out, obs_out, reward_out have 1, 2, 2 entries"),
    (dict(obs_out=np.empty(2, dtype=np.int32)), "obs_out must hold int64"),
    (dict(reward_out=np.frombuffer(bytes(16))), "reward_out must be a C-contiguous, writable array"),
    (dict(states=[0, 1]), "states must be a C-contiguous array \\(got list\\)"),
])
def test_bad_input_is_a_value_error_naming_the_argument(override, msg):
    _step_kernel.step(*_args())          # (the unchanged arguments are fine)
    args = _args(**override)
    with pytest.raises(ValueError, match=msg):
        _step_kernel.step(*args)


def test_row_masses_sum_each_row_left_to_right_and_reject_a_bad_indptr():
    data = np.array([0.1, 0.2, 0.3, 1e-17, 1.0, 1e16, 1.0, -1e16], dtype=np.float64)
    indptr = np.array([0, 3, 3, 5, 8], dtype=np.int64)
    mass = _masses(indptr, data)
    want = [0.1 + 0.2 + 0.3, 0.0, 1e-17 + 1.0, 1e16 + 1.0 - 1e16]       # (the last: 0.0, not 1.0 — in order)
    assert mass.tolist() == want
    assert _masses(indptr.astype(np.int32), data.astype(np.float32)).tolist() == [
        float(np.cumsum(data.astype(np.float32)[a:b], dtype=np.float64)[-1]) if b > a else 0.0
        for a, b in zip(indptr[:-1], indptr[1:])]
    with pytest.raises(ValueError, match=r"row_tables: the row of state 2, indptr\[2:2 \+ 2\] = \[3, 9\]"):
        _masses(np.array([0, 3, 3, 9]), data)
    with pytest.raises(ValueError, match=r"row_tables: the row of state 1, indptr\[1:1 \+ 2\] = \[3, 2\]"):
        _masses(np.array([0, 3, 2, 5]), data)                   # a row may not end before it starts
    with pytest.raises(ValueError, match=r"row_tables: mass has 2 entries, indptr 4"):
        _step_kernel.row_tables(np.array([0, 3, 3, 5]), data, np.empty(2), np.empty(1), np.empty(1))
    with pytest.raises(ValueError, match=r"row_tables: ends and peaks have 2 and 1 entries"):
        _step_kernel.row_tables(np.array([0, 3, 3, 5]), data, np.empty(3), np.empty(2), np.empty(1))
    with pytest.raises(ValueError, match=r"row_tables: indptr must hold int32 or int64"):
        _step_kernel.row_tables(np.array([0.0, 3.0]), data, np.empty(1), np.empty(1), np.empty(1))


def test_row_tables_hold_each_rows_running_sums_on_the_grid():
    """ends[b] / peaks[b]: the running sum before position b·BLOCK of the row holding it / the largest
    running sum of that row over the block; a row that starts after a grid point leaves it to the row before."""
    B = _step_kernel.BLOCK
    rng = np.random.default_rng(8)
    lengths = np.array([3, 0, 2 * B + 5, 1, B, 4 * B + 1])
    indptr = np.concatenate(([0], np.cumsum(lengths)))
    data = rng.random(int(lengths.sum()))
    data[rng.random(data.shape[0]) < 0.2] = -1e-7
    mass, ends, peaks = _tables(indptr, data)
    for b in range(ends.shape[0]):
        j = b * B
        if j >= indptr[-1]:
            assert ends[b] == 0.0 and peaks[b] == -np.inf
            continue
        r = int(np.searchsorted(indptr, j, side="right")) - 1
        run = np.cumsum(data[indptr[r]:indptr[r + 1]])
        before = run[j - indptr[r] - 1] if j > indptr[r] else 0.0
        assert ends[b] == before
        assert peaks[b] == run[j - indptr[r]:min(j + B, indptr[r + 1]) - indptr[r]].max()
    assert mass.tolist() == [float(np.cumsum(data[a:b])[-1]) if b > a else 0.0 for a, b in zip(indptr[:-1], indptr[1:])]


def test_explicit_model_names_the_model_and_action_in_its_errors():
    model = _hand_model(np.float64)
    g = ExplicitModel(model)
    with pytest.raises(ValueError, match=r"step under action 'Go': _step_kernel.step: states\[0\] = 3 is not a state"):
        g.step(np.array([3]), 1, np.full((1, 2), 0.5))
    with pytest.raises(ValueError, match=r"action 2 is not an action index \(0..1\)"):
        g.step(np.array([0]), 2, np.full((1, 2), 0.5))
    with pytest.raises(ValueError, match="uniforms has shape"):
        g.step(np.array([0, 1]), 0, np.full((1, 2), 0.5))
