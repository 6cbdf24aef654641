"""A working day through the real Pearl nodes (``pearl day --nodes``): DDS, ``/clock``, a bag split by the hour.

The belief tracker, the hierarchical policy and the action executor run as rclpy nodes with the
simulated hardware (:class:`pearl_sim.nodes.SimulatedHardware`) on one executor under simulated
time, as ``pearl demo`` runs Figure 4: ``/clock`` moves to each message's time and to the tracker's
own step deadline, so a day of ~5,400 steps goes as fast as the graph answers. Every topic is
recorded to a rosbag2 MCAP bag split by the hour (``max_duration_ns``), the domain and the policy
beside it, so ``pearl replay BAG`` and ``pearl bag-info BAG`` read it on their own.

Measured on the way, per hour of the day: the wall time the graph took to answer each step (the
``/clock`` move or input until the next action arrived: observation → action through DDS) and the
process's resident memory (the nodes share this one process).
"""
from __future__ import annotations

import json
import os
import shutil
import time
from pathlib import Path
from typing import Any, Callable, Dict, List, Optional

import numpy as np

from pearl_pomdp.errors import PearlError
from pearl_sim.nursing_home.day import DAY_SECONDS, DayPlan, DayWorld, day_scenario, day_score, plan_day

__all__ = ["run_day_graph", "resident_memory_bytes", "HOUR_S"]

HOUR_S = 3600.0


def resident_memory_bytes() -> int:
    """This process's resident set size now (Linux ``/proc/self/statm``; 0 where it cannot be read)."""
    try:
        pages = int(Path("/proc/self/statm").read_text().split()[1])
    except (OSError, IndexError, ValueError):  # pragma: no cover - not Linux
        return 0
    return pages * os.sysconf("SC_PAGE_SIZE")


class _TimedBackend:
    """A :class:`~pearl_sim.nodes.GraphBackend` whose answers are timed (wall seconds per step that answered)."""

    def __init__(self, backend, world, answers: List[tuple]):
        self.backend, self.world, self.answers = backend, world, answers

    def _timed(self, call: Callable[[], List[str]]) -> List[str]:
        t0 = time.perf_counter()
        got = call()
        if got:
            self.answers.append((self.world.time, time.perf_counter() - t0))
        return got

    def start(self) -> List[str]:
        return self.backend.start()

    def deliver(self, message) -> List[str]:
        return self._timed(lambda: self.backend.deliver(message))

    def tick(self, t_ns: int) -> List[str]:
        return self._timed(lambda: self.backend.tick(t_ns))

    def deadline(self):
        return self.backend.deadline()


def _per_hour(rows: List[tuple], hours: int) -> List[Dict[str, Any]]:
    out = []
    for h in range(hours):
        xs = np.array([dt for t, dt in rows if h * HOUR_S <= t < (h + 1) * HOUR_S]) * 1000.0
        out.append({"hour": h, "steps": int(xs.size),
                    "p50_ms": round(float(np.percentile(xs, 50)), 2) if xs.size else None,
                    "p99_ms": round(float(np.percentile(xs, 99)), 2) if xs.size else None})
    return out


def run_day_graph(domain_path, policy_dir, resident: Dict[str, Any], articulation_wer: float, noise: float,
                  seed: int, out_dir, *, until: float = DAY_SECONDS, split_s: float = HOUR_S,
                  domain_id: Optional[int] = None, wall_timeout: float = 30.0, name: str = "day",
                  plan: Optional[DayPlan] = None) -> Dict[str, Any]:
    """One day (to ``until`` world seconds) through the Pearl graph; returns the checklist and the measurements.

    Args:
        domain_path, policy_dir: the domain and a planned hierarchical policy (``pearl plan --out``);
            copies go beside the bag.
        resident, articulation_wer: her profile's ``resident:`` fields and articulation.
        noise: the recogniser's word error rate; seed: the day's seed (its draws: :func:`plan_day`,
            unless ``plan`` gives them).
        out_dir: created; receives ``bag/`` (split every ``split_s`` s of sim time), ``domain.yaml``, ``policy/``.

    Raises:
        PearlError: the graph did not answer within ``wall_timeout`` s, or ``out_dir`` already holds a bag.
    """
    import rclpy
    from rclpy.context import Context
    from rclpy.signals import SignalHandlerOptions

    from pearl_pomdp.bags.writer import BagWriter
    from pearl_pomdp.hierarchy import load_hierarchical_policy
    from pearl_pomdp.nodes.bag_recorder import Recorder
    from pearl_pomdp.nodes.graph import PearlGraph
    from pearl_pomdp.nodes.sim_clock import SimClockDriver
    from pearl_sim.nursing_home.demo import RECORDED_TOPICS
    from pearl_sim.loop import run_episode
    from pearl_sim.nodes import GraphBackend, SimulatedHardware
    from pearl_sim.nursing_home.residents import effective_word_error_rate
    from pearl_sim.world_demo import close_run, run_folder

    started = time.monotonic()
    out, bag_dir, domain = run_folder(out_dir, domain_path)
    local_policy = out / "policy"
    if Path(policy_dir).resolve() != local_policy:
        shutil.copytree(policy_dir, local_policy, dirs_exist_ok=True)
    decider = load_hierarchical_policy(local_policy, domain)
    plan = plan if plan is not None else plan_day(seed)
    scenario = day_scenario(resident, effective_word_error_rate(noise, articulation_wer), seed, name=name, plan=plan)
    world = DayWorld(scenario, plan, domain=domain)
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    context = Context()
    rclpy.init(args=["--ros-args", "--log-level", "warn"], context=context, domain_id=domain_id,
               signal_handler_options=SignalHandlerOptions.NO)
    graph = sim = writer = None
    answers: List[tuple] = []
    memory: List[Dict[str, Any]] = []
    timeline: List[Dict[str, Any]] = []
    bag_messages = 0
    try:
        tracker_params = scenario.tracker_parameters()
        graph = PearlGraph(context=context, shared={"domain": str(out / "domain.yaml")}, domain=domain,
                           model=domain.compile(), decider=decider,
                           overrides={"belief_tracker": {**tracker_params, "diagnostics_period": 600.0},
                                      "hierarchical_policy": {"policy": str(local_policy),
                                                              "diagnostics_period": 600.0}})
        sim = SimulatedHardware(context, world, domain)
        for node in sim.nodes:
            graph.add_node(node)
        rec_node = graph.add_node(rclpy.create_node("day_recorder", context=context, parameter_overrides=[
            rclpy.parameter.Parameter("use_sim_time", rclpy.parameter.Parameter.Type.BOOL, True)]))
        writer = BagWriter(bag_dir, max_duration_ns=int(split_s * 1e9), custom_data={
            "scenario": name, "seed": str(seed), "pearl.world": "day",
            "pearl.domain": os.path.relpath(out / "domain.yaml", bag_dir),
            "pearl.policy": os.path.relpath(local_policy, bag_dir),
            "pearl.tracker_params": json.dumps(tracker_params)})
        # Every input the domain declares (the day domain's battery driver too), so the bag replays.
        recorder = Recorder(rec_node, writer, topics=RECORDED_TOPICS + [c.topic for c in domain.inputs
                                                                         if c.topic not in RECORDED_TOPICS])
        recorder.wait_until_recording(graph.spin_until, wall_timeout)
        driver = SimClockDriver(graph, wait_s=wall_timeout)
        backend = GraphBackend(graph, sim, driver)
        driver.wait_for_clock_readers(extra=1)
        timed = _TimedBackend(backend, world, answers)

        def before(action: str) -> None:
            sim.publish_truth(backend.now_ns * 1e-9, "start", action)
            hour = int(world.time // HOUR_S)
            if len(memory) <= hour:
                memory.append({"hour": hour, "rss_mb": round(resident_memory_bytes() / 2 ** 20, 1)})
            timeline.append({"t": round(world.time, 1), "action": action, "robot": world.robot_at,
                             "resident": world.resident_state(), "battery": round(world.battery, 4)})

        run_episode(world, timed, before_action=before, stop_when=lambda: world.time >= until)
        sim.publish_truth(backend.now_ns * 1e-9, "start")
        graph.spin_until(lambda: recorder.counts.get("/pearl/action", 0) >= len(driver.actions), timeout_sec=5.0)
        for k in range(1, 11):
            driver.set_time(backend.now_ns + k * 100_000_000)
        memory.append({"hour": "end", "rss_mb": round(resident_memory_bytes() / 2 ** 20, 1)})
        recorder.stop()
        bag_messages = sum(recorder.counts.values())
        counters = dict(graph.tracker.counters())
        core = graph.tracker.core
        if core is None:
            raise PearlError("the belief tracker node was not configured: no belief to check")
        final_belief = np.asarray(core.belief, dtype=float)
    finally:
        close_run(writer, sim, graph, context)
    checklist = world.checklist()
    hours = int(np.ceil(min(until, world.time) / HOUR_S))
    return {"scenario": name, "seed": seed, "until": until, "score": day_score(checklist), "checklist": checklist,
            "timeline": timeline, "bag": str(bag_dir), "bag_messages": bag_messages,
            "bag_files": sorted(p.name for p in bag_dir.glob("*.mcap")),
            "answer_ms_per_hour": _per_hour(answers, max(1, hours)), "rss_mb": memory,
            "tracker_counters": counters,
            "final_belief_valid": bool(np.all(final_belief >= 0) and abs(final_belief.sum() - 1.0) < 1e-9),
            "wall_seconds": round(time.monotonic() - started, 1)}
