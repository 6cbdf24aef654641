"""Planning the POMDP controllers a study compares, for any domain (no world, no baseline here).

:func:`plan_controller` plans one of the POMDP controllers by name — the hierarchy, a flat
point-based solve, QMDP, the most-likely-state policy — as a :class:`Controller`;
:func:`pearl_sim.nursing_home.experiment.build_agents` (the nursing home) and
:func:`pearl_sim.reception.study.reception_agents` (the reception hall) add their own behaviour trees.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable, Dict, Optional, Sequence

from pearl_pomdp.interfaces import Decider

__all__ = ["Controller", "PlannedAgents", "plan_each", "plan_controller", "POMDP_POLICIES"]

#: The controllers :func:`plan_controller` plans.
POMDP_POLICIES = ("hierarchical", "flat_pointbased", "qmdp", "most_likely_state")


@dataclass
class Controller:
    """A named decider: what ``pearl experiment`` compares.

    ``domain``: the model the decider was planned with and tracks its belief in, when it is
    not the world's (``pearl experiment --speech-rows``: planned with measured speech rows);
    ``None``: the world's domain.
    """

    name: str
    decider: Decider
    domain: Optional[object] = None


class PlannedAgents(Dict[str, Any]):
    """name → agent (a :class:`Controller`, a behaviour tree, a scripted agent), with
    :attr:`timings`: name → seconds it took to plan."""

    def __init__(self) -> None:
        super().__init__()
        self.timings: Dict[str, float] = {}


def plan_each(policies: Sequence[str], build: Callable[[str], Any],
              log: Optional[Callable[[str], None]] = None) -> PlannedAgents:
    """name → ``build(name)`` for every name of ``policies`` in order, each one's wall seconds in
    ``timings`` (and, with ``log``, said as ``planned NAME in S s``)."""
    import time

    agents = PlannedAgents()
    for name in policies:
        t0 = time.perf_counter()
        agents[name] = build(name)
        agents.timings[name] = time.perf_counter() - t0
        if log:
            log(f"planned {name} in {agents.timings[name]:.1f} s")
    return agents


def plan_controller(name: str, domain, model, hierarchy_path, seed: int = 0, flat_trials: Optional[int] = None,
                    flat_time_limit: Optional[float] = None) -> Controller:
    """Plan the POMDP controller ``name`` (one of :data:`POMDP_POLICIES`) for ``domain`` (``model`` its compiled POMDP).

    ``hierarchical``: :func:`pearl_pomdp.hierarchy.plan` of ``hierarchy_path`` (``None``: the flat
    hierarchy); ``flat_pointbased``:
    one point-based solve of the whole model with ``flat_trials`` trials (or ``flat_time_limit``
    seconds), executed with one step of look-ahead (:data:`pearl_sim.policies.FLAT_LOOKAHEAD`).
    """
    from pearl_pomdp.policies import FlatPolicyDecider
    from pearl_pomdp.solvers.registry import solve
    from pearl_sim.policies import FLAT_LOOKAHEAD

    decider: Decider
    if name == "hierarchical":
        from pearl_pomdp.hierarchy import flat_hierarchy, load_hierarchy, plan

        # No hierarchy file: the flat hierarchy (one root over every primitive), as `pearl plan` does.
        hierarchy = flat_hierarchy(list(domain.actions)) if hierarchy_path is None else load_hierarchy(hierarchy_path, domain)
        decider = plan(domain, hierarchy, seed=seed)
    elif name == "flat_pointbased":
        budget = {"trials": flat_trials} if flat_time_limit is None else {"time_limit": flat_time_limit}
        decider = FlatPolicyDecider(solve(model, "pointbased", seed=seed, **budget).policy, model,
                                    lookahead=FLAT_LOOKAHEAD)
    elif name == "qmdp":
        decider = FlatPolicyDecider(solve(model, "qmdp").policy, model)
    elif name == "most_likely_state":
        from pearl_pomdp.solvers.mdp import most_likely_state_policy

        decider = FlatPolicyDecider(most_likely_state_policy(model), model)
    else:
        raise ValueError(f"{name!r} is not a POMDP controller ({', '.join(POMDP_POLICIES)})")
    return Controller(name, decider)
