"""Simulated episodes with the true state, as ``pearl fit`` reads them (``.jsonl``, one episode a line).

Each episode runs through the study's step loop (:func:`pearl_sim.loop.run_episode` with the
core executive: the robot's own tracker rules) and records, per closed step, the action that
opened it and the observation that closed it, and the world's true state at the start of
every action (and after the last one), in the domain's feature terms.
"""
from __future__ import annotations

import json
from pathlib import Path
from typing import Iterable, List, Sequence, Union

from pearl_sim.loop import ExecutiveBackend, run_episode
from pearl_sim.nursing_home.scenario import Scenario
from pearl_sim.nursing_home.world import World

__all__ = ["record_episodes"]


def record_episodes(scenarios: Sequence[Scenario], controller, domain, seeds: Iterable[int],
                    path: Union[str, Path]) -> List[dict]:
    """Run ``controller`` on every scenario × seed and write the episodes to ``path`` (``.jsonl``).

    The seed of an episode is ``scenario.seed + 1000 * k`` for each ``k`` in ``seeds`` (the
    study's rule). Returns the episode objects written.
    """
    from pearl_sim.nursing_home.experiment import episode_executive

    model = domain.compile()
    out = []
    for scenario in scenarios:
        for k in seeds:
            world = World(scenario, seed=scenario.seed + 1000 * int(k), domain=domain)
            executive = episode_executive(controller, domain, scenario, model)
            states = []
            run_episode(world, ExecutiveBackend(executive), before_action=lambda _a: states.append(world.truth()))
            states.append(world.truth())
            steps = executive.steps
            # The last action's step may still be open when the budget ends: keep closed steps only.
            out.append({"scenario": scenario.name, "seed": world.seed,
                        "actions": [s.action for s in steps], "observations": [s.observation for s in steps],
                        "states": states[:len(steps) + 1]})
    with Path(path).open("w", encoding="utf-8") as fh:
        for episode in out:
            fh.write(json.dumps(episode) + "\n")
    return out
