"""The simulator's journal (``pearl_sim_world``; docs/reliability.md, "Crashes"): a node started again on
the journal of one that died replays its calls and has the same world — the resident, the scheduler,
the base, the random streams, the messages not yet due, the actions taken — with its clock one tick
on, never back;
it does not carry out again the latched action it had taken; another scenario's journal is refused;
the journal is removed when the episode ends. (The whole graph with the simulator SIGKILLed:
``bench/fault_injection.py``.)"""
from __future__ import annotations

import json
from dataclasses import asdict
from pathlib import Path

import pytest

from pearl_interfaces.msg import Action

REPO = Path(__file__).resolve().parents[1]
SCENARIO = REPO / "config" / "scenarios" / "figure4.yaml"

pytestmark = pytest.mark.ros


def make_node(context, journal: Path, scenario: Path = SCENARIO):
    from rclpy.parameter import Parameter

    from pearl_sim.nursing_home.world_node import _make_node_class

    return _make_node_class()(context=context, parameter_overrides=[
        Parameter("scenario", value=str(scenario)), Parameter("journal", value=str(journal)),
        Parameter("rate", value=20.0)])


def action(name: str, sec: int) -> Action:
    msg = Action(name=name)
    msg.stamp.sec = sec
    return msg


def run_actions(node, names) -> None:
    """Carry out ``names`` as the graph would: each action published, then its step closed."""
    node.started = True
    for i, name in enumerate(names):
        node._on_action(action(name, 10 + i))
        while len(node.taken) <= i:
            node._tick()
        node.closed_steps = len(node.taken)     # the tracker closed the step (its /pearl/belief)
    for _ in range(5):                          # the clock runs on a little: the world lives on
        node._tick()


def test_a_restarted_simulator_resumes_the_world_it_journaled(ros_context, tmp_path):
    context, _ = ros_context
    journal = tmp_path / "world.json"
    first = make_node(context, journal)
    try:
        run_actions(first, ["DoNothing", "GotoPatientRoom", "RingDoorBell"])
        assert first.taken == ["DoNothing", "GotoPatientRoom", "RingDoorBell"] and journal.is_file()
        died = (first.now, first.world.time, first.world.truth(), first.world.rng.bit_generator.state,
                asdict(first.world.metrics), [(m.time, m.modality, m.text) for m in first.pending])
    finally:
        first.destroy_node()            # it "dies": nothing else is written
    second = make_node(context, journal)
    try:
        assert second.resumed and second.taken == ["DoNothing", "GotoPatientRoom", "RingDoorBell"]
        assert second.now == pytest.approx(died[0] + 20.0 * second.clock_period)   # one tick on, never back
        assert (second.world.time, second.world.truth(), second.world.rng.bit_generator.state,
                asdict(second.world.metrics), [(m.time, m.modality, m.text) for m in second.pending]) == died[1:]
        # The latched last action comes again on subscription: it was carried out, so it is not queued;
        # the next one is.
        second._on_action(action("RingDoorBell", 12))
        assert not second.actions
        second._on_action(action("RemindPhysioAppt", 13))
        assert [a for _, a in second.actions] == ["RemindPhysioAppt"]
        # Only the first action heard can be the latched one: a later action with the stamp of the last
        # one carried out (decided while the clock stood still) is new, and is carried out.
        second.last_taken_stamp = [13, 0]
        second._on_action(action("TellTime", 13))
        assert [a for _, a in second.actions] == ["RemindPhysioAppt", "TellTime"]
    finally:
        second.destroy_node()


def test_a_resumed_simulator_holds_its_clock_until_it_has_heard_the_latched_belief_and_action(ros_context, tmp_path):
    """Resumed, the node must not run its clock before it knows the tracker's closed steps (its count
    starts at 0, so the world would live on past steps the robot never answered) and before its action
    topic has matched (actions published before are lost): a day once stopped at step 695 with 692
    actions carried out. With every simulated input subscribed, it waits for the latched action and
    the latched belief, then starts."""
    import time

    import rclpy
    from rclpy.executors import SingleThreadedExecutor

    from pearl_interfaces.msg import Belief

    context, _ = ros_context
    journal = tmp_path / "world.json"
    first = make_node(context, journal)
    try:
        run_actions(first, ["DoNothing", "GotoPatientRoom"])
    finally:
        first.destroy_node()
    second = make_node(context, journal)
    tracker = rclpy.create_node("stand_in_tracker", context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(tracker)
    try:
        for publisher in second.hardware.publishers.values():
            tracker.create_subscription(publisher.msg_type, publisher.topic_name, lambda _msg: None, 10)
        deadline = time.monotonic() + 10.0
        while not all(p.get_subscription_count() for p in second.hardware.publishers.values()):
            assert time.monotonic() < deadline, "the stand-in tracker's subscriptions never matched"
            executor.spin_once(timeout_sec=0.05)
        now = second.now
        for _ in range(3):
            second._tick()
        assert second.resumed and not second.started and second.now == now
        assert second._waiting_for() == ["the tracker's latched /pearl/belief", "the policy's latched /pearl/action"]
        second._on_action(action("GotoPatientRoom", 11))      # the latched action, carried out already
        second._tick()
        assert not second.started and not second.actions
        assert second._waiting_for() == ["the tracker's latched /pearl/belief"]
        belief = Belief()
        belief.step = 2
        second._on_belief(belief)
        second._tick()
        assert second.started and second.closed_steps == 2
    finally:
        executor.shutdown()
        tracker.destroy_node()
        second.destroy_node()


def test_a_journal_of_another_scenario_is_refused_and_an_ended_episode_leaves_none(ros_context, tmp_path):
    context, _ = ros_context
    journal = tmp_path / "world.json"
    first = make_node(context, journal)
    try:
        run_actions(first, ["DoNothing"])
    finally:
        first.destroy_node()
    other = tmp_path / "other.yaml"
    other.write_text(SCENARIO.read_text().replace("seed:", "seed: 99  # was:", 1) if "seed:" in SCENARIO.read_text()
                     else SCENARIO.read_text() + "\n# another scenario\n")
    refused = make_node(context, journal, other)
    try:
        assert not refused.resumed and refused.taken == [] and refused.now == 0.0
        refused._finish(None)           # the episode ended: a new launch starts afresh
        assert not journal.exists()
    finally:
        refused.destroy_node()
    body = {"format": "nothing"}
    journal.write_text(json.dumps(body))
    damaged = make_node(context, journal)
    try:
        assert not damaged.resumed and damaged.now == 0.0
    finally:
        damaged.destroy_node()
