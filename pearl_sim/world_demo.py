"""``pearl demo`` for every world: one episode through the full ROS 2 graph.

The belief tracker, the policy and the action executor run as real rclpy nodes with the world's
params file, fed by the world's simulated sensors (:class:`~pearl_sim.world_hardware.WorldHardware`:
one publisher per input the domain declares) under simulated ``/clock``, through the same episode
loop as the study (:func:`pearl_sim.loop.run_episode` with :class:`pearl_sim.nodes.GraphBackend`).
Prints a transcript, writes it, ``summary.json`` and an MCAP bag (with the domain, node parameters
and policy beside it, so ``pearl replay`` needs nothing else) into the output folder, and ends with
a one-line outcome. What a world brings is a :class:`WorldDemo`: its scenario loader, how to make
its world, what it scores and how it says the outcome; a world may also bring its own transcript
lines, its end of the episode, a belief plot, its summary and a :class:`DemoWatcher` (the nursing
home's: Figure 4's features, "Pearl leaves", the belief plot and the Foxglove live view).
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple, Union

from pearl_pomdp.errors import PearlError
from pearl_sim.messages import Message, StepResult

__all__ = ["WorldDemo", "DemoRun", "DemoStep", "DemoWatcher", "run_world_demo", "run_demo_cli", "run_folder",
           "close_run", "describe_step", "trace_path"]


@dataclass
class DemoStep:
    """One step of a demo: the action the world carried out, what was heard during it (and the waits
    after it), what the graph decided (its EXECUTE trace) and believed after the step."""

    index: int
    time: float
    action: str
    trace: List[dict]
    heard: List[Message]
    events: List[str]
    observation: Optional[str]
    marginals: Dict[str, Dict[str, float]]
    wrong: Optional[str]


def trace_path(step: DemoStep) -> str:
    """The step's EXECUTE trace as ``root → … → primitive`` (the action alone without a trace)."""
    return " → ".join([step.trace[0]["subtask"]] + [t["choice"] for t in step.trace]) if step.trace else step.action


def describe_step(step: DemoStep, scenario: Any) -> str:
    """The transcript lines of one step: the action and its trace, everything heard, the world's
    events and the most likely value of each feature after the step."""
    lines = [f"[{step.time:7.1f} s] action {step.action:<16} trace {trace_path(step)}"]
    for m in step.heard:
        who = f"said \"{m.said}\" → " if m.said else ""
        lines.append(f"           {m.modality.lower()}: {who}{m.text}")
    if not step.heard:
        lines.append("           (nothing heard: the step timed out)")
    lines += [f"           * {e}" for e in step.events]
    if step.marginals:
        top = []
        for feature, values in step.marginals.items():
            v, p = max(values.items(), key=lambda kv: kv[1])
            top.append(f"{feature}={v} {p:.2f}")
        lines.append(f"           belief after '{step.observation}': " + " | ".join(top))
    return "\n".join(lines)


class DemoWatcher:
    """Watches a demo as it runs (the nursing home's Foxglove live view is one); here, each does nothing.

    :meth:`start` gets the graph's listener node (to subscribe to more of the graph), the scenario,
    the world and ``now()``: the sim time (s) at which the step being answered started.
    """

    def start(self, listener: Any, scenario: Any, world: Any, now: Callable[[], float]) -> None:
        """Before the episode."""

    def decision(self, decision: dict) -> None:
        """A decision of the policy (``conversions.msg_to_decision``)."""

    def belief(self, marginals: dict) -> None:
        """A belief of the tracker (``conversions.msg_to_marginals``)."""

    def step(self, step: DemoStep, world: Any) -> None:
        """A step the world carried out."""

    def stop(self) -> None:
        """After the demo, whatever happened."""


@dataclass
class DemoRun:
    """What a demo produced."""

    world: str
    scenario: str
    out_dir: Path
    demo: "WorldDemo"
    steps: List[DemoStep] = field(default_factory=list)
    lines: List[str] = field(default_factory=list)
    metrics: Dict[str, Any] = field(default_factory=dict)
    bag: Optional[Path] = None
    bag_messages: int = 0
    transcript: Optional[Path] = None
    plot: Optional[Path] = None
    seconds: float = 0.0
    tracker_counters: Dict[str, Any] = field(default_factory=dict)

    @property
    def actions(self) -> List[str]:
        """The actions the world carried out, in order."""
        return [s.action for s in self.steps]

    def outcome(self) -> str:
        """The world's outcome line and the bag."""
        return f"{self.demo.outcome(self.metrics)}; bag {self.bag} ({self.bag_messages} messages)"

    def summary(self) -> dict:
        """The ``--json`` object (and ``summary.json``): the world's, or the frame's."""
        if self.demo.summary is not None:
            return self.demo.summary(self)
        return {"world": self.world, "scenario": self.scenario, "out_dir": str(self.out_dir), "bag": str(self.bag),
                "bag_messages": self.bag_messages, "transcript": str(self.transcript), "steps": len(self.actions),
                "actions": self.actions, "seconds": round(self.seconds, 2), **self.metrics, "outcome": self.outcome()}


@dataclass(frozen=True)
class WorldDemo:
    """What one world brings to the frame's ``pearl demo``.

    Attributes:
        load_scenarios: a scenario file (path) -> its scenarios; the demo runs the first.
        make_world: ``(scenario, seed or None, domain)`` -> a fresh simulated world
            (:class:`~pearl_sim.world_base.StudyWorld`) for the domain the graph runs.
        metrics: the world after the episode -> its scores (JSON-ready; ``summary.json`` holds them).
        outcome: those scores -> the one-line outcome (``outcome: …``).
        describe_step: ``(step, scenario)`` -> the step's transcript lines (default :func:`describe_step`).
        stop_when: the world -> a test that ends the episode early (``None``: the scenario's steps end it).
        until_stop: ``True``: the scenario's step budget does not end the episode, only ``stop_when``
            does (which then holds a time limit of its own: the nursing home runs until Pearl leaves).
        pose_topic: where the simulated hardware publishes the robot's pose (``None``: nowhere).
        hierarchy: the hierarchy file planned with when ``--hierarchy`` is not given (``None``:
            ``NAME.hierarchy.yaml`` beside the domain, else the flat hierarchy).
        plot: ``(run, scenario)`` -> a picture of the run written into its folder (``None``: none).
        summary: the run -> the ``--json`` object (``None``: :meth:`DemoRun.summary`).
    """

    load_scenarios: Callable[[Any], Sequence[Any]]
    make_world: Callable[[Any, Optional[int], Any], Any]
    metrics: Callable[[Any], Dict[str, Any]]
    outcome: Callable[[Dict[str, Any]], str]
    describe_step: Callable[[DemoStep, Any], str] = describe_step
    stop_when: Optional[Callable[[Any], Callable[[], bool]]] = None
    until_stop: bool = False
    pose_topic: Optional[str] = None
    hierarchy: Optional[str] = None
    plot: Optional[Callable[[DemoRun, Any], Path]] = None
    summary: Optional[Callable[[DemoRun], dict]] = None


def _refuse_bag(bag_dir: Path) -> None:
    if bag_dir.exists() and any(bag_dir.iterdir()):
        raise PearlError(f"{bag_dir}: already holds a bag; choose another --out folder")


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
    _refuse_bag(bag_dir)
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


def run_world_demo(name: str, demo: WorldDemo, scenario_path: Path, out_dir: Path, *, domain_path: Path,
                   params_file: Union[Path, str, None], policy: str = "", hierarchy_path: Optional[Path] = None,
                   seed: Optional[int] = None, domain_id: Optional[int] = None,
                   echo: Optional[Callable[[str], None]] = None, wall_timeout: float = 30.0,
                   watcher: Optional[DemoWatcher] = None) -> DemoRun:
    """Run the scenario's first episode of world ``name`` through the graph; see the module doc.

    Args:
        params_file: the robot's node parameters, copied beside the bag (``None``: the nodes' code
            defaults; ``"default"``: the shipped file a node started alone reads, which the bag
            does not name, so ``pearl replay`` reads it too).
        policy: a planned policy folder (``pearl plan --out``) or ``online[:TRIALS]``; empty: plan
            ``hierarchy_path`` now (``None``: the flat hierarchy), saved beside the bag.
        echo: called with each step's transcript lines as they happen (e.g. ``print``).
        wall_timeout: wall seconds to wait for the graph's answer in one step before failing.
        watcher: sees the run as it happens (the nursing home's live view).

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
    params_data: Dict[str, str] = {}
    if params_file is None:
        params_data["pearl.params_file"] = ""   # the nodes ran on their code's defaults (pearl replay does the same)
    elif params_file != "default":
        # The robot's node params beside the bag too: `pearl replay` runs the tracker by its rules.
        shutil.copyfile(params_file, out_dir / "nodes.yaml")
        params_file = out_dir / "nodes.yaml"
        params_data["pearl.params_file"] = os.path.relpath(params_file, bag_dir)
    model = domain.compile()
    world = demo.make_world(scenario, seed, domain)
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
    result = DemoRun(name, scenario.name, out_dir, demo)
    watcher = watcher or DemoWatcher()
    graph = hardware = writer = None
    try:
        tracker_params = scenario.tracker_parameters()
        graph = PearlGraph(context=context, shared={"domain": str(out_dir / "domain.yaml")}, domain=domain,
                           model=model, decider=decider, params_file=params_file,
                           overrides={"belief_tracker": {**tracker_params, "diagnostics_period": 60.0},
                                      "hierarchical_policy": {"policy": node_policy, "diagnostics_period": 60.0}})
        hardware = WorldHardware(context, world, domain, name, pose_topic=demo.pose_topic)
        for node in hardware.nodes:
            graph.add_node(node)
        decisions: List[dict] = []
        marginals: List[dict] = []
        listener = graph.add_node(rclpy.create_node("demo_listener", context=context))
        sim_now = {"s": 0.0}   # sim time at which the step being answered started (the watcher's stamps)

        def on_decision(msg: Any) -> None:
            decisions.append(cv.msg_to_decision(msg))
            watcher.decision(decisions[-1])

        def on_belief(msg: Any) -> None:
            marginals.append(cv.msg_to_marginals(msg))
            watcher.belief(marginals[-1])

        listener.create_subscription(cv.DecisionMsg, "/pearl/decision", on_decision, 50)
        latched = QoSProfile(depth=10, durability=DurabilityPolicy.TRANSIENT_LOCAL)
        listener.create_subscription(cv.BeliefMsg, "/pearl/belief", on_belief, latched)
        watcher.start(listener, scenario, world, lambda: sim_now["s"])
        rec_node = graph.add_node(rclpy.create_node("demo_recorder", context=context, parameter_overrides=[
            rclpy.parameter.Parameter("use_sim_time", rclpy.parameter.Parameter.Type.BOOL, True)]))
        topics = ["/clock", "/pearl/action", "/pearl/belief", "/pearl/decision", "/pearl/say", "/pearl/display",
                  "/goal_pose", said_topic(name), truth_topic(name)] + [c.topic for c in domain.inputs]
        writer = BagWriter(bag_dir, custom_data={
            "scenario": str(scenario_path), "seed": str(world.seed),
            "pearl.domain": os.path.relpath(out_dir / "domain.yaml", bag_dir),
            "pearl.policy": (node_policy if node_policy != str(policy_dir)
                             else os.path.relpath(policy_dir, bag_dir.resolve())),
            "pearl.tracker_params": json.dumps(tracker_params), **params_data})
        recorder = Recorder(rec_node, writer, topics=topics + ([demo.pose_topic] if demo.pose_topic else []))
        # The bag must hold the loop from its first message (b0 and the answer to it are latched).
        recorder.wait_until_recording(graph.spin_until, wall_timeout)
        driver = SimClockDriver(graph, wait_s=wall_timeout)
        backend = GraphBackend(graph, hardware, driver)
        # Every /clock must reach the bag, or a replay would see inputs at the wrong time:
        # wait until each sim-time node and the recorder subscribe to the driver's /clock.
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
            sim_now["s"] = backend.now_ns * 1e-9
            graph.spin_until(lambda: answered(step.action), timeout_sec=wall_timeout)
            d = naming(step.action)
            decision = decisions[d] if d is not None else {"trace": []}
            latest = closing(decision) or {}
            if d is not None:
                unread["decision"] = d + 1
            hardware.publish_truth(backend.now_ns * 1e-9, "end", step.action, step)
            shown = DemoStep(index=len(result.steps) + 1, time=step.start, action=step.action,
                             trace=decision.get("trace", []), heard=step.messages + [m for w in waits for m in w.messages],
                             events=step.events + [e for w in waits for e in w.events],
                             observation=latest.get("observation"), marginals=latest.get("marginals", {}),
                             wrong=step.wrong)
            result.steps.append(shown)
            watcher.step(shown, world)
            result.lines.append(demo.describe_step(shown, scenario))
            if echo is not None:
                echo(result.lines[-1])

        run_episode(world, backend, on_action=on_action, max_steps=sys.maxsize if demo.until_stop else None,
                    stop_when=demo.stop_when(world) if demo.stop_when is not None else None,
                    before_action=lambda action: hardware.publish_truth(backend.now_ns * 1e-9, "start", action))
        hardware.publish_truth(backend.now_ns * 1e-9, "start")   # the state after the last action
        # The policy answers the last belief too: wait until that action is in the bag, or a
        # replay (which always sees the answer) would find one action more than recorded.
        graph.spin_until(lambda: recorder.counts.get("/pearl/action", 0) >= len(driver.actions), timeout_sec=5.0)
        # A second of /clock past the end, so a replay sees time pass beyond the last step as
        # the live nodes did (less than step_timeout: nothing else fires).
        for k in range(1, 11):
            driver.set_time(backend.now_ns + k * 100_000_000)
        recorder.stop()
        result.bag_messages = sum(recorder.counts.values())
        result.tracker_counters = dict(graph.tracker.counters())
    finally:
        close_run(writer, hardware, graph, context)
    result.metrics = demo.metrics(world)
    result.bag = bag_dir
    result.transcript = out_dir / "transcript.txt"
    result.transcript.write_text("\n".join(result.lines) + "\n" + result.outcome() + "\n", encoding="utf-8")
    if demo.plot is not None:
        result.plot = demo.plot(result, scenario)
    result.seconds = time.monotonic() - started
    (out_dir / "summary.json").write_text(json.dumps(result.summary(), indent=1), encoding="utf-8")
    return result


def run_demo_cli(args: argparse.Namespace, files, demo: WorldDemo, *, shipped_params: bool = False,
                 watch: Optional[Callable[[], DemoWatcher]] = None) -> DemoRun:
    """``pearl demo`` for the world ``files`` (its :class:`~pearl_sim.worlds.SimWorld`) from the demo
    command's parsed arguments; every input is checked before anything is planned or started.

    Args:
        shipped_params: the robot's nodes read the shipped params file themselves, as started alone
            (the nursing home's); else they run with the world's ``params_file``.
        watch: starts what watches the run (``--foxglove``: the nursing home's live view), once the
            inputs are checked; ``None``: ``--foxglove`` is refused.
    """
    from pearl_pomdp.cli import print_json
    from pearl_pomdp.cli._inputs import require_dir, require_file
    from pearl_pomdp.cli.plan import resolve_hierarchy_path
    from pearl_pomdp.online.decider import online_trials
    from pearl_sim.cli.demo import _saved_policy

    if getattr(args, "foxglove", False) and watch is None:
        raise PearlError(f"--foxglove: the live view's layout is the nursing home's; the {files.name} demo has none yet")
    scenario = args.scenario or files.path(files.demo_scenario)
    require_file(scenario, "scenario file (--scenario)")
    demo.load_scenarios(scenario)   # parse errors name the file and field before anything starts
    hierarchy = None
    if args.policy:
        if online_trials(args.policy, "--policy") is None:
            require_dir(args.policy, "policy directory (--policy, from `pearl plan`, or online[:TRIALS])")
    else:
        hierarchy = resolve_hierarchy_path(args.domain, args.hierarchy
                                           or (files.path(demo.hierarchy) if demo.hierarchy else None))
        args.policy = _saved_policy(args) or ""
    out = Path(args.out) if args.out else Path("out") / f"demo-{Path(scenario).stem}-{time.strftime('%Y%m%d-%H%M%S')}"
    _refuse_bag(out / "bag")
    params_file: Union[Path, str, None] = ("default" if shipped_params else
                                           Path(files.path(files.params_file)) if files.params_file else None)
    watcher = watch() if watch is not None and getattr(args, "foxglove", False) else None
    try:
        if not args.json:
            print(f"pearl demo: {files.name} world, scenario {scenario}; "
                  + ("starting the graph…" if args.policy else "planning the policy and starting the graph…"),
                  flush=True)
        result = run_world_demo(files.name, demo, Path(scenario), out, domain_path=Path(args.domain),
                                params_file=params_file, policy=args.policy, hierarchy_path=hierarchy,
                                seed=args.seed, domain_id=args.domain_id, watcher=watcher,
                                echo=None if args.json else (lambda text: print(text, flush=True)))
    finally:
        if watcher is not None:
            watcher.stop()
    if args.json:
        print_json(result.summary())
    else:
        print(f"wrote {result.transcript}, " + (f"{result.plot}, " if result.plot else "")
              + f"{result.bag} ({result.seconds:.1f} s)")
        print(result.outcome())
    return result
