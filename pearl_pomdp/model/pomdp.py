"""The flat POMDP and its array conventions (docs/design.md §2).

Conventions, used by every module of the project:

* ``T[a][s, s'] = P(s' | s, a)`` — one ``S×S`` matrix per action, a dense
  ``numpy.ndarray`` or a ``scipy.sparse.csr_matrix`` (large models).
* ``O[a, s', o] = P(o | s', a)`` — observation after arriving in ``s'``; dense ``A×S×Z``.
* ``R[s, a]`` — expected immediate reward for doing ``a`` in ``s``.
* ``b0[s]`` — start belief; ``discount`` in (0, 1].
"""
from __future__ import annotations

import hashlib
from dataclasses import dataclass, field
from typing import Any, List, Optional, Sequence

import sys

import numpy as np

#: One action's ``T[a]``: a dense ``np.ndarray`` or a ``scipy.sparse.csr_matrix``. scipy ships no
#: type stubs, so the union of the two cannot be checked member by member: it is ``Any``, and
#: code that needs one form tests :func:`issparse` first.
Matrix = Any


def issparse(x) -> bool:
    """``scipy.sparse.issparse(x)``, without importing scipy (~70-200 ms of start-up) when no
    sparse matrix can exist yet: small models are read and solved without scipy."""
    sp = sys.modules.get("scipy.sparse")
    return sp is not None and bool(sp.issparse(x))


def _csr(x):
    """``scipy.sparse.csr_matrix(x, dtype=float)``, importing scipy.sparse on first use."""
    import scipy.sparse as sp

    return sp.csr_matrix(x, dtype=float)

#: Entries of ``O`` past which a model counts as large: :meth:`FactoredDomain.compile` stores its
#: ``O`` as float32 (the ward: 52M entries, 210 MB instead of 420 MB; probabilities to ~1e-7) and
#: the belief filter keeps views of it instead of copies (:data:`pearl_pomdp.belief.VIEW_LIMIT`).
LARGE_O_ENTRIES = 16_000_000

#: A model with more than this many S×S entries per action keeps T sparse.
DENSE_LIMIT = 4_000_000


@dataclass
class Pomdp:
    """A flat, discrete POMDP (S, A, Z, T, O, R, b0, γ).

    Build one with :func:`Pomdp.create` (which validates and picks dense or
    sparse storage) or through a reader such as
    :func:`pearl_pomdp.model.pomdp_format.read_pomdp`.
    """

    states: List[str]
    actions: List[str]
    observations: List[str]
    T: List[Matrix]
    O: np.ndarray
    R: np.ndarray
    b0: np.ndarray
    discount: float
    name: str = "pomdp"
    #: Optional per-(a, s, s', o) reward information is reduced to R[s, a] by the readers.
    metadata: dict = field(default_factory=dict)

    # ------------------------------------------------------------------ build
    @classmethod
    def create(
        cls,
        states: Sequence[str],
        actions: Sequence[str],
        observations: Sequence[str],
        T,
        O,
        R,
        b0=None,
        discount: float = 0.95,
        name: str = "pomdp",
        sparse: Optional[bool] = None,
        tolerance: float = 1e-6,
        copy: bool = True,
    ) -> "Pomdp":
        """Validate the arrays and build a model.

        Args:
            T: ``[A, S, S]`` array, or a list of ``A`` matrices (dense or sparse).
            O: ``[A, S, Z]`` array.
            R: ``[S, A]`` array.
            b0: ``[S]`` start belief; uniform when ``None``.
            sparse: force sparse (True) or dense (False) T; default by size.
            tolerance: how far a probability row may be from summing to 1.
            copy: ``False`` takes ``T`` (CSR / float arrays) and ``O`` over without copying them when
                their type already fits (``O`` float64, or float32 for a large model): for a caller
                that built them for this model alone
                (:meth:`FactoredDomain.compile`; a 233,280-state ``O`` is 420 MB, a copy doubles it).

        Raises:
            ValueError: a shape is wrong or a row is not a distribution (the
                message names the action, state and the sum).
        """
        S, A, Z = len(states), len(actions), len(observations)
        if S == 0 or A == 0 or Z == 0:
            raise ValueError(f"a POMDP needs at least one state, action and observation (got {S}, {A}, {Z})")
        if sparse is None:
            sparse = S * S > DENSE_LIMIT
        mats: List[Matrix] = []
        if len(T) != A:
            raise ValueError(f"T has {len(T)} action matrices, expected {A}")
        for a, Ta in enumerate(T):
            if sparse:
                m = _csr(Ta).copy() if copy else _csr(Ta)
            else:
                m = Ta.toarray() if issparse(Ta) else np.array(Ta, dtype=float, copy=copy or None)
            if m.shape != (S, S):
                raise ValueError(f"T[{actions[a]}] has shape {m.shape}, expected ({S}, {S})")
            mats.append(m)
        # Copies: a model never aliases its caller's arrays (editing one must not edit the other),
        # unless the caller says it hands them over (copy=False).
        if copy or not (isinstance(O, np.ndarray) and O.dtype in (np.float32, np.float64)):
            O = np.array(O, dtype=float)
        if O.shape != (A, S, Z):
            raise ValueError(f"O has shape {O.shape}, expected ({A}, {S}, {Z})")
        R = np.array(R, dtype=float)
        if R.shape != (S, A):
            raise ValueError(f"R has shape {R.shape}, expected ({S}, {A})")
        b0 = np.full(S, 1.0 / S) if b0 is None else np.array(b0, dtype=float)
        if b0.shape != (S,):
            raise ValueError(f"b0 has shape {b0.shape}, expected ({S},)")
        if not 0.0 < discount <= 1.0:
            raise ValueError(f"discount {discount} is not in (0, 1]")
        model = cls(list(states), list(actions), list(observations), mats, O, R, b0, float(discount), name)
        model.check(tolerance)
        return model

    # ---------------------------------------------------------------- checks
    def check(self, tolerance: float = 1e-6) -> None:
        """Raise ``ValueError`` naming the first row of T, O or b0 that is not a distribution."""
        for a, Ta in enumerate(self.T):
            sums = np.asarray(Ta.sum(axis=1)).ravel()
            mins = Ta.min() if not issparse(Ta) else min(Ta.data.min(initial=0.0), 0.0)
            if mins < -tolerance:
                raise ValueError(f"T[{self.actions[a]}] has a negative entry ({mins})")
            bad = np.flatnonzero(np.abs(sums - 1.0) > tolerance)
            if bad.size:
                s = bad[0]
                raise ValueError(f"T[{self.actions[a]}][{self.states[s]}, :] sums to {sums[s]:.9g}, expected 1")
        if (self.O < -tolerance).any():
            a, s, o = np.argwhere(self.O < -tolerance)[0]
            raise ValueError(f"O[{self.actions[a]}, {self.states[s]}, {self.observations[o]}] is negative")
        sums = self.O.sum(axis=2)
        bad_rows = np.argwhere(np.abs(sums - 1.0) > tolerance)
        if bad_rows.size:
            a, s = bad_rows[0]
            raise ValueError(f"O[{self.actions[a]}, {self.states[s]}, :] sums to {sums[a, s]:.9g}, expected 1")
        if (self.b0 < -tolerance).any() or abs(self.b0.sum() - 1.0) > tolerance:
            raise ValueError(f"b0 sums to {self.b0.sum():.9g} (or has a negative entry), expected a distribution")
        if not np.isfinite(self.R).all():
            raise ValueError("R has a non-finite entry")

    # ------------------------------------------------------------ properties
    @property
    def num_states(self) -> int:
        return len(self.states)

    @property
    def num_actions(self) -> int:
        return len(self.actions)

    @property
    def num_observations(self) -> int:
        return len(self.observations)

    @property
    def is_sparse(self) -> bool:
        """True when T is stored as scipy sparse matrices."""
        return issparse(self.T[0])

    def T_dense(self) -> np.ndarray:
        """``T`` as one ``[A, S, S]`` array (raises MemoryError-prone models as ValueError)."""
        S, A = self.num_states, self.num_actions
        if A * S * S > 50 * DENSE_LIMIT:
            raise ValueError(f"a dense T of {A}x{S}x{S} is too large; use the sparse matrices in Pomdp.T")
        return np.stack([Ta.toarray() if issparse(Ta) else Ta for Ta in self.T])

    def index(self, kind: str, name: str) -> int:
        """Index of a state/action/observation ``name`` (``kind`` is 'states', 'actions' or 'observations')."""
        names = getattr(self, kind)
        try:
            return names.index(name)
        except ValueError:
            raise KeyError(f"unknown {kind[:-1]} {name!r}; known: {', '.join(names[:20])}{' …' if len(names) > 20 else ''}") from None

    def fingerprint(self) -> str:
        """A SHA-256 over names, arrays and discount: policies record it to detect a model mismatch."""
        h = hashlib.sha256()
        for names in (self.states, self.actions, self.observations):
            h.update("\x1f".join(names).encode())
            h.update(b"\x1e")
        for Ta in self.T:
            # Same bytes whether T is stored dense or sparse: the canonical CSR arrays.
            if issparse(Ta):
                c = _csr(Ta)
                c.sum_duplicates()
                c.eliminate_zeros()
                c.sort_indices()
                data, indices, indptr = c.data, c.indices, c.indptr
            else:  # (the same arrays from the dense matrix, row-major, without scipy)
                dense = np.asarray(Ta, dtype=float)
                rows, indices = np.nonzero(dense)
                data = dense[rows, indices]
                indptr = np.concatenate(([0], np.cumsum(np.bincount(rows, minlength=dense.shape[0]))))
            h.update(np.round(data, 12).tobytes())
            h.update(indices.astype(np.int64).tobytes())
            h.update(indptr.astype(np.int64).tobytes())
        for arr in (self.O, self.R, self.b0):
            h.update(np.round(arr, 12).tobytes())
        h.update(repr(round(self.discount, 12)).encode())
        return h.hexdigest()
