"""Pruning a set of α-vectors to its parsimonious (minimal) subset.

A vector α of a set Γ is *useful* when there is a belief ``b`` (its *witness*)
where it beats every other vector of Γ: ``α·b > α'·b`` for all ``α' ≠ α``.
Pruning keeps the useful vectors and drops the rest, without changing
``V(b) = max_{α∈Γ} α·b`` anywhere. This is the ``prune`` of incremental
pruning (Cassandra, Littman & Zhang 1997, §3) and of pomdp-solve.

The steps, cheapest first (as in AI-Toolbox's ``Utils/Prune.hpp`` and
pomdp-solve's ``purgeAlphaList``):

1. **Duplicates** are removed (the first copy is kept).
2. **Pointwise dominance**: a vector with another vector ``≥`` it in every
   state is dropped.
3. **Witness points without an LP**: the best vector at every corner of the
   belief simplex is useful (ties broken lexicographically, as pomdp-solve
   does), and so is the best vector at any given belief point where it wins
   by more than ``tol`` (``points``: witnesses of earlier prunes, say).
4. **Lark's filter** (White 1991): every other vector ``c`` is checked by one
   linear programme against the vectors ``K`` kept so far,

   ``δ* = max_{b ∈ simplex} ( c·b − max_{k∈K} α_k·b )``,

   written as ``max c·b − w  s.t.  α_k·b − w ≤ 0 (k ∈ K),  Σ b = 1, b ≥ 0``.
   If ``δ* ≥ tol`` the optimum ``b`` is a witness that *some* remaining
   vector is missing from ``K``: the best remaining vector at ``b`` is
   added (it need not be ``c``, which then waits for its turn again).
   If ``δ* < tol``, ``c`` is dropped: a vector must win by at least ``tol``
   somewhere to count as useful.

**The tolerance.** pomdp-solve asks for ``δ* ≥ 1e-9`` (its ``-epsilon``), but
its LP solver (lp_solve 3.2, ``DEF_EPSB``) rounds basic variable values
below 5.01e-7 to zero, so there a vector in fact needs ``δ* ≳ 5e-7`` to
survive. ``DEFAULT_TOL = 5.01e-7`` states that threshold openly; with it the
per-epoch vector counts agree with pomdp-solve's (tiger.95 epochs 1–20,
network.POMDP epochs 1–10; with 1e-9 network's epoch 9 keeps 136 vectors
instead of 135). Pass ``tol=1e-9`` for the mathematically tighter set.

**Where it runs.** The whole of one prune (all four steps) runs in a compiled
kernel, ``pearl_pomdp/solvers/_prune.c`` (built by ``pip install`` / colcon from
setup.py): thousands of small prunes per solve made numpy's per-call cost and
HiGHS's per-LP overhead (~25 µs a run) the solver's time. Its LP is a small
dense simplex of its own on the dual form of the LP above (``S + 1`` rows
however large ``K`` is; the duals of the state rows are the witness ``b``):
only ``c`` changes between candidates, so the basis is kept and the dual
simplex re-optimises, and a newly kept vector is a new column, after which the
primal simplex re-optimises. Harris's ratio test, Bland's rule after a run of
degenerate pivots, refactoring every 50 pivots, and one retry from a fresh
basis before an LP counts as "no witness" keep it robust. The random beliefs of
step 3 come from numpy's generator seeded by the set size (:func:`_random_beliefs`,
which the kernel calls back), so a prune's result never depends on earlier calls.

Array convention: ``alphas`` is ``[K, S]``, one vector per row.
"""
from __future__ import annotations

from typing import Optional, Sequence, Tuple, Union, cast

import numpy as np

from . import _prune

#: A vector must win by at least this much somewhere (pomdp-solve's effective threshold, see above).
DEFAULT_TOL = 5.01e-7

__all__ = ["prune", "PruneStats", "PruneTimeout", "pointwise_dominated", "WitnessLP", "DEFAULT_TOL"]


class PruneTimeout(Exception):
    """Raised inside :func:`prune` when its ``deadline`` (``time.perf_counter()`` value) passes."""


class PruneStats:
    """Counters a caller can pass to :func:`prune` to see where the work went."""

    def __init__(self) -> None:
        self.lps = 0  #: linear programmes solved
        self.lp_witnesses = 0  #: LPs that found a witness
        self.candidates = 0  #: vectors given to prune in total
        self.kept = 0  #: vectors kept in total
        self.lp_resolves = 0  #: LPs re-solved from a fresh basis (the warm answer did not hold up)
        self.lp_failures = 0  #: LPs without an answer (counted as "no witness")

    def as_dict(self) -> dict:
        return {"lps": self.lps, "lp_witnesses": self.lp_witnesses,
                "candidates": self.candidates, "kept": self.kept,
                "lp_resolves": self.lp_resolves, "lp_failures": self.lp_failures}


class WitnessLP:
    """``δ* = max_b c·b − max_{k∈K} α_k·b`` over the belief simplex, for many ``c`` and a growing ``K``:
    the kernel's LP on its own (the one :func:`prune` uses), for tests and checks."""

    def __init__(self, num_states: int) -> None:
        self.S = num_states
        self._lp = _prune.WitnessLP(num_states)

    def add(self, alpha: np.ndarray) -> None:
        """Add a kept vector (a new column of the dual form)."""
        self._lp.add(np.ascontiguousarray(alpha, dtype=float))

    def solve(self, c: np.ndarray) -> Tuple[float, Optional[np.ndarray]]:
        """Return ``(δ*, b*)``: the largest advantage of ``c`` over the kept set and where it is
        (``b*`` unclipped, as the simplex left it; ``(-inf, None)`` if the LP failed)."""
        delta, b = self._lp.solve(np.ascontiguousarray(c, dtype=float))
        return delta, (None if b is None else np.array(b))

    @property
    def iterations(self) -> int:
        """Simplex pivots so far."""
        return self._lp.iterations


# --------------------------------------------------------------- helpers
def pointwise_dominated(candidates: np.ndarray, by: np.ndarray, slack: float = 0.0,
                        chunk_elems: int = 4_000_000) -> np.ndarray:
    """Boolean mask over ``candidates [N, S]``: True where some row ``β`` of ``by [M, S]``
    has ``c(s) ≤ β(s)`` in every state (with ``slack > 0``: ``c(s) < β(s) + slack``).

    Rows of ``by`` equal to a candidate also count. Chunked so memory stays bounded.
    """
    N, S = candidates.shape
    out = np.zeros(N, dtype=bool)
    if N == 0 or by.shape[0] == 0:
        return out
    step = max(1, chunk_elems // max(1, by.shape[0] * S))
    for i in range(0, N, step):
        blk = candidates[i:i + step]
        if slack > 0.0:
            out[i:i + step] = cast(np.ndarray, (by[None, :, :] + slack > blk[:, None, :]).all(axis=2)).any(axis=1)
        else:
            out[i:i + step] = cast(np.ndarray, (by[None, :, :] >= blk[:, None, :]).all(axis=2)).any(axis=1)
    return out


_RANDOM_BELIEFS: dict = {}
_RANDOM_BELIEFS_SIZE = 0  # floats held by _RANDOM_BELIEFS


def _random_beliefs(seed: int, S: int, n: int) -> np.ndarray:
    """``n`` Dirichlet(1) beliefs from ``default_rng(seed)``, cached: the same numbers
    for the same arguments (a prune's result must not depend on earlier calls), without
    paying a new generator per prune. The kernel calls it (``seed`` = the number of
    candidates left after the dominance step)."""
    key = (seed, S, n)
    P = _RANDOM_BELIEFS.get(key)
    if P is None:
        P = np.random.default_rng(seed).dirichlet(np.ones(S), n)
        if P.size <= 65_536:  # only small sets are worth keeping (large S: the draw is not the cost)
            global _RANDOM_BELIEFS_SIZE
            if _RANDOM_BELIEFS_SIZE + P.size > 4_000_000:  # at most ~32 MB cached
                _RANDOM_BELIEFS.clear()
                _RANDOM_BELIEFS_SIZE = 0
            P.flags.writeable = False
            _RANDOM_BELIEFS[key] = P
            _RANDOM_BELIEFS_SIZE += P.size
    return P


# ----------------------------------------------------------------- prune
def prune(
    alphas: np.ndarray,
    actions: Optional[Sequence[int]] = None,
    tol: float = DEFAULT_TOL,
    points: Union[None, np.ndarray, Sequence[np.ndarray]] = None,
    return_witnesses: bool = False,
    stats: Optional[PruneStats] = None,
    deadline: Optional[float] = None,
    use_lp_core: Optional[bool] = None,
    random_budget: int = 4_000_000,
):
    """Indices of the useful vectors of ``alphas`` (sorted, into the input).

    Args:
        alphas: ``[K, S]`` α-vectors.
        actions: optional ``[K]`` action labels. Pruning depends on the vectors
            only; labels are accepted so callers can pass them along, and a
            vector repeated with different labels keeps its first copy.
        tol: a vector is kept only if it beats the others by at least ``tol``
            at some belief (default 5.01e-7, see the module docstring).
        points: optional ``[P, S]`` beliefs (or a list of such arrays, tried
            in order) to try before any LP; the best vector at each (when it
            wins by more than ``tol``) is kept at once.
        return_witnesses: also return ``[len(kept), S]`` witness beliefs, one
            per kept vector (a belief where it is best).
        stats: a :class:`PruneStats` to add counters to.
        deadline: ``time.perf_counter()`` value after which
            :class:`PruneTimeout` is raised: checked before every LP, and about every
            millisecond of work in the steps before the LPs (sorting, dominance, seed
            points, the first filter), so a prune overruns it by at most one LP.
        use_lp_core: accepted for compatibility and ignored: there is one LP
            solver now, the kernel's own (it chose between HiGHS models before).
        random_budget: about how many (vector, random belief) values to try
            before the LPs (0: none). Changes the work, and at most which vectors
            on the tolerance boundary (winning by < ``tol`` against the final set)
            are kept: the witnesses they yield seed later prunes.

    Returns:
        ``kept`` (int array), or ``(kept, witnesses)`` with ``return_witnesses``.

    Raises:
        ValueError: ``alphas`` is not a finite 2-D array, ``points`` are not finite
            ``[P, S]`` arrays, or ``tol`` is negative (the message says which).
    """
    A = np.ascontiguousarray(alphas, dtype=float)
    if A.ndim != 2:
        raise ValueError(f"alphas must be a [K, S] array, got shape {A.shape}")
    if tol < 0:
        raise ValueError(f"tol must be >= 0, got {tol}")
    if actions is not None and len(actions) != A.shape[0]:
        raise ValueError(f"{len(actions)} action labels for {A.shape[0]} vectors")
    K, S = A.shape
    if points is None:
        P: Optional[tuple] = None
    elif isinstance(points, (list, tuple)):  # several sets of points, tried in order (no vstack)
        P = tuple(np.ascontiguousarray(p, dtype=float) for p in points)
    else:
        P = (np.ascontiguousarray(points, dtype=float),)
    kept = np.empty(K, dtype=np.int64)
    witnesses = np.empty((K, S))
    # (the kernel checks finiteness and shapes, and raises ValueError naming what is wrong)
    n, lps, lp_witnesses, lp_resolves, lp_failures = _prune.prune(A, float(tol), P, int(random_budget), _random_beliefs,
                                        0.0 if deadline is None else float(deadline), kept, witnesses)
    if n < 0:
        raise PruneTimeout()
    if stats is not None:
        stats.candidates += K
        stats.kept += n
        stats.lps += lps
        stats.lp_witnesses += lp_witnesses
        stats.lp_resolves += lp_resolves
        stats.lp_failures += lp_failures
    if return_witnesses:
        return kept[:n], witnesses[:n]
    return kept[:n]
