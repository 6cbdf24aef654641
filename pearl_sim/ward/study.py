"""The ward study: controllers × episodes × speech noise × seeds, with paired statistics (docs/ward.md).

Every controller meets every *cell* — an episode of the study file at a noise level (the
recogniser's word error rate) with a seed — and a cell gives the same world to every controller,
so the differences against the behaviour tree are **paired**. Each episode runs through
:func:`pearl_sim.loop.run_episode` with the core executive and the tracker's rules from
``config/ward_nodes.yaml``. Every decision's wall time is recorded (p50/p99 per controller).
"""
from __future__ import annotations

import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Dict, List, Optional, Sequence, Union

from pearl_sim.ward.scenario import WardScenario
from pearl_sim.ward.world import WardWorld
from pearl_sim.world_study import episode_settings, paired_differences, per_policy_rows, run_scored_episode

__all__ = ["WardEpisode", "run_ward_episode", "ward_agents", "summarise", "BASELINE", "DEFAULT_POLICIES", "SCORES",
           "ONLINE_TRIALS"]

BASELINE = "behaviour_tree"
#: Trials per decision of the study's online controller (``online`` = ``online:20``).
ONLINE_TRIALS = 20
#: The compared controllers: the hierarchy, DESPOT online, the tree.
DEFAULT_POLICIES = ("hierarchical", "online", "behaviour_tree")
#: Per-episode scores reported with CIs and paired against the baseline.
SCORES = ("discounted_return", "success", "requests_met", "pills_taken", "wrong_actions", "questions",
          "unprompted_questions")


@dataclass
class WardEpisode:
    """One episode's scores and the cell it ran in."""

    policy: str
    scenario: str
    noise: float
    seed: int
    discounted_return: float
    success: bool
    requests: int
    requests_met: int
    pills: int
    pills_taken: int
    pills_on_time: int
    wrong_actions: int
    questions: int
    unprompted_questions: int
    steps: int
    seconds: float
    decision_seconds: List[float] = field(default_factory=list)
    request_wait: List[float] = field(default_factory=list)
    actions: List[str] = field(default_factory=list)
    wrong: List[str] = field(default_factory=list)


class _Timed:
    """A decider whose every decision's wall time is recorded (the executive calls ``execute``)."""

    def __init__(self, decider, seconds: List[float]):
        self._decider, self._seconds = decider, seconds

    def execute(self, belief):
        t0 = time.perf_counter()
        d = self._decider.execute(belief)
        self._seconds.append(time.perf_counter() - t0)
        return d

    def __getattr__(self, name):
        return getattr(self._decider, name)


def run_ward_episode(scenario: WardScenario, agent, domain, params_file: Union[str, Path], seed: Optional[int] = None,
                     word_error_rate: Optional[float] = None, model=None, on_step=None) -> WardEpisode:
    """Run ``agent`` (``name`` and ``decider``) in a fresh :class:`WardWorld` through the one step loop, and score it.

    The return is Σ_t γ^t R[s_t, a_t] with R and γ of ``domain`` and s_t the world's true state
    (:meth:`WardWorld.truth`) when a_t starts.
    """
    from pearl_pomdp.executive import Executive

    model = model if model is not None else domain.compile()
    world = WardWorld(scenario, seed=seed, word_error_rate=word_error_rate)
    if hasattr(agent.decider, "reset"):
        agent.decider.reset()
    seconds: List[float] = []
    decider = agent.decider if hasattr(agent.decider, "observe") else _Timed(agent.decider, seconds)
    executive = Executive(model, decider, domain=domain, settings=episode_settings(scenario, params_file))
    trace, total = run_scored_episode(world, executive, domain, model, on_step=on_step)
    m = world.metrics
    return WardEpisode(
        policy=agent.name, scenario=scenario.name, noise=float(world.word_error_rate), seed=world.seed,
        discounted_return=total, success=world.all_met, requests=m.requests, requests_met=m.requests_met,
        pills=m.pills, pills_taken=m.pills_on_time + m.pills_overdue, pills_on_time=m.pills_on_time,
        wrong_actions=m.wrong_actions, questions=m.questions, unprompted_questions=m.unprompted_questions,
        steps=m.steps, seconds=float(world.time), decision_seconds=seconds, request_wait=list(m.request_wait),
        actions=list(trace.actions), wrong=list(m.wrong))


def ward_agents(domain, hierarchy_path, policies: Sequence[str] = DEFAULT_POLICIES, seed: int = 0, log=None):
    """Plan the POMDP controllers and build the ward tree; name → controller, with ``.timings``.

    ``online`` / ``online:N``: :class:`~pearl_pomdp.online.decider.OnlineDecider` (DESPOT at every
    step, :data:`ONLINE_TRIALS` trials unless ``N``); ``hierarchical``: the hierarchy beside the domain.
    """
    from pearl_pomdp.online.decider import OnlineDecider, online_trials
    from pearl_pomdp.online.despot import DespotSettings
    from pearl_sim.planning import Controller, plan_controller, plan_each
    from pearl_sim.ward.behaviour_tree import WardBehaviourTree

    model = domain.compile()

    def build(name: str):
        if name == BASELINE:
            return WardBehaviourTree(name, list(model.actions))
        if name == "online" or name.startswith("online:"):
            trials = ONLINE_TRIALS if name == "online" else online_trials(name, "--policies")
            return Controller(name, OnlineDecider(model, settings=DespotSettings(trials=trials), seed=seed))
        return plan_controller(name, domain, model, hierarchy_path, seed=seed)

    return plan_each(policies, build, log)


def _ms(values: Sequence[float], q: float) -> Optional[float]:
    """The ``q``-th percentile of ``values`` (seconds) in milliseconds; ``None`` for no values."""
    import numpy as np

    return 1000.0 * float(np.percentile(values, q)) if len(values) else None


def summarise(episodes: Sequence[WardEpisode], baseline: str = BASELINE) -> dict:
    """``per_policy`` (policy → noise → score → mean, 95 % t CI; success with a Wilson CI; decision
    seconds p50/p99/max) and ``paired_vs_baseline`` (policy → noise → score → mean and 95 % CI of
    policy − baseline over the same cells), and ``paired`` between every two POMDP controllers."""
    from pearl_sim.stats import t_ci

    def extra(es: List[WardEpisode]) -> Dict[str, Any]:
        secs = [t for e in es for t in e.decision_seconds]
        return {"request_wait_s": t_ci([t for e in es for t in e.request_wait]),
                "decision_ms": {"p50": _ms(secs, 50), "p99": _ms(secs, 99), "max": _ms(secs, 100), "n": len(secs)}}

    per_policy = per_policy_rows(episodes, SCORES, extra)
    names = sorted(per_policy)
    vs_base = {p: paired_differences(episodes, SCORES, p, baseline) for p in names
               if p != baseline and baseline in per_policy}
    between = {f"{a} - {b}": paired_differences(episodes, SCORES, a, b) for a in names for b in names
               if a < b and baseline not in (a, b)}
    return {"per_policy": per_policy, "paired_vs_baseline": vs_base, "paired": between}


def episodes_json(episodes: Sequence[WardEpisode]) -> List[dict]:
    """JSON-ready rows, one per episode (decision times summarised, not listed)."""
    rows = []
    for e in episodes:
        row = {k: v for k, v in asdict(e).items() if k != "decision_seconds"}
        row["decisions"] = len(e.decision_seconds)
        rows.append(row)
    return rows


def format_table(summary: dict, baseline: str = BASELINE) -> str:
    """The study's table as text: return ± CI, the paired return difference to ``baseline`` with its
    95 % CI, task success, requests met, pills taken, wrong actions, decision p99."""
    lines = [f"{'policy':<16} {'noise':>5} {'return':>14} {'Δreturn vs tree [95% CI]':>28} {'success':>18} "
             f"{'met/ep':>7} {'pills/ep':>8} {'wrong/ep':>9} {'p99 ms':>8}"]
    for policy, by_noise in summary["per_policy"].items():
        for level, row in by_noise.items():
            r, s = row["discounted_return"], row["success_rate"]
            d = "-"
            if policy in summary["paired_vs_baseline"]:
                p = summary["paired_vs_baseline"][policy][level]["discounted_return"]
                d = f"{p['mean']:+.2f} [{p['low']:+.2f}, {p['high']:+.2f}]"
            p99 = row["decision_ms"]["p99"]
            lines.append(f"{policy:<16} {level:>5} {r['mean']:>7.2f} ± {r['ci95']:<5.2f} {d:>28} "
                         f"{s['successes']:>3}/{s['n']:<3} [{s['low']:.2f},{s['high']:.2f}] "
                         f"{row['requests_met']['mean']:>7.2f} {row['pills_taken']['mean']:>8.2f} "
                         f"{row['wrong_actions']['mean']:>9.2f} {'-' if p99 is None else f'{p99:.0f}':>8}")
    return "\n".join(lines)
