"""PLAN / SOLVE over an action hierarchy (Pineau & Thrun, Table 2; docs/design.md §4).

``PLAN(h)`` runs bottom-up: for every abstract child ``â_j`` of ``h``, ``PLAN(h_j)``
first, then PARAMETERIZE ``â_j`` with ``h_j``'s solved local policy (eq. 15–17);
PARAMETERIZE every primitive child (eq. 11–14); abstract the subtask (eq. 18); then
``SOLVE(h)`` with the solver its spec names: exact incremental pruning (Cassandra,
Littman & Zhang 1997) by default, as in the paper, or the point-based solver.

Subtasks that violate the local reward assumption are reported at plan time (a
warning on the ``pearl_pomdp.hierarchy`` logger and in the report); the hierarchy spec
can add reward shaping to fix them.
"""
from __future__ import annotations

import logging
import time
from typing import Dict, Optional

import numpy as np

from pearl_pomdp.errors import PearlError
from pearl_pomdp.hierarchy.abstraction import AbstractSubtask, KernelBuilder, abstract_subtask
from pearl_pomdp.hierarchy.execute import HierarchicalPolicy, Lookahead, SubtaskPolicy
from pearl_pomdp.hierarchy.parameterize import StateFactors, parameterize
from pearl_pomdp.hierarchy.spec import Hierarchy, SubtaskSpec
from pearl_pomdp.solvers.base import SolveResult
from pearl_pomdp.model.factored import FactoredDomain

__all__ = ["plan", "solve_subtask", "horizon_text"]

log = logging.getLogger("pearl_pomdp.hierarchy")


def horizon_text(info: dict) -> str:
    """A subtask's planning horizon for tables: ``"4"``, ``"1+1"`` (horizon + lookahead), ``"∞"`` (until converged)."""
    horizon = info.get("horizon")
    text = "∞" if horizon is None else str(horizon)
    return f"{text}+{info['lookahead']}" if info.get("lookahead") else text


def solve_subtask(model, spec: SubtaskSpec, seed: int = 0, solver: Optional[str] = None) -> SolveResult:
    """SOLVE(h): run the subtask's configured solver on its (abstract) model."""
    from pearl_pomdp.solvers.registry import solve

    which = solver or spec.solver
    if which == "pointbased":
        # The point-based solver is anytime: its budget is the subtask's time limit.
        return solve(model, which, epsilon=spec.epsilon, time_limit=spec.time_limit or 60.0, seed=seed,
                     where=f"subtask {spec.name!r}: solver")
    return solve(model, which, horizon=spec.horizon, epsilon=spec.epsilon, time_limit=spec.time_limit,
                 seed=seed, where=f"subtask {spec.name!r}: solver")


def plan(domain, hierarchy: Hierarchy, abstraction: bool = True, solver: Optional[str] = None,
         seed: int = 0, progress: bool = False, strict_local_reward: bool = False) -> HierarchicalPolicy:
    """PLAN(root): parameterize, abstract and solve every subtask bottom-up.

    Args:
        domain: a :class:`~pearl_pomdp.model.factored.FactoredDomain` (its features drive
            the abstraction) or a flat :class:`~pearl_pomdp.model.pomdp.Pomdp` (one
            ``state`` feature: only exact lumping of the whole state is possible).
        hierarchy: from :func:`~pearl_pomdp.hierarchy.spec.load_hierarchy`.
        abstraction: apply eq. 18 (``False``: every subtask keeps the full state and
            observation sets; used to check the abstraction).
        solver: override every subtask's solver (``"incprune"`` / ``"pointbased"``).
        seed: seed of the point-based solver.
        progress: a tqdm bar over subtasks on stderr.
        strict_local_reward: raise instead of warn when a subtask violates the local
            reward assumption.

    Returns:
        The :class:`~pearl_pomdp.hierarchy.execute.HierarchicalPolicy`; its ``report`` is the
        ``pearl plan --json`` object (``subtasks`` list and ``total_seconds``).
    """
    t_start = time.perf_counter()
    model = domain.compile() if isinstance(domain, FactoredDomain) else domain
    factored = domain if isinstance(domain, FactoredDomain) else None
    factors = StateFactors.from_domain(domain)
    builder = KernelBuilder(model)
    policies: Dict[str, SubtaskPolicy] = {}
    abstracts: Dict[str, AbstractSubtask] = {}
    reports = []
    order = hierarchy.postorder()
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=len(order), desc="plan", unit="subtask", leave=False)
    for name in order:
        spec = hierarchy.subtasks[name]
        t0 = time.perf_counter()
        effective = {c: policies[c].effective for c in spec.children if c in policies}
        sub = parameterize(model, spec, effective, factors)
        for problem in sub.warnings:
            if strict_local_reward:
                raise PearlError(f"{hierarchy.source}: subtasks.{name}: {problem}")
            log.warning("%s", problem)
        child_relevant = sorted({f for c in spec.children if c in abstracts for f in abstracts[c].relevant})
        abst = abstract_subtask(sub, factors, factored, child_relevant, enabled=abstraction, builder=builder)
        t1 = time.perf_counter()
        result = solve_subtask(abst.model, spec, seed=seed, solver=solver)
        t2 = time.perf_counter()
        pol = SubtaskPolicy(name=name, actions=list(spec.children), abstract=list(sub.abstract),
                            alphas=result.policy.alphas, alpha_actions=result.policy.actions,
                            state_to_model=abst.state_to_model, effective=np.zeros(model.num_states, dtype=np.int64),
                            lookahead=(Lookahead(abst.model.T, abst.model.O, abst.model.R, abst.model.discount,
                                                 result.policy.alphas, spec.lookahead) if spec.lookahead else None))
        # π_h(s): the primitive EXECUTE(h, e_s) reaches, for h's parent (eq. 15–17).
        if pol.lookahead is None:
            best = pol.alpha_actions[np.argmax(pol.alphas_full, axis=0)]  # [S] index into h's actions
        else:
            best = np.concatenate([pol.choose_batch(np.eye(model.num_states)[lo:lo + 256])
                                   for lo in range(0, model.num_states, 256)])
        eff = np.empty(model.num_states, dtype=np.int64)
        for k, child in enumerate(spec.children):
            rows = best == k
            eff[rows] = policies[child].effective[rows] if child in policies else model.actions.index(child)
        pol.effective = eff
        method = result.method
        timed_out = bool(result.extra.get("timed_out", False))
        info = {
            "name": name,
            "states_full": model.num_states,
            "states_abstract": abst.model.num_states,
            "observations_full": model.num_observations,
            "observations_abstract": abst.model.num_observations,
            "actions": list(spec.children),
            "solver": method,
            "alpha_vectors": int(result.policy.num_vectors),
            "seconds": round(t2 - t0, 6),
            "solve_seconds": round(t2 - t1, 6),
            "exact": method == "incprune" and not timed_out,
            "horizon": spec.horizon,
            "lookahead": spec.lookahead,
            "iterations": result.iterations,
            "converged": bool(result.converged),
            "value_at_start": float(result.value_at_start),
            "upper_bound": None if result.upper_bound is None else float(result.upper_bound),
            "warnings": list(sub.warnings) + ([f"subtask {name!r}: the solver hit its time limit "
                                               f"({spec.time_limit} s); the policy is not exact"] if timed_out else []),
            **abst.summary(),
        }
        if timed_out:
            log.warning("%s", info["warnings"][-1])
        pol.info = info
        policies[name] = pol
        abstracts[name] = abst
        reports.append(info)
        if bar is not None:
            bar.update(1)
            bar.set_postfix(subtask=name, states=abst.model.num_states)
    if bar is not None:
        bar.close()
    report = {
        "domain": model.name,
        "hierarchy": hierarchy.name,
        "root": hierarchy.root,
        "abstraction": abstraction,
        "subtasks": reports,
        "total_seconds": round(time.perf_counter() - t_start, 6),
    }
    hp = HierarchicalPolicy(hierarchy.root, {n: policies[n] for n in order}, list(model.actions),
                            model.fingerprint(), report, hierarchy.name, model.name)
    hp.abstract_models = abstracts  # kept for inspection (tests, `pearl hierarchy`); not saved
    return hp
