"""``pearl demo`` in the nursing home: Figure 4 through the full ROS 2 graph, on the frame's demo.

The frame (:mod:`pearl_sim.world_demo`) runs the graph, the simulated hardware under ``/clock``,
the transcript, the bag and the outcome; here is what is Pearl's own (:data:`DEMO`): the resident
in the transcript with the features a reader of Figure 4 follows, the episode's end when Pearl
has left for its station, the belief plot (``belief.png``), the outcome and summary, and the
Foxglove live view (:class:`LiveViewWatcher`, ``pearl demo --foxglove``).
"""
from __future__ import annotations

import time
from pathlib import Path
from typing import Any, Callable, Dict, List, Optional

from pearl_sim.nursing_home.scenario import Scenario, load_scenarios
from pearl_sim.nursing_home.world import World, until_pearl_leaves
from pearl_sim.world_demo import DemoRun, DemoStep, DemoWatcher, WorldDemo, run_world_demo, trace_path

__all__ = ["DEMO", "LiveViewWatcher", "run_demo", "plot_belief", "plotted_features", "outcome_line",
           "RECORDED_TOPICS", "SHOWN_FEATURES"]

#: Features shown in the transcript (the ones a reader of Figure 4 follows).
SHOWN_FEATURES = ("ReminderGoal", "UserPresent", "UserMotionGoal", "UserInfoGoal", "UserLocation")
#: What a run of Pearl's graph through the nursing home records (its inputs, the loop, the truth).
RECORDED_TOPICS = ["/clock", "/pearl/speech", "/pearl/touchscreen", "/pearl/laser", "/pearl/reminder",
                   "/pearl/action", "/pearl/belief", "/pearl/decision",
                   "/pearl/say", "/pearl/display", "/goal_pose", "/pearl/pose", "/pearl/sim/said",
                   "/pearl/sim/truth"]


def outcome_line(m: Dict[str, Any]) -> str:
    """The outcome of the scores :func:`_metrics` gives. Only what the scenario asked for is scored:
    the guidance when it wanted one (a physiotherapy appointment), x/y of the reminders that fell due
    and of the questions she came to have; nothing is said about a task the scenario never set."""
    ttg = f" in {m['time_to_goal'][0]:.0f} s" if m["time_to_goal"] else ""
    if m.get("guidance_wanted", True):
        guided = ("guidance completed" if m["guidances_completed"] else "guidance NOT completed") + ttg + "; "
    else:
        guided = "no guidance wanted; " if not m["guidances_started"] else "guided unasked; "
    parts = [f"{m['reminders_delivered']}/{m['reminders_due']} reminder(s) delivered" if m.get("reminders_due") else "",
             f"{m['questions_answered']}/{m['questions_raised']} question(s) answered"
             if m.get("questions_raised") else "",
             f"{int(m.get('clarifications', 0))} clarification question(s)",
             f"{m['unprompted_questions']} unprompted", f"{m['wrong_actions']} wrong action(s)",
             # The robot is back at its station (``home``) when the episode ends.
             "ended at home" if m.get("robot_at_end", "home") == "home" else "ended away from home"]
    return f"outcome: {guided}" + ", ".join(p for p in parts if p)


def _metrics(world: World) -> Dict[str, Any]:
    m = world.metrics
    return {"steps": m.steps, "reminders_delivered": m.reminders_delivered,
            "guidances_started": m.guidances_started, "guidances_completed": m.guidances_completed,
            "residents_lost": m.residents_lost, "questions_answered": m.questions_answered,
            "clarifications": m.clarifications, "unprompted_questions": m.unprompted_questions,
            "wrong_actions": m.wrong_actions, "reminders_due": m.reminders_due,
            "questions_raised": m.questions_raised, "robot_at_end": world.robot_at,
            "time_to_goal": m.time_to_goal, "wrong": m.wrong,
            "guidance_wanted": any(a.kind == "physio" for a in world.scenario.appointments)}


def _summary(run: DemoRun) -> dict:
    return {"scenario": run.scenario, "out_dir": str(run.out_dir), "bag": str(run.bag),
            "bag_messages": run.bag_messages, "plot": str(run.plot), "transcript": str(run.transcript),
            "steps": len(run.steps), "actions": run.actions,
            "clarification_questions": int(run.metrics.get("clarifications", 0)), "seconds": round(run.seconds, 2),
            "tracker_counters": run.tracker_counters,
            **{k: v for k, v in run.metrics.items() if k not in ("steps", "guidance_wanted")},
            "outcome": run.outcome()}


def _top(marginals: Dict[str, Dict[str, float]]) -> str:
    parts = []
    for f in SHOWN_FEATURES:
        vals = marginals.get(f)
        if vals:
            v, p = max(vals.items(), key=lambda kv: kv[1])
            parts.append(f"{f}={v} {p:.2f}")
    return " | ".join(parts)


def describe_step(step: DemoStep, scenario: Scenario) -> str:
    """The transcript lines of one step: the resident by name, what was recognised and the
    observation it made, and the belief in :data:`SHOWN_FEATURES`."""
    resident = scenario.resident.name
    lines = [f"[{step.time:7.1f} s] action {step.action:<22} trace {trace_path(step)}"]
    msg = step.heard[0] if step.heard else None
    if msg is not None and msg.modality == "Speech":
        from pearl_pomdp.speech import parse_speech_message

        text, confidence = parse_speech_message(msg.text)
        conf = f" ({confidence:.2f})" if confidence < 1.0 else ""
        meant = f" (meaning {msg.meant})" if msg.meant else ""
        lines.append(f"           {resident} said \"{msg.said}\"{meant} → recognised \"{text}\"{conf} → "
                     f"{step.observation}")
    elif msg is not None:
        who = f"{resident} " if msg.modality == "Touchscreen" else ""
        lines.append(f"           {who}{msg.modality.lower()}: {msg.text} → {step.observation}")
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


class LiveViewWatcher(DemoWatcher):
    """The demo streamed to a :class:`pearl_pomdp.live_view.LiveView` (``--foxglove``): belief
    marginals, actions, EXECUTE traces, the proposal and operator events, the transcript and the
    robot's pose on the scenario's map, stamped with the sim time of the step being answered.
    :meth:`stop` keeps the view up ``linger`` seconds, then stops it."""

    def __init__(self, view: Any, linger: float = 0.0):
        self.view, self.linger = view, linger
        self.scenario: Any = None
        self.now: Callable[[], float] = lambda: 0.0

    def show(self, topic: str, value: Any) -> None:
        """``value`` on the live view's ``topic`` at the sim time of the step being answered."""
        self.view.publish(topic, value, self.now())

    def start(self, listener: Any, scenario: Any, world: Any, now: Callable[[], float]) -> None:
        from rclpy.qos import DurabilityPolicy, QoSProfile

        from pearl_pomdp.nodes import conversions as cv

        self.scenario, self.now = scenario, now
        latched = QoSProfile(depth=10, durability=DurabilityPolicy.TRANSIENT_LOCAL)
        listener.create_subscription(cv.ActionMsg, "/pearl/action",
                                     lambda msg: self.show("/pearl/action", cv.msg_to_action(msg)), latched)
        # What a person in the loop sees: the proposal and every operator event.
        listener.create_subscription(cv.OperatorProposalMsg, "/pearl/proposal",
                                     lambda msg: self.show("/pearl/proposal", cv.msg_to_proposal(msg)), latched)
        listener.create_subscription(cv.OperatorEventMsg, "/pearl/operator/events",
                                     lambda msg: self.show("/pearl/operator/events", cv.msg_to_operator_event(msg)), 100)
        self.view.publish_places({name: [x, y, 0.0] for name, (x, y) in scenario.map.items()}, 0.0)

    def decision(self, decision: dict) -> None:
        self.show("/pearl/decision", decision)

    def belief(self, marginals: dict) -> None:
        self.show("/pearl/belief_marginals", marginals)

    def step(self, step: DemoStep, world: Any) -> None:
        x, y = self.scenario.map[world.robot_at]
        self.show("/pearl/pose", {"x": x, "y": y, "yaw": 0.0})
        self.show("/pearl/transcript", {"speaker": "Pearl", "text": f"[{step.index}] {step.action}"})
        if step.heard:
            msg = step.heard[0]
            self.show("/pearl/transcript", {"speaker": self.scenario.resident.name if msg.said else msg.modality,
                                            "text": msg.said or msg.text})
        for event in step.events:
            self.show("/pearl/transcript", {"speaker": "world", "text": event})

    def stop(self) -> None:
        if self.linger > 0:
            time.sleep(self.linger)
        self.view.stop()


#: What the nursing home brings to the frame's ``pearl demo``.
DEMO = WorldDemo(load_scenarios=load_scenarios,
                 make_world=lambda scenario, seed, domain: World(scenario, seed=seed, domain=domain),
                 metrics=_metrics, outcome=outcome_line, describe_step=describe_step, stop_when=until_pearl_leaves, until_stop=True,
                 pose_topic="/pearl/pose", hierarchy="config/pearl.hierarchy.yaml",
                 plot=lambda run, scenario: plot_belief(run.steps, run.out_dir / "belief.png",
                                                        f"{scenario.name}: {scenario.description}", scenario),
                 summary=_summary)


def run_demo(scenario_path: Path, out_dir: Path, *, domain_path: Path, hierarchy_path: Path,
             policy: str = "", seed: Optional[int] = None, domain_id: Optional[int] = None,
             echo: Optional[Callable[[str], None]] = None, wall_timeout: float = 30.0,
             live_view=None) -> DemoRun:
    """Run the scenario's first episode through Pearl's graph and the simulated nursing home, with
    the shipped node params (:func:`pearl_sim.world_demo.run_world_demo`; ``live_view``: a
    :class:`pearl_pomdp.live_view.LiveView` to stream to, left running)."""
    return run_world_demo("pearl", DEMO, Path(scenario_path), Path(out_dir), domain_path=Path(domain_path),
                          params_file="default", policy=policy, hierarchy_path=hierarchy_path, seed=seed,
                          domain_id=domain_id, echo=echo, wall_timeout=wall_timeout,
                          watcher=LiveViewWatcher(live_view) if live_view is not None else None)
