"""The interfaces the parts of Pearl POMDP meet at, declared once (after POMDPs.jl's verbs).

* :class:`Policy` — a flat policy over beliefs: ``action(belief) -> int``
  (:class:`~pearl_pomdp.solution.AlphaVectorPolicy`,
  :class:`~pearl_pomdp.policies.most_likely_state.MostLikelyStatePolicy`).
* :class:`Decider` — what the executive and the policy node run: ``execute(belief) ->``
  :class:`Decision` with an EXECUTE trace
  (:class:`~pearl_pomdp.hierarchy.execute.HierarchicalPolicy`,
  :class:`~pearl_pomdp.policies.flat.FlatPolicyDecider`).
* :class:`MaskingDecider` — a decider that can also decide with some actions forbidden
  (``execute_without(belief, forbidden)``): what an operator's veto needs.
* :class:`ObservingDecider` — a decider that also keeps its own memory of what was heard
  (a behaviour tree, a state machine): the executive tells it every closed step.
* :class:`Solver` — ``solve(model, *, options) -> SolveResult``; solvers are looked up by
  name in :mod:`pearl_pomdp.solvers.registry`.

These are :class:`typing.Protocol` s: anything with the methods fits, and mypy checks it.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Collection, FrozenSet, List, Optional, Protocol, runtime_checkable

import numpy as np

if TYPE_CHECKING:  # pragma: no cover - typing only
    from pearl_pomdp.model.pomdp import Pomdp
    from pearl_pomdp.solution import SolveResult

__all__ = ["TraceStep", "Decision", "Policy", "BatchPolicy", "Decider", "MaskingDecider", "ObservingDecider",
           "Solver", "forbidden_indices"]


@dataclass(frozen=True)
class TraceStep:
    """One level of an EXECUTE trace: in ``subtask`` the local policy chose ``choice``, whose
    α-vector gives the subtask value ``value`` at the current belief (NaN: the policy has none).

    ``runner_up``/``runner_up_value``: the best other child at that level and its value by the
    same measure (``""``/NaN where the level did not choose — a group passing an offer up — or
    has one child), so a reader sees what the choice beat and by how much."""

    subtask: str
    choice: str
    value: float
    runner_up: str = ""
    runner_up_value: float = math.nan

    def as_dict(self) -> dict:
        """JSON-ready form: NaN values become ``None``; the runner-up only where there is one."""
        out: dict = {"subtask": self.subtask, "choice": self.choice,
                     "value": None if math.isnan(self.value) else self.value}
        if self.runner_up:
            out["runner_up"] = self.runner_up
            out["runner_up_value"] = None if math.isnan(self.runner_up_value) else self.runner_up_value
        return out


@dataclass(frozen=True)
class Decision:
    """The primitive action to take now (index into the full model's actions and its name),
    with the trace root → … → primitive."""

    action: int
    action_name: str
    trace: List[TraceStep] = field(default_factory=list)
    #: Beliefs a forward search expanded for this decision (0: none beyond the one step).
    expansions: int = 0
    #: An online search's record (:class:`~pearl_pomdp.online.decider.OnlineDecider`): its size
    #: (trials, nodes), the bounds and gap at the root, its seconds and the top of its tree; ``None``
    #: for offline policies.
    search: Optional[dict] = None

    def as_dict(self) -> dict:
        """JSON-ready form (``value`` NaN becomes ``None``)."""
        return {"action": self.action, "action_name": self.action_name,
                "trace": [t.as_dict() for t in self.trace],
                "expansions": self.expansions, **({"search": self.search} if self.search is not None else {})}


@runtime_checkable
class Policy(Protocol):
    """A flat policy: the action index to take at a belief ``[S]``."""

    def action(self, belief: np.ndarray) -> int: ...


@runtime_checkable
class BatchPolicy(Policy, Protocol):
    """A policy that can also choose for many beliefs at once (``[N, S] -> [N]``): fast simulation."""

    def actions_batch(self, beliefs: np.ndarray) -> np.ndarray: ...


@runtime_checkable
class Decider(Protocol):
    """Chooses the next primitive action at a belief, with the trace of why."""

    def execute(self, belief: np.ndarray) -> Decision: ...


@runtime_checkable
class MaskingDecider(Decider, Protocol):
    """A decider that can decide with some primitive actions forbidden for this one decision.

    ``execute_without(belief, forbidden)`` is the choice among the actions not in ``forbidden``
    (action names) by the decider's own values; with ``forbidden`` empty it is ``execute(belief)``.
    Nothing is remembered: the next decision may choose a forbidden action again (a veto masks
    one step). Raises :class:`~pearl_pomdp.errors.PolicyError` when no action is left to choose.
    """

    def execute_without(self, belief: np.ndarray, forbidden: Collection[str]) -> Decision: ...


def forbidden_indices(actions: List[str], forbidden: Collection[str]) -> FrozenSet[int]:
    """The indices in ``actions`` of the ``forbidden`` names (for :meth:`MaskingDecider.execute_without`).

    Raises:
        PolicyError: a name is not in ``actions``, or every action is forbidden.
    """
    from pearl_pomdp.errors import PolicyError

    index = {a: i for i, a in enumerate(actions)}
    unknown = sorted(set(forbidden) - set(index))
    if unknown:
        raise PolicyError(f"cannot forbid {', '.join(map(repr, unknown))}: not an action of the model")
    banned = frozenset(index[a] for a in forbidden)
    if len(banned) == len(actions):
        raise PolicyError("every action is forbidden: nothing is left to choose")
    return banned


@runtime_checkable
class ObservingDecider(Decider, Protocol):
    """A decider with its own memory of the steps (it may ignore the belief).

    The executive calls :meth:`reset` with the belief and :meth:`observe` after every
    closed step, with the action that opened it and the observation symbol that closed it.
    """

    def reset(self) -> None: ...

    def observe(self, action: str, observation: str) -> None: ...


class Solver(Protocol):
    """A POMDP solver: ``solve(model, *, options) -> SolveResult``.

    Every solver takes the same keyword options (:mod:`pearl_pomdp.solvers.registry` says what
    each means); ``None`` is the solver's own default, and an option the solver has no use for
    must be ``None`` (it raises :class:`~pearl_pomdp.errors.PearlError` otherwise).
    """

    def __call__(self, model: "Pomdp", *, horizon: Optional[int] = None, epsilon: Optional[float] = None,
                 time_limit: Optional[float] = None, seed: Optional[int] = None, progress: bool = False,
                 trials: Optional[int] = None) -> "SolveResult": ...
