"""``pearl demo`` for every world of the frame: one episode through the full ROS 2 graph.

The belief tracker, the policy and the action executor run as real rclpy nodes with the world's
params file, fed by the world's simulated sensors (:class:`~pearl_sim.world_hardware.WorldHardware`:
one publisher per input the domain declares) under simulated ``/clock``, through the same episode
loop as the study (:func:`pearl_sim.loop.run_episode` with :class:`pearl_sim.nodes.GraphBackend`).
Prints a transcript, writes it, ``summary.json`` and an MCAP bag (with the domain, node parameters
and policy beside it, so ``pearl replay`` needs nothing else) into the output folder, and ends with
a one-line outcome. What a world brings is a :class:`WorldDemo`: its scenario loader, how to make
its world, what it scores and how it says the outcome.
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple

from pearl_pomdp.errors import PearlError
from pearl_sim.messages import StepResult

__all__ = ["WorldDemo", "DemoRun", "run_world_demo", "run_demo_cli", "run_folder", "close_run"]


@dataclass(frozen=True)
class WorldDemo:
    """What one world brings to the frame's ``pearl demo``.

    Attributes:
        load_scenarios: a scenario file (path) -> its scenarios; the demo runs the first.
        make_world: ``(scenario, seed or None)`` -> a fresh simulated world
            (:class:`~pearl_sim.world_base.StudyWorld`).
        metrics: the world after the episode -> its scores (JSON-ready; ``summary.json`` holds them).
        outcome: those scores -> the one-line outcome (``outcome: …``).
    """

    load_scenarios: Callable[[Any], Sequence[Any]]
    make_world: Callable[[Any, Optional[int]], Any]
    metrics: Callable[[Any], Dict[str, Any]]
    outcome: Callable[[Dict[str, Any]], str]


@dataclass
class DemoRun:
    """What a demo produced."""

    world: str
    scenario: str
    out_dir: Path
    outcome_line: Callable[[Dict[str, Any]], str]
    lines: List[str] = field(default_factory=list)
    actions: List[str] = field(default_factory=list)
    metrics: Dict[str, Any] = field(default_factory=dict)
    bag: Optional[Path] = None
    bag_messages: int = 0
    transcript: Optional[Path] = None
    seconds: float = 0.0

    def outcome(self) -> str:
        """The world's outcome line and the bag."""
        return f"{self.outcome_line(self.metrics)}; bag {self.bag} ({self.bag_messages} messages)"

    def summary(self) -> dict:
        """The ``--json`` object."""
        return {"world": self.world, "scenario": self.scenario, "out_dir": str(self.out_dir), "bag": str(self.bag),
                "bag_messages": self.bag_messages, "transcript": str(self.transcript), "steps": len(self.actions),
                "actions": self.actions, "seconds": round(self.seconds, 2), **self.metrics, "outcome": self.outcome()}


def run_folder(out_dir, domain_path) -> Tuple[Path, Path, Any]:
    """A run's output folder, made ready: ``(out_dir resolved, its bag folder, the domain)``, the
    domain copied beside the bag and loaded from the copy, so the bag replays on its own.

    Raises:
        PearlError: the bag folder already holds a bag (names it).
    """
    from pearl_pomdp.model.domain_yaml import load_domain

    out_dir = Path(out_dir).resolve()
    out_dir.mkdir(parents=True, exist_ok=True)
    bag_dir = out_dir / "bag"
    if bag_dir.exists() and any(bag_dir.iterdir()):
        raise PearlError(f"{bag_dir}: already holds a bag; choose another --out folder")
    shutil.copyfile(domain_path, out_dir / "domain.yaml")
    return out_dir, bag_dir, load_domain(out_dir / "domain.yaml")


def close_run(writer, hardware, graph, context) -> None:
    """End a run through the graph, whatever got started: the bag closed first (every message it took
    is kept), then the simulated hardware, the graph and the rclpy context."""
    import rclpy

    if writer is not None:
        writer.close()
    if hardware is not None:
        hardware.destroy()
    if graph is not None:
        graph.shutdown()
    rclpy.try_shutdown(context=context)


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


def run_world_demo(name: str, demo: WorldDemo, scenario_path: Path, out_dir: Path, *, domain_path: Path,
                   params_file: Optional[Path], policy: str = "", hierarchy_path: Optional[Path] = None,
                   seed: Optional[int] = None, domain_id: Optional[int] = None,
                   echo: Optional[Callable[[str], None]] = None, wall_timeout: float = 30.0) -> DemoRun:
    """Run the scenario's first episode of world ``name`` through the graph; see the module doc.

    Args:
        params_file: the robot's node parameters (``None``: the nodes' code defaults).
        policy: a planned policy folder (``pearl plan --out``) or ``online[:TRIALS]``; empty: plan
            ``hierarchy_path`` now (``None``: the flat hierarchy), saved beside the bag.

    Raises:
        PearlError: the output folder already holds a bag, or the graph did not answer (names the phase).
    """
    import rclpy
    from rclpy.context import Context
    from rclpy.qos import DurabilityPolicy, QoSProfile
    from rclpy.signals import SignalHandlerOptions

    from pearl_pomdp.bags.writer import BagWriter
    from pearl_pomdp.deciders import load_decider
    from pearl_pomdp.nodes import conversions as cv
    from pearl_pomdp.nodes.bag_recorder import Recorder
    from pearl_pomdp.nodes.graph import PearlGraph
    from pearl_pomdp.nodes.sim_clock import SimClockDriver
    from pearl_pomdp.online.decider import online_trials
    from pearl_sim.loop import run_episode
    from pearl_sim.nodes import GraphBackend
    from pearl_sim.world_hardware import WorldHardware, said_topic, truth_topic

    started = time.monotonic()
    scenario = demo.load_scenarios(scenario_path)[0]
    out_dir, bag_dir, domain = run_folder(out_dir, domain_path)
    if params_file is not None:
        # The robot's node params beside the bag too: `pearl replay` runs the tracker by its rules.
        shutil.copyfile(params_file, out_dir / "nodes.yaml")
        params_file = out_dir / "nodes.yaml"
    model = domain.compile()
    world = demo.make_world(scenario, seed)
    policy_dir = out_dir / "policy"
    if policy and online_trials(policy, "--policy") is not None:
        decider, node_policy = load_decider(policy, model, domain, where="--policy"), policy
    elif policy:
        decider, node_policy = load_decider(policy, model, domain, where="--policy"), str(policy_dir)
        if Path(policy).resolve() != policy_dir.resolve():
            shutil.copytree(policy, policy_dir, dirs_exist_ok=True)
    else:
        from pearl_pomdp.hierarchy import flat_hierarchy, load_hierarchy, plan

        # No hierarchy file: the flat hierarchy (one root over every primitive), as `pearl plan` does.
        hierarchy = (flat_hierarchy(list(domain.actions)) if hierarchy_path is None
                     else load_hierarchy(hierarchy_path, domain))
        decider, node_policy = plan(domain, hierarchy), str(policy_dir)
        decider.save(policy_dir)
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    context = Context()
    rclpy.init(args=["--ros-args", "--log-level", "warn"], context=context, domain_id=domain_id,
               signal_handler_options=SignalHandlerOptions.NO)
    result = DemoRun(name, scenario.name, out_dir, demo.outcome)
    graph = hardware = writer = None
    try:
        tracker_params = scenario.tracker_parameters()
        graph = PearlGraph(context=context, shared={"domain": str(out_dir / "domain.yaml")}, domain=domain,
                           model=model, decider=decider, params_file=params_file,
                           overrides={"belief_tracker": {**tracker_params, "diagnostics_period": 60.0},
                                      "hierarchical_policy": {"policy": node_policy, "diagnostics_period": 60.0}})
        hardware = WorldHardware(context, world, domain, name)
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
        topics = ["/clock", "/pearl/action", "/pearl/belief", "/pearl/decision", "/pearl/say", "/pearl/display",
                  "/goal_pose", said_topic(name), truth_topic(name)] + [c.topic for c in domain.inputs]
        writer = BagWriter(bag_dir, custom_data={
            "scenario": str(scenario_path), "seed": str(world.seed),
            "pearl.domain": os.path.relpath(out_dir / "domain.yaml", bag_dir),
            "pearl.policy": (node_policy if node_policy != str(policy_dir)
                             else os.path.relpath(policy_dir, bag_dir.resolve())),
            "pearl.tracker_params": json.dumps(tracker_params),
            # Empty: the nodes ran on their code's defaults (pearl replay does the same).
            "pearl.params_file": os.path.relpath(params_file, bag_dir) if params_file is not None else ""})
        recorder = Recorder(rec_node, writer, topics=topics)
        # The bag must hold the loop from its first message (b0 and the answer to it are latched).
        recorder.wait_until_recording(graph.spin_until, wall_timeout)
        driver = SimClockDriver(graph, wait_s=wall_timeout)
        backend = GraphBackend(graph, hardware, driver)
        driver.wait_for_clock_readers(extra=1)   # the recorder

        # The graph may publish more actions than the world carries out (a message mid-drive closes a
        # step and the policy answers; the world takes the latest action when the drive ends), so an
        # action is matched to the first unread decision naming it, and the belief shown is the one
        # that closed the step the decision opened (its belief step + 1), not the n-th of each.
        unread = {"decision": 0}

        def naming(action: str) -> Optional[int]:
            return next((i for i in range(unread["decision"], len(decisions)) if decisions[i]["action"] == action), None)

        def closing(decision: dict) -> Optional[dict]:
            return next((b for b in marginals if b.get("step") == decision.get("belief_step", -2) + 1), None)

        def answered(action: str) -> bool:
            d = naming(action)
            return d is not None and closing(decisions[d]) is not None

        def on_action(step: StepResult, waits: List[StepResult]) -> None:
            index = len(result.actions) + 1
            graph.spin_until(lambda: answered(step.action), timeout_sec=wall_timeout)
            d = naming(step.action)
            decision = decisions[d] if d is not None else {"trace": []}
            latest = closing(decision) or {}
            if d is not None:
                unread["decision"] = d + 1
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
        close_run(writer, hardware, graph, context)
    result.metrics = demo.metrics(world)
    result.bag = bag_dir
    result.transcript = out_dir / "transcript.txt"
    result.transcript.write_text("\n".join(result.lines) + "\n" + result.outcome() + "\n", encoding="utf-8")
    result.seconds = time.monotonic() - started
    (out_dir / "summary.json").write_text(json.dumps(result.summary(), indent=1), encoding="utf-8")
    return result


def run_demo_cli(args: argparse.Namespace, files, demo: WorldDemo) -> int:
    """``pearl demo`` for the world ``files`` (its :class:`~pearl_sim.worlds.SimWorld`) from the demo
    command's parsed arguments; every input is checked before anything is planned or started."""
    from pearl_pomdp.cli import print_json
    from pearl_pomdp.cli._inputs import require_dir, require_file
    from pearl_pomdp.cli.plan import resolve_hierarchy_path
    from pearl_pomdp.online.decider import online_trials
    from pearl_sim.cli.demo import _saved_policy

    if getattr(args, "foxglove", False):
        raise PearlError(f"--foxglove: the live view's layout is the nursing home's; the {files.name} demo has none yet")
    scenario = args.scenario or files.path(files.demo_scenario)
    require_file(scenario, "scenario file (--scenario)")
    demo.load_scenarios(scenario)   # parse errors name the file and field before anything starts
    hierarchy = None
    if args.policy:
        if online_trials(args.policy, "--policy") is None:
            require_dir(args.policy, "policy directory (--policy, from `pearl plan`, or online[:TRIALS])")
    else:
        hierarchy = resolve_hierarchy_path(args.domain, args.hierarchy)
        args.policy = _saved_policy(args) or ""
    out = Path(args.out) if args.out else Path("out") / f"demo-{Path(scenario).stem}-{time.strftime('%Y%m%d-%H%M%S')}"
    if not args.json:
        print(f"pearl demo: {files.name} world, scenario {scenario}; "
              + ("starting the graph…" if args.policy else "planning the policy and starting the graph…"), flush=True)
    result = run_world_demo(files.name, demo, Path(scenario), out, domain_path=Path(args.domain),
                            params_file=Path(files.path(files.params_file)) if files.params_file else None,
                            policy=args.policy,
                            hierarchy_path=hierarchy, seed=args.seed, domain_id=args.domain_id,
                            echo=None if args.json else (lambda text: print(text, flush=True)))
    if args.json:
        print_json(result.summary())
    else:
        print(f"wrote {result.transcript}, {result.bag} ({result.seconds:.1f} s)")
        print(result.outcome())
    return 0
