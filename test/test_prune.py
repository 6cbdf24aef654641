"""prune(): the parsimonious subset of a set of α-vectors (pointwise dominance, then LPs)."""
import numpy as np
import pytest

from pearl_pomdp.solvers.prune import DEFAULT_TOL, PruneStats, WitnessLP, pointwise_dominated, prune


def envelope(alphas, beliefs):
    return (beliefs @ np.asarray(alphas).T).max(axis=1)


def beliefs(S, n=4000, seed=0):
    rng = np.random.default_rng(seed)
    pts = rng.dirichlet(np.ones(S), n)
    return np.vstack([np.eye(S), pts])


# (alphas, expected kept indices, why)
CASES = [
    ([[1.0, 0.0], [0.0, 1.0], [0.4, 0.4]], [0, 1], "0.4,0.4 is below the envelope everywhere (max at b=.5 is .5)"),
    ([[1.0, 0.0], [0.0, 1.0], [0.6, 0.6]], [0, 1, 2], "0.6,0.6 wins around b=(.5,.5)"),
    ([[1.0, 0.0], [1.0, 0.0], [0.0, 1.0]], [0, 2], "exact duplicate: first copy kept"),
    ([[1.0, 0.0], [0.9, -1.0], [0.0, 1.0]], [0, 2], "pointwise dominated"),
    ([[1.0, 0.0], [0.0, 1.0], [0.5, 0.5]], [0, 1], "touches the envelope at one point only: no region"),
    ([[0.0, 0.0, 0.0]], [0], "a single vector is kept"),
]


@pytest.mark.parametrize("alphas,expected,why", CASES, ids=[c[2] for c in CASES])
def test_prune_hand_cases(alphas, expected, why):
    assert prune(np.array(alphas)).tolist() == expected, why


def test_tolerance_decides_small_regions():
    # The middle vector beats the two others by at most 1e-4 (at b = (.5, .5)).
    alphas = np.array([[1.0, 0.0], [0.0, 1.0], [0.5001, 0.5001]])
    assert prune(alphas, tol=1e-9).tolist() == [0, 1, 2]
    assert prune(alphas, tol=1e-3).tolist() == [0, 1]


def test_witnesses_are_where_each_kept_vector_is_best():
    rng = np.random.default_rng(3)
    alphas = rng.normal(size=(60, 4))
    kept, wit = prune(alphas, return_witnesses=True)
    assert wit.shape == (kept.size, 4)
    np.testing.assert_allclose(wit.sum(axis=1), 1.0)
    assert (wit >= 0).all()
    vals = wit @ alphas[kept].T  # [kept, kept]
    assert (np.argmax(vals, axis=1) == np.arange(kept.size)).all()


@pytest.mark.parametrize("S,K,seed", [(2, 40, 0), (3, 80, 1), (5, 150, 2), (8, 120, 3)])
def test_prune_keeps_the_value_function_and_is_minimal(S, K, seed):
    rng = np.random.default_rng(seed)
    # Vectors near a common surface, as in value iteration (many barely-useful ones).
    base = rng.normal(size=(K, S))
    alphas = base / np.linalg.norm(base, axis=1, keepdims=True)
    stats = PruneStats()
    kept = prune(alphas, tol=1e-9, stats=stats)
    B = beliefs(S, seed=seed)
    # Same value function everywhere (up to the tolerance) ...
    np.testing.assert_allclose(envelope(alphas[kept], B), envelope(alphas, B), atol=1e-8)
    # ... and every kept vector has a region of its own: removing it lowers V somewhere.
    for j in range(kept.size):
        others = np.delete(kept, j)
        lp = WitnessLP(S)
        for i in others:
            lp.add(alphas[i])
        delta, _ = lp.solve(alphas[kept[j]])
        assert delta >= 1e-9
    assert stats.lps > 0 and stats.kept == kept.size


def linprog_delta(kept, c):
    """δ* = max_b c·b − max_k α_k·b by scipy's linprog (HiGHS): the reference for the kernel's simplex."""
    from scipy.optimize import linprog

    kept = np.asarray(kept, dtype=float)
    S = kept.shape[1]
    res = linprog(np.append(-np.asarray(c, dtype=float), 1.0), A_ub=np.hstack([kept, -np.ones((len(kept), 1))]),
                  b_ub=np.zeros(len(kept)), A_eq=np.append(np.ones(S), 0.0)[None, :], b_eq=[1.0],
                  bounds=[(0.0, 1.0)] * S + [(None, None)], method="highs")
    assert res.status == 0
    return -res.fun


# (kept vectors, c, δ* by hand, an optimal b by hand or None when it is not unique)
LP_CASES = [
    ([[1.0, 0.0], [0.0, 1.0]], [0.6, 0.6], 0.1, [0.5, 0.5]),        # 0.6 − max(1−p, p), best at p = .5
    ([[1.0, 0.0], [0.0, 1.0]], [0.4, 0.4], -0.1, [0.5, 0.5]),       # below the envelope everywhere
    ([[1.0, 0.0], [0.0, 1.0]], [2.0, -1.0], 1.0, [1.0, 0.0]),       # wins most at the corner b = (1, 0)
    (np.eye(3).tolist(), [0.5, 0.5, 0.5], 0.5 - 1 / 3, [1 / 3, 1 / 3, 1 / 3]),
    ([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]], [0.0, 0.0, 0.3], 0.3, [0.0, 0.0, 1.0]),
    ([[0.0, 0.0, 0.0]], [1.0, 2.0, 3.0], 3.0, [0.0, 0.0, 1.0]),      # one kept vector: max_s c(s) − α(s)
]


@pytest.mark.parametrize("kept,c,delta,b", LP_CASES)
def test_kernel_lp_hand_cases(kept, c, delta, b):
    lp = WitnessLP(len(c))
    for k in kept:
        lp.add(np.array(k))
    d, where = lp.solve(np.array(c))
    assert d == pytest.approx(delta, abs=1e-12)
    np.testing.assert_allclose(where, b, atol=1e-12)


def test_kernel_lp_warm_starts_agree_with_linprog():
    """Objectives change and columns are added in between (the warm starts prune() uses): the
    optimum stays HiGHS's, and the returned b attains it."""
    rng = np.random.default_rng(5)
    for S in (2, 3, 5, 9):
        lp = WitnessLP(S)
        kept = [rng.normal(size=S)]
        lp.add(kept[0])
        for step in range(40):
            c = rng.normal(size=S) + 0.5
            d, b = lp.solve(c)
            assert d == pytest.approx(linprog_delta(kept, c), abs=1e-9)
            assert b.min() > -1e-12 and b.sum() == pytest.approx(1.0, abs=1e-12)
            assert c @ b - (np.array(kept) @ b).max() == pytest.approx(d, abs=1e-9)
            if step % 3 == 0:
                kept.append(rng.normal(size=S))
                lp.add(kept[-1])


def test_kernel_lp_degenerate_ties_do_not_cycle():
    """Many kept vectors through one point (all worth 1/3 at the uniform belief), duplicate
    columns, and objectives that tie with a kept vector: δ* exactly 0 or known, no cycling."""
    S = 3
    angles = np.linspace(0.0, 2 * np.pi, 13)[:-1]
    u = np.array([1.0, -1.0, 0.0]) / np.sqrt(2.0)
    v = np.array([1.0, 1.0, -2.0]) / np.sqrt(6.0)
    spokes = np.array([1 / 3 + 0.2 * (np.cos(t) * u + np.sin(t) * v) for t in angles])  # d·1 = 0: through (1/3)·1
    lp = WitnessLP(S)
    for k in np.vstack([spokes, spokes[:4], np.full((3, S), 1 / 3)]):  # duplicates and the centre, thrice
        lp.add(k)
    d, _ = lp.solve(np.full(S, 1 / 3))  # the centre: touches the envelope at one point only
    assert d == pytest.approx(0.0, abs=1e-12)
    for k in spokes:  # each kept vector against the set holding it: 0
        d, _ = lp.solve(k)
        assert d == pytest.approx(0.0, abs=1e-12)
    d, _ = lp.solve(np.full(S, 0.5))  # above everything by 1/6 at the centre, more nowhere
    assert d == pytest.approx(linprog_delta(spokes, np.full(S, 0.5)), abs=1e-12)
    assert lp.iterations < 500
    # And prune: the twelve spokes are useful, the centre (a tie at one point) and the copies are not.
    alphas = np.vstack([np.full((1, S), 1 / 3), spokes, spokes[:4]])
    assert prune(alphas).tolist() == list(range(1, 13))
    # lines through one point, two states: only the two steepest ones have a region
    t = np.linspace(-0.5, 0.5, 21)
    lines = np.stack([0.5 + t, 0.5 - t], axis=1)
    assert prune(lines).tolist() == [0, 20]


@pytest.mark.parametrize("call,msg", [
    (lambda: prune(np.array([[1.0, np.inf]])), "non-finite"),
    (lambda: prune(np.zeros((2, 2, 2))), "must be a \\[K, S\\] array"),
    (lambda: prune(np.eye(3), points=np.ones((2, 2)) / 2), "points must be \\[P, 3\\]"),
    (lambda: prune(np.eye(3), points=np.array([[np.nan, 0.5, 0.5]])), "points has a non-finite entry"),
    (lambda: prune(np.eye(3), points=np.ones(3) / 3), "points must be a 2-D array"),
    (lambda: WitnessLP(3).add(np.ones(2)), "alpha must be 3 finite values"),
    (lambda: WitnessLP(2).solve(np.ones(2)), "needs at least one added vector"),
    (lambda: WitnessLP(0), "num_states must be >= 1"),
])
def test_kernel_bad_input_is_a_clear_value_error(call, msg):
    with pytest.raises(ValueError, match=msg):
        call()


def test_kernel_rejects_wrong_buffers_directly():
    from pearl_pomdp.solvers import _prune

    A = np.eye(3)
    kept, wit = np.empty(3, dtype=np.int64), np.empty((3, 3))
    with pytest.raises(ValueError, match="float64"):
        _prune.prune(A.astype(np.float32), 1e-9, None, 0, lambda *a: None, 0.0, kept, wit)
    with pytest.raises(ValueError, match="kept_out"):
        _prune.prune(A, 1e-9, None, 0, lambda *a: None, 0.0, np.empty(2, dtype=np.int64), wit)
    with pytest.raises(ValueError, match="tol must be >= 0"):
        _prune.prune(A, float("nan"), None, 0, lambda *a: None, 0.0, kept, wit)
    n, lps, _, _, _ = _prune.prune(A, 1e-9, None, 0, lambda *a: None, 0.0, kept, wit)
    assert n == 3 and kept[:3].tolist() == [0, 1, 2] and lps == 0


def test_kernel_deadline_raises_prune_timeout():
    import time

    from pearl_pomdp.solvers.prune import PruneTimeout

    rng = np.random.default_rng(0)
    base = rng.normal(size=(400, 6))
    alphas = base / np.linalg.norm(base, axis=1, keepdims=True)
    with pytest.raises(PruneTimeout):
        prune(alphas, random_budget=0, deadline=time.perf_counter() - 1.0)


def test_kernel_deadline_holds_before_the_first_lp():
    """A large prune spends seconds before any LP (dominance, 4000 seed points against 200,000
    vectors: ~12 s here); the deadline holds there too (issue 26: it was read between LPs only).
    (3 s of slack: the sort before the first clock read takes ~1 s under AddressSanitizer.)"""
    import time

    from pearl_pomdp.solvers.prune import PruneTimeout

    rng = np.random.default_rng(0)
    alphas = rng.normal(size=(200_000, 24))
    points = rng.dirichlet(np.ones(24), 4000)
    t0 = time.perf_counter()
    with pytest.raises(PruneTimeout):
        prune(alphas, points=points, random_budget=0, deadline=t0 + 0.3)
    assert time.perf_counter() - t0 < 3.3


def test_seed_points_save_lps_without_changing_the_result():
    rng = np.random.default_rng(7)
    alphas = rng.normal(size=(200, 3))
    s0, s1 = PruneStats(), PruneStats()
    plain = prune(alphas, stats=s0)
    kept, wit = prune(alphas, return_witnesses=True)
    seeded = prune(alphas, points=wit, stats=s1)
    assert plain.tolist() == seeded.tolist() == kept.tolist()
    assert s1.lp_witnesses < s0.lp_witnesses


def test_pointwise_dominated_counts_equal_rows():
    cand = np.array([[1.0, 1.0], [2.0, 0.0], [0.5, 0.5]])
    by = np.array([[1.0, 1.0]])
    assert pointwise_dominated(cand, by).tolist() == [True, False, True]


@pytest.mark.parametrize("bad,msg", [
    (np.zeros(3), "must be a \\[K, S\\] array"),
    (np.array([[np.nan, 0.0]]), "non-finite"),
])
def test_bad_input_is_rejected_with_a_reason(bad, msg):
    with pytest.raises(ValueError, match=msg):
        prune(bad)


def test_negative_tolerance_is_rejected():
    with pytest.raises(ValueError, match="tol must be >= 0"):
        prune(np.eye(2), tol=-1.0)


def test_the_solvers_import_no_lp_solver():
    """Start-up: pruning (any number of states) never imports HiGHS or scipy.optimize: the LPs are the kernel's."""
    import subprocess
    import sys

    code = ("import sys\n"
            "import pearl_pomdp.solvers.incremental_pruning as ip\n"
            "from pearl_pomdp.solvers.prune import prune\n"
            "import numpy as np\n"
            "prune(np.random.default_rng(0).normal(size=(30, 2)))\n"
            "prune(np.random.default_rng(0).normal(size=(60, 4)))\n"
            "print(sorted(m for m in ('scipy.optimize', 'highspy') if m in sys.modules))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"


@pytest.mark.parametrize("seed", range(6))
def test_two_state_sets_with_near_ties_keep_the_envelope_and_only_useful_vectors(seed):
    """Two states, near-duplicate vectors (3e-7 apart) and rounded ones (exact ties): the kept set
    has the same envelope (to tol), every kept vector wins by ≥ tol against the other kept ones
    (checked by HiGHS), and each witness is a belief where its vector is best."""
    rng = np.random.default_rng(seed)
    base = rng.normal(size=(6, 2))
    alphas = np.vstack([rng.normal(size=(60, 2)), np.round(rng.normal(size=(40, 2)), 1),
                        base[rng.integers(0, 6, 40)] + rng.normal(scale=3e-7, size=(40, 2))])
    B = beliefs(2, seed=seed)
    for tol in (DEFAULT_TOL, 1e-9, 1e-3):
        kept, w1 = prune(alphas, tol=tol, return_witnesses=True)
        assert (envelope(alphas, B) - envelope(alphas[kept], B)).max() < tol + 1e-12
        for j in range(kept.size):
            assert linprog_delta(np.delete(alphas[kept], j, axis=0), alphas[kept[j]]) >= tol - 1e-9
        V = (w1 @ alphas.T).max(axis=1)
        assert np.all((w1 * alphas[kept]).sum(axis=1) >= V - tol)


@pytest.mark.parametrize("seed", [0, 1])
def test_near_duplicate_clusters_lose_no_useful_vector(seed):
    """Ill-conditioned warm bases: kept vectors 1e-6 apart in 8 states (as shuttle.95's epochs
    produce). Every dropped vector has δ* < tol against the kept set (checked by HiGHS), and
    every kept one is best at its witness; on shuttle.95 h10 a drifted basis once ended
    'optimal' while infeasible and dropped a vector winning by 2e-5."""
    rng = np.random.default_rng(seed)
    S, tol = 8, DEFAULT_TOL
    centres = rng.normal(size=(40, S))
    centres = 20 + 5 * centres / np.linalg.norm(centres, axis=1, keepdims=True)
    alphas = np.vstack([centres[rng.integers(0, 40, 400)] + rng.normal(scale=1e-6, size=(400, S)), centres])
    points = rng.dirichlet(np.ones(S), 30)
    stats = PruneStats()
    kept, wit = prune(alphas, tol=tol, points=points, stats=stats, return_witnesses=True)
    dropped = np.setdiff1d(np.arange(len(alphas)), kept)
    for i in dropped:
        assert linprog_delta(alphas[kept], alphas[i]) < tol + 1e-9, i
    # each kept vector is best (to tol) at its witness among all vectors
    assert np.all((wit * alphas[kept]).sum(axis=1) >= (wit @ alphas.T).max(axis=1) - tol)
    assert stats.lp_failures == 0


def test_more_states_than_vectors_on_the_large_set_path():
    # N²·S > 1e7 sends the dominance filter through its corner-based branch, which once kept
    # one entry per STATE in a buffer of one per VECTOR: with S > K it wrote past the end and
    # the heap corrupted (seen planning Pearl's eq. 15-17 hierarchy: "free(): invalid next
    # size"; .ci/sanitize-kernels reports the overflow, this test crashes or fails without the fix).
    K, S = 120, 700
    assert K * K * S > 1e7 and S > K
    alphas = np.zeros((K, S))
    alphas[np.arange(60), np.arange(60)] = 1.0         # vector i is best at corner i only
    alphas[60:] = alphas[:60] - 0.5                     # pointwise dominated copies
    kept = prune(alphas, tol=1e-9)
    assert sorted(kept.tolist()) == list(range(60))
