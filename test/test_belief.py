"""The Bayes filter (eq. 5) against hand-computed posteriors."""
import logging

import numpy as np
import pytest
import scipy.sparse as sp
from hypothesis import given, settings, strategies as st

from pearl_pomdp.belief import BeliefFilter, update_belief
from pearl_pomdp.errors import BeliefError
from pearl_pomdp.model.pomdp import Pomdp


def tiger(accuracy=0.85) -> Pomdp:
    """tiger.95 written out by hand (same numbers as test/data/pomdp/tiger.95.POMDP)."""
    listen_T = np.eye(2)
    reset_T = np.full((2, 2), 0.5)
    O = np.array([
        [[accuracy, 1 - accuracy], [1 - accuracy, accuracy]],  # listen
        [[0.5, 0.5], [0.5, 0.5]],                              # open-left
        [[0.5, 0.5], [0.5, 0.5]],                              # open-right
    ])
    R = np.array([[-1.0, -100.0, 10.0], [-1.0, 10.0, -100.0]])
    return Pomdp.create(["tiger-left", "tiger-right"], ["listen", "open-left", "open-right"],
                        ["tiger-left", "tiger-right"], [listen_T, reset_T, reset_T], O, R,
                        b0=[0.5, 0.5], discount=0.95, name="tiger.95")


def three_state(sparse=False) -> Pomdp:
    T = np.array([[0.7, 0.2, 0.1], [0.0, 0.6, 0.4], [0.3, 0.0, 0.7]])
    O = np.array([[[0.9, 0.1], [0.5, 0.5], [0.2, 0.8]]])
    return Pomdp.create(["s0", "s1", "s2"], ["go"], ["o0", "o1"], [T], O, np.zeros((3, 1)),
                        b0=[0.5, 0.3, 0.2], name="three", sparse=sparse)


def test_tiger_listen_twice_hear_left():
    f = BeliefFilter(tiger())
    b = f.initial()
    for _ in range(2):
        b = f.update(b, "listen", "tiger-left")
    # By hand: one "left" gives .85; two give .85² / (.85² + .15²) = .7225 / .745.
    expected = 0.85 ** 2 / (0.85 ** 2 + 0.15 ** 2)
    assert round(b[0], 4) == 0.9698
    assert b[0] == pytest.approx(expected, abs=1e-15)
    assert b.sum() == pytest.approx(1.0, abs=1e-15)
    assert f.updates == 2 and f.zero_likelihood_count == 0


def test_tiger_file_listen_twice(benchmarks_dir):
    """The same number on the benchmark file itself, read by our .pomdp reader."""
    from pearl_pomdp.model import pomdp_format
    model = pomdp_format.read_pomdp(benchmarks_dir / "tiger.95.POMDP")
    f = BeliefFilter(model)
    listen, left = model.index("actions", "listen"), model.index("observations", "tiger-left")
    b = f.update(f.update(f.initial(), listen, left), listen, left)
    assert round(b[model.index("states", "tiger-left")], 4) == 0.9698


def test_tiger_open_resets_to_uniform():
    f = BeliefFilter(tiger())
    b = f.update(np.array([0.97, 0.03]), 1, 0)
    np.testing.assert_allclose(b, [0.5, 0.5], atol=1e-15)


@pytest.mark.parametrize("sparse", [False, True])
def test_three_state_hand_computed(sparse):
    f = BeliefFilter(three_state(sparse))
    b = np.array([0.5, 0.3, 0.2])
    # p = bT = [.41, .28, .31]
    np.testing.assert_allclose(f.predict(b, 0), [0.41, 0.28, 0.31], atol=1e-15)
    np.testing.assert_allclose(f.observation_likelihood(b, 0), [0.571, 0.429], atol=1e-15)
    # o0: [.9·.41, .5·.28, .2·.31] = [.369, .14, .062] / .571
    np.testing.assert_allclose(f.update(b, 0, 0), np.array([369, 140, 62]) / 571, atol=1e-15)
    # o1: [.1·.41, .5·.28, .8·.31] = [.041, .14, .248] / .429
    np.testing.assert_allclose(f.update(b, "go", "o1"), np.array([41, 140, 248]) / 429, atol=1e-15)
    np.testing.assert_array_equal(b, [0.5, 0.3, 0.2])  # input untouched


def naive_update(T, O, b, a, o):
    S = len(b)
    out = np.zeros(S)
    for s2 in range(S):
        out[s2] = O[a, s2, o] * sum(T[a][s, s2] * b[s] for s in range(S))
    return out / out.sum()


@pytest.mark.parametrize("fused", [True, False])
def test_large_sparse_model_matches_naive_loop(fused, monkeypatch):
    """S ≥ 64 takes the CSR path (with and without the fused diag(O)·Tᵀ operators); it must
    agree with eq. 5 written as loops."""
    if not fused:
        monkeypatch.setattr("pearl_pomdp.belief.FUSED_LIMIT", 0)
    rng = np.random.default_rng(3)
    S, A, Z = 80, 3, 4
    T = []
    for _ in range(A):
        m = sp.random(S, S, density=0.05, random_state=rng).toarray() + np.eye(S)
        T.append(m / m.sum(axis=1, keepdims=True))
    O = rng.dirichlet(np.ones(Z), size=(A, S))
    model = Pomdp.create([f"s{i}" for i in range(S)], ["a", "b", "c"], list("wxyz"), T, O,
                         np.zeros((S, A)), sparse=True)
    f = BeliefFilter(model)
    assert sp.issparse(f._TT[0]) and f._fused_ok == fused
    b = rng.dirichlet(np.ones(S))
    for a in range(A):
        for o in range(Z):
            np.testing.assert_allclose(f.update(b, a, o), naive_update(T, O, b, a, o), rtol=1e-12, atol=1e-15)
    B = rng.dirichlet(np.ones(S), size=6)
    acts, obs = np.array([0, 1, 2, 0, 1, 2]), np.array([0, 1, 2, 3, 3, 0])
    batch = f.update_batch(B, acts, obs)
    for i in range(6):
        np.testing.assert_allclose(batch[i], naive_update(T, O, B[i], acts[i], obs[i]), rtol=1e-12, atol=1e-15)


@pytest.mark.parametrize("sparse", [False, True])
def test_a_batch_of_one_action_gives_the_rows_a_mixed_batch_gives_them(sparse):
    """update_batch takes a batch whose rows share one action in one product and normalises in place:
    each row is the bits the same row gets in a batch of several actions (computed per action group),
    for C- and Fortran-ordered input alike, and the input beliefs are left as they were."""
    rng = np.random.default_rng(11)
    S, A, Z = 40, 2, 3
    T = [m / m.sum(axis=1, keepdims=True) for m in rng.random((A, S, S)) * (rng.random((A, S, S)) < 0.2) + np.eye(S)]
    O = rng.dirichlet(np.ones(Z), size=(A, S))
    f = BeliefFilter(Pomdp.create([f"s{i}" for i in range(S)], ["a", "b"], list("xyz"), T, O, np.zeros((S, A)),
                                  sparse=sparse))
    B = rng.dirichlet(np.ones(S), size=5) * (rng.random((5, S)) < 0.5)
    B /= B.sum(axis=1, keepdims=True)
    kept = B.copy()
    observations = np.array([0, 1, 2, 0, 1])
    one_action = f.update_batch(B, np.zeros(5, dtype=int), observations)
    mixed = f.update_batch(np.vstack([B, B]), np.r_[np.zeros(5, dtype=int), np.ones(5, dtype=int)],
                           np.r_[observations, observations])
    assert one_action.tobytes() == mixed[:5].tobytes()
    assert f.update_batch(np.asfortranarray(B), np.zeros(5, dtype=int), observations).tobytes() == one_action.tobytes()
    assert B.tobytes() == kept.tobytes()
    for i in range(5):
        np.testing.assert_allclose(one_action[i], naive_update(T, O, B[i], 0, observations[i]), rtol=1e-12, atol=1e-15)


def test_the_filters_of_one_model_share_its_operators_until_it_gets_new_arrays():
    """A study builds a tracker, so a filter, per episode: the next filter on the same model reuses the
    operators the first built (Pearl's 380 fused ones: ~60 ms), with counters of its own; another model,
    or this one given a new O, gets operators built from its own arrays."""
    rng = np.random.default_rng(8)
    S, A, Z = 70, 2, 3
    T = [sp.random(S, S, density=0.05, random_state=rng).toarray() + np.eye(S) for _ in range(A)]
    T = [m / m.sum(axis=1, keepdims=True) for m in T]
    O = rng.dirichlet(np.ones(Z), size=(A, S))
    model = Pomdp.create([f"s{i}" for i in range(S)], ["a", "b"], ["x", "y", "z"], T, O, np.zeros((S, A)))
    first, second = BeliefFilter(model), BeliefFilter(model)
    assert first._M is not None and second._M is first._M and second._TT is first._TT
    b = first.update(model.b0, 1, 2)
    assert (first.updates, second.updates) == (1, 0)
    assert BeliefFilter(Pomdp.create(model.states, model.actions, model.observations, T, O,
                                     np.zeros((S, A))))._TT is not first._TT
    O2 = O.copy()
    O2[1, :, [0, 2]] = O2[1, :, [2, 0]]
    model.O = O2
    third = BeliefFilter(model)
    assert third._M is not first._M
    np.testing.assert_allclose(third.update(model.b0, 1, 2), naive_update(T, O2, model.b0, 1, 2), rtol=1e-12)
    assert not np.allclose(third.update(model.b0, 1, 2), b)


def test_zero_likelihood_recovers_and_counts(caplog):
    # "beep" is only ever heard in s2; the belief says we are surely in s0 and stay there.
    O = np.array([[[1.0, 0.0], [1.0, 0.0], [0.5, 0.5]], [[1.0, 0.0]] * 3])
    model = Pomdp.create(["s0", "s1", "s2"], ["stay", "mute"], ["quiet", "beep"], [np.eye(3), np.eye(3)], O,
                         np.zeros((3, 2)), b0=[1.0, 0.0, 0.0])
    f = BeliefFilter(model)
    with caplog.at_level(logging.WARNING, logger="pearl_pomdp.belief"):
        b = f.update(f.initial(), "stay", "beep")
    assert np.isfinite(b).all() and b.sum() == pytest.approx(1.0)
    # The uniform floor lets the observation decide: only s2 can beep.
    np.testing.assert_allclose(b, [0.0, 0.0, 1.0], atol=1e-12)
    assert f.zero_likelihood_count == 1
    assert "zero likelihood" in caplog.text and "'beep'" in caplog.text
    # "beep" can never follow "mute": the observation is ignored, the floored prediction kept.
    b2 = f.update(np.array([1.0, 0.0, 0.0]), "mute", "beep")
    assert f.zero_likelihood_count == 2
    eps = f.floor
    np.testing.assert_allclose(b2, [1 - eps + eps / 3, eps / 3, eps / 3], rtol=1e-12)
    # Batch updates recover the same way.
    batch = f.update_batch(np.array([[1.0, 0, 0], [0, 0, 1.0]]), [0, 0], [1, 1])
    np.testing.assert_allclose(batch, [[0, 0, 1.0], [0, 0, 1.0]], atol=1e-12)
    assert f.zero_likelihood_count == 3


@pytest.mark.parametrize("belief, action, obs, message", [
    ([0.5, 0.3], 0, 0, r"shape \(2,\), expected \(3,\)"),
    ([0.6, -0.1, 0.5], 0, 0, r"negative entry -0.1 at state 1 \('s1'\)"),
    ([0.5, 0.3, 0.1], 0, 0, r"sums to 0.9, expected 1"),
    ([np.nan, 0.5, 0.5], 0, 0, r"non-finite entry at state 0"),
    ([0.5, 0.3, 0.2], 1, 0, r"action index 1 is out of range: the model has 1 actions"),
    ([0.5, 0.3, 0.2], 0, 2, r"observation index 2 is out of range: the model has 2 observations"),
    ([0.5, 0.3, 0.2], 0, "o9", r"unknown observation 'o9'; known: o0, o1"),
    ([0.5, 0.3, 0.2], 0.0, 0, r"action must be an int index or a name, got 0.0"),
    ([0.5, 0.3, 0.2], True, 0, r"action must be an int index or a name"),
])
def test_bad_input_raises_belief_error(belief, action, obs, message):
    f = BeliefFilter(three_state())
    with pytest.raises(BeliefError, match=message):
        f.update(belief, action, obs)


def test_update_belief_function():
    np.testing.assert_allclose(update_belief(tiger(), [0.5, 0.5], 0, 1), [0.15, 0.85], atol=1e-15)


@st.composite
def model_and_belief(draw):
    seed = draw(st.integers(0, 2**32 - 1))
    S, A, Z = draw(st.integers(1, 6)), draw(st.integers(1, 3)), draw(st.integers(1, 4))
    rng = np.random.default_rng(seed)

    def rows(shape, k):
        x = rng.random(shape + (k,)) * (rng.random(shape + (k,)) < 0.6)  # some exact zeros
        x[..., 0] += (x.sum(axis=-1) == 0)
        return x / x.sum(axis=-1, keepdims=True)

    T = rows((A, S), S)
    O = rows((A, S), Z)
    model = Pomdp.create([f"s{i}" for i in range(S)], [f"a{i}" for i in range(A)], [f"o{i}" for i in range(Z)],
                         list(T), O, np.zeros((S, A)))
    b = rows((), S)
    return model, b, int(rng.integers(A)), int(rng.integers(Z))


@settings(max_examples=200, deadline=None)
@given(model_and_belief())
def test_update_is_a_distribution(case):
    model, b, a, o = case
    f = BeliefFilter(model)
    out = f.update(b, a, o)
    assert out.shape == b.shape
    assert (out >= 0).all() and np.isfinite(out).all()
    assert out.sum() == pytest.approx(1.0, abs=1e-12)
    likelihood = f.observation_likelihood(b, a)
    assert likelihood.sum() == pytest.approx(1.0, abs=1e-12)
    if likelihood[o] > 0:
        T = [np.asarray(t) for t in model.T]
        np.testing.assert_allclose(out, naive_update(T, model.O, b, a, o), rtol=1e-9, atol=1e-12)
        assert f.zero_likelihood_count == 0
    else:
        assert f.zero_likelihood_count == 1
