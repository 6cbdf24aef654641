"""PLAN / SOLVE over an action hierarchy (Pineau & Thrun, Table 2; docs/design.md §4).

``PLAN(h)`` runs bottom-up: every child subtask is solved before its parent. How a parent
models an abstract child is the hierarchy file's ``parameterize`` (docs/hierarchy.md):

**policy** (the default). Every subtask but the root is an *option* that may stop
(:mod:`pearl_pomdp.hierarchy.options`): its model is the full model restricted to the
primitives below it, abstracted exactly (eq. 18), plus ``Exit``; it is solved for the
discounted infinite horizon by the point-based solver under a deterministic trial budget
(exact incremental pruning where the subtask's actions are all primitive and it converges).
A parent's solve is **policy-contingent**: at every belief its backups may use only the
primitives its children would execute at that belief (their own EXECUTE, recursively), so
the parent's values are those of the children as they act — not eq. 17's "the child knows
the state". EXECUTE is the same rule (:meth:`HierarchicalPolicy.execute`). Trials start from
``b0``, from every corner of a small subtask, and from beliefs a cheap policy (QMDP) visits
in the full model, so each child is solved where a parent will consult it.

**corner** (the paper's). PARAMETERIZE ``â_j`` with ``h_j``'s solved local policy at the
belief concentrated on each state (eq. 15–17), every primitive child (eq. 11–14); abstract
the subtask (eq. 18); then ``SOLVE(h)`` with the solver its spec names: exact incremental
pruning (Cassandra, Littman & Zhang 1997) by default, as in the paper, or point-based.

Subtasks that violate the local reward assumption are reported at plan time (a
warning on the ``pearl_pomdp.hierarchy`` logger and in the report); the hierarchy spec
can add reward shaping to fix them.
"""
from __future__ import annotations

import dataclasses
import logging
import time
from typing import Any, Dict, List, Optional, Tuple

import numpy as np

from pearl_pomdp.errors import PearlError
from pearl_pomdp.hierarchy.abstraction import (AbstractionTooLarge, AbstractSubtask, KernelBuilder, SeparableTerms,
                                               abstract_subtask, separable_reward_terms)
from pearl_pomdp.hierarchy.execute import HierarchicalPolicy
from pearl_pomdp.hierarchy.parameterize import StateFactors, parameterize
from pearl_pomdp.hierarchy.spec import Hierarchy, SubtaskSpec
from pearl_pomdp.hierarchy.subtask import SubtaskPolicy
from pearl_pomdp.model.factored import FactoredDomain
from pearl_pomdp.policies.lookahead import Lookahead
from pearl_pomdp.solution import SolveResult

__all__ = ["plan", "solve_subtask", "horizon_text", "entry_beliefs", "CORNER_LIMIT"]

#: A subtask with at most this many abstract states also starts trials from each of its
#: corners (the beliefs certain of one state): its policy is then solved everywhere a parent
#: can meet it with certainty, at ~one short trial per corner.
CORNER_LIMIT = 64
#: The entry beliefs: ``ENTRY_EPISODES`` episodes of ``ENTRY_STEPS`` steps of QMDP in the full
#: model, one belief in ``ENTRY_EVERY`` kept (30 beliefs): the situations of the whole task
#: (waiting, a reminder heard, contact, a walk, a question) at a cost of a few milliseconds.
ENTRY_EPISODES, ENTRY_STEPS, ENTRY_EVERY = 20, 60, 40

log = logging.getLogger("pearl_pomdp.hierarchy")


def horizon_text(info: dict) -> str:
    """A subtask's planning horizon for tables: ``"4"``, ``"1+1"`` (horizon + lookahead), ``"∞"`` (until converged)."""
    horizon = info.get("horizon")
    if info.get("parameterize") == "policy":
        return f"∞+{info['lookahead']}" if info.get("lookahead") else "∞"
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
         seed: int = 0, progress: bool = False, strict_local_reward: bool = False,
         time_limit: Optional[float] = None) -> HierarchicalPolicy:
    """PLAN(root): parameterize, abstract and solve every subtask bottom-up.

    Args:
        domain: a :class:`~pearl_pomdp.model.factored.FactoredDomain` (its features drive
            the abstraction) or a flat :class:`~pearl_pomdp.model.pomdp.Pomdp` (one
            ``state`` feature: only exact lumping of the whole state is possible).
        hierarchy: from :func:`~pearl_pomdp.hierarchy.spec.load_hierarchy`.
        abstraction: apply eq. 18 (``False``: every subtask keeps the full state and
            observation sets; used to check the abstraction).
        solver: override every subtask's solver (``"incprune"`` / ``"pointbased"``).
        seed: seed of the point-based solver (and of the entry beliefs).
        progress: a tqdm bar over subtasks on stderr.
        strict_local_reward: raise instead of warn when a subtask violates the local
            reward assumption.
        time_limit: seconds for the whole plan, a guard over the subtasks' own budgets:
            each subtask's solver gets at most what is left (the plan then says which
            subtasks it cut short). ``None``: the budgets alone (deterministic).

    Returns:
        The :class:`~pearl_pomdp.hierarchy.execute.HierarchicalPolicy`; its ``report`` is the
        ``pearl plan --json`` object (``subtasks`` list and ``total_seconds``).

    Raises:
        PearlError: a solver the parameterisation cannot use, or a time limit that is not
            positive.
    """
    if time_limit is not None and not time_limit > 0:
        raise PearlError(f"the plan's time limit must be positive, got {time_limit!r}")
    if hierarchy.parameterize == "policy":
        return _plan_policy(domain, hierarchy, abstraction, solver, seed, progress, strict_local_reward, time_limit)
    return _plan_corner(domain, hierarchy, abstraction, solver, seed, progress, strict_local_reward, time_limit)


def _separate(sub, factored, primitives, charged_under, abstraction: bool) -> SeparableTerms:
    """The separable reward terms of a subtask (:func:`separable_reward_terms`), taken out of ``sub.R``
    (nothing when the abstraction is off: ``--no-abstraction`` solves the subtask as it is)."""
    if not abstraction or factored is None:
        return SeparableTerms([], np.zeros(0), [])
    separable = separable_reward_terms(factored, primitives, charged_under)
    sub.R = separable.apply(sub.R)
    return separable


def _left(deadline: Optional[float], own: Optional[float]) -> Optional[float]:
    """The smaller of a subtask's own limit and what is left of the plan's (``None``: none)."""
    if deadline is None:
        return own
    left = max(0.05, deadline - time.perf_counter())
    return left if own is None else min(own, left)


class _Planning:
    """What both PLANs share: the model, its factors, the clock and deadline, the subtasks solved so
    far (bottom-up, :meth:`Hierarchy.postorder`) with their abstractions and reports, the progress bar."""

    def __init__(self, domain, hierarchy: Hierarchy, abstraction: bool, progress: bool, strict_local_reward: bool,
                 time_limit: Optional[float]):
        self.t_start = time.perf_counter()
        self.deadline = None if time_limit is None else self.t_start + time_limit
        self.model = domain.compile() if isinstance(domain, FactoredDomain) else domain
        self.factored = domain if isinstance(domain, FactoredDomain) else None
        self.factors = StateFactors.from_domain(domain)
        self.builder = KernelBuilder(self.model)
        self.hierarchy, self.abstraction, self.time_limit = hierarchy, abstraction, time_limit
        self.strict_local_reward = strict_local_reward
        self.policies: Dict[str, SubtaskPolicy] = {}
        self.abstracts: Dict[str, AbstractSubtask] = {}
        self.reports: List[dict] = []
        self.order = hierarchy.postorder()
        self.bar = None
        if progress:
            from tqdm import tqdm

            self.bar = tqdm(total=len(self.order), desc="plan", unit="subtask", leave=False)

    def abstract(self, name: str, spec: SubtaskSpec, sub, below, charged_under) -> Tuple[AbstractSubtask, SeparableTerms]:
        """Subtask ``name``'s model ``sub`` abstracted (eq. 18) less its separable reward terms; its
        local-reward problems are warned about (or, strict, raised)."""
        for problem in sub.warnings:
            if self.strict_local_reward:
                raise PearlError(f"{self.hierarchy.source}: subtasks.{name}: {problem}")
            log.warning("%s", problem)
        child_relevant = sorted({f for c in spec.children if c in self.abstracts for f in self.abstracts[c].relevant})
        separable = _separate(sub, self.factored, below, charged_under, self.abstraction)
        try:
            abst = abstract_subtask(sub, self.factors, self.factored, child_relevant, enabled=self.abstraction,
                                    builder=self.builder, dropped=separable.rules)
        except AbstractionTooLarge as e:
            raise PearlError(f"{self.hierarchy.source}: subtasks.{name}: {e}") from None
        return abst, separable

    def solved(self, name: str, pol: SubtaskPolicy, info: dict, abst: Optional[AbstractSubtask] = None) -> None:
        """Subtask ``name`` planned: its policy (``info`` its report) and abstraction kept for its parents."""
        pol.info = info
        self.policies[name] = pol
        if abst is not None:
            self.abstracts[name] = abst
        self.reports.append(info)
        if self.bar is not None:
            self.bar.update(1)
            if abst is not None:
                self.bar.set_postfix(subtask=name, states=abst.model.num_states)

    def finish(self, parameterize: str, **extra: Any) -> HierarchicalPolicy:
        """The hierarchical policy of every subtask, its report the ``pearl plan --json`` object."""
        if self.bar is not None:
            self.bar.close()
        model, hierarchy = self.model, self.hierarchy
        report = {"domain": model.name, "hierarchy": hierarchy.name, "root": hierarchy.root,
                  "parameterize": parameterize, "time_limit": self.time_limit, "abstraction": self.abstraction,
                  **extra, "subtasks": self.reports, "total_seconds": round(time.perf_counter() - self.t_start, 6)}
        hp = HierarchicalPolicy(hierarchy.root, {n: self.policies[n] for n in self.order}, list(model.actions),
                                model.fingerprint(), report, hierarchy.name, model.name)
        hp.abstract_models = self.abstracts  # kept for inspection (tests, `pearl hierarchy`); not saved
        return hp


def _plan_corner(domain, hierarchy: Hierarchy, abstraction: bool, solver: Optional[str], seed: int, progress: bool,
                 strict_local_reward: bool, time_limit: Optional[float]) -> HierarchicalPolicy:
    """The paper's PLAN with eq. 15–17 (``parameterize: corner``)."""
    run = _Planning(domain, hierarchy, abstraction, progress, strict_local_reward, time_limit)
    model, policies, deadline = run.model, run.policies, run.deadline
    for name in run.order:
        spec = hierarchy.subtasks[name]
        t0 = time.perf_counter()
        effective = {c: policies[c].effective for c in spec.children if c in policies}
        sub = parameterize(model, spec, effective, run.factors)
        # Eq. 15-17's subtask never stops: a term charged under each of its primitives alike is separable.
        below = hierarchy.descendants(name)
        abst, separable = run.abstract(name, spec, sub, below, below)
        t1 = time.perf_counter()
        limited = spec if deadline is None else dataclasses.replace(spec, time_limit=_left(deadline, spec.time_limit))
        result = solve_subtask(abst.model, limited, seed=seed, solver=solver)
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
        # Exact when the exact solver ended by its own rule (converged, or its finite horizon),
        # not by the clock or a vector cap.
        timed_out = result.extra.get("stop_reason", "time_limit" if result.extra.get("timed_out") else None) in \
            ("time_limit", "vector_cap")
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
            "parameterize": "corner",
            "separable_reward_terms": separable.described,
            "stop_reason": result.extra.get("stop_reason"),
            "warnings": list(sub.warnings) + ([f"subtask {name!r}: the solver stopped by "
                                               f"{result.extra.get('stop_reason', 'its time limit')} "
                                               f"({limited.time_limit} s); the policy is not exact"]
                                              if timed_out else []),
            **abst.summary(),
        }
        if timed_out:
            log.warning("%s", info["warnings"][-1])
        run.solved(name, pol, info, abst)
    return run.finish("corner")


# ------------------------------------------------------------------ policy-contingent PLAN
def entry_beliefs(model, seed: int = 0, episodes: int = ENTRY_EPISODES, steps: int = ENTRY_STEPS,
                  every: int = ENTRY_EVERY, qmdp: Optional[np.ndarray] = None) -> np.ndarray:
    """Beliefs a cheap policy meets in the full model: ``[N, S]``, deterministic for ``seed``.

    QMDP (one α-vector per action, solved in milliseconds) is run for ``episodes`` episodes
    of ``steps`` steps — start state from ``b0``, next state from ``T``, observation from
    ``O``, belief by eq. 5 — and every ``every``-th belief is kept. QMDP does every service of
    the task (it reminds, walks, answers; it only never asks), so these beliefs are the
    situations in which parents will consult their children. ``qmdp``: the QMDP ``Q [S, A]`` when
    it is already computed (an online root's upper bound past ``FIB_LIMIT``: the same value
    iteration, not run twice on the ward's 233,280 states)."""
    from pearl_pomdp.belief import BeliefFilter
    from pearl_pomdp.simulate import EpisodeSampler
    from pearl_pomdp.solution import AlphaVectorPolicy
    from pearl_pomdp.solvers.mdp import solve_qmdp

    policy = solve_qmdp(model).policy if qmdp is None else AlphaVectorPolicy(
        np.asarray(qmdp, dtype=float).T.copy(), np.arange(model.num_actions))
    rng = np.random.default_rng(seed)
    filt = BeliefFilter(model)
    sampler = EpisodeSampler(model)
    states = sampler.start(rng.random(episodes))
    B = np.tile(sampler.b0, (episodes, 1))
    # The beliefs of the kept steps, one after the other, are thinned to every `stride`-th: only
    # those rows are copied (the ward's 600 kept beliefs of 233,280 states would take 1.1 GB).
    kept_steps = [t for t in range(steps) if t % every == 0 or (t * episodes) % every < episodes]
    stride = max(1, len(kept_steps) * episodes // max(1, (episodes * steps) // every))
    rows_at = {t: [g % episodes for g in range(k * episodes, (k + 1) * episodes) if g % stride == 0]
               for k, t in enumerate(kept_steps)}
    picked = []
    for t in range(steps):
        if rows_at.get(t):
            picked.append(B[rows_at[t]])
        actions = policy.actions_batch(B)
        u_s, u_o = rng.random(episodes), rng.random(episodes)
        nxt, obs = sampler.step(states, actions, u_s, u_o)
        B = filt.update_batch(B, actions, obs)
        states = nxt
    return np.concatenate(picked)


def _starts(abst: AbstractSubtask, n_model: int, entries: np.ndarray) -> np.ndarray:
    """The start beliefs of a subtask's trials besides its b0: every corner of a small
    subtask (:data:`CORNER_LIMIT`), and the entry beliefs projected onto its states,
    rounded to 1e-6 and deduplicated (rows over the model's ``n_model`` states)."""
    X = abst.model.num_states
    rows = []
    if abst.lumped_states <= CORNER_LIMIT:
        for x in range(X):
            e = np.zeros(n_model)
            e[x] = 1.0
            rows.append(e)
    if entries.size:
        projected = np.stack([np.bincount(abst.state_to_model, weights=b, minlength=X) for b in entries])
        projected = np.unique(np.round(projected, 6), axis=0)
        for p in projected:
            if p.sum() > 0:
                e = np.zeros(n_model)
                e[:X] = p / p.sum()
                rows.append(e)
    return np.array(rows) if rows else np.zeros((0, n_model))


def _online_root(spec: SubtaskSpec, model, policies: Dict[str, SubtaskPolicy], seed: int, features) -> SubtaskPolicy:
    """The placeholder policy of a root that plans online (``solver: online``): its children and the
    search's record; EXECUTE runs :class:`~pearl_pomdp.hierarchy.online_root.OnlineRoot`."""
    from pearl_pomdp.online.despot import DespotSettings

    base = DespotSettings()
    record = {"trials": spec.trials, "time_limit": spec.time_limit, "scenarios": base.scenarios,
              "depth": base.depth, "seed": int(seed)}
    S = model.num_states
    pol = SubtaskPolicy(name=spec.name, actions=list(spec.children), abstract=[c in policies for c in spec.children],
                        alphas=np.zeros((1, 1)), alpha_actions=np.zeros(1, dtype=np.int64),
                        state_to_model=np.zeros(S, dtype=np.int64), effective=np.full(S, -1, dtype=np.int64),
                        online=record)
    pol.info = {
        "name": spec.name, "parameterize": "policy", "solver": "online", "states_full": S, "states_abstract": S,
        "model_states": S, "observations_full": model.num_observations,
        "observations_abstract": model.num_observations, "actions": list(spec.children), "option": False,
        "alpha_vectors": 0, "seconds": 0.0, "solve_seconds": 0.0, "exact": False, "horizon": None, "lookahead": 0,
        "trials_budget": spec.trials, "online": record, "warnings": [], "separable_reward_terms": [],
        "relevant_features": list(features), "irrelevant_features": [], "stop_reason": "online",
        "value_at_start": float("nan"), "upper_bound": None, "gap": None,
    }
    return pol


class _ChildOffers:
    """The action filter of a policy-contingent parent: at a belief over the parent's model,
    the primitives its children offer there (:meth:`HierarchicalPolicy.offers`: what each child
    subtask would execute, a group's children's offers) and ``Exit`` for an option."""

    def __init__(self, solved: HierarchicalPolicy, spec: SubtaskSpec, model_actions, state_to_model: np.ndarray,
                 n_states: int, has_exit: bool):
        self.solved = solved
        self.children = list(spec.children)
        self.index = {a: i for i, a in enumerate(model_actions)}
        self.n_model = len(model_actions) and None
        self.has_exit = has_exit
        self.A = len(model_actions)
        X = int(state_to_model.max()) + 1
        self.representative = np.full(n_states + (1 if has_exit else 0), -1, dtype=np.int64)
        order = np.arange(state_to_model.shape[0] - 1, -1, -1)
        self.representative[state_to_model[order]] = order
        self.X = X
        self.S = state_to_model.shape[0]
        self.asked = 0

    def __call__(self, idx: np.ndarray, val: np.ndarray) -> np.ndarray:
        self.asked += 1
        mask = np.zeros(self.A, dtype=bool)
        if self.has_exit:
            mask[-1] = True                         # stopping is always possible
        real = idx < self.X
        if not real.any():
            return mask                             # all mass on `done`: nothing else to do
        b = np.zeros(self.S)
        b[self.representative[idx[real]]] = val[real]
        b /= b.sum()
        memo: Dict[str, tuple] = {}
        for prim, _path in self.solved.offers(self.children, b, memo):
            mask[self.index[self.solved.action_names[prim]]] = True
        return mask


def _plan_policy(domain, hierarchy: Hierarchy, abstraction: bool, solver: Optional[str], seed: int, progress: bool,
                 strict_local_reward: bool, time_limit: Optional[float]) -> HierarchicalPolicy:
    """PLAN with policy-contingent parents and options (``parameterize: policy``; module doc)."""
    from pearl_pomdp.hierarchy.options import with_exit
    from pearl_pomdp.solvers.point_based import PointBasedSettings, PointBasedSolver

    if solver not in (None, "pointbased", "incprune"):
        raise PearlError(f"unknown solver {solver!r}; choose pointbased or incprune (an online root stays online)")
    run = _Planning(domain, hierarchy, abstraction, progress, strict_local_reward, time_limit)
    model, policies, deadline = run.model, run.policies, run.deadline
    online_bounds, bounds_seconds, qmdp = None, 0.0, None
    if hierarchy.subtasks[hierarchy.root].solver == "online":
        from pearl_pomdp.online.decider import default_bounds, default_upper

        # The online root's bounds first: past FIB_LIMIT their upper bound is the QMDP Q the entry
        # beliefs' policy needs too (one value iteration over the full model, not two).
        t_bounds = time.perf_counter()
        online_bounds = default_bounds(model)
        bounds_seconds = time.perf_counter() - t_bounds
        qmdp = getattr(online_bounds, "upper_q", None) if default_upper(model) == "qmdp" else None
    entries = entry_beliefs(model, seed=seed, qmdp=qmdp)
    for name in run.order:
        spec = hierarchy.subtasks[name]
        is_root = name == hierarchy.root
        t0 = time.perf_counter()
        below = hierarchy.descendants(name)
        if is_root and spec.solver == "online":
            # Not planned here: DESPOT over its actions at run time (bound to the model below).
            root = _online_root(spec, model, policies, seed, run.factors.names)
            run.solved(name, root, root.info)
            continue
        # The subtask over the primitives below it (eq. 11–14 for each), abstracted exactly.
        flat_spec = dataclasses.replace(spec, children=list(below))
        sub = parameterize(model, flat_spec, {}, run.factors)
        # An option hands the step back to its parent when it stops: a term is separable only when
        # every action of the domain pays it (the root never stops: its own primitives suffice).
        abst, separable = run.abstract(name, spec, sub, below, below if is_root else list(model.actions))
        solve_model = abst.model if is_root else with_exit(abst.model)
        starts = _starts(abst, solve_model.num_states, entries)
        abstract_children = [c for c in spec.children if c in policies]
        offers = None
        if abstract_children:
            solved = HierarchicalPolicy(abstract_children[0], dict(policies), list(model.actions))
            offers = _ChildOffers(solved, spec, solve_model.actions, abst.state_to_model, abst.model.num_states,
                                  not is_root)
        which = solver or spec.solver
        if which == "incprune" and abstract_children:
            which = "pointbased"   # a parent's offers depend on the belief (only the solver override gets here)
        t1 = time.perf_counter()
        notes = []
        result = None
        if which == "incprune":
            from pearl_pomdp.solvers.incremental_pruning import solve_incremental_pruning

            # The exact attempt gets half of the subtask's time (and of what is left of the plan's):
            # if it does not converge, the point-based fallback must still have time for its
            # trials, or an early stop would leave a policy worse than point-based alone.
            own = None if spec.time_limit is None else 0.5 * spec.time_limit
            plan_share = None if deadline is None else 0.5 * max(0.05, deadline - time.perf_counter())
            exact_limit = min((x for x in (own, plan_share) if x is not None), default=None)
            result = solve_incremental_pruning(solve_model, horizon=spec.horizon, epsilon=spec.epsilon,
                                               time_limit=exact_limit)
            if result.extra.get("stop_reason") in ("time_limit", "vector_cap"):
                notes.append(f"subtask {name!r}: incremental pruning stopped by {result.extra['stop_reason']} after "
                             f"{result.iterations} epochs; planned point-based instead")
                log.warning("%s", notes[-1])
                result = None
        if result is None:
            t_fallback = time.perf_counter()   # its own clock: what an exact attempt spent is not its
            own = spec.time_limit if spec.time_limit is None or which != "incprune" else 0.5 * spec.time_limit
            limit = _left(deadline, own)
            # FIB (the first upper bound) only to within the target gap: every iterate is a bound.
            pb = PointBasedSolver(solve_model, seed=seed, fib_time=None if limit is None else max(0.05, 0.1 * limit),
                                  settings=PointBasedSettings(fib_epsilon=max(spec.epsilon, 1e-6)),
                                  action_filter=offers, starts=starts)
            result = pb.run(time_limit=float("inf") if limit is None else max(0.0, limit - (time.perf_counter() - t_fallback)),
                            epsilon=spec.epsilon, max_trials=spec.trials)
            result.extra["setup_seconds"] = pb.setup_seconds
            stopped = "converged" if result.converged else (
                "trials" if spec.trials is not None and result.iterations >= spec.trials else "time_limit")
            result.extra["stop_reason"] = stopped
            if stopped == "time_limit":
                notes.append(f"subtask {name!r}: the point-based solve stopped at the time limit after "
                             f"{result.iterations} trials (gap {result.extra['gap']:.3g} at b0)")
                log.warning("%s", notes[-1])
        t2 = time.perf_counter()
        alphas = result.policy.alphas
        pol = SubtaskPolicy(name=name, actions=list(spec.children), abstract=[c in policies for c in spec.children],
                            alphas=alphas, alpha_actions=result.policy.actions, state_to_model=abst.state_to_model,
                            effective=np.zeros(model.num_states, dtype=np.int64),
                            lookahead=Lookahead(solve_model.T, solve_model.O, solve_model.R, solve_model.discount,
                                                alphas, 1),
                            model_actions=list(solve_model.actions), exit=not is_root,
                            search_depth=1 + spec.lookahead, expansions=spec.expansions)
        exact = result.method == "incprune" and result.extra.get("stop_reason") in ("converged", "horizon")
        ub = None if result.upper_bound is None else float(result.upper_bound)
        info = {
            "name": name,
            "parameterize": "policy",
            "states_full": model.num_states,
            "states_abstract": abst.model.num_states,
            "model_states": solve_model.num_states,
            "observations_full": model.num_observations,
            "observations_abstract": abst.model.num_observations,
            "actions": list(spec.children),
            "primitives": list(below),
            "option": not is_root,
            "solver": result.method,
            "alpha_vectors": int(result.policy.num_vectors),
            "seconds": round(t2 - t0, 6),
            "solve_seconds": round(t2 - t1, 6),
            "exact": bool(exact),
            "horizon": spec.horizon,
            "lookahead": spec.lookahead,
            "expansions": spec.expansions,
            "trials_budget": spec.trials,
            "iterations": result.iterations,
            "converged": bool(result.converged),
            "stop_reason": result.extra.get("stop_reason"),
            "value_at_start": float(result.value_at_start),
            "upper_bound": ub,
            "gap": None if ub is None else ub - float(result.value_at_start),
            "epsilon": spec.epsilon,
            "starts": int(result.extra.get("starts", 1)),
            "max_start_gap": result.extra.get("max_start_gap"),
            "offers_asked": 0 if offers is None else offers.asked,
            "separable_reward_terms": separable.described,
            "warnings": list(sub.warnings) + notes,
            **abst.summary(),
        }
        run.solved(name, pol, info, abst)
    hp = run.finish("policy", entry_beliefs=int(entries.shape[0]))
    # π_h(s) for the record (`pearl explain`, `pearl hierarchy`): the primitive each subtask
    # picks at the belief certain of s (an online root has none: -1).
    for name in run.order:
        if policies[name].online is None:
            policies[name].effective = hp.corner_picks(name)
    if hp.online:
        hp.bind_model(model, bounds=online_bounds)
        info = policies[hierarchy.root].info
        info["bounds"] = hp.online_root.bounds.description
        info["bounds_seconds"] = round(bounds_seconds, 6)
        # One decision at b0: the search's size and root bounds, as the online decider reports them.
        first = hp.execute(np.asarray(model.b0, dtype=float))
        search = dict(first.search or {})
        info.update(value_at_start=float(search["lower"]), upper_bound=float(search["upper"]), gap=float(search["gap"]),
                    b0_decision={"action": first.action_name, "trace": [t.choice for t in first.trace],
                                 **{k: search[k] for k in ("trials", "nodes", "expansions", "seconds", "stop")}})
        info["seconds"] = round(info["seconds"] + info["bounds_seconds"], 6)
        hp.report["total_seconds"] = round(time.perf_counter() - run.t_start, 6)
    return hp
