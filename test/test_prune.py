"""prune(): the parsimonious subset of a set of α-vectors (pointwise dominance, then LPs)."""
import numpy as np
import pytest

from pearl_pomdp.solvers.prune import DEFAULT_TOL, PruneStats, _WitnessLP, pointwise_dominated, prune


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
        lp = _WitnessLP(S)
        for i in others:
            lp.add(alphas[i])
        delta, _ = lp.solve(alphas[kept[j]])
        assert delta >= 1e-9
    assert stats.lps > 0 and stats.kept == kept.size


@pytest.mark.parametrize("S", [2, 4, 7])
def test_incremental_highs_model_agrees_with_linprog(S):
    rng = np.random.default_rng(S)
    alphas = rng.normal(size=(70, S))
    assert prune(alphas, use_lp_core=True).tolist() == prune(alphas, use_lp_core=False).tolist()
    lp_core, lp_plain = _WitnessLP(S, use_core=True), _WitnessLP(S, use_core=False)
    for a in alphas[:20]:
        lp_core.add(a)
        lp_plain.add(a)
    for c in rng.normal(size=(15, S)):
        d1, b1 = lp_core.solve(c)
        d2, b2 = lp_plain.solve(c)
        assert d1 == pytest.approx(d2, abs=1e-9)
        # the returned belief achieves the advantage
        assert c @ b1 - (alphas[:20] @ b1).max() == pytest.approx(d1, abs=1e-9)


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


def test_scipys_bundled_highs_is_the_fallback_when_highspy_is_missing(monkeypatch):
    import sys

    import pearl_pomdp.solvers.prune as prune_module

    rng = np.random.default_rng(11)
    alphas = rng.normal(size=(60, 5))
    with_highspy = prune(alphas, use_lp_core=True).tolist()
    monkeypatch.setitem(sys.modules, "highspy._core", None)  # `import highspy._core` now fails
    monkeypatch.setattr(prune_module, "_HAVE_HIGHS_CORE", None)
    monkeypatch.setattr(prune_module, "_highs_core", None)
    assert prune_module._load_highs()
    assert prune_module._highs_core.__name__.startswith("scipy.")
    assert prune(alphas, use_lp_core=True).tolist() == with_highspy


def test_the_solvers_import_no_lp_solver_until_the_first_lp():
    """Start-up: a two-state model (closed-form LPs) or `pearl --help` never pays for HiGHS/scipy.optimize."""
    import subprocess
    import sys

    code = ("import sys\n"
            "import pearl_pomdp.solvers.incremental_pruning as ip\n"
            "from pearl_pomdp.solvers.prune import prune\n"
            "import numpy as np\n"
            "prune(np.random.default_rng(0).normal(size=(30, 2)))\n"
            "print(sorted(m for m in ('scipy.optimize', 'highspy') if m in sys.modules))\n"
            "prune(np.random.default_rng(0).normal(size=(30, 3)))\n"
            "print('highspy' in sys.modules or 'scipy.optimize' in sys.modules)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.split("\n")
    assert out[0] == "[]" and out[1] == "True"


@pytest.mark.parametrize("seed", range(6))
def test_two_state_batched_filter_matches_the_lp_loop(seed):
    """Two states: the round-wise closed-form filter keeps what the one-LP-per-candidate loop keeps."""
    rng = np.random.default_rng(seed)
    base = rng.normal(size=(6, 2))
    alphas = np.vstack([rng.normal(size=(60, 2)), np.round(rng.normal(size=(40, 2)), 1),
                        base[rng.integers(0, 6, 40)] + rng.normal(scale=3e-7, size=(40, 2))])
    for tol in (DEFAULT_TOL, 1e-9, 1e-3):
        batched, w1 = prune(alphas, tol=tol, return_witnesses=True)
        looped, w2 = prune(alphas, tol=tol, return_witnesses=True, use_lp_core=False)  # linprog, one LP each
        assert batched.tolist() == looped.tolist()
        # each witness is a belief where its vector is best
        V = (w1 @ alphas.T).max(axis=1)
        assert np.all((w1 * alphas[batched]).sum(axis=1) >= V - tol)
