"""Lower-bound backups over the point-based solver's whole belief set, between its trials.

A trial backs up the lower bound along one path from ``b0``; these spread it over every belief
the trials have expanded (the module docstring of :mod:`pearl_pomdp.solvers.point_based` says
when each runs):

* a **PBVI sweep** (Pineau, Gordon & Thrun, IJCAI 2003): one synchronous backup at every
  belief, each reading Γ as it was before the sweep, when the products are small enough;
* **Perseus** (Spaan & Vlassis, JAIR 24, 2005): randomised backups; a belief leaves the round
  as soon as a new vector reaches its value from the round's start.

Both read and grow the solver's Γ and count their backups in the solver's counters
(``sweeps``, ``sweep_backups``, ``perseus_backups``, ``spread_gain``), which its schedule reads.
"""
from __future__ import annotations

from typing import Any, Dict, List, Optional, Protocol, Tuple

import numpy as np


class SolverState(Protocol):
    """What the backups read and change of :class:`~pearl_pomdp.solvers.point_based.PointBasedSolver`
    (this module is below it: the solver holds a :class:`BeliefSetBackups` of itself)."""

    nodes: Dict[bytes, Any]            # key → BeliefNode (idx, val, p, Rb, reach)
    K: int
    A: int
    Z: int
    g: float
    rng: np.random.Generator
    sweep_max_flops: float
    spread_gain: float
    sweeps: int
    sweep_backups: int
    perseus_backups: int

    def lower(self, idx: np.ndarray, val: np.ndarray, k0: int = 0) -> float: ...

    def successors(self, node: Any) -> Tuple[np.ndarray, np.ndarray, np.ndarray]: ...

    def lower_children(self, U, C, live) -> Tuple[np.ndarray, np.ndarray]: ...

    def backed_up_alpha(self, a: int, best_a: np.ndarray) -> np.ndarray: ...

    def add_alpha(self, alpha: np.ndarray, action: int) -> None: ...


class BeliefSetBackups:
    """The sweeps and Perseus rounds of one :class:`~pearl_pomdp.solvers.point_based.PointBasedSolver`."""

    def __init__(self, solver: SolverState):
        self.solver = solver
        # The current Perseus round: its beliefs as one flat list of (belief, state, probability)
        # entries (a new vector's values at all of them are one gather and one bincount), their
        # lower bounds at the round's start, and the ones still to improve (None: no round yet).
        self._seg = np.zeros(0, dtype=np.int64)
        self._idx = np.zeros(0, dtype=np.int64)
        self._val = np.zeros(0)
        self._nodes: List[Any] = []
        self._lb = np.zeros(0)
        self._todo: Optional[np.ndarray] = None

    def _expanded(self) -> List[Any]:
        return [n for n in self.solver.nodes.values() if n.p is not None]

    def _start_round(self) -> bool:
        s = self.solver
        nodes = self._expanded()
        if len(nodes) < 2:
            return False
        self._seg = np.repeat(np.arange(len(nodes)), [n.idx.shape[0] for n in nodes])
        self._idx = np.concatenate([n.idx for n in nodes])
        self._val = np.concatenate([n.val for n in nodes])
        self._nodes = nodes
        self._lb = np.array([s.lower(n.idx, n.val) for n in nodes])
        self._todo = np.ones(len(nodes), dtype=bool)
        return True

    def batched_children(self, nodes) -> Optional[Tuple[np.ndarray, np.ndarray, np.ndarray]]:
        """For beliefs ``nodes``: ``(Ql [N,A], best [N,A,Z], live [N,A,Z])`` — the one-step LB
        lookahead and the maximising vector at every successor, against Γ as it is (or ``None``
        when that would cost more than ``sweep_max_flops`` multiply-adds)."""
        s = self.solver
        N, K, A, Z, g = len(nodes), s.K, s.A, s.Z, s.g
        nnz = sum(n.idx.shape[0] for n in nodes)
        if N == 0 or nnz * A * K * 4 > s.sweep_max_flops:
            return None
        Ql = np.empty((N, A))
        best = np.empty((N, A, Z), dtype=np.int64)
        live = np.zeros((N, A * Z), dtype=bool)
        for i, node in enumerate(nodes):
            U, C, lv = s.successors(node)
            lb, best[i] = s.lower_children(U, C, lv)
            Ql[i] = node.Rb + g * (node.p * lb).sum(axis=1)
            live[i, lv] = True
        return Ql, best, live.reshape(N, A, Z)

    def sweep(self) -> bool:
        """One synchronous point-based backup of every expanded belief (PBVI, Pineau et al. 2003):
        every backup reads Γ as it was before the sweep; adds the new vectors that improve their
        own belief. Returns False (and does nothing) when the products would be too large."""
        s = self.solver
        nodes = self._expanded()
        if len(nodes) < 2:
            return False
        got = self.batched_children(nodes)
        if got is None:
            return False
        Ql, best, _ = got
        N = len(nodes)
        an = Ql.argmax(axis=1)
        qn = Ql[np.arange(N), an]
        new = []
        for i, node in enumerate(nodes):
            cur = s.lower(node.idx, node.val)
            if qn[i] > cur + 1e-10 * max(1.0, abs(cur)):
                s.spread_gain = max(s.spread_gain, (float(qn[i]) - cur) * node.reach)
                new.append((s.backed_up_alpha(int(an[i]), best[i, an[i]]), int(an[i])))
        for alpha, a in new:
            s.add_alpha(alpha, a)
        s.sweeps += 1
        s.sweep_backups += N
        return True

    def perseus(self, budget: int) -> None:
        """Up to ``budget`` Perseus backups: a random belief of the round's to-do set is backed
        up; every belief at which the new vector reaches its value from the start of the round
        leaves the set; a new round starts (with the beliefs found since) when it is empty."""
        s = self.solver
        done = 0
        while done < budget:
            if self._todo is None or not self._todo.any():
                if not self._start_round():
                    return
            todo_mask = self._todo
            assert todo_mask is not None   # set by _start_round above
            todo = np.flatnonzero(todo_mask)
            i = int(todo[s.rng.integers(todo.size)])
            todo_mask[i] = False
            node = self._nodes[i]
            U, C, live = s.successors(node)
            lb, best = s.lower_children(U, C, live)
            Ql = node.Rb + s.g * (node.p * lb).sum(axis=1)
            a = int(np.argmax(Ql))
            done += 1
            s.perseus_backups += 1
            if Ql[a] <= self._lb[i] + 1e-10 * max(1.0, abs(self._lb[i])):
                continue
            alpha = s.backed_up_alpha(a, best[a])
            cur = s.lower(node.idx, node.val)
            if Ql[a] > cur + 1e-10 * max(1.0, abs(Ql[a])):
                s.spread_gain = max(s.spread_gain, (float(Ql[a]) - cur) * node.reach)
                s.add_alpha(alpha, a)
            values = np.bincount(self._seg, weights=self._val * alpha[self._idx], minlength=len(self._nodes))
            covered = values >= self._lb
            todo_mask &= ~covered
