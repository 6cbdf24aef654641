"""The reception study: controllers × episodes × speech noise × seeds, with paired statistics.

Protocol (docs/reception.md): every controller meets every *cell* — an episode of the study file
at a noise level (the recogniser's word error rate) with a seed — and a cell gives the same world
to every controller, so the differences against the behaviour tree are **paired**. Each episode
runs through :func:`pearl_sim.loop.run_episode` with the core executive and the belief tracker's
rules from ``config/reception_nodes.yaml`` (the robot's own step loop).

Scores per episode: the discounted return (the domain's rewards on the world's *true* state when
each action starts), task success (every visitor handed over where they wanted to go and the
robot never stranded), visitors served, wrong actions, clarification questions and unprompted
ones, seconds from arrival to hand-over.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Dict, List, Optional, Sequence, Union

from pearl_sim.reception.scenario import ReceptionScenario
from pearl_sim.reception.world import ReceptionWorld
from pearl_sim.world_study import episode_settings, paired_differences, per_policy_rows, run_scored_episode

__all__ = ["ReceptionEpisode", "run_reception_episode", "reception_agents", "summarise",
           "BASELINE", "DEFAULT_POLICIES", "SCORES"]

BASELINE = "behaviour_tree"
#: The compared controllers: the hierarchical POMDP, the flat point-based POMDP, QMDP and the tree.
DEFAULT_POLICIES = ("hierarchical", "flat_pointbased", "qmdp", "behaviour_tree")
#: Per-episode scores reported with CIs and paired against the baseline.
SCORES = ("discounted_return", "success", "visitors_served", "wrong_actions", "clarifications",
          "unprompted_questions")


@dataclass
class ReceptionEpisode:
    """One episode's scores and the cell it ran in."""

    policy: str
    scenario: str
    noise: float
    seed: int
    discounted_return: float
    success: bool
    visitors: int
    visitors_served: int
    visitors_left: int
    wrong_actions: int
    clarifications: int
    unprompted_questions: int
    stranded: bool
    docks: int
    steps: int
    seconds: float
    time_to_handover: List[float] = field(default_factory=list)
    actions: List[str] = field(default_factory=list)
    wrong: List[str] = field(default_factory=list)
    #: The episode as ``pearl fit`` reads it (one ``.jsonl`` line).
    record: Dict[str, Any] = field(default_factory=dict)


def run_reception_episode(scenario: ReceptionScenario, agent, domain, params_file: Union[str, Path],
                          seed: Optional[int] = None, word_error_rate: Optional[float] = None, model=None,
                          on_step=None) -> ReceptionEpisode:
    """Run ``agent`` (a controller: ``name`` and ``decider``) in a fresh :class:`ReceptionWorld`
    through the one step loop, and score it.

    The return is Σ_t γ^t R[s_t, a_t] with R and γ of ``domain`` and s_t the world's true state
    (:meth:`ReceptionWorld.truth`) when a_t starts.
    """
    from pearl_pomdp.executive import Executive

    model = model if model is not None else domain.compile()
    world = ReceptionWorld(scenario, seed=seed, word_error_rate=word_error_rate)
    executive = Executive(model, agent.decider, domain=domain, settings=episode_settings(scenario, params_file))
    states: List[Dict[str, str]] = []
    trace, total = run_scored_episode(world, executive, domain, model, on_step=on_step,
                                      on_start=lambda action: states.append(world.truth()))
    states.append(world.truth())
    # Closed steps of actions the world carried out: queued observations can close the steps of
    # actions decided but not yet carried out when the step budget ends.
    steps = executive.steps[:len(trace.actions)]
    m = world.metrics
    return ReceptionEpisode(
        policy=agent.name, scenario=scenario.name, noise=float(world.word_error_rate), seed=world.seed,
        discounted_return=total, success=world.served_all, visitors=len(scenario.visitors),
        visitors_served=m.visitors_served, visitors_left=m.visitors_left, wrong_actions=m.wrong_actions,
        clarifications=m.clarifications, unprompted_questions=m.unprompted_questions, stranded=m.stranded,
        docks=m.docks, steps=m.steps, seconds=float(world.time), time_to_handover=list(m.time_to_handover),
        actions=list(trace.actions), wrong=list(m.wrong),
        # What `pearl fit` reads: the closed steps (the last may still be open) and the true state
        # at the start of every action, and after the last closed one.
        record={"scenario": scenario.name, "seed": world.seed, "actions": [st.action for st in steps],
                "observations": [st.observation for st in steps], "states": states[:len(steps) + 1]})


def reception_agents(domain, hierarchy_path, policies: Sequence[str] = DEFAULT_POLICIES, seed: int = 0,
                     flat_trials: Optional[int] = None, flat_time_limit: Optional[float] = None, log=None):
    """Plan the POMDP controllers (as the nursing-home study plans them: :func:`pearl_sim.planning.plan_controller`)
    and build the reception behaviour tree; name → controller, with ``.timings``."""
    from pearl_sim.planning import plan_controller, plan_each
    from pearl_sim.policies import DEFAULT_FLAT_TRIALS
    from pearl_sim.reception.behaviour_tree import ReceptionBehaviourTree

    known = set(DEFAULT_POLICIES) | {"most_likely_state"}
    unknown = [p for p in policies if p not in known]
    if unknown:
        raise ValueError(f"unknown policy {unknown[0]!r} for the reception world; known: {', '.join(sorted(known))}")
    model = domain.compile()

    def build(name: str):
        if name == BASELINE:
            return ReceptionBehaviourTree(name, list(model.actions))
        return plan_controller(name, domain, model, hierarchy_path, seed=seed,
                               flat_trials=flat_trials or DEFAULT_FLAT_TRIALS, flat_time_limit=flat_time_limit)

    return plan_each(policies, build, log)


def summarise(episodes: Sequence[ReceptionEpisode], baseline: str = BASELINE) -> dict:
    """``per_policy`` (policy → noise → score → mean, 95 % t CI, n; task success with a Wilson CI;
    mean seconds to hand-over) and ``paired`` (policy → noise → score → mean and 95 % CI of
    policy − baseline over the same cells)."""
    from pearl_sim.stats import t_ci

    def extra(es: List[ReceptionEpisode]) -> Dict[str, Any]:
        return {"time_to_handover_s": t_ci([t for e in es for t in e.time_to_handover]),
                "stranded": int(sum(e.stranded for e in es))}

    per_policy = per_policy_rows(episodes, SCORES, extra)
    paired = {p: paired_differences(episodes, SCORES, p, baseline) for p in sorted(set(per_policy) - {baseline})}
    per_scenario: Dict[str, Dict[str, List[ReceptionEpisode]]] = {}
    for e in episodes:
        per_scenario.setdefault(e.scenario, {}).setdefault(e.policy, []).append(e)
    scen = {name: {p: {"episodes": len(es), "success": sum(x.success for x in es) / len(es),
                       "wrong_actions": sum(x.wrong_actions for x in es) / len(es),
                       "discounted_return": sum(x.discounted_return for x in es) / len(es)}
                   for p, es in by.items()}
            for name, by in sorted(per_scenario.items())}
    return {"per_policy": per_policy, "paired_vs_baseline": paired, "per_scenario": scen}


def episodes_json(episodes: Sequence[ReceptionEpisode]) -> List[dict]:
    """JSON-ready rows, one per episode (with its actions and wrong actions; not the fit record)."""
    return [{k: v for k, v in asdict(e).items() if k != "record"} for e in episodes]


def format_table(summary: dict, baseline: str = BASELINE) -> str:
    """The study's table as text: per controller and noise level, return ± CI, the paired return
    difference to ``baseline`` with its 95 % CI, task success and wrong actions per episode."""
    lines = [f"{'policy':<16} {'noise':>5} {'return':>14} {'Δreturn vs tree [95% CI]':>28} {'success':>18} "
             f"{'wrong/ep':>12} {'clar/ep':>8}"]
    for policy, by_noise in summary["per_policy"].items():
        for level, row in by_noise.items():
            r, w, s = row["discounted_return"], row["wrong_actions"], row["success_rate"]
            d = "-"
            if policy != baseline and policy in summary["paired_vs_baseline"]:
                p = summary["paired_vs_baseline"][policy][level]["discounted_return"]
                d = f"{p['mean']:+.1f} [{p['low']:+.1f}, {p['high']:+.1f}]"
            lines.append(f"{policy:<16} {level:>5} {r['mean']:>7.1f} ± {r['ci95']:<5.1f} {d:>28} "
                         f"{s['successes']:>3}/{s['n']:<3} [{s['low']:.2f},{s['high']:.2f}] "
                         f"{w['mean']:>5.2f} ± {w['ci95']:<4.2f} {row['clarifications']['mean']:>8.2f}")
    return "\n".join(lines)
