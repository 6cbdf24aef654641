"""What every solver returns: an α-vector policy and a result record.

At the bottom of the import order with :mod:`pearl_pomdp.errors` and :mod:`pearl_pomdp.model`
(it imports nothing of the package), so :mod:`pearl_pomdp.interfaces` can name
:class:`SolveResult` and the solvers, the policies and the hierarchy all stand above both.

A value function is a set Γ of α-vectors, each labelled with an action
(docs/design.md §2): ``V(b) = max_k Γ[k]·b`` and the policy takes the action of the
maximising vector, a single matrix-vector product.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import List, Optional

import numpy as np


@dataclass
class AlphaVectorPolicy:
    """A piecewise-linear value function with an action per vector.

    Attributes:
        alphas: ``[K, S]`` array, one α-vector per row.
        actions: ``[K]`` int array, the action index of each vector.
    """

    alphas: np.ndarray
    actions: np.ndarray

    def __post_init__(self) -> None:
        self.alphas = np.atleast_2d(np.asarray(self.alphas, dtype=float))
        self.actions = np.asarray(self.actions, dtype=np.int64).ravel()
        if self.alphas.shape[0] != self.actions.shape[0]:
            raise ValueError(
                f"{self.alphas.shape[0]} α-vectors but {self.actions.shape[0]} action labels"
            )

    @property
    def num_vectors(self) -> int:
        return int(self.alphas.shape[0])

    def values(self, belief: np.ndarray) -> np.ndarray:
        """``Γ·b`` for every vector (or ``[N, K]`` for a batch of beliefs ``[N, S]``)."""
        return np.asarray(belief, dtype=float) @ self.alphas.T

    def value(self, belief: np.ndarray) -> float:
        """``V(b) = max_k α_k·b``."""
        return float(np.max(self.values(belief)))

    def best_vector(self, belief: np.ndarray) -> int:
        """Index of the maximising α-vector at ``belief``."""
        return int(np.argmax(self.values(belief)))

    def action(self, belief: np.ndarray) -> int:
        """The action index the policy takes at ``belief``."""
        return int(self.actions[self.best_vector(belief)])

    def actions_batch(self, beliefs: np.ndarray) -> np.ndarray:
        """:meth:`action` for every row of ``beliefs`` ``[N, S]`` (the first maximising vector)."""
        return self.actions[np.argmax(np.asarray(beliefs, dtype=float) @ self.alphas.T, axis=1)]


@dataclass
class SolveResult:
    """Outcome of a solver run.

    Attributes:
        policy: the lower-bound α-vector policy.
        method: ``"incprune"``, ``"pointbased"``, ``"qmdp"``...
        value_at_start: ``V(b0)`` of the policy's value function (a lower bound
            for point-based methods).
        upper_bound: an upper bound on the optimal value at ``b0`` when the
            method has one, else ``None``.
        iterations: epochs (exact) or backup rounds (point-based).
        seconds: wall-clock solve time.
        vectors_per_epoch: for exact solvers, ``|Γ_t|`` after each epoch.
        converged: whether the stopping criterion was met, or a finite horizon
            completed (vs. a time limit, trial budget or vector cap).
        extra: method-specific figures (kept JSON-serialisable). The exact solver
            (``incprune``, :func:`~pearl_pomdp.solvers.incremental_pruning.solve_incremental_pruning`)
            always sets:

            * ``stop_reason``: ``"converged"`` (its stop rule held), ``"horizon"``
              (all the epochs asked for), ``"time_limit"`` or ``"vector_cap"`` (a set
              an epoch would build was over ``max_vectors``); in the last two the
              epoch in progress is dropped and ``policy`` is the last complete one;
            * ``last_residual``: the Bellman residual ``max_b |V_t(b) − V_{t−1}(b)|``
              over the belief simplex between the last two complete epochs (``None``
              with fewer than one), and ``last_residual_exact`` (False: an upper
              bound, when the time limit left no room for its LPs);
            * ``cycle_period``: ``k`` when it stopped because Γ_t repeated Γ_{t−k}
              (``k ≥ 2``), else ``None``; ``stop_error`` (the weak bound to Γ_{t−1})
              and ``stop_threshold``; ``timed_out``; ``vector_cap``; ``epoch_seconds``;
              ``prune`` (LP counts).
    """

    policy: AlphaVectorPolicy
    method: str
    value_at_start: float
    upper_bound: Optional[float] = None
    iterations: int = 0
    seconds: float = 0.0
    vectors_per_epoch: List[int] = field(default_factory=list)
    converged: bool = False
    extra: dict = field(default_factory=dict)

    @property
    def gap(self) -> Optional[float]:
        """``upper_bound - value_at_start`` or ``None``."""
        return None if self.upper_bound is None else float(self.upper_bound - self.value_at_start)
