"""The guidance study, run fast on the robot's own step loop (the core executive, no DDS).

Every episode runs through :func:`pearl_sim.loop.run_episode` with the belief tracker's
rules from ``config/pearl_nodes.yaml`` (the same object the ``belief_tracker`` node
wraps; ``test/test_one_loop.py`` checks that the nodes over DDS give the same actions).

Reproduces the shape of the paper's evaluation (12 guidances, 6 residents) and goes
past it: every controller of :mod:`pearl_sim.nursing_home.agents` meets the same seeded
residents; we score guidance success, time to goal, clarification questions per
goal achieved, wrong actions and the discounted return (the Pearl domain's own
reward rules applied to the *true* state), each with a 95% confidence interval,
plus a sweep over the recogniser's word error rate and a comparison of the
paper's fixed-pace guidance against walking-pace adaptation.
"""
from __future__ import annotations

import sys
from dataclasses import dataclass, field, replace
from typing import Callable, List, Optional, Sequence

from pearl_sim.nursing_home.scenario import Scenario
from pearl_sim.nursing_home.world import World, until_pearl_leaves


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
    unprompted_questions: int
    goals_achieved: int
    wrong_actions: int
    residents_lost: int
    walking_speed: float
    actions: List[str] = field(default_factory=list)
    questions_answered: int = 0
    reminders_delivered: int = 0
    #: She wanted the walk at some point (``guidance_needed`` only says an appointment was due:
    #: a resident may decline it).
    guidance_wanted: bool = False
    #: Questions she came to have (the world's count), of which ``questions_answered`` were answered.
    questions_raised: int = 0
    #: Simulated seconds the episode lasted (the world's clock at its end).
    seconds: float = 0.0


def episode_executive(controller, domain, scenario: Scenario, model=None):
    """The robot's loop for one episode: the controller's decider in an Executive with the
    belief tracker's parameters from ``config/pearl_nodes.yaml`` and the scenario's step timeout
    and map (:meth:`~pearl_sim.nursing_home.scenario.Scenario.tracker_parameters`: drive deadlines)."""
    from pearl_pomdp.executive import Executive
    from pearl_pomdp.params import step_settings

    settings = step_settings(**scenario.tracker_parameters())
    return Executive(model if model is not None else domain.compile(), controller.decider, domain=domain,
                     settings=settings)


def run_episode(scenario: Scenario, agent, domain, keyword_filter=None, seed: Optional[int] = None,
                pace_adaptation: Optional[bool] = None, on_step: Optional[Callable] = None,
                until_left: bool = False) -> EpisodeResult:
    """Run ``agent`` (a :class:`~pearl_sim.nursing_home.agents.Controller`) in a fresh :class:`World` through the step loop.

    The loop is :func:`pearl_sim.loop.run_episode` with the core executive as the robot —
    the tracker rules of the ``belief_tracker`` node. The return is Σ_t γ^t R[s_t, a_t] with
    R and γ from ``domain`` (a FactoredDomain) and s_t the world's true state, mapped onto
    the domain's features, when a_t starts. ``keyword_filter`` is unused (the tracker builds
    the domain's own); it stays for callers of the old signature. ``until_left``: the episode
    runs until Pearl leaves (:func:`~pearl_sim.nursing_home.world.until_pearl_leaves`, as ``pearl
    demo``) instead of for the scenario's step budget.
    """
    from pearl_sim.loop import ExecutiveBackend, run_episode as run_loop

    model = domain.compile()
    world = World(scenario, seed=seed, pace_adaptation=pace_adaptation, domain=domain)
    # The robot's model: the agent's own (planned with other observation rows) or the world's.
    own = getattr(agent, "domain", None)
    executive = episode_executive(agent, own, scenario, own.compile()) if own is not None else \
        episode_executive(agent, domain, scenario, model)
    backend = ExecutiveBackend(executive)
    returns = {"total": 0.0, "discount": 1.0}
    action_index = {a: i for i, a in enumerate(model.actions)}

    def score(action: str) -> None:
        # Reward of the true state the action starts in (before the world changes it).
        state = domain.state_index(world.truth())
        returns["total"] += returns["discount"] * float(model.R[state, action_index[action]])
        returns["discount"] *= model.discount

    callback = (lambda result, waits: on_step(world, result, waits, executive)) if on_step is not None else None
    # Until Pearl leaves, the step budget does not end the episode; the leaving rule (with its time limit) does.
    trace = run_loop(world, backend, on_action=callback, before_action=score,
                     max_steps=sys.maxsize if until_left else None,
                     stop_when=until_pearl_leaves(world) if until_left else None)
    m = world.metrics
    needed = any(a.kind == "physio" for a in scenario.appointments)
    return EpisodeResult(
        scenario=scenario.name, agent=agent.name, seed=world.seed, discounted_return=returns["total"], steps=m.steps,
        guidance_needed=needed, guidance_completed=m.guidances_completed > 0,
        time_to_goal=m.time_to_goal[0] if m.time_to_goal else None, clarifications=m.clarifications,
        unprompted_questions=m.unprompted_questions,
        goals_achieved=m.reminders_delivered + m.questions_answered + m.guidances_completed,
        wrong_actions=m.wrong_actions, residents_lost=m.residents_lost,
        walking_speed=scenario.resident.walking_speed, actions=list(trace.actions),
        questions_answered=m.questions_answered, reminders_delivered=m.reminders_delivered,
        guidance_wanted=m.walk_wishes > 0, questions_raised=m.questions_raised, seconds=float(world.time),
    )


def with_word_error_rate(scenario: Scenario, wer: float) -> Scenario:
    """A copy of ``scenario`` whose recogniser has word error rate ``wer`` (resident override cleared)."""
    return replace(scenario, word_error_rate=float(wer), resident=replace(scenario.resident, word_error_rate=None))


# --------------------------------------------------------------------- the study
from pearl_sim.policies import DEFAULT_FLAT_TRIALS, POLICY_NAMES  # noqa: E402  (one list, cheap to import: pearl --help)




from pearl_sim.planning import PlannedAgents, plan_controller  # noqa: E402,F401  (re-exported)


def build_agents(domain, hierarchy_path, flat_time_limit: Optional[float] = None, policies: Sequence[str] = POLICY_NAMES,
                 seed: int = 0, log: Optional[Callable[[str], None]] = None,
                 flat_trials: Optional[int] = DEFAULT_FLAT_TRIALS) -> PlannedAgents:
    """Plan every compared controller once; returns name → agent (and each one's planning time).

    Args:
        domain: the Pearl FactoredDomain.
        hierarchy_path: the action hierarchy for the hierarchical POMDP.
        flat_trials: trials of the flat point-based solve (deterministic for a seed).
        flat_time_limit: instead, seconds of wall clock for it (then the flat policy depends on
            the machine's speed and load; given alone it replaces the trial budget). The other
            policies are planned exactly.
        policies: which of :data:`POLICY_NAMES` to build.
    """
    import time as _time

    from pearl_sim.nursing_home.agents import ScriptedAgent

    unknown = sorted(set(policies) - set(POLICY_NAMES))
    if unknown:
        raise ValueError(f"unknown policy {unknown[0]!r}; known: {', '.join(POLICY_NAMES)}")
    model = domain.compile()
    agents = PlannedAgents()
    timings = agents.timings
    for name in policies:
        if name == "behaviour_tree":
            from pearl_sim.nursing_home.behaviour_tree import PearlBehaviourTree

            agents[name] = PearlBehaviourTree(name, list(model.actions))
            timings[name] = 0.0
            continue
        if name == "scripted":
            agents[name] = ScriptedAgent(name, list(model.actions))
            timings[name] = 0.0
            continue
        t0 = _time.perf_counter()
        agents[name] = plan_controller(name, domain, model, hierarchy_path, seed=seed, flat_trials=flat_trials,
                                       flat_time_limit=flat_time_limit)
        timings[name] = _time.perf_counter() - t0
        if log:
            log(f"planned {name} in {timings[name]:.1f} s")
    return agents
