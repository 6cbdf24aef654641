"""Forward search over a model with α-vectors at the leaves (docs/hierarchy.md, "Lookahead").

* :class:`Lookahead` — exact ``d``-step search, batched over beliefs (a subtask's ``lookahead: d``,
  :class:`~pearl_pomdp.policies.flat.FlatPolicyDecider`'s ``lookahead``).
* :class:`OneStep` — one Bellman step at one belief through the point-based solver's C kernel
  (the policy-contingent EXECUTE's inner step).
* :class:`LookaheadPolicy` — an α-vector policy acting by one step of :class:`Lookahead`, as a
  batch :class:`~pearl_pomdp.interfaces.Policy` (the evaluation's and simulation's fast path).
"""
from __future__ import annotations

from typing import Dict, Optional, Sequence

import numpy as np
import scipy.sparse as sp

from pearl_pomdp.model.pomdp import Pomdp

__all__ = ["Lookahead", "OneStep", "LookaheadPolicy"]


class Lookahead:
    """Exact forward search over a subtask's model, ``depth`` steps, α-vectors at the leaves.

    With ``V_0(b) = max_k α_k·b`` the solved horizon-``h`` value, one step of the
    Bellman recursion (eq. 6) is ``Q_d(b, a) = b·R_a + γ Σ_o V_{d−1}(b T_a diag O_{a,o})``
    and ``V_d(b) = max_a Q_d(b, a)``. Every ``V_d`` is positively homogeneous, so the
    unnormalised successor ``b T_a diag O_{a,o}`` (whose mass is ``P(o | b, a)``) is used
    as it is: ``Q_d`` is then the exact horizon-``h + d`` Q-function at ``b``, the same
    value incremental pruning would give after ``d`` more epochs, without enumerating
    the vectors that would need. Cost per belief: ``(|A|·|Z|)^d`` sparse mat-vecs.

    Args:
        T: per action, ``[S_h, S_h]`` transition matrix (dense or sparse) of the subtask model.
        O: ``[A, S_h, Z]`` observation model (``O[a, s', o]``).
        R: ``[S_h, A]`` reward (shaping included).
        discount: γ.
        alphas: ``[K, S_h]`` leaf vectors (the solved horizon-``h`` value).
        depth: search depth ``d ≥ 1``.
    """

    def __init__(self, T, O, R, discount: float, alphas, depth: int):
        if depth < 1:
            raise ValueError(f"lookahead depth must be >= 1, got {depth}")
        self.T = [sp.csr_matrix(t, dtype=float) for t in T]
        self.O = np.asarray(O, dtype=float)
        self.R = np.asarray(R, dtype=float)
        self.discount = float(discount)
        self.alphas = np.atleast_2d(np.asarray(alphas, dtype=float))
        self.depth = int(depth)
        # Tᵀ per action, so a batch of row beliefs B [N, S] advances as (Tᵀ Bᵀ)ᵀ.
        self._Tt = [t.T.tocsr() for t in self.T]
        # The same, stacked [A·S, S]: one sparse product advances B under every action (a CSR
        # product sums each row in the same order, so the rows equal the per-action ones).
        self._Tt_stacked = sp.vstack(self._Tt).tocsr()
        # O as [A, Z, 1, S], laid out for the last step's broadcast (see _q_last_step).
        self._O_azs = np.ascontiguousarray(self.O.transpose(0, 2, 1)[:, :, None, :])
        # Per action, the observations it can produce: the loop skips the others, whose
        # successor is 0 and whose term is exactly 0 (Pearl's flat model: most of them).
        self._live_obs = [np.flatnonzero(self.O[a].any(axis=0)) for a in range(self.O.shape[0])]

    #: Most elements of the ``[A, Z, N, S]`` successor block :meth:`_q_last_step` builds; a
    #: larger batch takes the per-``(a, o)`` loop (splitting the rows would change the BLAS
    #: products' rounding: a row's ``[N, S] @ [S, K]`` result depends on ``N``).
    LAST_STEP_BLOCK = 1 << 22

    def q_values(self, B: np.ndarray, depth: Optional[int] = None) -> np.ndarray:
        """``Q_d(b, a)`` for every row ``b`` of ``B [N, S_h]`` (rows need not be normalised) → ``[N, A]``."""
        d = self.depth if depth is None else depth
        B = np.atleast_2d(np.asarray(B, dtype=float))
        A, S, Z = self.O.shape
        if d == 1 and A * Z * B.shape[0] * S <= self.LAST_STEP_BLOCK:
            return self._q_last_step(B)
        Q = B @ self.R
        for a, Tt in enumerate(self._Tt):
            predicted = np.asarray((Tt @ B.T).T)  # [N, S_h]
            for o in self._live_obs[a]:
                successor = predicted * self.O[a, :, o]
                if d == 1:
                    Q[:, a] += self.discount * (successor @ self.alphas.T).max(axis=1)
                else:
                    Q[:, a] += self.discount * self.q_values(successor, d - 1).max(axis=1)
        return Q

    def _q_last_step(self, B: np.ndarray) -> np.ndarray:
        """``Q_1`` for the rows of ``B``: every action and observation in a few array operations.

        The same products and sums as the per-``(a, o)`` loop of :meth:`q_values` (one
        ``[N, S] @ [S, K]`` product per ``(a, o)``, then ``Q[:, a] += γ·max`` in observation
        order), so the values are bit-identical to it — ties break the same way — at a
        fraction of the Python overhead (the policy node runs this at every step).
        """
        A, S, Z = self.O.shape
        N = B.shape[0]
        predicted = np.asarray(self._Tt_stacked @ B.T).reshape(A, S, N).transpose(0, 2, 1)  # [A, N, S]
        successor = predicted[:, None, :, :] * self._O_azs                                 # [A, Z, N, S]
        best = np.matmul(successor, self.alphas.T).max(axis=3)                             # [A, Z, N]
        # B·R + γ·best[o=0] + γ·best[o=1] + …, added left to right as the loop does
        # (add.accumulate is sequential; a sum would pair terms up and round differently).
        terms = np.concatenate([(B @ self.R)[None], self.discount * best.transpose(1, 2, 0)])  # [1 + Z, N, A]
        return np.add.accumulate(terms, axis=0)[-1]

    def arrays(self, prefix: str) -> Dict[str, np.ndarray]:
        """The arrays :meth:`from_arrays` needs, keys prefixed (for ``policy.npz``)."""
        stacked = sp.vstack(self.T).tocsr()
        return {f"{prefix}_T_data": stacked.data, f"{prefix}_T_indices": stacked.indices,
                f"{prefix}_T_indptr": stacked.indptr, f"{prefix}_O": self.O, f"{prefix}_R": self.R}

    @classmethod
    def from_arrays(cls, arrays: Dict[str, np.ndarray], prefix: str, discount: float, alphas, depth: int) -> "Lookahead":
        """Rebuild from :meth:`arrays` (``KeyError`` when one is missing)."""
        O = arrays[f"{prefix}_O"]
        A, S = O.shape[0], O.shape[1]
        stacked = sp.csr_matrix((arrays[f"{prefix}_T_data"], arrays[f"{prefix}_T_indices"],
                                 arrays[f"{prefix}_T_indptr"]), shape=(A * S, S))
        return cls([stacked[a * S:(a + 1) * S] for a in range(A)], O, arrays[f"{prefix}_R"], discount, alphas, depth)


class OneStep:
    """``Q(b, a) = b·R_a + γ Σ_o max_k α_k·(b T_a diag O_{a,o})`` at one belief, every action.

    The policy-contingent EXECUTE's inner step (a parent values its children's offers with
    it), at every level of every decision, so it runs through the point-based solver's C
    kernel — the same successor and lower-bound loops the planner backed these vectors up
    with — in ~10 µs for a small subtask instead of ~100 µs of numpy. Batches are row by row
    (:meth:`q_rows`), so a simulation decides exactly as the robot does.

    Args:
        T: per action, ``[S_h, S_h]`` transitions (dense or sparse); O ``[A, S_h, Z]``; R ``[S_h, A]``.
        discount: γ.
        alphas: ``[K, S_h]`` the subtask's vectors.
    """

    def __init__(self, T, O, R, discount: float, alphas):
        from pearl_pomdp.solvers.point_based import transition_block

        self.O = np.ascontiguousarray(O, dtype=float)
        self.R = np.ascontiguousarray(R, dtype=float)
        self.A, self.S, self.Z = self.O.shape
        self.g = float(discount)
        self.t_ptr, self.t_ind, self.t_dat = transition_block(list(T))
        alphas = np.atleast_2d(np.asarray(alphas, dtype=float))
        self.K = alphas.shape[0]
        self.GT = np.ascontiguousarray(alphas.T)            # [S, K]: the kernel's layout
        self._bT = np.zeros(self.A * self.S)
        self._pos = np.full(self.S, -1, dtype=np.int64)
        self._U = np.zeros(self.S, dtype=np.int64)
        self._C = np.zeros(self.A * self.Z * min(self.S, 64))
        self._p = np.zeros(self.A * self.Z)
        self._live = np.zeros(self.A * self.Z, dtype=np.int64)
        self._lb = np.zeros(self.A * self.Z)
        self._best = np.zeros(self.A * self.Z, dtype=np.int64)

    def q(self, b: np.ndarray, actions: Optional[Sequence[int]] = None) -> np.ndarray:
        """``[A]`` Q-values at the belief ``b [S_h]`` (need not be normalised).

        ``actions``: the action indices whose values are wanted (a parent ranks only its
        children's offers, often a third of its model's actions); the others are NaN. A wanted
        action's value is bit for bit the one of a call without ``actions``: the kernel skips the
        other actions' columns and rows, and every sum it keeps adds the same terms in the same
        order (a state no wanted action reaches adds exact zeros)."""
        from pearl_pomdp.solvers import _pointbased_kernel as kernel

        b = np.asarray(b, dtype=float)
        idx = np.flatnonzero(b > 0)
        val = np.ascontiguousarray(b[idx])
        allowed = bytearray()
        if actions is not None:
            allowed = bytearray(self.A)
            for a in actions:
                allowed[a] = 1
        while True:
            nU, nl = kernel.successors(idx, val, self.t_ptr, self.t_ind, self.t_dat, self.O, self.A, self.S, self.Z,
                                       self._bT, self._pos, self._U, self._C, self._p, self._live, allowed)
            if nl >= 0:
                break
            self._C = np.zeros(2 * self.A * self.Z * nU)
        self._lb[:] = 0.0
        if nl:
            kernel.lower_rows(self._C, nU, self._U, self._live[:nl], self.GT, self.K, 0, self.K, self._lb,
                              self._best, False)
        expect = (self._p * self._lb).reshape(self.A, self.Z).sum(axis=1)
        q = val @ self.R[idx] + self.g * expect
        if actions is not None:
            q[np.frombuffer(allowed, dtype=np.uint8) == 0] = np.nan
        return q

    def q_rows(self, B: np.ndarray) -> np.ndarray:
        """:meth:`q` for every row of ``B [N, S_h]`` → ``[N, A]``."""
        B = np.atleast_2d(np.asarray(B, dtype=float))
        return np.stack([self.q(b) for b in B]) if B.shape[0] else np.zeros((0, self.A))


class LookaheadPolicy:
    """An α-vector policy executed with one step of exact forward search over the model, batched:
    ``argmax_a [b·R_a + γ Σ_o max_k α_k·(b T_a diag O_{a,o})]`` — the choice of
    :class:`~pearl_pomdp.policies.flat.FlatPolicyDecider` with ``lookahead=1``, through the same
    :class:`Lookahead`, over every episode's belief at once
    (its loop skips the observations an action never produces, which is what makes thousands
    of episodes on Pearl's flat model affordable)."""

    def __init__(self, policy, model: Pomdp):
        self._search = Lookahead(model.T, model.O, model.R, model.discount, policy.alphas, 1)

    def q_values(self, B: np.ndarray) -> np.ndarray:
        """``[N, A]`` one-step look-ahead Q-values at the rows of ``B`` ``[N, S]``."""
        return self._search.q_values(B)

    def actions_batch(self, beliefs: np.ndarray) -> np.ndarray:
        """The look-ahead action per row of ``beliefs`` ``[N, S]``."""
        return np.argmax(self.q_values(beliefs), axis=1).astype(np.int64)

    def action(self, belief: np.ndarray) -> int:
        return int(self.actions_batch(np.asarray(belief, dtype=float)[None, :])[0])
