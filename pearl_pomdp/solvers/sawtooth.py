"""The point-based solver's upper bound (HSVI2, Smith & Simmons 2005): the fast informed bound
(FIB) vectors with a sawtooth point set over corner values,

    ``UB(b) = min(max_a b·Q_FIB(:,a), b·V_c + min_i min_{s∈supp b_i} (b(s)/b_i(s)) (v_i − b_i·V_c))``,

``V_c(s) = max_a Q_FIB(s, a)`` lowered as corner beliefs are backed up. The arrays are laid out
for ``_pointbased_kernel.c``, which reads the bound (:meth:`SawtoothUpperBound.point_set`).
:class:`~pearl_pomdp.solvers.point_based.PointBasedSolver` owns one and lowers it at every
belief it backs up (:meth:`SawtoothUpperBound.lower_at`).
"""
from __future__ import annotations

import time
from typing import Dict, Optional, Tuple

import numpy as np

from ..model.pomdp import Pomdp
from . import _pointbased_kernel as _kernel
from .mdp import fib_q

__all__ = ["SawtoothUpperBound", "PROBES"]

#: Probe states per sawtooth point (its most likely ones) for the branch-and-bound bound.
PROBES = 4


class SawtoothUpperBound:
    """FIB vectors and a sawtooth point set: an upper bound on the optimal value that only falls.

    Args:
        model: the POMDP (``γ < 1``).
        fib_epsilon: the FIB iteration's stopping tolerance (every iterate is an upper bound).
        fib_time: seconds for FIB (``None``: to its own convergence).
        pos: the solver's ``[S]`` scratch (all -1 between kernel calls): state → position in a support.
    """

    def __init__(self, model: Pomdp, fib_epsilon: float, fib_time: Optional[float], pos: np.ndarray) -> None:
        self.A = model.num_actions
        t0 = time.perf_counter()
        Q, self.fib_iterations, self.fib_converged = fib_q(model, epsilon=fib_epsilon, time_limit=fib_time)
        self.fib_seconds = time.perf_counter() - t0
        self.Qfib = np.ascontiguousarray(Q, dtype=float)   # [S, A]
        self.Vc = np.ascontiguousarray(Q.max(axis=1))      # corner values
        self.pt_cap = 1024
        self.pt_n = 0
        self.pt_start = np.zeros(self.pt_cap, dtype=np.int64)
        self.pt_len = np.zeros(self.pt_cap, dtype=np.int64)
        # Probe states (the point's PROBES most likely) and 1/b_i there: λ_i(c) ≤ min over
        # probes of c(s)/b_i(s).
        self.pt_probe = np.zeros((self.pt_cap, PROBES), dtype=np.int64)
        self.pt_pinv = np.zeros((self.pt_cap, PROBES))
        self.pt_v = np.zeros(self.pt_cap)
        self.pt_delta = np.zeros(self.pt_cap)
        # Versions: a point's stamp is the version at which its value last fell; a cached
        # successor bound read at version t only needs the points stamped after t again,
        # unless a corner value fell since (that moves every point's delta: full re-read).
        self.pt_stamp = np.zeros(self.pt_cap, dtype=np.int64)
        self.ub_version = 0
        self.vc_version = 0
        self.ent_cap = 1 << 14
        self.ent_n = 0
        self.ent_idx = np.zeros(self.ent_cap, dtype=np.int64)
        self.ent_val = np.zeros(self.ent_cap)
        self.pt_index: Dict[bytes, int] = {}
        self.pos = pos

    def refresh_deltas(self) -> None:
        """Recompute every point's ``δ_i = v_i − b_i·V_c`` (after a corner value fell)."""
        n = self.pt_n
        if n == 0:
            return
        seg = np.repeat(np.arange(n), self.pt_len[:n])
        ent = self.entries(np.arange(n))
        dots = np.bincount(seg, weights=self.ent_val[ent] * self.Vc[self.ent_idx[ent]], minlength=n)
        self.pt_delta[:n] = self.pt_v[:n] - dots

    def entries(self, pts: np.ndarray) -> np.ndarray:
        """The positions in ``ent_idx`` / ``ent_val`` of the supports of points ``pts``, concatenated."""
        lens = self.pt_len[pts]
        total = int(lens.sum())
        if total == 0:
            return np.zeros(0, dtype=np.int64)
        offs = np.cumsum(lens) - lens
        return np.repeat(self.pt_start[pts] - offs, lens) + np.arange(total)

    def batch(self, U: np.ndarray, C: np.ndarray, since: Optional[int] = None,
                     rows: Optional[np.ndarray] = None, with_points: bool = True) -> np.ndarray:
        """Upper bound at the rows ``rows`` of ``C`` ([M, |U|], beliefs on states ``U``; all rows
        when ``None``).

        With ``since`` (a version): only the sawtooth over the points whose value fell after
        it, ``b·V_c + min(0, min_i λ_i δ_i)``, without the FIB vectors; the caller takes the
        minimum with what it read before. Without: ``min(max_a b·Q_FIB(:,a), b·V_c + min(0, min_i λ_i δ_i))``
        over all points (over none with ``with_points=False``: the cheap bound of a first expansion).

        ``λ_i(c) = min_{s ∈ supp b_i} c(s)/b_i(s)`` is at most ``c(s)/b_i(s)`` at each of the
        point's probe states (its most likely ones), and ``δ_i < 0``, so the probes bound the
        point's correction from below; the kernel reads a point in full only when that bound
        beats the best correction found so far, and stops reading it as soon as it cannot
        (branch and bound): the result is the full sawtooth minimum."""
        C = np.ascontiguousarray(C, dtype=float)
        if rows is None:
            rows = np.arange(C.shape[0], dtype=np.int64)
        out = np.empty(rows.shape[0])
        if since is None:
            # every point (none for the cheap bound), and the FIB vectors
            since, with_fib = (-1 if with_points else self.ub_version + 1), True
        else:
            with_fib = False
        _kernel.sawtooth(C, U.shape[0], U, rows, with_fib, since, self.pos, *self.point_set(), self.A, out)
        return out

    def value(self, idx: np.ndarray, val: np.ndarray) -> float:
        """Upper bound at the belief ``val`` on states ``idx``."""
        return float(self.batch(idx, val[None, :])[0])

    def lower_at(self, idx: np.ndarray, val: np.ndarray, v: float, key: bytes) -> None:
        """Record the bound ``v`` at the belief ``val`` on states ``idx`` (``key`` names it): a corner
        value, a lower value of a known point, or a new point when it beats the corners there."""
        if idx.shape[0] == 1:
            s = int(idx[0])
            if v < self.Vc[s] - 1e-12:
                self.Vc[s] = v
                self.refresh_deltas()
                self.ub_version += 1
                self.vc_version = self.ub_version
            return
        delta = v - float(val @ self.Vc[idx])
        i = self.pt_index.get(key)
        if i is not None:
            if v < self.pt_v[i]:
                self.pt_v[i] = v
                self.pt_delta[i] = delta
                self.ub_version += 1
                self.pt_stamp[i] = self.ub_version
            return
        if delta >= 0.0:
            return  # no better than the corners: the point would never bind
        if self.pt_n == self.pt_cap:
            self.pt_cap *= 2
            for name in ("pt_start", "pt_len", "pt_v", "pt_delta", "pt_stamp", "pt_probe", "pt_pinv"):
                old = getattr(self, name)
                new = np.zeros((self.pt_cap,) + old.shape[1:], dtype=old.dtype)
                new[: old.shape[0]] = old
                setattr(self, name, new)
        m = idx.shape[0]
        while self.ent_n + m > self.ent_cap:
            self.ent_cap *= 2
            self.ent_idx = np.resize(self.ent_idx, self.ent_cap)
            self.ent_val = np.resize(self.ent_val, self.ent_cap)
        i = self.pt_n
        self.ent_idx[self.ent_n: self.ent_n + m] = idx
        self.ent_val[self.ent_n: self.ent_n + m] = val
        top = int(np.argmax(val))
        self.pt_start[i], self.pt_len[i] = self.ent_n, m
        probes = np.argsort(-val, kind="stable")[:PROBES]
        probes = np.concatenate([probes, np.full(PROBES - probes.size, top)])
        self.pt_probe[i], self.pt_pinv[i] = idx[probes], 1.0 / val[probes]
        self.pt_v[i], self.pt_delta[i] = v, delta
        self.ub_version += 1
        self.pt_stamp[i] = self.ub_version
        self.ent_n += m
        self.pt_n += 1
        self.pt_index[key] = i

    def point_set(self) -> Tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray,
                                  np.ndarray, np.ndarray, np.ndarray, int, int]:
        """The sawtooth point set as the kernel reads it (see ``_pointbased_kernel.c``)."""
        return (self.Vc, self.Qfib, self.pt_start, self.pt_len, self.pt_probe, self.pt_pinv, self.ent_idx,
                self.ent_val, self.pt_delta, self.pt_stamp, self.pt_n, PROBES)
