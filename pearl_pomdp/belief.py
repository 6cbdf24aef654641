"""The Bayes filter over a flat POMDP's states (DESIGN.md §2, eq. 5 of Pineau & Thrun).

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
the ``pearl_pomdp.belief`` logger naming the action and observation, so a node can report
it; nothing is recovered silently.
"""
from __future__ import annotations

import logging
import numbers
from typing import Optional, Union

import numpy as np
import scipy.sparse as sp

from pearl_pomdp.errors import BeliefError
from pearl_pomdp.model.pomdp import Pomdp

__all__ = ["BeliefFilter", "update_belief", "MIN_LIKELIHOOD", "SUM_TOLERANCE"]

log = logging.getLogger(__name__)

#: Below this, ``P(o | b, a)`` counts as zero (the smallest normal double): the recovery applies.
MIN_LIKELIHOOD = float(np.finfo(float).tiny)
#: How far an input belief may be from summing to 1 (it is renormalised within this).
SUM_TOLERANCE = 1e-6
#: How negative an input entry may be (rounding noise), before it is an error.
NEGATIVE_TOLERANCE = 1e-12

Index = Union[int, np.integer, str]


class BeliefFilter:
    """Exact discrete Bayes filter for one :class:`~pearl_pomdp.model.pomdp.Pomdp`.

    Construction precomputes, per action, ``T[a]ᵀ`` in the cheaper of CSR or dense storage
    (CSR when ``S ≥ 64`` and T is at most 30 % full; one sparse mat-vec then costs a few µs
    on a 576-state model) and ``O`` as ``[A, Z, S]`` so that the column ``O[a, :, o]`` is
    contiguous. :meth:`update` is pure: it never mutates its input.

    Args:
        model: the POMDP.
        floor: weight ``ε`` of the uniform floor in the zero-likelihood recovery.

    Attributes:
        zero_likelihood_count: how many updates needed the recovery (see the module doc).
        updates: how many updates were done.
    """

    def __init__(self, model: Pomdp, floor: float = 1e-6):
        if not 0.0 < floor < 1.0:
            raise ValueError(f"floor must be in (0, 1), got {floor}")
        self.model = model
        self.floor = float(floor)
        self.num_states = S = model.num_states
        self.num_actions = model.num_actions
        self.num_observations = model.num_observations
        self._TT = []
        for Ta in model.T:
            nnz = Ta.nnz if sp.issparse(Ta) else int(np.count_nonzero(Ta))
            if S >= 64 and nnz <= 0.3 * S * S:
                self._TT.append(sp.csr_matrix(Ta, dtype=float).T.tocsr())
            else:
                dense = Ta.toarray() if sp.issparse(Ta) else np.asarray(Ta, dtype=float)
                self._TT.append(np.ascontiguousarray(dense.T))
        # [A, Z, S]: O[a, :, o] as a contiguous row.
        self._OT = np.ascontiguousarray(np.transpose(model.O, (0, 2, 1)))
        self.zero_likelihood_count = 0
        self.updates = 0

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
        total = b.sum()
        lowest = b.min()
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
        return self._index(action, self.model.actions, "action")

    def observation_index(self, observation: Index) -> int:
        """The index of ``observation`` (an int index or a name); :class:`BeliefError` if unknown."""
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
        return self._TT[a] @ b

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
        predicted = self._TT[a] @ b
        column = self._OT[a, o]
        unnormalised = column * predicted
        likelihood = unnormalised.sum()
        if likelihood >= MIN_LIKELIHOOD:
            return unnormalised / likelihood
        return self._recover(predicted, a, o)

    def _recover(self, predicted: np.ndarray, a: int, o: int) -> np.ndarray:
        """Zero-likelihood recovery (module doc): uniform floor, then ignore ``o`` if still zero."""
        self.zero_likelihood_count += 1
        eps = self.floor
        floored = (1.0 - eps) * predicted + eps / self.num_states
        floored /= floored.sum()
        unnormalised = self._OT[a, o] * floored
        likelihood = unnormalised.sum()
        if likelihood >= MIN_LIKELIHOOD:
            log.warning(
                "observation %r has zero likelihood after action %r under the current belief; "
                "mixed the prediction with a uniform floor (eps=%g) [%d recoveries so far]",
                self.model.observations[o], self.model.actions[a], eps, self.zero_likelihood_count,
            )
            return unnormalised / likelihood
        log.warning(
            "observation %r can never follow action %r in this model; ignored it and kept the floored "
            "prediction [%d recoveries so far]",
            self.model.observations[o], self.model.actions[a], self.zero_likelihood_count,
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
        B = np.asarray(beliefs, dtype=float)
        actions = np.asarray(actions, dtype=np.int64)
        observations = np.asarray(observations, dtype=np.int64)
        predicted = np.empty_like(B)
        for a in np.unique(actions):
            rows = np.flatnonzero(actions == a)
            # (T[a]ᵀ Bᵀ)ᵀ = B T[a]; works for dense and CSR T[a]ᵀ.
            predicted[rows] = np.asarray(self._TT[a] @ B[rows].T).T
        unnormalised = self._OT[actions, observations] * predicted
        likelihood = unnormalised.sum(axis=1)
        self.updates += B.shape[0]
        ok = likelihood >= MIN_LIKELIHOOD
        out = np.empty_like(B)
        out[ok] = unnormalised[ok] / likelihood[ok, None]
        for i in np.flatnonzero(~ok):
            out[i] = self._recover(predicted[i], int(actions[i]), int(observations[i]))
        return out


def update_belief(model: Pomdp, belief, action: Index, observation: Index) -> np.ndarray:
    """One eq. 5 update without keeping a filter (builds one; use :class:`BeliefFilter` in loops)."""
    return BeliefFilter(model).update(belief, action, observation)
