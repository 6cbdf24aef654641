"""The Bayes filter over a flat POMDP's states (docs/design.md §2, eq. 5 of Pineau & Thrun).

After doing action ``a`` in belief ``b`` and observing ``o``::

    b'(s') = η · O[a, s', o] · Σ_s T[a][s, s'] · b(s)

with ``η = 1 / P(o | b, a)`` and ``P(o | b, a) = Σ_{s'} O[a, s', o] · Σ_s T[a][s, s'] b(s)``.

Array conventions (as everywhere in the project): ``T[a][s, s'] = P(s' | s, a)``
(dense ``S×S`` or scipy CSR), ``O[a, s', o] = P(o | s', a)`` (``A×S×Z``), beliefs are
``[S]`` float arrays that sum to 1.

**Zero-likelihood recovery.** If the model says the observation cannot happen under the
current belief (``P(o | b, a) < MIN_LIKELIHOOD``, i.e. zero up to floating-point
underflow), eq. 5 divides 0 by 0. The filter then does not raise and never returns NaN or
an all-zero vector; instead it

1. mixes the prediction with a uniform floor, ``p̃ = (1 − ε) p + ε / S`` (``ε = floor``,
   default ``1e-6``), which says "the belief was wrong; any state is possible", and
   applies eq. 5 to ``p̃``. With an exactly-zero likelihood this gives the states that can
   emit ``o`` weighted by ``O[a, :, o]`` (the observation decides);
2. if even that is zero (``O[a, :, o]`` is zero for every state: the observation can never
   follow action ``a``), it ignores the observation and returns ``p̃``.

Each recovery increments :attr:`BeliefFilter.zero_likelihood_count` and logs a warning on
the ``pearl_pomdp.belief`` logger naming the action and observation (the first 10, then
every 1000th, so that a long simulation does not flood the log), so a node can report it;
nothing is recovered silently.
"""
from __future__ import annotations

import logging
import numbers
import weakref
from typing import Dict, Optional, Union

import numpy as np
import scipy.sparse as sp

from pearl_pomdp.errors import BeliefError
from pearl_pomdp.model.pomdp import LARGE_O_ENTRIES, Pomdp

__all__ = ["BeliefFilter", "update_belief", "MIN_LIKELIHOOD", "SUM_TOLERANCE"]

log = logging.getLogger(__name__)

#: Below this, ``P(o | b, a)`` counts as zero (the smallest normal double): the recovery applies.
MIN_LIKELIHOOD = float(np.finfo(float).tiny)
#: How far an input belief may be from summing to 1 (used as given; the output is normalised).
SUM_TOLERANCE = 1e-6
#: How negative an input entry may be (rounding noise), before it is an error.
NEGATIVE_TOLERANCE = 1e-12
#: Most matrix entries the fused per-(action, observation) operators may hold in total.
FUSED_LIMIT = 20_000_000
#: Most entries of ``O`` for which the filter keeps its own contiguous copies of ``Tᵀ`` and ``O``
#: (beyond it: views of the model's arrays; see :class:`BeliefFilter`).
VIEW_LIMIT = LARGE_O_ENTRIES
#: The first this many zero-likelihood recoveries are logged one by one, then every 1000th.
LOG_FIRST = 10

try:  # scipy's compiled CSR mat-vec, called directly: a third of the cost of ``csr @ x`` for
    # the small matrices of a belief update. Checked against ``@`` when first used; any
    # difference or error falls back to the public operator.
    from scipy.sparse._sparsetools import csr_matvec as _csr_matvec
except ImportError:  # pragma: no cover - depends on the scipy version
    _csr_matvec = None
_DIRECT_MATVEC: Dict[str, Optional[bool]] = {"ok": None}
_sum = np.add.reduce
_min = np.minimum.reduce


def _transposed_csr(Ta) -> sp.csr_matrix:
    """``T[a]ᵀ`` as a canonical CSR matrix (sorted indices, no duplicates, no stored zeros). A dense
    ``T[a]`` is read once, row by row of its transpose (a third faster than a COO detour, and a
    filter is built for every episode of a study)."""
    if sp.issparse(Ta):
        TTa = sp.csr_matrix(Ta, dtype=float).T.tocsr()
        TTa.sum_duplicates()
        TTa.eliminate_zeros()
        TTa.sort_indices()
        return TTa
    transposed = np.asarray(Ta, dtype=float).T
    nonzero = transposed != 0
    rows, cols = np.nonzero(nonzero)                  # row-major: by row, then by column
    indptr = np.zeros(transposed.shape[0] + 1, dtype=np.int32)
    np.cumsum(np.bincount(rows, minlength=transposed.shape[0]), out=indptr[1:])
    TTa = sp.csr_matrix((transposed[nonzero], cols.astype(np.int32), indptr), shape=transposed.shape)
    TTa.has_sorted_indices = True
    return TTa


def _matvec(M, x: np.ndarray) -> np.ndarray:
    """``M @ x`` for a dense array or a CSR matrix with float64 data (``x`` float64, contiguous)."""
    if isinstance(M, np.ndarray) or M.format != "csr":
        return M @ x
    ok = _DIRECT_MATVEC["ok"]
    if ok:
        y = np.zeros(M.shape[0])
        _csr_matvec(M.shape[0], M.shape[1], M.indptr, M.indices, M.data, x, y)
        return y
    if ok is None:
        _DIRECT_MATVEC["ok"] = _check_direct_matvec()
        return _matvec(M, x)
    return M @ x


def _check_direct_matvec() -> bool:
    if _csr_matvec is None:
        return False
    try:
        M = sp.csr_matrix(np.array([[0.5, 0.0, 0.25], [0.0, 2.0, 0.0]]))
        x = np.array([1.0, 3.0, 4.0])
        y = np.zeros(2)
        _csr_matvec(2, 3, M.indptr, M.indices, M.data, x, y)
        return bool(np.array_equal(y, M @ x))
    except Exception:  # noqa: BLE001 - any failure means: use the public operator
        return False


Index = Union[int, np.integer, str]

#: id(model) -> (weak reference to the model, what the operators were built from, the operators):
#: the filters of one model share its operators (see :class:`BeliefFilter`).
_SHARED_OPERATORS: Dict[int, tuple] = {}


def _forget(key: int):
    """The callback that drops a model's shared operators when the model is collected."""
    return lambda _ref: _SHARED_OPERATORS.pop(key, None)


def _same_key(built: tuple, now: tuple) -> bool:
    """Whether operators built for ``built`` (views?, FUSED_LIMIT, T's matrices, O) fit ``now``: the
    same settings and the very same T and O objects."""
    return built[:2] == now[:2] and len(built[2]) == len(now[2]) and \
        all(x is y for x, y in zip(built[2], now[2])) and built[3] is now[3]


class BeliefFilter:
    """Exact discrete Bayes filter for one :class:`~pearl_pomdp.model.pomdp.Pomdp`.

    Construction precomputes, per action, ``T[a]ᵀ`` in the cheaper of CSR or dense storage
    (CSR when ``S ≥ 64`` and T is at most 30 % full) and ``O`` as ``[A, Z, S]``. An update
    is one mat-vec with the fused operator ``diag(O[a, :, o]) · T[a]ᵀ`` (built for every
    ``(a, o)`` here; a few µs on a 576-state model), a sum and a division.
    :meth:`update` is pure: it never mutates its input.

    The filters of one model object share these operators: the first builds them (Pearl: ~60 ms),
    the next ones (a study's tracker per episode) reuse them while the model holds the same ``T``
    and ``O`` objects. Change a model's ``T`` or ``O`` in place after a filter was built on it and
    the next filter would not see it: build a new model (:meth:`Pomdp.create` copies) or assign
    new arrays instead.

    Args:
        model: the POMDP.
        floor: weight ``ε`` of the uniform floor in the zero-likelihood recovery.
        log_recoveries: log each recovery (first few, then every 1000th) on the
            ``pearl_pomdp.belief`` logger; the step loop turns this off because it reports
            the recovery itself (one message per event, with the node's name).

    Attributes:
        zero_likelihood_count: how many updates needed the recovery (see the module doc).
        updates: how many updates were done.
    """

    def __init__(self, model: Pomdp, floor: float = 1e-6, log_recoveries: bool = True):
        self.log_recoveries = bool(log_recoveries)
        if not 0.0 < floor < 1.0:
            raise ValueError(f"floor must be in (0, 1), got {floor}")
        self.model = model
        self.floor = float(floor)
        self.num_states = model.num_states
        self.num_actions = model.num_actions
        self.num_observations = model.num_observations
        # Past VIEW_LIMIT entries of O (the ward: 52M) the filter keeps views of the model's
        # arrays instead of copies: T[a]ᵀ as the CSC view of T[a]'s CSR, O[a, :, o] a strided
        # column. Slower per update (milliseconds there), but no second T and O in memory.
        self.views = model.O.size > VIEW_LIMIT
        key = (self.views, FUSED_LIMIT, list(model.T), model.O)
        shared = _SHARED_OPERATORS.get(id(model))
        if shared is not None and shared[0]() is model and _same_key(shared[1], key):
            ops = shared[2]
        else:
            ops = self._build(model, self.views)
            # Shared by the next filters on this model (a study builds one per episode); the entry
            # goes when the model does.
            _SHARED_OPERATORS[id(model)] = (weakref.ref(model, _forget(id(model))), key, ops)
        self._TT, self._T_rows, self._OT, self._fused_ok, self._M = ops
        self.zero_likelihood_count = 0
        self.updates = 0

    @staticmethod
    def _build(model: Pomdp, views: bool) -> tuple:
        """``(T[a]ᵀ per action, T[a] where T[a]ᵀ is its view, O as [A, Z, S], fused?, the fused
        operators or None)`` for ``model`` (see the class doc)."""
        S, A, Z = model.num_states, model.num_actions, model.num_observations
        TT = []
        # T[a] (CSR) where TT[a] is its CSC view, for update_batch's support-only product.
        T_rows: list = []
        stored = 0
        for Ta in model.T:
            nnz = Ta.nnz if sp.issparse(Ta) else int(np.count_nonzero(Ta))
            T_rows.append(None)
            if views and sp.issparse(Ta) and Ta.format == "csr":
                TTa = Ta.T                       # CSC, sharing T[a]'s arrays
                T_rows[-1] = Ta
                stored += TTa.nnz
            elif S >= 64 and nnz <= 0.3 * S * S:
                TTa = _transposed_csr(Ta)
                stored += TTa.nnz
            else:
                dense = Ta.toarray() if sp.issparse(Ta) else np.asarray(Ta, dtype=float)
                TTa = np.ascontiguousarray(dense.T)
                stored += S * S
            TT.append(TTa)
        # [A, Z, S]: O[a, :, o] as a contiguous row.
        OT = np.transpose(model.O, (0, 2, 1))
        if not views:
            OT = np.ascontiguousarray(OT)
        # Fused operators M[a][o] = diag(O[a, :, o]) · T[a]ᵀ: one mat-vec gives the
        # unnormalised posterior, and rows where O[a, s', o] = 0 drop out of the sparse
        # product. Built here (steady per-update latency), unless they would hold more than
        # FUSED_LIMIT entries; then the update multiplies by the column after the mat-vec.
        fused_ok = stored * Z <= FUSED_LIMIT and not views
        M = [[BeliefFilter._fused(OT[a, o], TT[a]) for o in range(Z)] for a in range(A)] if fused_ok else None
        return TT, T_rows, OT, fused_ok, M

    # ---------------------------------------------------------------- inputs
    def initial(self) -> np.ndarray:
        """A copy of the model's start belief ``b0`` (``[S]``)."""
        return np.array(self.model.b0, dtype=float)

    def check_belief(self, belief) -> np.ndarray:
        """Return ``belief`` as a float ``[S]`` array summing to 1, or raise :class:`BeliefError`.

        A belief within :data:`SUM_TOLERANCE` of 1 is accepted (and used as given; the
        update normalises its output anyway).
        """
        b = np.asarray(belief, dtype=float)
        S = self.num_states
        if b.shape != (S,):
            raise BeliefError(f"belief has shape {b.shape}, expected ({S},) for model '{self.model.name}' with {S} states")
        # The ufuncs' reduce directly: ndarray.sum/min add a Python-level wrapper per call.
        total = _sum(b)
        lowest = _min(b)
        # Written so that NaN fails both comparisons.
        if not lowest >= -NEGATIVE_TOLERANCE:
            if not np.isfinite(b).all():
                raise BeliefError(f"belief has a non-finite entry at state {self._state_of(~np.isfinite(b))}")
            raise BeliefError(f"belief has a negative entry {lowest:.6g} at state {self._state_of(b < -NEGATIVE_TOLERANCE)}")
        if not abs(total - 1.0) <= SUM_TOLERANCE:
            if not np.isfinite(b).all():
                raise BeliefError(f"belief has a non-finite entry at state {self._state_of(~np.isfinite(b))}")
            raise BeliefError(f"belief sums to {total:.9g}, expected 1 (within {SUM_TOLERANCE:g})")
        return b

    def _state_of(self, mask: np.ndarray) -> str:
        s = int(np.flatnonzero(mask)[0])
        return f"{s} ({self.model.states[s]!r})"

    def action_index(self, action: Index) -> int:
        """The index of ``action`` (an int index or an action name); :class:`BeliefError` if unknown."""
        if type(action) is int and 0 <= action < self.num_actions:  # the common case, fast
            return action
        return self._index(action, self.model.actions, "action")

    def observation_index(self, observation: Index) -> int:
        """The index of ``observation`` (an int index or a name); :class:`BeliefError` if unknown."""
        if type(observation) is int and 0 <= observation < self.num_observations:
            return observation
        return self._index(observation, self.model.observations, "observation")

    @staticmethod
    def _index(value: Index, names, kind: str) -> int:
        if isinstance(value, str):
            try:
                return names.index(value)
            except ValueError:
                shown = ", ".join(names[:12]) + (" …" if len(names) > 12 else "")
                raise BeliefError(f"unknown {kind} {value!r}; known: {shown}") from None
        if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Integral):
            raise BeliefError(f"{kind} must be an int index or a name, got {value!r} ({type(value).__name__})")
        i = int(value)
        if not 0 <= i < len(names):
            raise BeliefError(f"{kind} index {i} is out of range: the model has {len(names)} {kind}s (0..{len(names) - 1})")
        return i

    # ------------------------------------------------------------- the filter
    def predict(self, belief, action: Index) -> np.ndarray:
        """The predicted next-state distribution ``p(s') = Σ_s T[a][s, s'] b(s)`` (``[S]``)."""
        b = self.check_belief(belief)
        return self._predict(b, self.action_index(action))

    def _predict(self, b: np.ndarray, a: int) -> np.ndarray:
        return _matvec(self._TT[a], b)

    def observation_likelihood(self, belief, action: Index) -> np.ndarray:
        """``P(o | b, a)`` for every observation ``o`` (``[Z]``, sums to 1)."""
        b = self.check_belief(belief)
        a = self.action_index(action)
        return self._OT[a] @ self._predict(b, a)

    def update(self, belief, action: Index, observation: Index) -> np.ndarray:
        """Eq. 5: the belief after doing ``action`` in ``belief`` and observing ``observation``.

        Args:
            belief: ``[S]`` distribution (not modified).
            action: action index (or name).
            observation: observation index (or name).

        Returns:
            A new ``[S]`` array, non-negative and summing to 1. On a zero-likelihood
            observation the documented recovery applies (module doc) and
            :attr:`zero_likelihood_count` is incremented.

        Raises:
            BeliefError: malformed belief or unknown action/observation.
        """
        b = self.check_belief(belief)
        a = self.action_index(action)
        o = self.observation_index(observation)
        self.updates += 1
        if self._M is not None:   # the fused operators (built when they fit: _fused_ok)
            unnormalised = _matvec(self._M[a][o], b)
        else:
            unnormalised = self._OT[a, o] * _matvec(self._TT[a], b)
        likelihood = _sum(unnormalised)
        if likelihood >= MIN_LIKELIHOOD:
            unnormalised /= likelihood
            return unnormalised
        return self._recover(self._predict(b, a), a, o)

    @staticmethod
    def _fused(column: np.ndarray, TTa):
        """``diag(O[a, :, o]) · T[a]ᵀ`` (``column`` = ``O[a, :, o]``) in the storage of ``T[a]ᵀ``
        (zero rows dropped when sparse)."""
        if isinstance(TTa, np.ndarray):
            return np.ascontiguousarray(column[:, None] * TTa)
        # Row s' of T[a]ᵀ scaled by O[a, s', o]: each entry is the one product diag(O)·Tᵀ would
        # compute, without a diagonal matrix and a sparse product per (a, o): Pearl's filter (380
        # operators) takes 55 ms to build instead of 85, and a study builds one per episode.
        data = TTa.data * np.repeat(column, np.diff(TTa.indptr))
        M = sp.csr_matrix((data, TTa.indices.copy(), TTa.indptr.copy()), shape=TTa.shape)
        M.eliminate_zeros()
        M.sort_indices()
        return M

    def _recover(self, predicted: np.ndarray, a: int, o: int) -> np.ndarray:
        """Zero-likelihood recovery (module doc): uniform floor, then ignore ``o`` if still zero."""
        self.zero_likelihood_count += 1
        n = self.zero_likelihood_count
        # Every recovery is counted; the log shows the first LOG_FIRST, then every 1000th.
        loud = self.log_recoveries and (n <= LOG_FIRST or n % 1000 == 0)
        eps = self.floor
        floored = (1.0 - eps) * predicted + eps / self.num_states
        floored /= floored.sum()
        unnormalised = self._OT[a, o] * floored
        likelihood = unnormalised.sum()
        if likelihood >= MIN_LIKELIHOOD:
            if loud:
                log.warning(
                    "observation %r has zero likelihood after action %r under the current belief; "
                    "mixed the prediction with a uniform floor (eps=%g) [%d recoveries so far%s]",
                    self.model.observations[o], self.model.actions[a], eps, n,
                    "; further ones are counted and logged every 1000th" if n == LOG_FIRST else "",
                )
            return unnormalised / likelihood
        if loud:
            log.warning(
                "observation %r can never follow action %r in this model; ignored it and kept the floored "
                "prediction [%d recoveries so far]",
                self.model.observations[o], self.model.actions[a], n,
            )
        return floored

    # ---------------------------------------------------------------- batches
    def update_batch(self, beliefs: np.ndarray, actions: np.ndarray, observations: np.ndarray) -> np.ndarray:
        """Eq. 5 for ``N`` beliefs at once (used by simulation).

        Args:
            beliefs: ``[N, S]`` (rows are distributions; not validated, not modified).
            actions: ``[N]`` int action indices.
            observations: ``[N]`` int observation indices.

        Returns:
            ``[N, S]`` posteriors; rows with zero likelihood get the same recovery as
            :meth:`update` (each counted).
        """
        B = np.ascontiguousarray(beliefs, dtype=float)
        actions = np.asarray(actions, dtype=np.int64)
        observations = np.asarray(observations, dtype=np.int64)
        groups = np.unique(actions)
        if len(groups) == 1:
            # One action for every row (a batch of one, or a policy that agrees): its product is the
            # prediction, without copying the [N, S] rows out and back (the ward: 37 MB each way).
            predicted = np.ascontiguousarray(self._predict_rows(int(groups[0]), B), dtype=B.dtype)
        else:
            predicted = np.empty_like(B)
            for a in groups:
                rows = np.flatnonzero(actions == a)
                predicted[rows] = self._predict_rows(int(a), B[rows])
        if self.views:
            unnormalised = self._weigh_on_support(predicted, actions, observations)
        else:
            unnormalised = self._OT[actions, observations] * predicted
        likelihood = unnormalised.sum(axis=1)
        self.updates += B.shape[0]
        ok = likelihood >= MIN_LIKELIHOOD
        if ok.all() and unnormalised.dtype == B.dtype:
            # Every row normalised in place: the same divisions as below, without copying the rows
            # out by the mask and back (on the ward's entry beliefs, half of this method's time).
            unnormalised /= likelihood[:, None]
            return unnormalised
        out = np.empty_like(B)
        out[ok] = unnormalised[ok] / likelihood[ok, None]
        for i in np.flatnonzero(~ok):
            out[i] = self._recover(predicted[i], int(actions[i]), int(observations[i]))
        return out

    def _predict_rows(self, a: int, Ba: np.ndarray) -> np.ndarray:
        """``Ba T[a]`` for the beliefs ``Ba [n, S]`` (on their support when T[a] is CSR)."""
        Ta = self._T_rows[a]
        if Ta is not None:
            return self._predict_on_support(Ta, Ba)
        # (T[a]ᵀ Bᵀ)ᵀ = B T[a]; works for dense and CSR T[a]ᵀ.
        return np.asarray(self._TT[a] @ Ba.T).T

    @staticmethod
    def _predict_on_support(Ta, Ba: np.ndarray) -> np.ndarray:
        """``Ba T[a]`` for the beliefs ``Ba [n, S]`` and the CSR ``T[a]``, reading only the rows of
        ``T[a]`` at the states some belief of ``Ba`` holds (the ward: 9,261 of 233,280 at its start).
        The same numbers as the full product ``T[a]ᵀ Baᵀ`` bit for bit: that product (CSC times
        dense) adds each ``T[a][s, s'] b(s)`` into ``p(s')`` in ascending ``s``, and so does this
        one over the support (still ascending), leaving out only terms that are exactly ``+0``."""
        support = np.flatnonzero(Ba.any(axis=0))
        return np.asarray(Ta[support].T @ Ba[:, support].T).T

    def _weigh_on_support(self, predicted: np.ndarray, actions: np.ndarray, observations: np.ndarray) -> np.ndarray:
        """``O[a_i, :, o_i] * predicted[i]`` for every row ``i``, multiplied where ``predicted[i]`` is
        not zero only (elsewhere the product is ``+0``: ``O`` is finite and non-negative). On the
        ward this reads 4 % of its strided ``O`` column instead of all of it, and casts that much
        of the float32 ``O`` to float64 (which the full product casts too, so the numbers match)."""
        out = np.zeros(predicted.shape, dtype=np.result_type(self._OT.dtype, predicted.dtype))
        for i in range(predicted.shape[0]):
            nz = np.flatnonzero(predicted[i])
            out[i, nz] = self._OT[actions[i], observations[i], nz] * predicted[i, nz]
        return out


def update_belief(model: Pomdp, belief, action: Index, observation: Index) -> np.ndarray:
    """One eq. 5 update without keeping a filter (builds one; use :class:`BeliefFilter` in loops)."""
    return BeliefFilter(model).update(belief, action, observation)
