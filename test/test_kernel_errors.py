"""Every error path of the compiled kernels: a clear exception, and nothing left half-done.

Each call below goes through the kernel's argument checks or its cleanup after a failure
(bad shapes, non-finite values, short or read-only output buffers, a callback that raises
or returns the wrong thing, a deadline). ``.ci/sanitize-kernels`` runs this file (with
test_prune.py and the point-based kernel tests) against an AddressSanitizer +
UndefinedBehaviorSanitizer build of the kernels, where a leak of a buffer, a read past
one or a free of an uninitialised pointer on any of these paths stops the run.
"""
import numpy as np
import pytest

from pearl_pomdp.solvers import _pointbased_kernel as pbk
from pearl_pomdp.solvers import _prune
from pearl_pomdp.solvers.prune import _random_beliefs, prune


def outputs(K, S):
    return np.empty(K, dtype=np.int64), np.empty((K, S))


def call(alphas, tol=5e-7, points=None, budget=0, beliefs=_random_beliefs, deadline=0.0, kept=None, wit=None):
    alphas = np.ascontiguousarray(alphas, dtype=float)
    k, w = outputs(*alphas.shape) if alphas.ndim == 2 else outputs(1, 1)
    return _prune.prune(alphas, tol, points, budget, beliefs, deadline, k if kept is None else kept,
                        w if wit is None else wit)


@pytest.mark.parametrize("alphas,points,msg", [
    (np.zeros(3), None, "must be a 2-D array"),
    (np.zeros((2, 0)), None, "S >= 1"),
    (np.array([[0.0, np.nan], [1.0, 0.0]]), None, "alphas has a non-finite entry"),
    (np.array([[0.0, -np.inf], [1.0, 0.0]]), None, "alphas has a non-finite entry"),
    (np.eye(3), [np.ones((2, 3)) / 3], "points must be None or a tuple"),
    (np.eye(3), (np.ones((2, 2)) / 2,), "points must be \\[P, 3\\]"),
    (np.eye(3), (np.ones((1, 3)) / 3, np.array([[np.nan, 0.5, 0.5]])), "points has a non-finite entry"),
    (np.eye(3), (np.ones((1, 3)) / 3, np.ones(3)), "points must be a 2-D array"),
    (np.eye(3), (np.ones((1, 3), dtype=np.float32),), "points must hold float64"),
    (np.eye(3), (np.ones((1, 3)) / 3, "not an array"), "points must be a C-contiguous"),
])
def test_prune_rejects_bad_shapes_and_nans(alphas, points, msg):
    with pytest.raises(ValueError, match=msg):
        call(alphas, points=points)


@pytest.mark.parametrize("tol", [float("nan"), -1.0, float("inf")])
def test_prune_rejects_a_bad_tolerance(tol):
    with pytest.raises(ValueError, match="tol must be >= 0"):
        call(np.eye(3), tol=tol)


def test_prune_rejects_short_or_wrong_output_buffers():
    A = np.eye(4)
    with pytest.raises(ValueError, match="kept_out"):
        call(A, kept=np.empty(3, dtype=np.int64))
    with pytest.raises(ValueError, match="kept_out"):
        call(A, kept=np.empty(4, dtype=np.int32))
    with pytest.raises(ValueError, match="kept_out"):
        call(A, kept=np.empty(8, dtype=np.int64)[::2])  # not contiguous
    read_only = np.empty(4, dtype=np.int64)
    read_only.flags.writeable = False
    with pytest.raises(ValueError, match="kept_out"):
        call(A, kept=read_only)
    with pytest.raises(ValueError, match="witness_out must hold at least K x S"):
        call(A, wit=np.empty((3, 4)))
    with pytest.raises(ValueError, match="witness_out must be a 2-D"):
        call(A, wit=np.empty(16))
    with pytest.raises(ValueError, match="witness_out must be a C-contiguous writable"):
        call(A, wit=np.empty((4, 4)).T)
    # ... and the same arrays, right, still work (every buffer was released)
    n, *_ = call(A, points=(np.full((2, 4), 0.25),))
    assert n == 4


def many_vectors():
    """Enough candidates that the kernel asks for random beliefs (C > max(S, kept + points))."""
    rng = np.random.default_rng(1)
    v = rng.normal(size=(300, 3))
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def test_a_raising_callback_propagates_its_exception():
    def boom(seed, S, n):
        raise RuntimeError(f"random beliefs unavailable ({seed}, {S}, {n})")

    with pytest.raises(RuntimeError, match="random beliefs unavailable"):
        call(many_vectors(), budget=4_000_000, beliefs=boom)
    # a callback returning the wrong thing: a clear error, not garbage beliefs
    with pytest.raises(ValueError, match="random_beliefs returned a wrong array"):
        call(many_vectors(), budget=4_000_000, beliefs=lambda seed, S, n: np.zeros((n, S + 1)))
    with pytest.raises(ValueError, match="random_beliefs returned a wrong array"):
        call(many_vectors(), budget=4_000_000, beliefs=lambda seed, S, n: np.zeros((n, S), dtype=np.float32))
    with pytest.raises(TypeError):
        call(many_vectors(), budget=4_000_000, beliefs=lambda seed, S, n: object())
    with pytest.raises(TypeError):
        call(many_vectors(), budget=4_000_000, beliefs=None)
    # and then the real callback: the same result as the Python wrapper's
    n, *_ = call(many_vectors(), budget=4_000_000)
    assert n == len(prune(many_vectors()))


def test_a_past_deadline_is_n_minus_one_and_releases_everything():
    A = many_vectors()
    n, *_ = call(A, budget=4_000_000, deadline=1e-9, points=(np.full((5, 3), 1 / 3),))
    assert n == -1
    n, *_ = call(A, budget=4_000_000)
    assert n == len(prune(A))


def test_witness_lp_bad_input():
    lp = _prune.WitnessLP(3)
    with pytest.raises(ValueError, match="needs at least one added vector"):
        lp.solve(np.zeros(3))
    for bad in (np.zeros(2), np.array([0.0, np.nan, 1.0]), np.zeros((1, 3))):
        with pytest.raises(ValueError):
            lp.add(bad)
    lp.add(np.array([1.0, 0.0, 0.0]))
    with pytest.raises(ValueError, match="c must be 3 finite values"):
        lp.solve(np.array([np.inf, 0.0, 0.0]))
    delta, b = lp.solve(np.array([0.0, 1.0, 0.0]))
    assert delta == pytest.approx(1.0) and b[1] == pytest.approx(1.0)
    with pytest.raises(ValueError, match="num_states must be >= 1"):
        _prune.WitnessLP(0)
    with pytest.raises(TypeError):
        _prune.WitnessLP("three")


def test_point_based_kernel_short_buffers_are_value_errors():
    p = np.full(6, 0.5)
    with pytest.raises(ValueError, match="buffer X holds 40 bytes, needs 48"):
        pbk.qvalue(np.zeros(3), p, np.zeros(5), 0.95, 3, 2)
    with pytest.raises(ValueError, match="no actions"):
        pbk.qvalue(np.zeros(3), p, np.zeros(6), 0.95, 0, 2)
    assert pbk.qvalue(np.array([0.0, 1.0, 0.0]), p, np.zeros(6), 0.95, 3, 2) == (1, 1.0)
    with pytest.raises(ValueError, match="buffer jitter"):
        pbk.excess_obs(p, p, p, np.zeros(1), 2, 0.0, 2)
    with pytest.raises(ValueError, match="bad action or no observations"):
        pbk.excess_obs(p, p, p, np.zeros(2), -1, 0.0, 2)
    with pytest.raises(ValueError, match="bad vector range"):
        pbk.lower_rows(np.zeros(4), 2, np.zeros(2, dtype=np.int64), np.zeros(1, dtype=np.int64), np.zeros(8),
                       4, 2, 2, np.zeros(1), np.zeros(1, dtype=np.int64), False)
    with pytest.raises(TypeError):  # a read-only output buffer
        out = np.zeros(1)
        out.flags.writeable = False
        pbk.lower_rows(np.zeros(4), 2, np.zeros(2, dtype=np.int64), np.zeros(1, dtype=np.int64), np.zeros(8),
                       4, 0, 2, out, np.zeros(1, dtype=np.int64), False)


def resident_bytes():
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * 4096


@pytest.mark.skipif(not __import__("os").path.exists("/proc/self/statm"), reason="needs Linux's /proc")
def test_error_paths_release_what_they_took():
    """The failures that come after the kernel copied the seed points (a 4 MB block) and took the
    buffers: 40 rounds of them must not keep 40 copies (160 MB) or the arrays alive."""
    A = np.eye(50)
    points = (np.full((10_000, 50), 0.02),)

    def round_of_errors():
        for kept, wit in ((np.empty(3, dtype=np.int64), np.empty((50, 50))),
                          (np.empty(50, dtype=np.int64), np.empty((3, 50))),
                          (np.empty(50, dtype=np.int64), np.empty(10))):
            with pytest.raises(ValueError):
                _prune.prune(A, 5e-7, (points[0].copy(),), 0, _random_beliefs, 0.0, kept, wit)

    round_of_errors()  # (first-call allocations)
    before = resident_bytes()
    for _ in range(40):
        round_of_errors()
    assert resident_bytes() - before < 40 * 2**20


def test_lower_rows_reads_rows_in_blocks_and_gives_each_rows_sums_in_order_bit_for_bit():
    """lower_rows handles its rows eight at a time (each vector row read once per block; an AVX2 clone
    where the CPU has one): every v_k is still the sum of c_j GT[U[j], k] over ascending j with zero
    weights skipped, the first maximiser wins, only_better keeps the better bound; rows past a block
    boundary and a state out of range with a zero weight (never read) included."""
    from pearl_pomdp.solvers import _pointbased_kernel as pbk

    rng = np.random.default_rng(17)
    S, cap, K, nU = 30, 48, 41, 23
    GT = rng.normal(size=(S, cap))
    U = rng.choice(S, size=nU, replace=False).astype(np.int64)
    C = rng.random((21, nU)) * (rng.random((21, nU)) < 0.4)
    C[5] = 0.0
    C[:, 4] = 0.0                                                     # a state no row weighs
    rows = np.array([20, 3, 5, 0, 11, 7, 19, 2, 13, 8, 1, 17, 4], dtype=np.int64)

    def reference(r, k0):
        v = []
        for k in range(k0, K):
            total = 0.0
            for j in range(nU):
                if C[r, j] != 0.0:
                    total += C[r, j] * GT[U[j], k]
            v.append(total)
        return max(v), k0 + v.index(max(v))

    for k0, only_better in ((0, False), (9, True)):
        lb, best = np.full(21, 0.5), np.full(21, -1, dtype=np.int64)
        pbk.lower_rows(C.ravel(), nU, U, rows, GT.ravel(), cap, k0, K, lb, best, only_better)
        for r in range(21):
            if r not in rows:
                assert (lb[r], best[r]) == (0.5, -1)
                continue
            value, arg = reference(r, k0)
            if only_better and not value > 0.5:
                assert (lb[r], best[r]) == (0.5, -1)
            else:
                assert lb[r].tobytes() == np.float64(value).tobytes() and best[r] == arg
    bad = U.copy()
    bad[4] = S + 5                                                   # never read: no row weighs it
    pbk.lower_rows(C.ravel(), nU, bad, rows, GT.ravel(), cap, 0, K, np.zeros(21), np.zeros(21, dtype=np.int64), False)
    bad[np.argmax(C[rows[-1]] > 0)] = S + 5                          # one the last block's row weighs
    with pytest.raises(IndexError, match="state out of range"):
        pbk.lower_rows(C.ravel(), nU, bad, rows, GT.ravel(), cap, 0, K, np.zeros(21), np.zeros(21, dtype=np.int64),
                       False)
    with pytest.raises(IndexError, match="row out of range"):
        pbk.lower_rows(C.ravel(), nU, U, np.array([3, 21], dtype=np.int64), GT.ravel(), cap, 0, K, np.zeros(21),
                       np.zeros(21, dtype=np.int64), False)
