"""MDP value iteration, QMDP, FIB, blind bounds and the most-likely-state policy.

Values are hand-computed for tiger.95 (Kaelbling, Littman & Cassandra 1998):
in the fully observed MDP the agent always opens the safe door, so
``V(s) = 10 / (1 − 0.95) = 200``; hence ``Q(s, listen) = −1 + 0.95·200 = 189``,
``Q(tiger-left, open-right) = 10 + 190 = 200``, ``Q(tiger-left, open-left) = −100 + 190 = 90``.
"""
from pathlib import Path

import numpy as np
import pytest

from pearl_pomdp.model.pomdp import Pomdp
from pearl_pomdp.solvers import mdp

TIGER_EXACT = 19.3713683743952   # pomdp-solve 5.5.2, infinite horizon


def tiger(discount=0.95, sparse=False) -> Pomdp:
    listen = np.eye(2)
    reset = np.full((2, 2), 0.5)
    O = np.array([[[0.85, 0.15], [0.15, 0.85]], np.full((2, 2), 0.5), np.full((2, 2), 0.5)])
    R = np.array([[-1.0, -100.0, 10.0], [-1.0, 10.0, -100.0]])
    return Pomdp.create(["tiger-left", "tiger-right"], ["listen", "open-left", "open-right"],
                        ["tiger-left", "tiger-right"], [listen, reset, reset], O, R,
                        discount=discount, name="tiger", sparse=sparse)


def read(path: Path) -> Pomdp:
    from pearl_pomdp.model import pomdp_format as fmt
    return fmt.read_pomdp(path)


def test_mdp_value_iteration_tiger_hand_values():
    V, Q = mdp.mdp_value_iteration(tiger())
    np.testing.assert_allclose(V, [200.0, 200.0], atol=1e-5)
    np.testing.assert_allclose(Q, [[189.0, 90.0, 200.0], [189.0, 200.0, 90.0]], atol=1e-5)


def test_mdp_value_iteration_sparse_matches_dense():
    rng = np.random.default_rng(3)
    S, A, Z = 30, 3, 2
    T = rng.random((A, S, S)) * (rng.random((A, S, S)) < 0.1)
    T[:, np.arange(S), np.arange(S)] += 0.1
    T /= T.sum(axis=2, keepdims=True)
    O = np.full((A, S, Z), 0.5)
    R = rng.normal(size=(S, A))
    names = lambda n, k: [f"{k}{i}" for i in range(n)]
    dense = Pomdp.create(names(S, "s"), names(A, "a"), names(Z, "o"), T, O, R, discount=0.9, sparse=False)
    sparse = Pomdp.create(names(S, "s"), names(A, "a"), names(Z, "o"), T, O, R, discount=0.9, sparse=True)
    assert sparse.is_sparse
    Vd, Qd = mdp.mdp_value_iteration(dense)
    Vs, Qs = mdp.mdp_value_iteration(sparse)
    np.testing.assert_allclose(Vd, Vs, atol=1e-9)
    # The Bellman equation holds at the returned fixed point.
    resid = R + 0.9 * np.stack([T[a] @ Vd for a in range(A)], axis=1) - Qd
    assert np.abs(resid).max() < 1e-9
    assert np.abs(Qd.max(axis=1) - Vd).max() < 1e-5


def test_qmdp_tiger_is_189_at_uniform_and_bounds_exact():
    res = mdp.solve_qmdp(tiger())
    assert res.method == "qmdp"
    assert res.value_at_start == pytest.approx(189.0, abs=1e-5)
    assert res.upper_bound == pytest.approx(189.0, abs=1e-5)
    assert res.policy.num_vectors == 3
    np.testing.assert_array_equal(res.policy.actions, [0, 1, 2])
    # At a confident belief QMDP opens the safe door.
    assert res.policy.action(np.array([0.99, 0.01])) == 2


def test_fib_is_between_exact_and_qmdp_on_tiger():
    m = tiger()
    q = mdp.solve_qmdp(m).value_at_start
    f = mdp.solve_fib(m)
    assert f.converged
    assert TIGER_EXACT - 1e-6 <= f.value_at_start < q - 1.0
    # FIB's Q is pointwise below QMDP's.
    _, Qm = mdp.mdp_value_iteration(m)
    assert (f.policy.alphas.T <= Qm + 1e-9).all()


def test_blind_policies_tiger_hand_values():
    # always listen: −1/(1−γ) = −20; always open-left: the tiger is reset uniformly after
    # each opening, so the mean m = −45 + 0.95 m = −900, α = (−100 + 0.95 m, 10 + 0.95 m).
    alphas = mdp.blind_lower_bound(tiger())
    np.testing.assert_allclose(alphas[0], [-20.0, -20.0], atol=1e-4)
    np.testing.assert_allclose(alphas[1], [-955.0, -845.0], atol=1e-4)
    np.testing.assert_allclose(alphas[2], [-845.0, -955.0], atol=1e-4)
    assert (alphas @ np.array([0.5, 0.5])).max() <= TIGER_EXACT


def test_bounds_order_on_benchmarks(benchmarks_dir):
    # QMDP ≥ FIB ≥ optimal ≥ blind at b0; optimal values from pomdp-solve 5.5.2.
    for name, exact in [("cheese.95.POMDP", 3.486206824), ("parr95.95.POMDP", 7.201039921),
                        ("1d.POMDP", 1.260343623), ("tiger.95.POMDP", TIGER_EXACT)]:
        m = read(benchmarks_dir / name)
        q = mdp.solve_qmdp(m).value_at_start
        f = mdp.solve_fib(m).value_at_start
        blind = (mdp.blind_lower_bound(m) @ m.b0).max()
        assert q >= f - 1e-9 >= exact - 1e-6 >= blind - 1e-6, name


def test_most_likely_state_policy_hand_model():
    # Three states that never change; action a pays 1 only in state a, so the MDP action in
    # state s is s and MLS answers the belief's argmax.
    S = 3
    T = [np.eye(S)] * S
    O = np.full((S, S, 1), 1.0)
    R = np.eye(S)
    m = Pomdp.create(["s0", "s1", "s2"], ["a0", "a1", "a2"], ["o"], T, O, R, discount=0.9)
    pol = mdp.most_likely_state_policy(m)
    np.testing.assert_array_equal(pol.state_actions, [0, 1, 2])
    assert pol.action(np.array([0.2, 0.5, 0.3])) == 1
    assert pol.action(np.array([0.1, 0.2, 0.7])) == 2
    assert pol.action(np.array([0.4, 0.4, 0.2])) == 0      # tie → lowest state index
    with pytest.raises(ValueError):
        pol.action(np.array([0.5, 0.5]))


def test_most_likely_state_policy_tiger():
    pol = mdp.most_likely_state_policy(tiger())
    # The MDP opens the door away from the tiger; listening is never MDP-optimal.
    np.testing.assert_array_equal(pol.state_actions, [2, 1])
    assert pol.action(np.array([0.8, 0.2])) == 2
    assert pol.action(np.array([0.3, 0.7])) == 1


def test_blind_rejects_undiscounted():
    with pytest.raises(ValueError):
        mdp.blind_lower_bound(tiger(discount=1.0))


def random_sparse_model(S=3000, A=4, discount=0.97, seed=5):
    """A sparse MDP large enough for the Krylov path (each row: 3 random successors)."""
    import scipy.sparse as sp

    rng = np.random.default_rng(seed)
    T = []
    for _ in range(A):
        cols = rng.integers(0, S, size=(S, 3))
        vals = rng.random((S, 3)) + 0.05
        vals /= vals.sum(axis=1, keepdims=True)
        T.append(sp.csr_matrix((vals.ravel(), cols.ravel(), np.arange(0, 3 * S + 1, 3)), shape=(S, S)))
    R = rng.normal(size=(S, A))
    names = lambda n, k: [f"{k}{i}" for i in range(n)]
    model = Pomdp.create(names(S, "s"), names(A, "a"), ["o"], T, np.ones((A, S, 1)), R, discount=discount, sparse=True)
    return model, T, R


def _value_iteration_reference(T, R, g, sweeps):
    """Plain value iteration, written out here: the independent number the solver must meet."""
    V = np.zeros(R.shape[0])
    for _ in range(sweeps):
        V = np.max(R + g * np.stack([Ta @ V for Ta in T], axis=1), axis=1)
    return V


def _assert_certificates_hold(T, R, g, V, alphas):
    """``HV <= V`` and ``R_a + γ T_a α_a >= α_a``, as the floating-point comparisons a user would write:
    then V is an upper bound and each α_a a lower bound whatever the solver did."""
    assert (np.max(R + g * np.stack([Ta @ V for Ta in T], axis=1), axis=1) <= V).all()
    for a, Ta in enumerate(T):
        assert (R[:, a] + g * (Ta @ alphas[a]) >= alphas[a]).all()


def test_mdp_values_on_a_sparse_model_match_plain_value_iteration_and_are_certified():
    model, T, R = random_sparse_model()
    g = model.discount
    V, Q = mdp.mdp_value_iteration(model)
    # 1500 sweeps at γ = 0.97 leave an error below 0.97**1500 · 1e3 ≈ 1e-17: exact to rounding.
    reference = _value_iteration_reference(T, R, g, 1500)
    assert np.abs(V - reference).max() < 1e-6
    assert (Q.max(axis=1) <= V).all()
    alphas = mdp.blind_lower_bound(model)
    _assert_certificates_hold(T, R, g, V, alphas)
    for a, Ta in enumerate(T):
        assert np.abs(alphas[a] - _value_iteration_reference([Ta], R[:, [a]], g, 1500)).max() < 1e-6


def test_bounds_stay_valid_when_the_linear_solver_is_wrong(monkeypatch):
    # A solver that returns its answer off by up to ±5: the certificate must move V up (and the
    # blind vectors down) far enough that they are still bounds of the true values.
    model, T, R = random_sparse_model(S=800, seed=9)
    g = model.discount
    exact_V = _value_iteration_reference(T, R, g, 1500)
    true_evaluate = mdp._evaluate
    rng = np.random.default_rng(0)

    def sloppy(P, r, g_, v0, tol, max_iterations):
        v = true_evaluate(P, r, g_, v0, tol, max_iterations)
        return v + rng.uniform(-5, 5, size=v.shape)

    monkeypatch.setattr(mdp, "_evaluate", sloppy)
    V, _ = mdp.mdp_value_iteration(model)
    assert (V >= exact_V - 1e-9).all()
    alphas = mdp.blind_lower_bound(model)
    for a, Ta in enumerate(T):
        assert (alphas[a] <= _value_iteration_reference([Ta], R[:, [a]], g, 1500) + 1e-9).all()


def test_stalled_krylov_falls_back_to_sweeps(monkeypatch):
    # One Krylov iteration cannot reach the tolerance: the sweeps must finish the job.
    monkeypatch.setattr(mdp, "_KRYLOV_MAX_ITERATIONS", 1)
    model, T, R = random_sparse_model(S=1000, seed=2)
    V, _ = mdp.mdp_value_iteration(model)
    assert np.abs(V - _value_iteration_reference(T, R, model.discount, 1500)).max() < 1e-6


@pytest.mark.parametrize("seed", range(8))
def test_certificates_hold_exactly_in_floating_point(seed):
    # The shift δ/(1-γ) leaves the worst state's inequality an equality in exact arithmetic; its
    # recomputation can round ~1e-16 the wrong way (the sparse test model, seed 5 at S=3000, did
    # under numpy 2.4.6 / scipy 1.17.1).
    model, T, R = random_sparse_model(S=400, seed=seed)
    V, _ = mdp.mdp_value_iteration(model)
    _assert_certificates_hold(T, R, model.discount, V, mdp.blind_lower_bound(model))
