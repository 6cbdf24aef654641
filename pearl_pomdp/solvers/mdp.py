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

All iterations start on the safe side (upper bounds from ``R_max/(1-γ)``, lower
bounds from ``R_min/(1-γ)``) and the Bellman operators are monotone, so every
iterate — not only the converged one — is a valid bound.
"""
from __future__ import annotations

import time
from typing import List, Tuple

import numpy as np

from ..model.pomdp import Pomdp
from .base import AlphaVectorPolicy, SolveResult

__all__ = [
    "mdp_value_iteration",
    "solve_qmdp",
    "solve_fib",
    "fib_q",
    "blind_lower_bound",
    "MostLikelyStatePolicy",
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


def _iterations_needed(discount: float, span: float, epsilon: float, cap: int) -> int:
    if discount >= 1.0:
        return cap
    if span <= 0:
        return 1
    return int(min(cap, np.ceil(np.log(epsilon / span) / np.log(discount)) + 2))


def mdp_value_iteration(model: Pomdp, epsilon: float = 1e-6, max_iterations: int = 100_000) -> Tuple[np.ndarray, np.ndarray]:
    """Value iteration on the fully observed MDP ``(S, A, T, R, γ)``.

    Starts from ``R_max/(1-γ)`` so every iterate is an upper bound of the MDP
    value (hence of the POMDP value) and stops when successive iterates differ
    by at most ``epsilon·(1-γ)/(2γ)`` (then ``V`` is ``epsilon``-close), or after
    ``max_iterations`` sweeps (the only stop when ``γ = 1``).

    Returns:
        ``(V [S], Q [S, A])`` with ``Q[s, a] = R[s, a] + γ Σ_s' T[a][s, s'] V(s')``.
    """
    mats = _transition_mats(model)
    R = np.asarray(model.R, dtype=float)
    g = float(model.discount)
    S, A = R.shape
    if g < 1.0:
        V = np.full(S, R.max() / (1.0 - g))
        tol = epsilon * (1.0 - g) / (2.0 * g)
    else:
        V = np.zeros(S)
        tol = epsilon
    Q = np.empty((S, A))
    for _ in range(max_iterations):
        for a, Ta in enumerate(mats):
            Q[:, a] = R[:, a] + g * (Ta @ V)
        Vn = Q.max(axis=1)
        delta = float(np.max(np.abs(Vn - V)))
        V = Vn
        if delta <= tol:
            break
    for a, Ta in enumerate(mats):
        Q[:, a] = R[:, a] + g * (Ta @ V)
    return V, Q


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

    Iterates ``α ← R(:,a) + γ T[a] α`` from ``R_min/(1-γ)`` (increasing), so each
    iterate is a lower bound; ``max_a b·alphas[a]`` lower-bounds the POMDP value.

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
        # The constant start is the worst single-action value of action a.
        v = np.full(S, R[:, a].min() / (1.0 - g))
        for _ in range(max_iterations):
            vn = R[:, a] + g * (Ta @ v)
            vn = np.maximum(vn, v)
            if np.max(vn - v) <= tol:
                v = vn
                break
            v = vn
        alphas[a] = v
    return alphas


class MostLikelyStatePolicy:
    """Act as if the most probable state were the true one.

    Attributes:
        state_actions: ``[S]`` int array, the action for each state (usually the
            MDP-optimal one).
    """

    def __init__(self, state_actions) -> None:
        self.state_actions = np.asarray(state_actions, dtype=np.int64).ravel()

    def action(self, belief: np.ndarray) -> int:
        """``state_actions[argmax_s belief[s]]`` (ties: the lowest state index)."""
        b = np.asarray(belief, dtype=float).ravel()
        if b.shape[0] != self.state_actions.shape[0]:
            raise ValueError(f"belief has {b.shape[0]} entries, the policy has {self.state_actions.shape[0]} states")
        return int(self.state_actions[int(np.argmax(b))])

    def actions_batch(self, beliefs: np.ndarray) -> np.ndarray:
        """:meth:`action` for every row of ``beliefs`` ``[N, S]`` (ties: the lowest state index)."""
        return self.state_actions[np.argmax(np.asarray(beliefs, dtype=float), axis=1)]


def most_likely_state_policy(model: Pomdp) -> MostLikelyStatePolicy:
    """The most-likely-state policy with the MDP-optimal action per state (ties: lowest action index)."""
    _, Q = mdp_value_iteration(model)
    return MostLikelyStatePolicy(np.argmax(Q, axis=1))
