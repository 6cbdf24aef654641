"""The guidance study, run fast on the core executive (no DDS).

Reproduces the shape of the paper's evaluation (12 guidances, 6 residents) and goes
past it: every controller of :mod:`pearl_sim.agents` meets the same seeded
residents; we score guidance success, time to goal, clarification questions per
goal achieved, wrong actions and the discounted return (the Pearl domain's own
reward rules applied to the *true* state), each with a 95% confidence interval,
plus a sweep over the recogniser's word error rate and a comparison of the
paper's fixed-pace guidance against walking-pace adaptation.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Callable, Dict, Iterable, List, Optional, Sequence

import numpy as np

from pearl_sim.agents import message_symbol
from pearl_sim.scenario import Scenario
from pearl_sim.world import World


@dataclass
class EpisodeResult:
    """One episode's scores."""

    scenario: str
    agent: str
    seed: int
    discounted_return: float
    steps: int
    guidance_needed: bool
    guidance_completed: bool
    time_to_goal: Optional[float]
    clarifications: int
    goals_achieved: int
    wrong_actions: int
    residents_lost: int
    walking_speed: float
    actions: List[str] = field(default_factory=list)


def run_episode(scenario: Scenario, agent, domain, keyword_filter, seed: Optional[int] = None,
                pace_adaptation: Optional[bool] = None, on_step: Optional[Callable] = None) -> EpisodeResult:
    """Run ``agent`` in a fresh :class:`World` until the scenario's step budget is used.

    The return is Σ_t γ^t R[s_t, a_t] with R and γ from ``domain`` (a FactoredDomain)
    and s_t the world's true state mapped onto the domain's features.
    """
    model = domain.compile()
    world = World(scenario, seed=seed, pace_adaptation=pace_adaptation)
    agent.reset()
    total, discount = 0.0, 1.0
    actions: List[str] = []
    while not world.done:
        action = agent.act()
        state = domain.state_index(world.truth())
        total += discount * float(model.R[state, model.actions.index(action)])
        discount *= model.discount
        result = world.step(action)
        symbol = message_symbol(result.message, keyword_filter)
        agent.observe(action, symbol)
        actions.append(action)
        if on_step is not None:
            on_step(world, result, symbol, agent)
    m = world.metrics
    needed = any(a.kind == "physio" for a in scenario.appointments)
    return EpisodeResult(
        scenario=scenario.name, agent=agent.name, seed=world.seed, discounted_return=total, steps=m.steps,
        guidance_needed=needed, guidance_completed=m.guidances_completed > 0,
        time_to_goal=m.time_to_goal[0] if m.time_to_goal else None, clarifications=m.clarifications,
        goals_achieved=m.reminders_delivered + m.questions_answered + m.guidances_completed,
        wrong_actions=m.wrong_actions, residents_lost=m.residents_lost,
        walking_speed=scenario.resident.walking_speed, actions=actions,
    )


# ----------------------------------------------------------------- statistics
def mean_ci(values: Sequence[float]) -> Dict[str, float]:
    """Mean and 95% half-width (normal approximation; 0 for fewer than two values)."""
    x = np.asarray(list(values), dtype=float)
    if x.size == 0:
        return {"mean": None, "ci95": None, "n": 0}
    half = 1.96 * x.std(ddof=1) / math.sqrt(x.size) if x.size > 1 else 0.0
    return {"mean": float(x.mean()), "ci95": float(half), "n": int(x.size)}


def proportion_ci(successes: int, n: int) -> Dict[str, float]:
    """Success rate with a 95% Wilson score interval."""
    if n == 0:
        return {"rate": None, "low": None, "high": None, "successes": 0, "n": 0}
    z = 1.96
    p = successes / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return {"rate": p, "low": max(0.0, centre - half), "high": min(1.0, centre + half), "successes": successes, "n": n}


def summarise(results: Iterable[EpisodeResult]) -> Dict[str, dict]:
    """Per-agent scores with confidence intervals."""
    by_agent: Dict[str, List[EpisodeResult]] = {}
    for r in results:
        by_agent.setdefault(r.agent, []).append(r)
    out = {}
    for agent, rs in by_agent.items():
        guided = [r for r in rs if r.guidance_needed]
        goals = sum(r.goals_achieved for r in rs)
        out[agent] = {
            "episodes": len(rs),
            "guidance_success": proportion_ci(sum(r.guidance_completed for r in guided), len(guided)),
            "time_to_goal_s": mean_ci([r.time_to_goal for r in guided if r.time_to_goal is not None]),
            "clarifications_per_goal": (sum(r.clarifications for r in rs) / goals) if goals else None,
            "wrong_actions_per_episode": mean_ci([r.wrong_actions for r in rs]),
            "residents_lost": int(sum(r.residents_lost for r in rs)),
            "discounted_return": mean_ci([r.discounted_return for r in rs]),
        }
    return out


def with_word_error_rate(scenario: Scenario, wer: float) -> Scenario:
    """A copy of ``scenario`` whose recogniser has word error rate ``wer`` (resident override cleared)."""
    return replace(scenario, word_error_rate=float(wer), resident=replace(scenario.resident, word_error_rate=None))
