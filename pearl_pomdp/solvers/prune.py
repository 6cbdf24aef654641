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
   state is dropped (vectorised numpy).
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

The LPs are solved by HiGHS, the solver behind ``scipy.optimize.linprog(
method="highs")``. Only the objective changes from one candidate to the next
and ``K`` only grows, so one HiGHS model is kept per prune and warm-started
(rows are appended, the cost vector is swapped): about 7x less overhead per
LP than a fresh ``linprog`` call. The incremental model uses HiGHS's own
``highspy`` bindings, or scipy's bundled copy (``scipy.optimize._highspy``)
when ``highspy`` is not installed, imported on the first LP; if neither is
there, every LP goes through ``linprog(method="highs")`` instead, with the
same result.

Array convention: ``alphas`` is ``[K, S]``, one vector per row.
"""
from __future__ import annotations

import time
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np

_highs_core = None  # the HiGHS bindings, imported on first use (see _load_highs)
_HAVE_HIGHS_CORE: Optional[bool] = None  # unknown until _load_highs has run


def _load_highs() -> bool:
    """Import HiGHS's Python bindings on first use; True when an incremental model is available.

    ``highspy`` (HiGHS's own package) imports in ~50 ms; scipy's bundled copy
    (``scipy.optimize._highspy``, private, hence the fallback order) drags in all
    of ``scipy.optimize`` (~0.3 s), which a two-state model — solved in closed
    form — or a command that never prunes should not pay. Both expose the same
    raw ``_Highs`` class (the ``highspy.Highs`` wrapper prints a banner on stdout).
    """
    global _highs_core, _HAVE_HIGHS_CORE
    if _HAVE_HIGHS_CORE is None:
        _HAVE_HIGHS_CORE = False
        for name in ("highspy._core", "scipy.optimize._highspy._core"):
            try:
                import importlib

                core = importlib.import_module(name)
            except Exception:  # pragma: no cover - depends on what is installed
                continue
            if hasattr(core, "_Highs"):
                _highs_core, _HAVE_HIGHS_CORE = core, True
                break
    return bool(_HAVE_HIGHS_CORE)

#: A vector must win by at least this much somewhere (pomdp-solve's effective threshold, see above).
DEFAULT_TOL = 5.01e-7

__all__ = ["prune", "PruneStats", "PruneTimeout", "pointwise_dominated", "DEFAULT_TOL"]


class PruneTimeout(Exception):
    """Raised inside :func:`prune` when its ``deadline`` (``time.perf_counter()`` value) passes."""


class PruneStats:
    """Counters a caller can pass to :func:`prune` to see where the work went."""

    def __init__(self) -> None:
        self.lps = 0  #: linear programmes solved
        self.lp_witnesses = 0  #: LPs that found a witness
        self.candidates = 0  #: vectors given to prune in total
        self.kept = 0  #: vectors kept in total

    def as_dict(self) -> dict:
        return {"lps": self.lps, "lp_witnesses": self.lp_witnesses,
                "candidates": self.candidates, "kept": self.kept}


# ---------------------------------------------------------------------- LP
#: Idle HiGHS models by number of states: building one (the object, its options and
#: S + 1 rows) costs ~0.2 ms, which a solve of many small prunes would pay per prune.
_IDLE_HIGHS: Dict[int, list] = {}


def _take_highs(S: int):
    """A HiGHS model of the witness LP with no kept-vector columns yet: an idle one
    (columns deleted, solver data cleared, so it solves exactly as a new one) or a new one."""
    idle = _IDLE_HIGHS.get(S)
    if idle:
        return idle.pop()
    h = _highs_core._Highs()
    h.setOptionValue("output_flag", False)
    h.setOptionValue("presolve", "off")
    # One thread: these LPs have S + 1 rows, and HiGHS's thread pool costs more per
    # run() (about 40 µs on an unchanged model) than a small LP's pivots.
    h.setOptionValue("threads", 1)
    # Tighter than HiGHS's 1e-7 defaults, below the decision threshold.
    h.setOptionValue("primal_feasibility_tolerance", 1e-10)
    h.setOptionValue("dual_feasibility_tolerance", 1e-10)
    inf = _highs_core.kHighsInf
    h.addVar(-inf, inf)  # t
    h.changeColCost(0, 1.0)
    one = np.array([0], dtype=np.int32)
    for _ in range(S):
        h.addRow(0.0, inf, 1, one, np.ones(1))
    h.addRow(1.0, 1.0, 0, np.zeros(0, dtype=np.int32), np.zeros(0))
    return h


def _give_back_highs(S: int, h) -> None:
    """Reset ``h`` to the state :func:`_take_highs` builds and keep it (a few per size)."""
    n = h.getNumCol()
    if n > 1:
        h.deleteCols(n - 1, np.arange(1, n, dtype=np.int32))
    h.clearSolver()  # no basis from the last prune: the next one starts as a new model would
    for s in range(S):
        h.changeRowBounds(s, 0.0, _highs_core.kHighsInf)
    idle = _IDLE_HIGHS.setdefault(S, [])
    if len(idle) < 2 and len(_IDLE_HIGHS) <= 16:
        idle.append(h)


class _WitnessLP:
    """``δ* = max_b c·b − max_{k∈K} α_k·b`` over the belief simplex, for many ``c`` and a growing ``K``.

    Solved in its dual form, which has ``S + 1`` rows however large ``K`` is::

        min t   s.t.   Σ_k λ_k α_k(s) + t ≥ c(s)  (s = 0 … S−1),   Σ_k λ_k = 1,   λ ≥ 0, t free.

    By LP duality its optimum is ``δ*`` (``c`` is beaten, up to ``t``, by a
    convex combination of kept vectors), and the duals of the ``S`` state
    rows are the primal optimum ``b*`` — the witness. A candidate changes only
    the row bounds and a kept vector adds a column, so HiGHS warm-starts.
    """

    def __init__(self, num_states: int, use_core: Optional[bool] = None) -> None:
        self.S = num_states
        # Two states: solve exactly at the envelope's breakpoints (see _breakpoints_2),
        # unless plain linprog was asked for.
        self.exact_2 = use_core is not False
        self._bp: Optional[tuple] = None
        self.rows: List[np.ndarray] = []
        self._col_index = np.arange(num_states + 1, dtype=np.int32)
        if self.S == 2 and self.exact_2:
            self.use_core = False  # solved in closed form, no LP model needed
        else:
            self.use_core = use_core is not False and _load_highs()
        if self.use_core:
            inf = _highs_core.kHighsInf
            self._inf = inf
            self._infs = np.full(num_states, inf)
            self._h = _take_highs(num_states)
            self._bulk_bounds = hasattr(self._h, "changeRowsBounds")
            self._optimal = _highs_core.HighsModelStatus.kOptimal

    def release(self) -> None:
        """Hand the HiGHS model back for the next prune with as many states (see :func:`_take_highs`)."""
        if self.use_core and self._h is not None:
            _give_back_highs(self.S, self._h)
            self._h = None

    def add(self, alpha: np.ndarray) -> None:
        """Add a newly kept vector (a column ``λ_k``)."""
        alpha = np.asarray(alpha, dtype=float)
        self.rows.append(np.append(alpha, -1.0))
        if self.use_core:
            self._h.addCol(0.0, 0.0, self._inf, self.S + 1, self._col_index, np.append(alpha, 1.0))

    def add_many(self, alphas: np.ndarray) -> None:
        """:meth:`add` for every row of ``alphas`` (one HiGHS call)."""
        n = alphas.shape[0]
        if n == 0:
            return
        ext = np.empty((n, self.S + 1))
        ext[:, :self.S] = alphas
        ext[:, self.S] = -1.0
        self.rows.extend(ext.copy())
        if self.use_core:
            ext[:, self.S] = 1.0
            S1 = self.S + 1
            self._h.addCols(n, np.zeros(n), np.zeros(n), np.full(n, self._inf), n * S1,
                            np.arange(0, n * S1, S1, dtype=np.int32), np.tile(self._col_index, n), ext.ravel())

    def _breakpoints_2(self) -> Tuple[np.ndarray, np.ndarray]:
        """Two states: candidate optima ``p`` (b = (1−p, p)) and ``V_K(p)`` there.

        ``c·b − V_K(b)`` is linear minus convex piecewise-linear in ``p``, so its
        maximum over [0, 1] lies at an end or where two kept lines cross: the
        LP is solved exactly by checking those points (no simplex needed).
        """
        if self._bp is None or self._bp[2] != len(self.rows):
            K = np.vstack(self.rows)[:, :2]
            a0, slope = K[:, 0], K[:, 1] - K[:, 0]
            i, j = np.triu_indices(K.shape[0], 1)
            den = slope[i] - slope[j]
            ok = den != 0.0
            p = (a0[j][ok] - a0[i][ok]) / den[ok]
            inside = (p > 0.0) & (p < 1.0)
            ii, p = i[ok][inside], p[inside]
            p = np.concatenate([[0.0, 1.0], p])
            V = (a0[None, :] + slope[None, :] * p[:, None]).max(axis=1)
            # Only the envelope's breakpoints matter: a crossing below the envelope is a
            # point where V is linear, so c·b − V there never beats both neighbouring vertices.
            on = np.ones(p.size, dtype=bool)
            on[2:] = a0[ii] + slope[ii] * p[2:] >= V[2:] - 1e-12 * (1.0 + np.abs(V[2:]))
            self._bp = (p[on], V[on], len(self.rows))
        return self._bp[0], self._bp[1]

    @property
    def closed_form(self) -> bool:
        """True when the LPs are solved exactly at the envelope's breakpoints (two states)."""
        return self.S == 2 and self.exact_2

    def solve_many(self, C: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
        """Two states only: :meth:`solve` for every row of ``C [N, 2]`` at once (same arithmetic).

        Returns ``(δ* [N], b* [N, 2])``.
        """
        if not (self.closed_form and self.rows):
            raise RuntimeError("solve_many needs two states and at least one kept vector")
        p, V = self._breakpoints_2()
        g = C[:, 0:1] + (C[:, 1:2] - C[:, 0:1]) * p[None, :] - V[None, :]
        k = np.argmax(g, axis=1)
        pk = p[k]
        return g[np.arange(C.shape[0]), k], np.stack([1.0 - pk, pk], axis=1)

    def solve(self, c: np.ndarray, need_below: Optional[float] = None) -> Tuple[float, Optional[np.ndarray]]:
        """Return ``(δ*, b*)``: the largest advantage of ``c`` over the kept set and where it is.

        With ``need_below``, ``b*`` is not fetched (``None``) when ``δ* < need_below``.
        """
        if self.S == 2 and self.exact_2 and self.rows:
            p, V = self._breakpoints_2()
            g = c[0] + (c[1] - c[0]) * p - V
            k = int(np.argmax(g))
            return float(g[k]), np.array([1.0 - p[k], p[k]])
        if self.use_core:
            h = self._h
            if self._bulk_bounds:
                h.changeRowsBounds(self.S, self._col_index[:self.S], np.asarray(c, dtype=float), self._infs)
            else:  # (scipy's bundled copy has no changeRowsBounds)
                for s in range(self.S):
                    h.changeRowBounds(s, float(c[s]), self._inf)
            h.run()
            if h.getModelStatus() == self._optimal:
                delta = float(h.getObjectiveValue())
                if need_below is not None and delta < need_below:
                    return delta, None  # fetching the solution costs O(K): skip it
                return delta, np.asarray(h.getSolution().row_dual[:self.S])
            # A numerically troubled warm start: fall back to a cold linprog solve.
        return self._solve_linprog(c)

    def _solve_linprog(self, c: np.ndarray) -> Tuple[float, np.ndarray]:
        """The primal form through ``scipy.optimize.linprog(method="highs")``:
        ``max c·b − w  s.t.  α_k·b − w ≤ 0,  Σ b = 1,  b ≥ 0``."""
        from scipy.optimize import linprog

        S = self.S
        res = linprog(
            np.append(-np.asarray(c, dtype=float), 1.0),
            A_ub=np.vstack(self.rows), b_ub=np.zeros(len(self.rows)),
            A_eq=np.append(np.ones(S), 0.0)[None, :], b_eq=[1.0],
            bounds=[(0.0, 1.0)] * S + [(None, None)], method="highs",
            options={"primal_feasibility_tolerance": 1e-10, "dual_feasibility_tolerance": 1e-10},
        )
        if res.status != 0:
            # Cannot certify a witness: treat as none (pomdp-solve does the same on LP trouble).
            return -np.inf, np.full(S, 1.0 / S)
        return float(-res.fun), np.asarray(res.x[:S])


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
            out[i:i + step] = (by[None, :, :] + slack > blk[:, None, :]).all(axis=2).any(axis=1)
        else:
            out[i:i + step] = (by[None, :, :] >= blk[:, None, :]).all(axis=2).any(axis=1)
    return out


def _best_index(alphas: np.ndarray, idx: np.ndarray, b: np.ndarray, tol: float,
                lexrank: Optional[np.ndarray] = None) -> Tuple[int, float]:
    """Best of ``alphas[idx]`` at ``b``; values within ``tol`` of the best tie and the
    lexicographically largest vector wins (pomdp-solve's tie-break). Returns (index, value).

    ``lexrank[i]`` (optional) is the lexicographic rank of row ``i`` of ``alphas``.
    """
    vals = alphas[idx] @ b
    m = vals.max()
    tied = idx[vals >= m - tol]
    if tied.size == 1:
        return int(tied[0]), float(m)
    if lexrank is not None:
        return int(tied[np.argmax(lexrank[tied])]), float(m)
    rows = alphas[tied]
    order = np.lexsort(rows.T[::-1])  # primary key: state 0
    return int(tied[order[-1]]), float(m)


#: Sets with ``K·K·S`` up to this use the fused duplicate/dominance step of :func:`prune`.
_FUSED_LIMIT = 200_000
_LOWER = np.tril(np.ones((448, 448), dtype=bool), -1)  # _LOWER[i, j]: j < i (K ≤ 447 when fused)

_EYE: dict = {}
_RANDOM_BELIEFS: dict = {}
_RANDOM_BELIEFS_SIZE = 0  # floats held by _RANDOM_BELIEFS


def _eye(S: int) -> np.ndarray:
    """``np.eye(S)``, read-only (witnesses are views of its rows), made once per small size."""
    e = _EYE.get(S)
    if e is None:
        e = np.eye(S)
        e.flags.writeable = False
        if S <= 512:  # (a large identity is cheap to build next to that prune's work)
            _EYE[S] = e
    return e


def _random_beliefs(seed: int, S: int, n: int) -> np.ndarray:
    """``n`` Dirichlet(1) beliefs from ``default_rng(seed)``, cached: the same numbers
    for the same arguments (a prune's result must not depend on earlier calls), without
    paying a new generator per prune."""
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


def _lex_order(alphas: np.ndarray) -> np.ndarray:
    """Row indices in lexicographic order (state 0 first); stable, so equal rows keep input order."""
    return np.lexsort(alphas.T[::-1])


def _unique_rows_first(alphas: np.ndarray, order: np.ndarray) -> np.ndarray:
    """Indices of the first occurrence of each distinct row, in input order (``order`` from :func:`_lex_order`)."""
    srt = alphas[order]
    new_group = np.ones(len(order), dtype=bool)
    new_group[1:] = (srt[1:] != srt[:-1]).any(axis=1)
    return np.sort(order[new_group])


def _best_at_corners(alphas: np.ndarray, idx: np.ndarray, tol: float) -> Tuple[np.ndarray, Optional[np.ndarray]]:
    """:func:`_best_index` at every corner of the simplex at once (``idx``: distinct rows).

    Returns ``(best [S], lexrank)``; ``lexrank`` (ranks of the rows ``idx``, as for
    :func:`_best_index`) is computed only when some corner has a tie to break, else None.
    """
    vals = alphas[idx]  # the value at corner s is component s
    tied = vals >= vals.max(axis=0) - tol
    if tied.sum(axis=0).max() == 1:  # no ties: the best is the only one within tol
        return idx[np.argmax(vals, axis=0)], None
    # Distinct rows: their relative lexicographic order is the same as among all rows.
    lexrank = np.full(alphas.shape[0], -1, dtype=np.int64)
    lexrank[idx[_lex_order(vals)]] = np.arange(idx.size)
    return idx[np.argmax(np.where(tied, lexrank[idx][:, None], -1), axis=0)], lexrank


# ----------------------------------------------------------------- prune
def prune(
    alphas: np.ndarray,
    actions: Optional[Sequence[int]] = None,
    tol: float = DEFAULT_TOL,
    points: Optional[np.ndarray] = None,
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
        points: optional ``[P, S]`` beliefs to try before any LP; the best
            vector at each (when it wins by more than ``tol``) is kept at once.
        return_witnesses: also return ``[len(kept), S]`` witness beliefs, one
            per kept vector (a belief where it is best).
        stats: a :class:`PruneStats` to add counters to.
        deadline: ``time.perf_counter()`` value after which
            :class:`PruneTimeout` is raised (checked between LPs).
        use_lp_core: force the incremental HiGHS model (True) or plain
            ``linprog`` (False); default: incremental when available.
        random_budget: about how many (vector, random belief) values to try
            before the LPs (0: none). Changes only the work, not the result.

    Returns:
        ``kept`` (int array), or ``(kept, witnesses)`` with ``return_witnesses``.

    Raises:
        ValueError: ``alphas`` is not a finite 2-D array or ``tol`` is negative.
    """
    A = np.asarray(alphas, dtype=float)
    if A.ndim != 2:
        raise ValueError(f"alphas must be a [K, S] array, got shape {A.shape}")
    if not np.isfinite(A).all():
        raise ValueError("alphas has a non-finite entry")
    if tol < 0:
        raise ValueError(f"tol must be >= 0, got {tol}")
    if actions is not None and len(actions) != A.shape[0]:
        raise ValueError(f"{len(actions)} action labels for {A.shape[0]} vectors")
    K, S = A.shape
    if stats is not None:
        stats.candidates += K
    if K <= 1:
        kept = np.arange(K)
        if stats is not None:
            stats.kept += K
        if return_witnesses:
            w = np.zeros((K, S))
            if K:
                w[0, 0] = 1.0
            return kept, w
        return kept

    # 1. duplicates; 2. (weak) pointwise dominance among what is left.
    if K * K * S <= _FUSED_LIMIT:
        # Small sets (most prunes of a long solve): both steps from one comparison matrix,
        # ge[i, j] = "row j ≥ row i everywhere"; i goes if some j dominates it strictly
        # or equals it and comes first. The same rows as the two steps below, in fewer
        # numpy calls (their fixed cost is what a small prune pays).
        ge: np.ndarray = np.asarray((A[None, :, :] >= A[:, None, :]).all(axis=2))
        np.fill_diagonal(ge, False)
        cand = np.flatnonzero(~(ge & (~ge.T | _LOWER[:K, :K])).any(axis=1))
    else:
        order = _lex_order(A)
        cand = _unique_rows_first(A, order)
        if cand.size > 1:
            cand = cand[~_dominated_within(A[cand])]

    # 3. witnesses without LPs: simplex corners (pomdp-solve), then given points.
    is_kept = np.zeros(K, dtype=bool)
    kept_order: List[int] = []
    witness: dict = {}

    def keep(i: int, b: np.ndarray) -> None:
        is_kept[i] = True
        kept_order.append(i)
        witness[i] = b

    eye = _eye(S)
    # (lexrank: pomdp-solve's lexicographic tie-break, None until a tie needs it)
    corner_best, lexrank = _best_at_corners(A, cand, tol)
    for s, i in enumerate(corner_best):
        if not is_kept[i]:
            keep(int(i), eye[s])
    # Random beliefs too (seeded, so results are reproducible): a vector that
    # wins clearly at one needs no LP. Their number keeps C·P bounded.
    n_random = int(min(max(4 * S, 64), max(0, random_budget // max(1, cand.size))))
    P_parts = [] if points is None or not len(points) else [np.asarray(points, dtype=float)]
    if n_random > 0 and cand.size > max(S, len(kept_order) + sum(len(p) for p in P_parts)):
        P_parts.append(_random_beliefs(cand.size, S, n_random))
    if P_parts and len(kept_order) < cand.size:  # (nothing left to find when all are kept)
        P = np.vstack(P_parts)
        vals = A[cand] @ P.T  # [C, P]
        if cand.size >= 2:
            top2 = np.partition(vals, vals.shape[0] - 2, axis=0)[-2:]
            clear = top2[1] - top2[0] > tol  # strict winner at that point
        else:
            clear = np.ones(P.shape[0], dtype=bool)
        best = cand[np.argmax(vals, axis=0)]
        pts = np.flatnonzero(clear)
        winners, first = np.unique(best[pts], return_index=True)  # one point per new winner
        for i, p in zip(winners.tolist(), pts[first].tolist()):
            if not is_kept[i]:
                keep(i, P[p])

    # 4. Lark's filter over the rest, one LP per candidate.
    remaining = [int(i) for i in cand if not is_kept[i]]
    if remaining:
        # The kept vectors, in a growing buffer (a row per kept vector).
        KA = np.empty((len(kept_order) + len(remaining), S))
        nk = len(kept_order)
        KA[:nk] = A[kept_order]
        # Cheap pass first: a candidate within tol of a kept vector in every state
        # has δ* < tol, so the LP would drop it too.
        rem = np.array(remaining)
        rem = rem[~pointwise_dominated(A[rem], KA[:nk], slack=tol)]
        lp = _WitnessLP(S, use_core=use_lp_core)
        lp.add_many(A[kept_order])
        queue = list(rem)
        alive = np.zeros(K, dtype=bool)
        alive[rem] = True
        filtered_upto = nk  # kept rows already used by the pointwise filter
        pos = 0
        if lp.closed_form:
            # Two states: every candidate's LP at once (same arithmetic, same order of events).
            _lark_two_states(A, queue, alive, lp, KA, nk, tol, lexrank, keep, stats, deadline)
            queue = []
        while pos < len(queue):
            c = queue[pos]
            pos += 1
            if not alive[c]:
                continue
            if deadline is not None and time.perf_counter() > deadline:
                raise PruneTimeout()
            # Re-filter against the vectors kept since the last pass, in batches.
            if nk - filtered_upto >= max(1, nk // 8):
                live = np.flatnonzero(alive)
                dom = pointwise_dominated(A[live], KA[filtered_upto:nk], slack=tol)
                alive[live[dom]] = False
                filtered_upto = nk
                if not alive[c]:
                    continue
            delta, b = lp.solve(A[c], need_below=tol)
            if stats is not None:
                stats.lps += 1
            if delta < tol:
                alive[c] = False
                continue
            b = np.clip(b, 0.0, None)  # type: ignore[arg-type]  # the LP returned a witness (not None) here
            b = b / b.sum()
            j, vbest = _best_index(A, np.flatnonzero(alive), b, tol, lexrank)
            # The LP's witness must hold up in plain arithmetic; otherwise no witness.
            if vbest - float(np.max(KA[:nk] @ b)) <= 0.0:
                alive[c] = False
                continue
            if stats is not None:
                stats.lp_witnesses += 1
            alive[j] = False
            keep(j, b)
            KA[nk] = A[j]
            nk += 1
            lp.add(A[j])
            if j != c:
                queue.append(c)  # c still waits for its own verdict
        lp.release()  # (after a PruneTimeout the model is simply dropped)

    kept = np.array(sorted(kept_order), dtype=np.int64)
    if stats is not None:
        stats.kept += kept.size
    if return_witnesses:
        return kept, np.array([witness[i] for i in kept]).reshape(kept.size, S)
    return kept


def _lark_two_states(A, queue, alive, lp, KA, nk, tol, lexrank, keep, stats, deadline) -> None:
    """Lark's filter of :func:`prune` for two states, with each round's LPs solved together.

    The sequential loop takes the queue in order: a candidate with ``δ* < tol``
    is dropped, the first with ``δ* ≥ tol`` yields a witness (and the kept set
    grows). Between two witnesses the kept set is fixed, so the LPs of all
    waiting candidates are solved at once (closed form, :meth:`_WitnessLP.solve_many`);
    those before the first witness-giving one are dropped, exactly as the loop
    would, and the rest wait for the grown set. The pointwise re-filter runs at
    the same moments as in the loop, so the kept vectors (and their order) are
    the loop's.
    """
    filtered_upto = nk
    rest = [c for c in queue if alive[c]]
    while rest:
        if deadline is not None and time.perf_counter() > deadline:
            raise PruneTimeout()
        if nk - filtered_upto >= max(1, nk // 8):
            live = np.flatnonzero(alive)
            dom = pointwise_dominated(A[live], KA[filtered_upto:nk], slack=tol)
            alive[live[dom]] = False
            filtered_upto = nk
            rest = [c for c in rest if alive[c]]
            if not rest:
                break
        delta, where = lp.solve_many(A[rest])
        hits = np.flatnonzero(delta >= tol)
        first = int(hits[0]) if hits.size else len(rest)
        if stats is not None:
            stats.lps += min(first + 1, len(rest))  # the LPs the sequential loop would solve
        alive[rest[:first]] = False
        if first == len(rest):
            break
        c = rest[first]
        b = where[first]
        j, vbest = _best_index(A, np.flatnonzero(alive), b, tol, lexrank)
        tail = rest[first + 1:]
        if vbest - float(np.max(KA[:nk] @ b)) <= 0.0:  # the witness must hold up in plain arithmetic
            alive[c] = False
            rest = tail
            continue
        if stats is not None:
            stats.lp_witnesses += 1
        alive[j] = False
        keep(j, b)
        KA[nk] = A[j]
        nk += 1
        lp.add(A[j])
        rest = [x for x in tail if alive[x]] + ([c] if j != c else [])


def _dominated_within(B: np.ndarray, chunk_elems: int = 4_000_000) -> np.ndarray:
    """Mask of rows of ``B`` (distinct rows) weakly dominated by another row of ``B``.

    For large sets the full ``N²`` comparison is too costly; then only the
    rows that are best at some corner are used as dominators (the rest is
    left to the kept-set filter and the LPs).
    """
    N, S = B.shape
    # With two states the LP is solved in closed form, so a cheap dominator set is enough.
    if N * N * S <= (200_000 if S == 2 else 10_000_000):
        # Every row against every row: the only exact self-match of a row is itself.
        ge: np.ndarray = np.asarray((B[None, :, :] >= B[:, None, :]).all(axis=2))  # ge[i, j]: row j ≥ row i everywhere
        np.fill_diagonal(ge, False)
        return np.asarray(ge.any(axis=1))
    by = B[np.unique(np.argmax(B, axis=0))]
    out = np.zeros(N, dtype=bool)
    step = max(1, chunk_elems // max(1, by.shape[0] * S))
    for i in range(0, N, step):
        blk = B[i:i + step]
        ge = (by[None, :, :] >= blk[:, None, :]).all(axis=2)  # [blk, M]
        # A row is never dominated by itself: distinct rows, so ≥ everywhere and
        # equal means identical; exclude exact self-matches.
        eq = (by[None, :, :] == blk[:, None, :]).all(axis=2)
        out[i:i + step] = (ge & ~eq).any(axis=1)
    return out
