"""``pearl demo``: a whole scenario through the full ROS 2 graph, in one process.

The Pearl nodes (belief tracker, hierarchical policy, action executor) and the
simulated hardware (:mod:`pearl_sim.nodes`) run on one executor under simulated
time, so the run is deterministic for a seed and goes as fast as the CPU allows.
Every topic is recorded to a rosbag2 MCAP bag. The demo prints a transcript (time,
what the resident said, what was recognised, the belief's top features, the action
and its EXECUTE trace), writes it with a PNG of the belief over time into the output
folder, and ends with a one-line outcome.
"""
from __future__ import annotations

import json
import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Dict, List, Optional

from pearl_sim.nursing_home.scenario import Scenario, load_scenarios
from pearl_sim.nursing_home.world import StepResult, World

#: Features shown in the transcript (the ones a reader of Figure 4 follows).
SHOWN_FEATURES = ("ReminderGoal", "UserPresent", "UserMotionGoal", "UserInfoGoal", "UserLocation")
RECORDED_TOPICS = ["/clock", "/pearl/speech", "/pearl/touchscreen", "/pearl/laser", "/pearl/reminder",
                   "/pearl/action", "/pearl/belief", "/pearl/decision",
                   "/pearl/say", "/pearl/display", "/goal_pose", "/pearl/pose", "/pearl/sim/said",
                   "/pearl/sim/truth"]


@dataclass
class DemoStep:
    """One line of the transcript."""

    index: int
    time: float
    action: str
    trace: List[dict]
    modality: Optional[str]
    said: str
    heard: str
    meant: str
    observation: Optional[str]
    marginals: Dict[str, Dict[str, float]]
    events: List[str]
    wrong: Optional[str]


@dataclass
class DemoResult:
    """What ``pearl demo`` produced."""

    scenario: str
    out_dir: Path
    steps: List[DemoStep] = field(default_factory=list)
    metrics: dict = field(default_factory=dict)
    bag: Optional[Path] = None
    plot: Optional[Path] = None
    transcript: Optional[Path] = None
    bag_messages: int = 0
    seconds: float = 0.0
    tracker_counters: dict = field(default_factory=dict)
    #: Whether the scenario wanted a guidance (a physiotherapy appointment): only then does
    #: the outcome line say whether one was completed.
    guidance_wanted: bool = True

    @property
    def clarifications(self) -> int:
        return int(self.metrics.get("clarifications", 0))

    def outcome(self) -> str:
        m = self.metrics
        ttg = f" in {m['time_to_goal'][0]:.0f} s" if m["time_to_goal"] else ""
        if self.guidance_wanted:
            guided = ("guidance completed" if m["guidances_completed"] else "guidance NOT completed") + ttg + "; "
        else:
            guided = "no guidance wanted; " if not m["guidances_started"] else "guided unasked; "
        # Only what the scenario asked for is scored: x/y of the reminders that fell due and of
        # the questions she came to have; nothing is said about a task the scenario never set.
        parts = [f"{m['reminders_delivered']}/{m['reminders_due']} reminder(s) delivered" if m.get("reminders_due") else "",
                 f"{m['questions_answered']}/{m['questions_raised']} question(s) answered"
                 if m.get("questions_raised") else "",
                 f"{self.clarifications} clarification question(s)",
                 f"{m['unprompted_questions']} unprompted", f"{m['wrong_actions']} wrong action(s)",
                 "ended at home" if self.ended_home else "ended away from home"]
        return (f"outcome: {guided}" + ", ".join(p for p in parts if p)
                + f"; bag {self.bag} ({self.bag_messages} messages)")

    @property
    def ended_home(self) -> bool:
        """The robot is back at its station (``home``) when the episode ends."""
        return self.metrics.get("robot_at_end", "home") == "home"


def _top(marginals: Dict[str, Dict[str, float]]) -> str:
    parts = []
    for f in SHOWN_FEATURES:
        vals = marginals.get(f)
        if vals:
            v, p = max(vals.items(), key=lambda kv: kv[1])
            parts.append(f"{f}={v} {p:.2f}")
    return " | ".join(parts)


def format_step(step: DemoStep, resident: str) -> str:
    """The transcript lines of one step."""
    trace = " → ".join([step.trace[0]["subtask"]] + [t["choice"] for t in step.trace]) if step.trace else step.action
    lines = [f"[{step.time:7.1f} s] action {step.action:<22} trace {trace}"]
    if step.modality == "Speech":
        from pearl_pomdp.speech import parse_speech_message

        text, confidence = parse_speech_message(step.heard)
        conf = f" ({confidence:.2f})" if confidence < 1.0 else ""
        meant = f" (meaning {step.meant})" if step.meant else ""
        lines.append(f"           {resident} said \"{step.said}\"{meant} → recognised \"{text}\"{conf} → "
                     f"{step.observation}")
    elif step.modality is not None:
        who = f"{resident} " if step.modality == "Touchscreen" else ""
        lines.append(f"           {who}{step.modality.lower()}: {step.heard} → {step.observation}")
    else:
        lines.append(f"           (nothing heard: timeout → {step.observation})")
    for e in step.events:
        lines.append(f"           * {e}")
    if step.marginals:
        lines.append(f"           belief: {_top(step.marginals)}")
    return "\n".join(lines)


#: Feature values worth plotting for each thing a scenario can involve.
INFO_VALUES = {"time": "wantTime", "weather": "wantWeather"}


def plotted_features(scenario: Optional[Scenario]) -> List[tuple]:
    """``(feature, value)`` series for the belief plot, chosen from what the scenario involves:
    a reminder per appointment kind, the walk and arrival when there is a physiotherapy
    appointment, each kind of question asked; contact always."""
    series = [("UserPresent", "yes")]
    if scenario is None:
        kinds, asks = ["physio"], ["time", "weather"]
    else:
        kinds = list(dict.fromkeys(a.kind for a in scenario.appointments))
        asks = list(dict.fromkeys(q.ask for q in scenario.questions))
    series += [("ReminderGoal", kind) for kind in kinds]
    if "physio" in kinds:
        series += [("UserMotionGoal", "toPhysioWithRobot"), ("UserLocation", "physio")]
    series += [("UserInfoGoal", INFO_VALUES[a]) for a in asks if a in INFO_VALUES]
    return series


def plot_belief(steps: List[DemoStep], path: Path, title: str, scenario: Optional[Scenario] = None) -> Path:
    """A PNG: the belief in the scenario's features over sim time, and the actions below it.

    Top: P(feature = value) for :func:`plotted_features`, with each clarification question
    as a labelled red band. Bottom: a strip with every action at the time it started,
    coloured by its domain category (Move, Communicate, Clarify, Other); waiting
    (``DoNothing``) is drawn but not labelled.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from pearl_sim.nursing_home.scenario import default_domain

    categories = default_domain().categories
    colours = {"Move": "tab:blue", "Communicate": "tab:green", "Clarify": "tab:red", "Other": "tab:grey"}
    fig, (ax, strip) = plt.subplots(2, 1, figsize=(12, 6.5), sharex=True,
                                    gridspec_kw={"height_ratios": [3.2, 1.0], "hspace": 0.08})
    shown = [s for s in steps if s.marginals]
    times = [s.time for s in shown]
    for feature, value in plotted_features(scenario):
        ax.step(times, [s.marginals.get(feature, {}).get(value, 0.0) for s in shown], where="post",
                lw=1.8, label=f"P({feature}={value})")
    end = steps[-1].time + 5.0 if steps else 1.0
    for k, s in enumerate(steps):
        nxt = steps[k + 1].time if k + 1 < len(steps) else end
        category = categories.get(s.action, "Other")
        if category == "Clarify":
            ax.axvspan(s.time, max(nxt, s.time + 1.0), color="tab:red", alpha=0.15, lw=0)
            ax.text(s.time, 1.03, "?", color="tab:red", fontsize=11, ha="left", va="bottom", weight="bold")
        strip.barh(0, max(nxt - s.time, 0.5), left=s.time, height=0.6, color=colours.get(category, "tab:grey"),
                   alpha=0.35 if s.action == "DoNothing" else 0.9, edgecolor="white", lw=0.5)
        if s.action != "DoNothing":
            strip.text(s.time, 0.42, s.action, rotation=35, fontsize=7, ha="left", va="bottom")
    ax.set_ylabel("belief")
    ax.set_ylim(-0.02, 1.12)
    ax.set_title(title)
    ax.legend(loc="center left", bbox_to_anchor=(1.0, 0.5), fontsize=8)
    strip.set_yticks([])
    strip.set_ylim(-0.5, 2.2)
    strip.set_xlabel("simulated time (s)     red bands and ?: clarification questions")
    handles = [plt.Rectangle((0, 0), 1, 1, color=c) for c in colours.values()]
    strip.legend(handles, list(colours), loc="center left", bbox_to_anchor=(1.0, 0.5), fontsize=8,
                 title="action", title_fontsize=8)
    fig.subplots_adjust(left=0.06, right=0.78, top=0.93, bottom=0.1)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def run_demo(scenario_path: Path, out_dir: Path, *, domain_path: Path, hierarchy_path: Path,
             policy: str = "", seed: Optional[int] = None, domain_id: Optional[int] = None,
             echo: Optional[Callable[[str], None]] = None, wall_timeout: float = 30.0,
             live_view=None) -> DemoResult:
    """Run the scenario's first episode through the Pearl graph and the simulated hardware.

    Args:
        scenario_path: a scenario file (its first episode is used).
        out_dir: folder for ``transcript.txt``, ``belief.png``, ``summary.json`` and the bag
            (``bag/``); created, and must not already hold a bag.
        policy: a planned policy folder (``pearl plan --out``); empty plans at start-up.
        domain_id: ROS domain of the in-process graph (default: ``ROS_DOMAIN_ID`` or 0).
        echo: called with each transcript block as it happens (e.g. ``print``).
        wall_timeout: wall seconds to wait for the graph's answer in one step before failing.
        live_view: a :class:`pearl_pomdp.live_view.LiveView` to stream to (``--foxglove``):
            belief marginals, actions, EXECUTE traces, the transcript and the robot's pose,
            stamped with sim time.
    """
    import rclpy
    from rclpy.context import Context
    from rclpy.signals import SignalHandlerOptions

    from pearl_pomdp.nodes.bag_recorder import Recorder
    from pearl_pomdp.bags.writer import BagWriter
    from pearl_pomdp.nodes import conversions as cv
    from pearl_pomdp.nodes.graph import PearlGraph

    started = time.monotonic()
    scenario: Scenario = load_scenarios(scenario_path)[0]
    # The bag must be replayable on its own: keep the domain and the planned policy beside it.
    import shutil

    from pearl_pomdp.hierarchy import load_hierarchical_policy
    from pearl_pomdp.hierarchy.plan import plan
    from pearl_pomdp.hierarchy.spec import load_hierarchy
    from pearl_sim.world_demo import close_run, run_folder

    out_dir, bag_dir, domain = run_folder(out_dir, domain_path)
    world = World(scenario, seed=seed, domain=domain)
    if policy:
        # A copy beside the bag, so the bag replays on its own (as a freshly planned one does).
        decider = load_hierarchical_policy(policy, domain)
        policy_dir = out_dir / "policy"
        if Path(policy).resolve() != policy_dir.resolve():
            shutil.copytree(policy, policy_dir, dirs_exist_ok=True)
    else:
        decider = plan(domain, load_hierarchy(hierarchy_path, domain))
        policy_dir = decider.save(out_dir / "policy")
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    context = Context()
    rclpy.init(args=["--ros-args", "--log-level", "warn"], context=context, domain_id=domain_id,
               signal_handler_options=SignalHandlerOptions.NO)
    result = DemoResult(scenario.name, out_dir,
                        guidance_wanted=any(a.kind == "physio" for a in scenario.appointments))
    graph = None
    sim = None
    writer = None
    try:
        tracker_params = scenario.tracker_parameters()
        graph = PearlGraph(context=context, shared={"domain": str(out_dir / "domain.yaml")},
                           domain=domain, model=domain.compile(), decider=decider,
                           overrides={"belief_tracker": {**tracker_params, "diagnostics_period": 60.0},
                                      "hierarchical_policy": {"policy": str(policy_dir), "diagnostics_period": 60.0}})
        from pearl_pomdp.nodes.sim_clock import SimClockDriver
        from pearl_sim.loop import run_episode
        from pearl_sim.nodes import GraphBackend, SimulatedHardware

        sim = SimulatedHardware(context, world, domain)
        for node in sim.nodes:
            graph.add_node(node)
        decisions: List[dict] = []
        marginals: List[dict] = []
        listener = graph.add_node(rclpy.create_node("demo_listener", context=context))
        sim_now = {"s": 0.0}   # sim time of the last /clock step, for the live view's stamps

        def shown(topic: str, value) -> None:
            if live_view is not None:
                live_view.publish(topic, value, sim_now["s"])

        def on_decision(msg) -> None:
            decisions.append(cv.msg_to_decision(msg))
            shown("/pearl/decision", decisions[-1])

        def on_marginals(msg) -> None:
            marginals.append(cv.msg_to_marginals(msg))
            shown("/pearl/belief_marginals", marginals[-1])

        listener.create_subscription(cv.DecisionMsg, "/pearl/decision", on_decision, 50)
        from rclpy.qos import DurabilityPolicy, QoSProfile

        latched = QoSProfile(depth=10, durability=DurabilityPolicy.TRANSIENT_LOCAL)
        listener.create_subscription(cv.BeliefMsg, "/pearl/belief", on_marginals, latched)
        if live_view is not None:
            def on_action_message(msg: Any) -> None:   # pearl_interfaces/Action
                shown("/pearl/action", cv.msg_to_action(msg))

            listener.create_subscription(cv.ActionMsg, "/pearl/action", on_action_message, latched)
            # What a person in the loop sees: the proposal and every operator event.
            listener.create_subscription(cv.OperatorProposalMsg, "/pearl/proposal",
                                         lambda msg: shown("/pearl/proposal", cv.msg_to_proposal(msg)), latched)
            listener.create_subscription(cv.OperatorEventMsg, "/pearl/operator/events",
                                         lambda msg: shown("/pearl/operator/events", cv.msg_to_operator_event(msg)), 100)
            live_view.publish_places({name: [x, y, 0.0] for name, (x, y) in scenario.map.items()}, 0.0)
        rec_node = graph.add_node(rclpy.create_node("demo_recorder", context=context,
                                                    parameter_overrides=[rclpy.parameter.Parameter(
                                                        "use_sim_time", rclpy.parameter.Parameter.Type.BOOL, True)]))
        writer = BagWriter(bag_dir, custom_data={
            "scenario": str(scenario_path), "seed": str(world.seed),
            "pearl.domain": os.path.relpath(out_dir / "domain.yaml", bag_dir),
            "pearl.policy": os.path.relpath(policy_dir, bag_dir.resolve()),
            "pearl.tracker_params": json.dumps(tracker_params)})
        recorder = Recorder(rec_node, writer, topics=RECORDED_TOPICS)
        # The bag must hold the loop from its first message (b0 and the answer to it are latched).
        recorder.wait_until_recording(graph.spin_until, wall_timeout)
        driver = SimClockDriver(graph, wait_s=wall_timeout)
        backend = GraphBackend(graph, sim, driver)
        # Every /clock must reach the bag, or a replay would see inputs at the wrong time:
        # wait until each sim-time node and the recorder subscribe to the driver's /clock.
        driver.wait_for_clock_readers(extra=1)   # the recorder

        def on_action(step_result: StepResult, waits: List[StepResult]) -> None:
            sim_now["s"] = backend.now_ns * 1e-9
            index = len(result.steps) + 1
            graph.spin_until(lambda: len(decisions) >= index and len(marginals) > index, timeout_sec=wall_timeout)
            decision = decisions[index - 1] if len(decisions) >= index else {"trace": []}
            latest = marginals[index] if len(marginals) > index else {}
            heard = step_result.messages + [m for w in waits for m in w.messages]
            msg = heard[0] if heard else None
            sim.publish_truth(backend.now_ns * 1e-9, "end", step_result.action, step_result)
            step = DemoStep(index=index, time=step_result.start, action=step_result.action,
                            trace=decision.get("trace", []), modality=msg.modality if msg else None,
                            said=msg.said if msg else "", heard=msg.text if msg else "", meant=msg.meant if msg else "",
                            observation=latest.get("observation"), marginals=latest.get("marginals", {}),
                            events=step_result.events + [e for w in waits for e in w.events], wrong=step_result.wrong)
            result.steps.append(step)
            if live_view is not None:
                x, y = scenario.map[world.robot_at]
                shown("/pearl/pose", {"x": x, "y": y, "yaw": 0.0})
                shown("/pearl/transcript", {"speaker": "Pearl", "text": f"[{step.index}] {step.action}"})
                if msg is not None:
                    shown("/pearl/transcript", {"speaker": scenario.resident.name if msg.said else msg.modality,
                                                "text": msg.said or msg.text})
                for event in step.events:
                    shown("/pearl/transcript", {"speaker": "world", "text": event})
            if echo is not None:
                echo(format_step(step, scenario.resident.name))

        went_out = {"yes": False}

        def pearl_left() -> bool:
            # Figure 4(f), "Pearl leaves": once the robot has been out and is back at its station
            # with nothing wanted and no appointment still to come, the episode is over (else the
            # scenario's max_steps end it, as before).
            if world.robot_at != "home":
                went_out["yes"] = True
                return False
            return (went_out["yes"] and not world.due and not world.wants_guidance and world.info_goal is None
                    and all(a.at <= world.time for a in scenario.appointments))

        run_episode(world, backend, on_action=on_action, stop_when=pearl_left,
                    before_action=lambda action: sim.publish_truth(backend.now_ns * 1e-9, "start", action))
        sim.publish_truth(backend.now_ns * 1e-9, "start")   # the state after the last action
        # The policy answers the last belief too: wait until that action is in the bag, or a
        # replay (which always sees the answer) would find one action more than recorded.
        graph.spin_until(lambda: recorder.counts.get("/pearl/action", 0) >= len(driver.actions),
                         timeout_sec=5.0)
        # A second of /clock past the end, so a replay sees time pass beyond the last step as
        # the live nodes did (less than step_timeout: nothing else fires).
        for k in range(1, 11):
            driver.set_time(backend.now_ns + k * 100_000_000)
        recorder.stop()
        result.bag_messages = sum(recorder.counts.values())
        result.tracker_counters = dict(graph.tracker.counters())
    finally:
        close_run(writer, sim, graph, context)
    m = world.metrics
    result.metrics = {"steps": m.steps, "reminders_delivered": m.reminders_delivered,
                      "guidances_started": m.guidances_started, "guidances_completed": m.guidances_completed,
                      "residents_lost": m.residents_lost, "questions_answered": m.questions_answered,
                      "clarifications": m.clarifications, "unprompted_questions": m.unprompted_questions,
                      "wrong_actions": m.wrong_actions, "reminders_due": m.reminders_due,
                      "questions_raised": m.questions_raised, "robot_at_end": world.robot_at,
                      "time_to_goal": m.time_to_goal, "wrong": m.wrong}
    result.bag = bag_dir
    result.transcript = out_dir / "transcript.txt"
    result.transcript.write_text("\n".join(format_step(s, scenario.resident.name) for s in result.steps)
                                 + "\n" + result.outcome() + "\n", encoding="utf-8")
    result.plot = plot_belief(result.steps, out_dir / "belief.png", f"{scenario.name}: {scenario.description}",
                              scenario)
    result.seconds = time.monotonic() - started
    (out_dir / "summary.json").write_text(json.dumps(summary_dict(result), indent=1), encoding="utf-8")
    return result


def summary_dict(result: DemoResult) -> dict:
    """The ``--json`` object of ``pearl demo``."""
    return {
        "scenario": result.scenario, "out_dir": str(result.out_dir), "bag": str(result.bag),
        "bag_messages": result.bag_messages, "plot": str(result.plot), "transcript": str(result.transcript),
        "steps": len(result.steps), "actions": [s.action for s in result.steps],
        "clarification_questions": result.clarifications, "seconds": round(result.seconds, 2),
        "tracker_counters": result.tracker_counters,
        **{k: v for k, v in result.metrics.items() if k != "steps"},
        "outcome": result.outcome(),
    }
