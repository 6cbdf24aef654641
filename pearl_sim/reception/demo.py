"""``pearl demo --domain config/reception.domain.yaml``: a reception episode through the full ROS 2 graph.

The belief tracker, the hierarchical policy and the action executor run as real rclpy nodes with
the params file ``config/reception_nodes.yaml``, fed by the reception robot's simulated sensors
(:class:`~pearl_sim.reception.hardware.ReceptionHardware`: one publisher per input the domain
declares) under simulated ``/clock``, through the same episode loop as the study
(:func:`pearl_sim.loop.run_episode` with :class:`pearl_sim.nodes.GraphBackend`). Prints a
transcript, writes it, ``summary.json`` and an MCAP bag (with the domain and policy beside it)
into the output folder, and ends with a one-line outcome.
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Dict, List, Optional

from pearl_pomdp.errors import PearlError
from pearl_sim.messages import StepResult
from pearl_sim.reception.scenario import load_reception_scenarios
from pearl_sim.reception.world import ReceptionWorld

__all__ = ["ReceptionDemo", "run_reception_demo", "run_cli"]


@dataclass
class ReceptionDemo:
    """What the reception demo produced."""

    scenario: str
    out_dir: Path
    lines: List[str] = field(default_factory=list)
    actions: List[str] = field(default_factory=list)
    metrics: Dict[str, object] = field(default_factory=dict)
    bag: Optional[Path] = None
    bag_messages: int = 0
    transcript: Optional[Path] = None
    seconds: float = 0.0

    def outcome(self) -> str:
        m = self.metrics
        return (f"outcome: {m['visitors_served']}/{m['visitors']} visitor(s) handed over where they wanted to go"
                + (f" (arrival to hand-over {', '.join(f'{t:.0f} s' for t in m['time_to_handover'])})"  # type: ignore[attr-defined]
                   if m["time_to_handover"] else "")
                + f", {m['visitors_left']} left unserved, {m['clarifications']} clarification question(s), "
                f"{m['wrong_actions']} wrong action(s), {m['docks']} dock(s)"
                + (", STRANDED (flat battery)" if m["stranded"] else "")
                + f"; bag {self.bag} ({self.bag_messages} messages)")

    def summary(self) -> dict:
        """The ``--json`` object."""
        return {"world": "reception", "scenario": self.scenario, "out_dir": str(self.out_dir), "bag": str(self.bag),
                "bag_messages": self.bag_messages, "transcript": str(self.transcript), "steps": len(self.actions),
                "actions": self.actions, "seconds": round(self.seconds, 2), **self.metrics, "outcome": self.outcome()}


def _format(index: int, result: StepResult, waits: List[StepResult], trace: List[dict], marginals: dict) -> str:
    path = " → ".join([trace[0]["subtask"]] + [t["choice"] for t in trace]) if trace else result.action
    lines = [f"[{result.start:7.1f} s] action {result.action:<16} trace {path}"]
    heard = result.messages + [m for w in waits for m in w.messages]
    for m in heard:
        who = f"said \"{m.said}\" → " if m.said else ""
        lines.append(f"           {m.modality.lower()}: {who}{m.text}")
    if not heard:
        lines.append("           (nothing heard: the step timed out)")
    for e in result.events + [e for w in waits for e in w.events]:
        lines.append(f"           * {e}")
    if marginals.get("marginals"):
        top = []
        for feature, values in marginals["marginals"].items():
            v, p = max(values.items(), key=lambda kv: kv[1])
            top.append(f"{feature}={v} {p:.2f}")
        lines.append(f"           belief after '{marginals.get('observation')}': " + " | ".join(top))
    return "\n".join(lines)


def run_reception_demo(scenario_path: Path, out_dir: Path, *, domain_path: Path, params_file: Path, policy: str = "",
                       hierarchy_path: Optional[Path] = None, seed: Optional[int] = None,
                       domain_id: Optional[int] = None, echo: Optional[Callable[[str], None]] = None,
                       wall_timeout: float = 30.0) -> ReceptionDemo:
    """Run the scenario's first episode through the graph; see the module doc.

    Args:
        policy: a planned policy folder (``pearl plan --out``); empty: plan ``hierarchy_path`` now.
    """
    import rclpy
    from rclpy.context import Context
    from rclpy.qos import DurabilityPolicy, QoSProfile
    from rclpy.signals import SignalHandlerOptions
    from std_msgs.msg import String

    from pearl_pomdp.bags.writer import BagWriter
    from pearl_pomdp.hierarchy import load_hierarchical_policy
    from pearl_pomdp.hierarchy.plan import plan
    from pearl_pomdp.hierarchy.spec import load_hierarchy
    from pearl_pomdp.model.domain_yaml import load_domain
    from pearl_pomdp.nodes import conversions as cv
    from pearl_pomdp.nodes.bag_recorder import Recorder
    from pearl_pomdp.nodes.graph import PearlGraph
    from pearl_pomdp.nodes.sim_clock import SimClockDriver
    from pearl_sim.loop import run_episode
    from pearl_sim.nodes import GraphBackend
    from pearl_sim.reception.hardware import SAID_TOPIC, TRUTH_TOPIC, ReceptionHardware

    started = time.monotonic()
    scenario = load_reception_scenarios(scenario_path)[0]
    out_dir = Path(out_dir).resolve()
    out_dir.mkdir(parents=True, exist_ok=True)
    bag_dir = out_dir / "bag"
    if bag_dir.exists() and any(bag_dir.iterdir()):
        raise PearlError(f"{bag_dir}: already holds a bag; choose another --out folder")
    shutil.copyfile(domain_path, out_dir / "domain.yaml")
    # The robot's node params beside the bag too: `pearl replay` runs the tracker by its rules.
    shutil.copyfile(params_file, out_dir / "nodes.yaml")
    params_file = out_dir / "nodes.yaml"
    domain = load_domain(out_dir / "domain.yaml")
    world = ReceptionWorld(scenario, seed=seed)
    policy_dir = out_dir / "policy"
    if policy:
        decider = load_hierarchical_policy(policy, domain)
        if Path(policy).resolve() != policy_dir.resolve():
            shutil.copytree(policy, policy_dir, dirs_exist_ok=True)
    else:
        if hierarchy_path is None:
            raise PearlError(f"{domain_path}: no policy and no hierarchy to plan")
        decider = plan(domain, load_hierarchy(hierarchy_path, domain))
        decider.save(policy_dir)
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    context = Context()
    rclpy.init(args=["--ros-args", "--log-level", "warn"], context=context, domain_id=domain_id,
               signal_handler_options=SignalHandlerOptions.NO)
    result = ReceptionDemo(scenario.name, out_dir)
    graph = hardware = writer = None
    try:
        tracker_params = scenario.tracker_parameters()
        graph = PearlGraph(context=context, shared={"domain": str(out_dir / "domain.yaml")}, domain=domain,
                           model=domain.compile(), decider=decider, params_file=params_file,
                           overrides={"belief_tracker": {**tracker_params, "diagnostics_period": 60.0},
                                      "hierarchical_policy": {"policy": str(policy_dir), "diagnostics_period": 60.0}})
        hardware = ReceptionHardware(context, world, domain)
        for node in hardware.nodes:
            graph.add_node(node)
        decisions: List[dict] = []
        marginals: List[dict] = []
        listener = graph.add_node(rclpy.create_node("demo_listener", context=context))
        listener.create_subscription(cv.DecisionMsg, "/pearl/decision",
                                     lambda msg: decisions.append(cv.msg_to_decision(msg)), 50)
        latched = QoSProfile(depth=10, durability=DurabilityPolicy.TRANSIENT_LOCAL)
        listener.create_subscription(cv.BeliefMsg, "/pearl/belief", lambda msg: marginals.append(cv.msg_to_marginals(msg)),
                                     latched)
        rec_node = graph.add_node(rclpy.create_node("demo_recorder", context=context, parameter_overrides=[
            rclpy.parameter.Parameter("use_sim_time", rclpy.parameter.Parameter.Type.BOOL, True)]))
        topics = ["/clock", "/pearl/action", "/pearl/belief", "/pearl/decision",
                  "/pearl/say", "/pearl/display", "/goal_pose", SAID_TOPIC, TRUTH_TOPIC] + [
                      c.topic for c in domain.inputs]
        writer = BagWriter(bag_dir, custom_data={
            "scenario": str(scenario_path), "seed": str(world.seed),
            "pearl.domain": os.path.relpath(out_dir / "domain.yaml", bag_dir),
            "pearl.policy": os.path.relpath(policy_dir, bag_dir.resolve()),
            "pearl.tracker_params": json.dumps(tracker_params),
            "pearl.params_file": os.path.relpath(params_file, bag_dir)})
        recorder = Recorder(rec_node, writer, topics=topics)
        # The bag must hold the loop from its first message (b0 and the answer to it are latched).
        recorder.wait_until_recording(graph.spin_until, wall_timeout)
        driver = SimClockDriver(graph, wait_s=wall_timeout)
        backend = GraphBackend(graph, hardware, driver)
        driver.wait_for_clock_readers(extra=1)   # the recorder

        def on_action(step: StepResult, waits: List[StepResult]) -> None:
            index = len(result.actions) + 1
            graph.spin_until(lambda: len(decisions) >= index and len(marginals) > index, timeout_sec=wall_timeout)
            decision = decisions[index - 1] if len(decisions) >= index else {"trace": []}
            latest = marginals[index] if len(marginals) > index else {}
            hardware.publish_truth(backend.now_ns * 1e-9, "end", step.action, step)
            result.actions.append(step.action)
            block = _format(index, step, waits, decision.get("trace", []), latest)
            result.lines.append(block)
            if echo is not None:
                echo(block)

        run_episode(world, backend, on_action=on_action,
                    before_action=lambda action: hardware.publish_truth(backend.now_ns * 1e-9, "start", action))
        hardware.publish_truth(backend.now_ns * 1e-9, "start")
        graph.spin_until(lambda: recorder.counts.get("/pearl/action", 0) >= len(driver.actions), timeout_sec=5.0)
        for k in range(1, 11):
            driver.set_time(backend.now_ns + k * 100_000_000)
        recorder.stop()
        result.bag_messages = sum(recorder.counts.values())
    finally:
        if writer is not None:
            writer.close()
        if hardware is not None:
            hardware.destroy()
        if graph is not None:
            graph.shutdown()
        rclpy.try_shutdown(context=context)
    m = world.metrics
    result.metrics = {"visitors": len(scenario.visitors), "visitors_arrived": m.visitors_arrived,
                      "visitors_greeted": m.visitors_greeted, "visitors_served": m.visitors_served,
                      "visitors_left": m.visitors_left, "clarifications": m.clarifications,
                      "unprompted_questions": m.unprompted_questions, "wrong_actions": m.wrong_actions,
                      "wrong": m.wrong, "docks": m.docks, "stranded": m.stranded,
                      "time_to_handover": m.time_to_handover, "robot_at_end": world.robot_at,
                      "served_all": world.served_all}
    result.bag = bag_dir
    result.transcript = out_dir / "transcript.txt"
    result.transcript.write_text("\n".join(result.lines) + "\n" + result.outcome() + "\n", encoding="utf-8")
    result.seconds = time.monotonic() - started
    (out_dir / "summary.json").write_text(json.dumps(result.summary(), indent=1), encoding="utf-8")
    return result


def run_cli(args: argparse.Namespace) -> int:
    """``pearl demo`` for the reception world (from the demo command's parsed arguments)."""
    from pearl_pomdp.cli import print_json
    from pearl_pomdp.cli._inputs import require_dir, require_file
    from pearl_pomdp.cli.plan import resolve_hierarchy_path
    from pearl_sim.cli.demo import _saved_policy, _share
    from pearl_sim.worlds import WORLDS

    world = WORLDS["reception"]
    if getattr(args, "foxglove", False):
        raise PearlError("--foxglove: the live view's layout is the nursing home's; the reception demo has none yet")
    scenario = args.scenario or _share(world.demo_scenario)
    require_file(scenario, "scenario file (--scenario)")
    load_reception_scenarios(scenario)   # parse errors name the file and field before anything starts
    hierarchy = None
    if args.policy:
        require_dir(args.policy, "policy directory (--policy, from `pearl plan`)")
    else:
        hierarchy = resolve_hierarchy_path(args.domain, args.hierarchy)
        args.policy = _saved_policy(args) or ""
    out = Path(args.out) if args.out else Path("out") / f"demo-{Path(scenario).stem}-{time.strftime('%Y%m%d-%H%M%S')}"
    if not args.json:
        print(f"pearl demo: reception world, scenario {scenario}; "
              + ("starting the graph…" if args.policy else "planning the policy and starting the graph…"), flush=True)
    result = run_reception_demo(Path(scenario), out, domain_path=Path(args.domain),
                                params_file=Path(_share(world.params_file)), policy=args.policy,
                                hierarchy_path=hierarchy, seed=args.seed, domain_id=args.domain_id,
                                echo=None if args.json else (lambda text: print(text, flush=True)))
    if args.json:
        print_json(result.summary())
    else:
        print(f"wrote {result.transcript}, {result.bag} ({result.seconds:.1f} s)")
        print(result.outcome())
    return 0
