"""MDP-based bounds and baseline policies for a POMDP.

* **MDP value iteration** on the underlying fully observed MDP.
* **QMDP** (Littman, Cassandra & Kaelbling 1995): the MDP Q-functions used as
  α-vectors, ``V_QMDP(b) = max_a b·Q(:, a)`` — an upper bound on the POMDP value.
* **FIB**, the fast informed bound (Hauskrecht 2000, "Value-function
  approximations for partially observable Markov decision processes", JAIR 13):
  ``Q(s,a) = R(s,a) + γ Σ_o max_a' Σ_s' T[a][s,s'] O[a,s',o] Q(s',a')``, an upper
  bound that is never looser than QMDP.
* **Blind policies** ("always do a"), ``α_a = R(:,a) + γ T[a] α_a``: each is the
  exact value of a policy, so ``max_a b·α_a`` is a lower bound.
* **Most-likely-state** policy: the MDP action of the most probable state.

Array conventions (docs/design.md §2): ``T[a][s, s'] = P(s'|s,a)`` (dense or scipy
sparse CSR), ``O[a, s', o] = P(o|s',a)``, ``R[s, a]``, ``b0[s]``.

The MDP values and blind values are solved as linear systems (policy iteration) and then
*certified*: shifted by their Bellman residual over ``1-γ`` so that the operator's inequality
holds exactly, which makes them valid bounds whatever the linear solver's error. FIB iterates
from such a certified QMDP and is monotone, so every FIB iterate is a valid bound.
"""
from __future__ import annotations

import time
from typing import List, Tuple

import numpy as np

from ..model.pomdp import Pomdp
from ..policies.most_likely_state import MostLikelyStatePolicy
from ..solution import AlphaVectorPolicy, SolveResult

__all__ = [
    "mdp_value_iteration",
    "solve_qmdp",
    "solve_fib",
    "fib_q",
    "blind_lower_bound",
    "most_likely_state_policy",
]

#: Matrices sparser than this are kept (or made) CSR for the Bellman products ...
_SPARSE_DENSITY = 0.25
#: ... when they have more rows than this (a small dense product is cheaper than importing scipy).
_SPARSE_MIN_STATES = 64


def _transition_mats(model: Pomdp) -> List:
    """``T[a]`` as CSR when sparse enough (FIB on TagAvoid is ~100× faster that way), else dense."""
    mats = []
    for Ta in model.T:
        if hasattr(Ta, "tocsr"):  # scipy.sparse (then already imported by whoever built it)
            mats.append(Ta.tocsr())
            continue
        nnz = np.count_nonzero(Ta)
        if nnz < _SPARSE_DENSITY * Ta.size and Ta.shape[0] > _SPARSE_MIN_STATES:
            import scipy.sparse as sp  # not for small dense models: its import costs more than their solve

            mats.append(sp.csr_matrix(Ta))
        else:
            mats.append(np.asarray(Ta))
    return mats


#: Krylov iterations one policy evaluation may take before it falls back to plain sweeps. On the
#: ward's 233,280 states BiCGSTAB needs 7 for ``(I - γ T_a) v = R_a``; a chain on which it stalls
#: (nearly periodic, γ close to 1) is left to the sweeps, which always converge for γ < 1.
_KRYLOV_MAX_ITERATIONS = 200
#: Policy improvements before policy iteration hands over to value iteration. Howard's iteration
#: takes a handful (the ward and Pearl: 6 evaluations; the test files: at most 19, RockSample(7,8));
#: only a linear solver too inexact to rank the actions keeps it switching.
_MAX_POLICY_IMPROVEMENTS = 50
#: Models up to this many states solve a policy's linear system densely (LAPACK, exact).
_DENSE_SOLVE_STATES = 500


def _policy_matrix(mats: List, actions: np.ndarray):
    """The transition matrix of the stationary policy ``s -> actions[s]``: row ``s`` of ``T[actions[s]]``."""
    S = actions.shape[0]
    rows = [np.flatnonzero(actions == a) for a in range(len(mats))]
    if not hasattr(mats[0], "tocsr"):
        P = np.empty((S, S))
        for a, r in enumerate(rows):
            P[r] = mats[a][r]
        return P
    import scipy.sparse as sp

    blocks = [mats[a][r] for a, r in enumerate(rows) if r.shape[0]]
    order = np.concatenate([r for r in rows if r.shape[0]])
    stacked = sp.vstack(blocks, format="csr")
    inverse = np.empty(S, dtype=np.int64)
    inverse[order] = np.arange(S)
    return stacked[inverse]


def _sweep_to(P, r: np.ndarray, g: float, v: np.ndarray, tol: float, max_iterations: int) -> np.ndarray:
    """Plain fixed-point sweeps ``v <- r + γ P v`` until successive iterates differ by ``tol``."""
    for _ in range(max_iterations):
        vn = r + g * (P @ v)
        done = float(np.max(np.abs(vn - v))) <= tol
        v = vn
        if done:
            break
    return v


def _evaluate(P, r: np.ndarray, g: float, v0: np.ndarray, tol: float, max_iterations: int) -> np.ndarray:
    """``v`` with ``(I - γ P) v ≈ r``: the value of the policy whose transitions are ``P``.

    Dense LAPACK for small models; BiCGSTAB from ``v0`` for large sparse ones, finished by plain
    sweeps when it stalls. The answer is approximate either way: callers certify it
    (:func:`_certify_upper` / :func:`_certify_lower`), so a solver's error can loosen a bound by its
    residual but never make it invalid.
    """
    S = r.shape[0]
    if not hasattr(P, "tocsr"):
        if S <= _DENSE_SOLVE_STATES:
            return np.linalg.solve(np.eye(S) - g * np.asarray(P), r)
        return _sweep_to(np.asarray(P), r, g, v0, tol, max_iterations)
    import scipy.sparse as sp
    from scipy.sparse.linalg import bicgstab

    system = (sp.identity(S, format="csr") - g * P).tocsr()
    v, info = bicgstab(system, r, x0=v0, rtol=0.0, atol=tol * (1.0 - g) / 4.0, maxiter=_KRYLOV_MAX_ITERATIONS)
    if not np.all(np.isfinite(v)):
        v, info = v0, 1
    if info != 0:
        v = _sweep_to(P, r, g, v, tol, max_iterations)
    return v


def _rounding_margin(v: np.ndarray, Tv: np.ndarray) -> float:
    """Slack for the floating-point error of recomputing ``T v`` after the certificate's shift.

    The shift ``δ/(1-γ)`` makes the worst state's inequality hold with equality in exact
    arithmetic, so the rounding of ``R + γ T (v ± c)`` (a few ulps of the values' size) could
    break it by ~1e-16; a margin of 16 ulps of that size, spread by ``1/(1-γ)`` like ``δ``, keeps
    it exact at a cost of ~1e-13 of the values.
    """
    scale = max(float(np.max(np.abs(v))), float(np.max(np.abs(Tv))), 1.0)
    return 16.0 * float(np.finfo(float).eps) * scale


def _certify_upper(V: np.ndarray, HV: np.ndarray, g: float) -> np.ndarray:
    """``V`` raised so that ``H V <= V``, hence ``V >= V*`` (H monotone, a γ-contraction).

    With ``δ = max(HV - V)``, ``H(V + c) = HV + γc <= V + δ + γc <= V + c`` once ``c >= δ/(1-γ)``.
    """
    delta = float(np.max(HV - V))
    return V + (max(delta, 0.0) + _rounding_margin(V, HV)) / (1.0 - g)


def _certify_lower(v: np.ndarray, Tv: np.ndarray, g: float) -> np.ndarray:
    """``v`` lowered so that ``T_π v >= v``, hence ``v <= v_π`` (the mirror of :func:`_certify_upper`)."""
    delta = float(np.max(v - Tv))
    return v - (max(delta, 0.0) + _rounding_margin(v, Tv)) / (1.0 - g)


def _backup(mats: List, R: np.ndarray, g: float, V: np.ndarray, Q: np.ndarray) -> np.ndarray:
    for a, Ta in enumerate(mats):
        Q[:, a] = R[:, a] + g * (Ta @ V)
    return Q


def mdp_value_iteration(model: Pomdp, epsilon: float = 1e-6, max_iterations: int = 100_000) -> Tuple[np.ndarray, np.ndarray]:
    """The optimal values of the fully observed MDP ``(S, A, T, R, γ)``, as a certified upper bound.

    For ``γ < 1``, policy iteration (Howard): each policy's value solved as a linear system
    (:func:`_evaluate`), improved greedily until no state's action gains; then ``V`` is raised by
    ``max(HV - V)/(1-γ)`` so that ``HV <= V`` holds exactly (so ``V >= V*`` whatever the linear
    solver's error, and ``Q`` below satisfies ``max_a Q <= V``, which FIB's iteration needs). A
    handful of improvements, each one backup over every action and a policy's solve, where value
    iteration took ~500 backups to its tolerance (the ward: 27 s -> about 1 s). For ``γ = 1``,
    value iteration from ``0`` for ``max_iterations`` sweeps (a finite-horizon use).

    Returns:
        ``(V [S], Q [S, A])`` with ``Q[s, a] = R[s, a] + γ Σ_s' T[a][s, s'] V(s')``; ``V`` is
        within ``epsilon`` of the MDP value (above it) when the policy iteration converges.
    """
    mats = _transition_mats(model)
    R = np.asarray(model.R, dtype=float)
    g = float(model.discount)
    S, A = R.shape
    Q = np.empty((S, A))
    if g >= 1.0:
        V = np.zeros(S)
        for _ in range(max_iterations):
            Vn = _backup(mats, R, g, V, Q).max(axis=1)
            delta = float(np.max(np.abs(Vn - V)))
            V = Vn
            if delta <= epsilon:
                break
        return V, _backup(mats, R, g, V, Q)
    tol = epsilon * (1.0 - g) / (2.0 * g)
    # The greedy policy of the one-step reward, evaluated from the optimistic constant.
    policy = np.argmax(R, axis=1)
    V = np.full(S, R.max() / (1.0 - g))
    rows = np.arange(S)
    converged = False
    for _ in range(min(max_iterations, _MAX_POLICY_IMPROVEMENTS)):
        V = _evaluate(_policy_matrix(mats, policy), R[rows, policy], g, V, tol, max_iterations)
        _backup(mats, R, g, V, Q)
        best = np.argmax(Q, axis=1)
        # Switch only on a gain above the tolerance, so ties (and the solver's rounding) cannot
        # make the iteration cycle; what is left is in the certificate's shift (<= epsilon/2).
        gain = Q[rows, best] - Q[rows, policy]
        switch = gain > tol
        if not switch.any():
            converged = True
            break
        policy = np.where(switch, best, policy)
    V = _certify_upper(V, Q.max(axis=1), g)
    if not converged:
        # Policy iteration did not settle (a solver too inexact to rank the actions): value
        # iteration from the certified V, every iterate still an upper bound (HV <= V is kept).
        for _ in range(max_iterations):
            Vn = np.minimum(_backup(mats, R, g, V, Q).max(axis=1), V)
            delta = float(np.max(V - Vn))
            V = Vn
            if delta <= tol:
                break
    return V, _backup(mats, R, g, V, Q)


def solve_qmdp(model: Pomdp, epsilon: float = 1e-6) -> SolveResult:
    """QMDP: the MDP Q-functions as α-vectors (one per action, ``alphas[a] = Q(:, a)``).

    ``value_at_start = upper_bound = max_a Q(:, a)·b0`` — an upper bound on the
    optimal POMDP value at ``b0`` (QMDP assumes the state becomes known after one step).
    """
    t0 = time.perf_counter()
    _, Q = mdp_value_iteration(model, epsilon=epsilon)
    policy = AlphaVectorPolicy(Q.T.copy(), np.arange(model.num_actions))
    v = policy.value(model.b0)
    return SolveResult(policy, "qmdp", v, upper_bound=v, iterations=0,
                       seconds=time.perf_counter() - t0, converged=True)


def fib_q(model: Pomdp, epsilon: float = 1e-6, max_iterations: int = 100_000,
          time_limit: float | None = None, Q_init: np.ndarray | None = None) -> Tuple[np.ndarray, int, bool]:
    """Fast-informed-bound Q-function ``[S, A]`` (Hauskrecht 2000).

    Iterates ``Q ← R + γ Σ_o max_a' (T[a] diag(O[a,:,o])) Q(:, a')`` from the QMDP
    ``Q`` (or ``Q_init``, which must be an upper bound satisfying ``H Q ≤ Q``, as QMDP's
    does); the sequence decreases monotonically, so every iterate is an upper bound.

    Returns:
        ``(Q, iterations, converged)``.
    """
    mats = _transition_mats(model)
    R = np.asarray(model.R, dtype=float)
    O = np.asarray(model.O, dtype=float)
    g = float(model.discount)
    S, A = R.shape
    if Q_init is None:
        _, Q = mdp_value_iteration(model, epsilon=min(epsilon, 1e-6))
    else:
        Q = np.array(Q_init, dtype=float)
    tol = epsilon * (1.0 - g) / (2.0 * g) if g < 1.0 else epsilon
    # Observations action a can never produce add max_a' 0 = 0: leave them out (on Pearl's
    # domain an action has 3-15 of the 18 symbols, so FIB iterates ~3x faster).
    live = [np.flatnonzero(O[a].any(axis=0)) for a in range(A)]
    Olive = [np.ascontiguousarray(O[a][:, live[a]]) for a in range(A)]
    t0 = time.perf_counter()
    it, converged = 0, False
    while it < max_iterations:
        it += 1
        Qn = np.empty_like(Q)
        for a, Ta in enumerate(mats):
            # Y[s', o, a'] = O[a, s', o] Q[s', a']; one product T[a] @ Y covers every o.
            nz = live[a].shape[0]
            Y = (Olive[a][:, :, None] * Q[:, None, :]).reshape(S, nz * A)
            TY = np.asarray(Ta @ Y).reshape(S, nz, A)
            Qn[:, a] = R[:, a] + g * TY.max(axis=2).sum(axis=1)
        # Monotone from above: the min keeps the bound valid under rounding.
        Qn = np.minimum(Qn, Q)
        delta = float(np.max(np.abs(Qn - Q)))
        Q = Qn
        if delta <= tol:
            converged = True
            break
        if time_limit is not None and time.perf_counter() - t0 > time_limit:
            break
    return Q, it, converged


def solve_fib(model: Pomdp, epsilon: float = 1e-6, time_limit: float | None = None) -> SolveResult:
    """The fast informed bound as an α-vector set (``alphas[a] = Q_FIB(:, a)``).

    ``value_at_start = upper_bound = max_a Q_FIB(:, a)·b0``; it is an upper bound on
    the optimal POMDP value at ``b0`` and at most the QMDP bound. Method ``"fib"``.
    """
    t0 = time.perf_counter()
    Q, it, conv = fib_q(model, epsilon=epsilon, time_limit=time_limit)
    policy = AlphaVectorPolicy(Q.T.copy(), np.arange(model.num_actions))
    v = policy.value(model.b0)
    return SolveResult(policy, "fib", v, upper_bound=v, iterations=it,
                       seconds=time.perf_counter() - t0, converged=conv)


def blind_lower_bound(model: Pomdp, epsilon: float = 1e-6, max_iterations: int = 100_000) -> np.ndarray:
    """Blind-policy α-vectors ``[A, S]``: ``alphas[a]`` is the value of always doing ``a``.

    Each ``α_a`` solves ``(I - γ T[a]) α = R(:, a)`` (:func:`_evaluate`: dense LAPACK, or
    BiCGSTAB on sparse ``T``), then is lowered by ``max(α - R_a - γ T[a] α)/(1-γ)`` so that
    ``R_a + γ T[a] α >= α`` holds exactly: ``α`` is below the blind value whatever the solver's
    error, and ``max_a b·alphas[a]`` lower-bounds the POMDP value.

    Raises:
        ValueError: ``γ = 1`` (an infinite-horizon blind value need not exist).
    """
    g = float(model.discount)
    if g >= 1.0:
        raise ValueError("blind-policy bounds need a discount below 1")
    mats = _transition_mats(model)
    R = np.asarray(model.R, dtype=float)
    S, A = R.shape
    tol = epsilon * (1.0 - g) / (2.0 * g)
    alphas = np.empty((A, S))
    for a, Ta in enumerate(mats):
        # From the worst single-action value of action a (where the sweeps would start).
        v = _evaluate(Ta, R[:, a], g, np.full(S, R[:, a].min() / (1.0 - g)), tol, max_iterations)
        alphas[a] = _certify_lower(v, R[:, a] + g * (Ta @ v), g)
    return alphas


def most_likely_state_policy(model: Pomdp) -> MostLikelyStatePolicy:
    """The most-likely-state policy with the MDP-optimal action per state (ties: lowest action index)."""
    _, Q = mdp_value_iteration(model)
    return MostLikelyStatePolicy(np.argmax(Q, axis=1))
