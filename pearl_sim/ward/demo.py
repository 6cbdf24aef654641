"""``pearl demo --domain config/ward.domain.yaml``: a ward episode through the full ROS 2 graph.

The frame runs it (:mod:`pearl_sim.world_demo`: the nodes, the simulated sensors under ``/clock``,
the transcript, the bag); here is what is the ward's own: its world and what its outcome says.
The demo runs the first episode of the ward's study file.
"""
from __future__ import annotations

from typing import Any, Dict

from pearl_sim.ward.scenario import load_ward_scenarios
from pearl_sim.ward.world import WardWorld
from pearl_sim.world_demo import WorldDemo

__all__ = ["DEMO"]


def _metrics(world: WardWorld) -> Dict[str, Any]:
    m = world.metrics
    return {"residents": len(world.scenario.residents), "requests": m.requests, "requests_met": m.requests_met,
            "request_wait": list(m.request_wait), "pills": m.pills, "pills_on_time": m.pills_on_time,
            "pills_overdue": m.pills_overdue, "questions": m.questions,
            "unprompted_questions": m.unprompted_questions, "wrong_actions": m.wrong_actions, "wrong": m.wrong,
            "robot_at_end": world.robot_at, "all_met": world.all_met}


def _outcome(m: Dict[str, Any]) -> str:
    return (f"outcome: {m['requests_met']}/{m['requests']} request(s) met"
            + (f" (waits {', '.join(f'{t:.0f} s' for t in m['request_wait'])})" if m["request_wait"] else "")
            + f", {m['pills_on_time']}/{m['pills']} medication(s) taken on time ({m['pills_overdue']} overdue), "
            f"{m['questions']} question(s) ({m['unprompted_questions']} unprompted), {m['wrong_actions']} wrong "
            f"action(s); ended at {m['robot_at_end']}")


#: What the ward brings to the frame's ``pearl demo``.
DEMO = WorldDemo(load_scenarios=load_ward_scenarios,
                 make_world=lambda scenario, seed, domain: WardWorld(scenario, seed=seed),
                 metrics=_metrics, outcome=_outcome)
