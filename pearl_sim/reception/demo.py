"""``pearl demo --domain config/reception.domain.yaml``: a reception episode through the full ROS 2 graph.

The frame runs it (:mod:`pearl_sim.world_demo`: the nodes, the simulated sensors under ``/clock``,
the transcript, the bag); here is what is the reception's own: its world and what its outcome says.
"""
from __future__ import annotations

from typing import Any, Dict

from pearl_sim.reception.scenario import load_reception_scenarios
from pearl_sim.reception.world import ReceptionWorld
from pearl_sim.world_demo import WorldDemo

__all__ = ["DEMO"]


def _metrics(world: ReceptionWorld) -> Dict[str, Any]:
    m = world.metrics
    return {"visitors": len(world.scenario.visitors), "visitors_arrived": m.visitors_arrived,
            "visitors_greeted": m.visitors_greeted, "visitors_served": m.visitors_served,
            "visitors_left": m.visitors_left, "clarifications": m.clarifications,
            "unprompted_questions": m.unprompted_questions, "wrong_actions": m.wrong_actions,
            "wrong": m.wrong, "docks": m.docks, "stranded": m.stranded,
            "time_to_handover": m.time_to_handover, "robot_at_end": world.robot_at,
            "served_all": world.served_all}


def _outcome(m: Dict[str, Any]) -> str:
    return (f"outcome: {m['visitors_served']}/{m['visitors']} visitor(s) handed over where they wanted to go"
            + (f" (arrival to hand-over {', '.join(f'{t:.0f} s' for t in m['time_to_handover'])})"
               if m["time_to_handover"] else "")
            + f", {m['visitors_left']} left unserved, {m['clarifications']} clarification question(s), "
            f"{m['wrong_actions']} wrong action(s), {m['docks']} dock(s)"
            + (", STRANDED (flat battery)" if m["stranded"] else ""))


#: What the reception brings to the frame's ``pearl demo``.
DEMO = WorldDemo(load_scenarios=load_reception_scenarios,
                 make_world=lambda scenario, seed, domain: ReceptionWorld(scenario, seed=seed),
                 metrics=_metrics, outcome=_outcome)
