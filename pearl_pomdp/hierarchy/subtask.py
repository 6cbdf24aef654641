"""One subtask's solved local policy (:class:`SubtaskPolicy`): its vectors or forward search,
the projection of a full belief onto its abstract model, and its choice among its children.

EXECUTE (:mod:`pearl_pomdp.hierarchy.execute`) walks these top-down; PLAN
(:mod:`pearl_pomdp.hierarchy.plan`) builds them bottom-up; :mod:`pearl_pomdp.hierarchy.storage`
saves and loads them.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import List, Optional, Tuple, cast

import numpy as np
import scipy.sparse as sp

from pearl_pomdp.errors import PolicyError
from pearl_pomdp.policies.lookahead import Lookahead, OneStep

__all__ = ["SubtaskPolicy"]


@dataclass
class SubtaskPolicy:
    """The solved local policy of one subtask.

    Attributes:
        name: the subtask.
        actions: its action names (children).
        abstract: per action, whether it is a subtask.
        alphas: ``[K, S_h]`` α-vectors over the abstract model's states.
        alpha_actions: ``[K]`` index into ``actions`` of each vector.
        state_to_model: ``[S]`` full state → abstract model state.
        effective: ``[S]`` π_h(s): the primitive (full-model action index) EXECUTE(h) reaches
            at the belief concentrated on s (eq. 15–17's input for h's parent).
        info: the planning report of this subtask (sizes, solver, seconds...).
        lookahead: the forward search EXECUTE uses instead of the bare vectors (``None``: none).
        model_actions: policy-contingent subtasks only (``None`` otherwise): the actions of the
            model the subtask was solved on — every primitive below it, then ``Exit`` when it is
            an option (:mod:`pearl_pomdp.hierarchy.options`). ``lookahead`` is then the one-step
            search over that model, and EXECUTE compares the primitives its children pick.
        exit: the model has the ``Exit`` pseudo-action (every policy-contingent subtask but the root).
        search_depth: policy-contingent only: steps of forward search EXECUTE takes over the
            children's choices (1: one Bellman step with the vectors at the leaves).
        expansions: the deeper search's budget of expanded beliefs per decision (depth > 1).
        online: the root only, when it plans online (``solver: online``): the search's record
            (``trials``, ``time_limit``, ``scenarios``, ``depth``, ``seed``); its vectors are a
            placeholder and EXECUTE runs :class:`~pearl_pomdp.hierarchy.online_root.OnlineRoot`.
    """

    name: str
    actions: List[str]
    abstract: List[bool]
    alphas: np.ndarray
    alpha_actions: np.ndarray
    state_to_model: np.ndarray
    effective: np.ndarray
    info: dict = field(default_factory=dict)
    lookahead: Optional[Lookahead] = None
    model_actions: Optional[List[str]] = None
    exit: bool = False
    search_depth: int = 1
    expansions: int = 256
    online: Optional[dict] = None

    def __post_init__(self) -> None:
        self.alphas = np.atleast_2d(np.asarray(self.alphas, dtype=float))
        self.alpha_actions = np.asarray(self.alpha_actions, dtype=np.int64)
        self.state_to_model = np.asarray(self.state_to_model, dtype=np.int64)
        self.effective = np.asarray(self.effective, dtype=np.int64)
        # α expanded to the full state space: α_full[k, s] = α[k, state_to_model[s]].
        self.alphas_full = np.ascontiguousarray(self.alphas[:, self.state_to_model])

        n_model = self.alphas.shape[1]
        # P_h [S, S_h]: full state → its abstract state (copy 0), for the forward search.
        self._projection = sp.csr_matrix((np.ones(self.state_to_model.shape[0]),
                                          (np.arange(self.state_to_model.shape[0]), self.state_to_model)),
                                         shape=(self.state_to_model.shape[0], n_model))
        # P_hᵀ, built once (transposing per decision cost more than the product).
        self._projection_t = self._projection.T.tocsr()
        if self.model_actions is not None:
            if self.lookahead is None:
                raise PolicyError(f"subtask {self.name!r}: a policy-contingent subtask needs its model's search")
            la = self.lookahead
            self.one_step = OneStep(la.T, la.O, la.R, la.discount, self.alphas)
            #: A full state standing for each model state (the first that maps there; -1: the
            #: option's ``done`` state): a belief over the model lifts to the full state space
            #: this way, which is enough for the children, whose features are among this model's.
            self.representative = np.full(n_model, -1, dtype=np.int64)
            order = np.arange(self.state_to_model.shape[0] - 1, -1, -1)
            self.representative[self.state_to_model[order]] = order

    @property
    def contingent(self) -> bool:
        """Whether EXECUTE compares the children's picks through this subtask's model (see ``model_actions``)."""
        return self.model_actions is not None

    def project_states(self, states: np.ndarray) -> np.ndarray:
        """The particle belief of full states ``states [K]`` (equal weights) → this subtask's model states."""
        states = np.asarray(states, dtype=np.int64)
        return np.bincount(self.state_to_model[states], minlength=self.alphas.shape[1]) / float(states.shape[0])

    def project(self, B: np.ndarray) -> np.ndarray:
        """Full beliefs ``[N, S]`` (or ``[S]``) → this subtask's model states (the X+ marginal)."""
        B = np.asarray(B, dtype=float)
        return np.asarray((self._projection_t @ np.atleast_2d(B).T).T)

    def lift(self, b_model: np.ndarray) -> np.ndarray:
        """A belief over this subtask's model states → a full belief with the same X+ marginal
        (each model state's mass on its representative; the option's ``done`` state dropped)."""
        out = np.zeros(self.state_to_model.shape[0])
        keep = np.flatnonzero((b_model > 0) & (self.representative >= 0))
        out[self.representative[keep]] = b_model[keep]
        return out

    def _q_values(self, B: np.ndarray) -> np.ndarray:
        return cast(Lookahead, self.lookahead).q_values(np.asarray((self._projection_t @ B.T).T))

    def _scores(self, belief: np.ndarray, allowed: Optional[np.ndarray] = None) -> Tuple[np.ndarray, np.ndarray]:
        """``(labels, values)`` at a full belief: the exact Q-value of each child (lookahead) or each
        vector's value and the child it is labelled with; a child not ``allowed`` scores ``-inf``."""
        if self.lookahead is not None:
            labels = np.arange(len(self.actions))
            values = self._q_values(np.asarray(belief, dtype=float)[None, :])[0]
        else:
            labels, values = self.alpha_actions, self.alphas_full @ belief
        return labels, values if allowed is None else np.where(allowed[labels], values, -np.inf)

    def choose(self, belief: np.ndarray, allowed: Optional[np.ndarray] = None) -> Optional[Tuple[int, float]]:
        """``(action index in self.actions, value)`` at a full belief ``[S]``: the largest Q-value
        (lookahead) or vector, among the children with ``allowed[k]`` true (``[len(actions)]``
        bools; ``None``: all of them). ``None`` when no allowed child has a value here (no vector
        carries one)."""
        labels, values = self._scores(belief, allowed)
        k = int(np.argmax(values))
        return (int(labels[k]), float(values[k])) if np.isfinite(values[k]) else None

    def runner_up(self, belief: np.ndarray, chosen: int, allowed: Optional[np.ndarray] = None) -> Tuple[str, float]:
        """The best allowed child other than ``chosen`` (an index into ``self.actions``) at a full belief,
        by :meth:`choose`'s measure: ``(name, value)``, or ``("", NaN)`` when no other child has one."""
        labels, values = self._scores(belief, allowed)
        values = np.where(labels != chosen, values, -np.inf)
        k = int(np.argmax(values))
        return (self.actions[int(labels[k])], float(values[k])) if np.isfinite(values[k]) else ("", math.nan)

    def choose_batch(self, beliefs: np.ndarray) -> np.ndarray:
        """``[N]`` action indices (into ``self.actions``) for full beliefs ``[N, S]``; ties as :meth:`choose`."""
        B = np.atleast_2d(np.asarray(beliefs, dtype=float))
        if self.lookahead is not None:
            return np.argmax(self._q_values(B), axis=1).astype(np.int64)
        return self.alpha_actions[np.argmax(B @ self.alphas_full.T, axis=1)]

    def value(self, belief: np.ndarray) -> float:
        """The subtask's value at a full belief: ``max_k α_k·P_hᵀ b``, or ``max_a Q_{h+d}`` with lookahead."""
        return float(np.max(self._scores(belief)[1]))
