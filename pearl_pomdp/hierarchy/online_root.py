"""An online root over offline-planned children (docs/hierarchy.md, "Online root").

A hierarchy whose root says ``solver: online`` is not planned at the root: PLAN solves the
children as usual (policy-contingent options, each abstracted and solved point-based), and at
run time the root runs DESPOT (:mod:`pearl_pomdp.online.despot`, the same search, bounds and
deterministic trial budget as :class:`~pearl_pomdp.online.decider.OnlineDecider`) over *its own*
actions. A primitive root action is itself. An abstract one — a child subtask — is resolved at
every DESPOT node to the primitive the child's offline policy picks at that node's particle
belief projected onto the child's abstraction (the X+ marginal of the node's scenarios): the
search values each child as the child would act in that situation, steps and rewards are the
full model's, so what the root weighs is the world's return of "let CareAnn act now", not a
model of it.

The bounds are the full model's (:func:`~pearl_pomdp.online.decider.default_bounds`): the upper
bound of the unrestricted problem is one of the restricted one; the lower bound (best blind
policy) is the value of a policy the robot can run, though not always through the root's
actions — the search's root values are those of the hierarchy's actions wherever the tree grew.
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Any, Dict, FrozenSet, List, Mapping, Optional, Protocol, Tuple

import numpy as np

from pearl_pomdp.errors import PolicyError
from pearl_pomdp.interfaces import Decision, TraceStep
from pearl_pomdp.online.beliefs import sample_belief
from pearl_pomdp.online.despot import Despot, DespotSettings, SearchResult
from pearl_pomdp.online.generative import Bounds, ExplicitModel

if TYPE_CHECKING:  # pragma: no cover
    from pearl_pomdp.model.pomdp import Pomdp

__all__ = ["Children", "RootModel", "OnlineRoot", "online_settings"]


class Children(Protocol):
    """What the root's search asks of the offline policies below it: a
    :class:`~pearl_pomdp.hierarchy.execute.HierarchicalPolicy` (which builds the root, so this
    module does not import it back)."""

    @property
    def root(self) -> str: ...

    @property
    def subtasks(self) -> Mapping[str, Any]: ...

    @property
    def action_names(self) -> List[str]: ...

    @property
    def num_states(self) -> int: ...

    def action_index(self, name: str) -> int: ...

    def is_group(self, name: str) -> bool: ...

    def pick(self, name: str, b: np.ndarray, memo: Dict[str, Any], banned: FrozenSet[int] = frozenset()) -> Any: ...

    def pick_projected(self, name: str, bh: np.ndarray, banned: FrozenSet[int] = frozenset()) -> Any: ...


def online_settings(record: dict) -> DespotSettings:
    """The search's settings from a subtask's saved ``online`` record (``trials``, ``time_limit``;
    scenarios and depth: :class:`DespotSettings`' defaults unless recorded)."""
    base = DespotSettings()
    return DespotSettings(scenarios=int(record.get("scenarios", base.scenarios)),
                          depth=int(record.get("depth", base.depth)),
                          trials=record.get("trials"), time_limit=record.get("time_limit"))


class RootModel:
    """The root's actions as a :class:`~pearl_pomdp.online.generative.GenerativeModel` over the full states.

    ``step_many(states, u)`` resolves every root action once for the particle set ``states`` (one
    DESPOT node: :meth:`resolve`) and steps the particles under each resolved primitive with the
    explicit model's inverse-CDF sampling (the same uniforms give the same outcome).
    """

    uniforms_per_step = ExplicitModel.uniforms_per_step

    def __init__(self, policy: Children, explicit: ExplicitModel):
        self.policy = policy
        self.explicit = explicit
        root = policy.subtasks[policy.root]
        self.name = f"{explicit.name}/{policy.root}"
        self.actions: List[str] = list(root.actions)
        self.discount = explicit.discount
        self.abstract = list(root.abstract)
        self._fixed = [-1 if root.abstract[k] else policy.action_index(a) for k, a in enumerate(root.actions)]
        self.num_states = policy.num_states

    def resolve(self, states: np.ndarray, banned: FrozenSet[int] = frozenset()) -> List[Tuple[int, float]]:
        """Per root action, ``(primitive index, child's value)`` at the particle belief of ``states``
        (a primitive: itself, value nan; a child: its pick at the X+ marginal of the particles, -1 when
        nothing is left to it once ``banned`` primitives are masked)."""
        states = np.asarray(states, dtype=np.int64)
        out: List[Tuple[int, float]] = []
        full: Optional[np.ndarray] = None
        memo: Dict[str, Any] = {}
        for k, child in enumerate(self.actions):
            if not self.abstract[k]:
                out.append((self._fixed[k], float("nan")))
                continue
            if self.policy.is_group(child):
                if full is None:
                    full = np.bincount(states, minlength=self.num_states) / states.shape[0]
                got = self.policy.pick(child, full, memo, banned)
            else:
                got = self.policy.pick_projected(child, self.policy.subtasks[child].project_states(states), banned)
            out.append((-1, float("nan")) if got is None else (int(got[0]), float(got[2])))
        return out

    def step_many(self, states, uniforms):
        """Every root action's ``(next_states, observations, rewards)`` for one node's particles."""
        return self.explicit.step_actions(states, [p for p, _ in self.resolve(states)], uniforms)

    def step(self, states, action, uniforms):
        p = self.resolve(states)[action][0]
        return self.explicit.step(states, p, uniforms)

    def is_terminal(self, states):
        return self.explicit.is_terminal(states)


class OnlineRoot:
    """DESPOT over the root's actions at every decision (module doc).

    Args:
        policy: the hierarchical policy (its children planned).
        model: the full model the policy was planned for.
        settings: the search's :class:`DespotSettings` (the root's ``trials`` and ``time_limit``).
        seed: mixed with each belief into the decision's seed
            (:func:`~pearl_pomdp.online.decider.decision_seed`).
        bounds: the heuristics; default :func:`~pearl_pomdp.online.decider.default_bounds` of ``model``.
    """

    def __init__(self, policy: Children, model: "Pomdp", settings: DespotSettings, seed: int = 0,
                 bounds: Optional[Bounds] = None):
        from pearl_pomdp.online.decider import default_bounds

        self.policy = policy
        self.settings = settings
        self.seed = int(seed)
        self.bounds = bounds if bounds is not None else default_bounds(model)
        self.generative = RootModel(policy, ExplicitModel(model))
        self.engine = Despot(self.generative, self.bounds, settings)
        self.last_search: Optional[SearchResult] = None

    def search(self, belief: np.ndarray):
        """``(search result, the root's resolution at its particles)`` at the full belief ``belief``."""
        from pearl_pomdp.online.decider import decision_seed

        seed = decision_seed(belief, self.seed)
        roots = sample_belief(belief, self.settings.scenarios, np.random.default_rng([seed, 1]))
        resolved = self.generative.resolve(roots)
        self.last_search = self.engine.search(roots, seed)
        return self.last_search, resolved

    def execute(self, belief: np.ndarray, banned: FrozenSet[int] = frozenset()) -> Decision:
        """The root action with the best lower bound after the search, and the primitive it resolves to
        at the root's particles. ``banned`` (a veto): root actions whose primitive there is banned are
        passed over; a child whose pick is banned offers its best allowed primitive instead (at the
        same particles)."""
        result, resolved = self.search(belief)
        gen = self.generative
        lows = np.array([lo for lo, _ in result.action_bounds])
        if banned:
            masked = gen.resolve(self.engine_roots(belief), banned)
            allowed = np.array([p >= 0 and p not in banned for p, _ in masked])
            if not allowed.any():
                raise PolicyError(f"no action is left below {self.policy.root!r} once {len(banned)} are forbidden")
            lows = np.where(allowed, lows, -np.inf)
            resolved = masked
        k = int(np.argmax(lows))
        prim, child_value = resolved[k]
        names = self.policy.action_names
        trace = [TraceStep(self.policy.root, gen.actions[k], float(result.action_bounds[k][0]))]
        if gen.abstract[k]:
            trace.append(TraceStep(gen.actions[k], names[prim], child_value))
        record = result.as_dict()
        record.update(bounds=self.bounds.description, top=result.top, root=self.policy.root,
                      action_bounds=[{"action": a, "resolves_to": names[p] if p >= 0 else None, "lower": lo, "upper": up}
                                     for a, (p, _), (lo, up) in zip(gen.actions, resolved, result.action_bounds)])
        return Decision(prim, names[prim], trace, expansions=result.expansions, search=record)

    def engine_roots(self, belief: np.ndarray) -> np.ndarray:
        """The root particles the search at ``belief`` starts from (the same draw as :meth:`search`)."""
        from pearl_pomdp.online.decider import decision_seed

        seed = decision_seed(belief, self.seed)
        return sample_belief(belief, self.settings.scenarios, np.random.default_rng([seed, 1]))
