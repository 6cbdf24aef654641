"""PARAMETERIZE: the model of one subtask (Pineau & Thrun, eq. 11–17).

Subtask ``h`` has the full state set ``S`` and observation set ``Z`` (before
abstraction) and the actions ``A_h`` = its children in the hierarchy.

* Primitive child ``a`` (eq. 11–14): ``b0_h = b0``, ``T_h(s,a,s') = T(s,a,s')``,
  ``O_h = O``, ``R_h = R``.
* Abstract child ``â_j`` (eq. 15–17): let ``π_j(s)`` be the primitive that the
  already-solved subtask ``h_j`` selects (recursively through its own abstract
  actions) at the belief concentrated on ``s``. Then
  ``T_h(s,â_j,s') = T(s,π_j(s),s')``, ``R_h(s,â_j) = R(s,π_j(s))`` and the observation
  model is that of the primitive chosen in the *previous* state:
  ``P(o | s, â_j, s') = O(s', π_j(s), o)`` (state-pair form, docs/design.md §4).

Both cases are one representation: a ``source`` array ``[A_h, S]`` giving, for each
action of ``h`` and each state, the primitive executed there (constant for a
primitive). Everything else follows exactly:
``T_h[k][s, :] = T[source[k, s]][s, :]``, ``R_h[s, k] = R[s, source[k, s]]``,
``P(o | s, k, s') = O[source[k, s], s', o]``. The state-pair observation model is kept
exact downstream: :mod:`pearl_pomdp.hierarchy.abstraction` turns it into a standard
``O[a, s', o]`` model by augmenting the states that need it (see its docstring).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import List, Mapping, Optional, Sequence

import numpy as np
import scipy.sparse as sp

from pearl_pomdp.hierarchy.spec import SubtaskSpec
from pearl_pomdp.model.pomdp import Pomdp
from pearl_pomdp.model.factored import FactoredDomain

__all__ = ["SubtaskModel", "StateFactors", "parameterize", "local_reward_problems"]


@dataclass
class StateFactors:
    """The factored view of a flat model's states.

    Attributes:
        names: feature names, in domain order.
        values: per feature, its value names.
        state_values: ``[S, F]`` int array: value index of each feature in each state.
    """

    names: List[str]
    values: List[List[str]]
    state_values: np.ndarray

    @classmethod
    def from_domain(cls, domain) -> "StateFactors":
        """From a FactoredDomain (its features), or a flat Pomdp (one feature ``state``)."""
        if isinstance(domain, FactoredDomain):
            return cls([f.name for f in domain.features], [list(f.values) for f in domain.features],
                       np.asarray(domain.state_values, dtype=np.int64))
        return cls(["state"], [list(domain.states)], np.arange(domain.num_states, dtype=np.int64)[:, None])

    @property
    def radices(self) -> List[int]:
        return [len(v) for v in self.values]

    def mask(self, assignment: Mapping[str, Sequence[str]]) -> np.ndarray:
        """Boolean ``[S]``: states where every feature in ``assignment`` takes one of the given values."""
        m = np.ones(self.state_values.shape[0], dtype=bool)
        for feat, vals in assignment.items():
            f = self.names.index(feat)
            idx = [self.values[f].index(v) for v in vals]
            m &= np.isin(self.state_values[:, f], idx)
        return m


@dataclass
class SubtaskModel:
    """Subtask ``h`` after PARAMETERIZE, over the full state space.

    Attributes:
        name: the subtask.
        actions: its action names (children in hierarchy order).
        abstract: per action, True when it is an abstract action.
        source: ``[A_h, S]`` int: the primitive (index into ``model.actions``) that action
            ``k`` executes in state ``s`` (eq. 15–17; constant for a primitive).
        R: ``[S, A_h]`` reward, including shaping.
        R_unshaped: ``[S, A_h]`` reward before shaping (eq. 14/17 exactly).
        model: the full flat POMDP.
    """

    name: str
    actions: List[str]
    abstract: List[bool]
    source: np.ndarray
    R: np.ndarray
    R_unshaped: np.ndarray
    model: Pomdp
    warnings: List[str] = field(default_factory=list)

    @property
    def num_actions(self) -> int:
        return len(self.actions)

    @property
    def b0(self) -> np.ndarray:
        """Eq. 11: ``b0_h = b0``."""
        return self.model.b0

    @property
    def discount(self) -> float:
        return self.model.discount

    def transition(self, k: int):
        """``T_h[k]`` as an ``S×S`` matrix (dense or CSR like the model): row ``s`` is ``T[source[k,s]][s, :]``."""
        src = self.source[k]
        prims = np.unique(src)
        if prims.size == 1:
            return self.model.T[int(prims[0])]
        if self.model.is_sparse:
            out = None
            for p in prims:
                part = sp.diags((src == p).astype(float)) @ self.model.T[int(p)]
                out = part if out is None else out + part
            return sp.csr_matrix(out)
        out = np.empty((src.size, src.size))
        for p in prims:
            rows = np.flatnonzero(src == p)
            Tp = self.model.T[int(p)]
            out[rows] = Tp[rows].toarray() if sp.issparse(Tp) else Tp[rows]
        return out

    def observation_pair(self, k: int) -> np.ndarray:
        """``P(o | s, k, s')`` as a dense ``[S, S', Z]`` array (eq. 13/16; small models only)."""
        return self.model.O[self.source[k]]


def parameterize(model: Pomdp, spec: SubtaskSpec, effective: Mapping[str, np.ndarray],
                 factors: Optional[StateFactors] = None) -> SubtaskModel:
    """Build subtask ``spec``'s model from the full ``model`` and its solved children.

    Args:
        model: the full flat POMDP.
        spec: the subtask (its children are its actions).
        effective: for each abstract child ``j``, ``π_j`` as an ``[S]`` int array of primitive
            action indices (the primitive the child's policy picks at the belief concentrated
            on each state, recursively).
        factors: the factored state view; needed only when ``spec.shaping`` has ``when`` rules.

    Returns:
        The :class:`SubtaskModel` (with local-reward warnings filled in).
    """
    S = model.num_states
    src = np.empty((len(spec.children), S), dtype=np.int64)
    abstract = []
    for k, child in enumerate(spec.children):
        if child in effective:
            pi = np.asarray(effective[child], dtype=np.int64)
            if pi.shape != (S,):
                raise ValueError(f"π of abstract action {child!r} has shape {pi.shape}, expected ({S},)")
            src[k] = pi
            abstract.append(True)
        else:
            src[k] = model.index("actions", child)
            abstract.append(False)
    # Eq. 14 / 17: R_h(s, k) = R(s, source[k, s]).
    R_unshaped = np.take_along_axis(model.R, src.T, axis=1)
    R = R_unshaped.copy()
    for rule in spec.shaping:
        k = spec.children.index(rule.action)
        if rule.when:
            if factors is None:
                raise ValueError(f"subtask {spec.name!r}: shaping with 'when' needs the factored domain")
            mask = factors.mask(dict(rule.when))
        else:
            mask = np.ones(S, dtype=bool)
        R[mask, k] += rule.reward
    sub = SubtaskModel(spec.name, list(spec.children), abstract, src, R, R_unshaped, model)
    sub.warnings = local_reward_problems(R, spec.children, spec.name)
    return sub


def local_reward_problems(R: np.ndarray, actions: Sequence[str], name: str = "", tol: float = 1e-9) -> List[str]:
    """Ways subtask reward ``R [S, A_h]`` violates the local reward assumption (empty: fine).

    The local policy of a subtask can only be optimised when its reward discriminates
    (Pineau & Thrun, "local reward assumption"; Dietterich 2000): between actions, and
    between states for at least one action. Reported:

    * every action gives the same reward in every state (nothing to choose between);
    * no action's reward depends on the state (the belief cannot matter; the local policy
      is a constant);
    * a subtask with a single action (nothing to optimise).
    """
    label = f"subtask {name!r}: " if name else ""
    problems = []
    if R.shape[1] < 2:
        problems.append(f"{label}has a single action ({', '.join(actions)}); nothing to optimise")
        return problems
    if np.all(np.abs(R - R[:, :1]) <= tol):
        problems.append(f"{label}all actions give the same reward in every state; the local policy cannot be "
                        "optimised (add reward shaping to the subtask)")
    elif np.all(np.ptp(R, axis=0) <= tol):
        problems.append(f"{label}no action's reward depends on the state; the local policy ignores the belief "
                        "(add discriminative reward or shaping)")
    return problems
