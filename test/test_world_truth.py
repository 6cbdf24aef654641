"""A world's true state on ``/WORLD/sim/truth`` (issue 40): ``pearl_interfaces/WorldTruth`` from the
world's truth record and back, and every reader — ``pearl fit``, the bag claims — reads it and the JSON
``std_msgs/String`` that bags recorded before it hold, giving the same records and the same fit."""
from __future__ import annotations

import functools
import json
from pathlib import Path

import pytest

pytestmark = pytest.mark.ros
import rclpy  # noqa: F401,E402  (a missing install fails, it is not skipped)
from rclpy.serialization import serialize_message  # noqa: E402
from std_msgs.msg import String  # noqa: E402

from pearl_pomdp.bags.reader import BagReader  # noqa: E402
from pearl_pomdp.bags.writer import BagWriter  # noqa: E402
from pearl_pomdp.errors import PearlError  # noqa: E402
from pearl_pomdp.fit import episodes_from_bag, fit_domain, fitted_section  # noqa: E402
from pearl_pomdp.model.domain_yaml import load_domain  # noqa: E402
from pearl_pomdp.nodes.conversions import msg_to_truth, truth_to_msg  # noqa: E402
from pearl_pomdp.world_truth import TRUTH_TYPE, truth_records, truth_topic, truth_topics  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
#: Recorded before WorldTruth: the truth is JSON in a std_msgs/String (and, in the first, the belief too).
OLD_BAGS = [REPO / "test" / "data" / "bag_before_typed" / "figure4_guidance", REPO / "bags" / "figure4_guidance"]
TRUTH = "/pearl/sim/truth"


def _figure4_sim_world(context):
    """``pearl_sim_world`` on Figure 4 in this process, without a journal, at 20 times real time."""
    from rclpy.parameter import Parameter

    from pearl_sim.nursing_home.world_node import _make_node_class

    return _make_node_class()(context=context, parameter_overrides=[
        Parameter("scenario", value=str(REPO / "config" / "scenarios" / "figure4.yaml")),
        Parameter("journal", value=""), Parameter("rate", value=20.0)])


def _spin_until(executor, done, what, timeout=20.0):
    """Spin ``executor`` until ``done()``; fail with ``what`` after ``timeout`` s."""
    import time

    deadline = time.monotonic() + timeout
    while not done():
        assert time.monotonic() < deadline, what
        executor.spin_once(timeout_sec=0.05)


def figure4_records():
    """The nursing home's truth records over Figure 4's first actions: starts, ends with events, a wrong one."""
    from pearl_sim.nursing_home.scenario import load_scenarios
    from pearl_sim.nursing_home.world import World

    world = World(load_scenarios(REPO / "config" / "scenarios" / "figure4.yaml")[0], seed=4)
    records = []
    for action in ("DoNothing", "GotoPatientRoom", "RingDoorBell", "TellWeather", "RemindPhysioAppt"):
        records.append(world.truth_record("start", action))
        records.append(world.truth_record("end", action, world.act(action)))
    records.append(world.truth_record("start"))
    return records


def test_a_truth_record_crosses_the_message_and_cdr_unchanged():
    records = figure4_records()
    # Real values: the robot drove to the room, the bell rang, a question nobody asked was wrong.
    assert records[3]["state"]["RobotLocation"] == "room" and records[0]["state"]["RobotLocation"] == "home"
    assert any(r.get("wrong") for r in records) and any(r.get("events") for r in records)
    for record in records:
        msg = truth_to_msg(record, stamp_s=12.25)
        assert (msg.stamp.sec, msg.stamp.nanosec) == (12, 250_000_000)
        assert list(msg.feature_names)[:2] == ["RobotLocation", "UserLocation"]
        assert msg.has_outcome == (record["phase"] == "end")
        assert msg_to_truth(msg) == record
    wrong = next(r for r in records if r.get("wrong"))
    assert truth_to_msg(wrong).wrong == wrong["wrong"]


def _rewrite(source: Path, out: Path, typed: bool) -> Path:
    """``source`` rewritten into ``out`` with every message as it was, except the truth: as WorldTruth
    (``typed``) or as the JSON String a bag recorded before it holds."""
    reader = BagReader(source)
    records = iter(truth_records(reader, TRUTH))
    with BagWriter(out) as bag:
        for name, info in reader.topics.items():
            if name == TRUTH:
                bag.add_topic(name, TRUTH_TYPE if typed else "std_msgs/msg/String")
            else:
                bag.add_topic(name, info.type, definition=info.definition, type_hash=info.type_description_hash)
        for m in reader.messages:
            data = m.data
            if m.topic == TRUTH:
                record = next(records)
                data = serialize_message(truth_to_msg(record, m.log_time * 1e-9) if typed
                                         else String(data=json.dumps(record)))
            bag.write(m.topic, data, m.log_time, m.publish_time)
    return out


@pytest.mark.parametrize("old", OLD_BAGS, ids=["before_typed", "shipped"])
def test_a_bag_with_typed_truth_gives_the_records_and_the_fit_of_the_json_bag(old, tmp_path):
    """The same episode recorded with the JSON truth (as users' bags are) and with WorldTruth: the same
    records, the same true states, the same fitted tables."""
    new = _rewrite(old, tmp_path / "typed", typed=True)
    assert BagReader(old).topics[TRUTH].type == "std_msgs/msg/String"
    assert BagReader(new).topics[TRUTH].type == TRUTH_TYPE
    before, after = truth_records(BagReader(old), TRUTH), truth_records(BagReader(new), TRUTH)
    assert after == before and len(before) == 61          # 30 actions: start and end each, and the last state
    assert before[0] == {"time": 0.0, "phase": "start", "action": "DoNothing", "state": before[0]["state"]}
    assert before[0]["state"]["RobotLocation"] == "home" and before[1]["events"] == [] and before[1]["wrong"] is None
    old_episode, new_episode = episodes_from_bag(old), episodes_from_bag(new)
    assert new_episode.states == old_episode.states and len(old_episode.states) == len(old_episode.actions) + 1 == 31
    assert new_episode.actions == old_episode.actions and new_episode.observations == old_episode.observations
    domain = load_domain(REPO / "config" / "pearl.domain.yaml")
    fits = [fit_domain(domain, [ep], min_count=1) for ep in (old_episode, new_episode)]
    assert fits[0].with_truth and fits[1].with_truth and fits[0].rows
    assert [(r.table, r.row, r.n, r.after) for r in fits[1].rows] == [(r.table, r.row, r.n, r.after) for r in fits[0].rows]
    assert fitted_section(fits[1], 10.0) == fitted_section(fits[0], 10.0)


def test_a_json_truth_bag_written_now_still_reads(tmp_path):
    """A bag holding the truth as JSON (std_msgs/String), written here from a world's records."""
    records = figure4_records()
    with BagWriter(tmp_path / "json") as bag:
        bag.add_topic(truth_topic("pearl"), "std_msgs/msg/String")
        for k, record in enumerate(records):
            bag.write(TRUTH, serialize_message(String(data=json.dumps(record))), 1_000 + k)
    reader = BagReader(tmp_path / "json")
    assert truth_topics(reader) == [TRUTH] and truth_records(reader, TRUTH) == records


def test_truth_topics_are_the_worlds_and_a_bad_truth_message_is_named(tmp_path):
    records = figure4_records()
    with BagWriter(tmp_path / "bad") as bag:
        bag.add_topic("/reception/sim/truth", TRUTH_TYPE)
        bag.add_topic("/ward/sim/truth", "std_msgs/msg/String")
        bag.add_topic("/pearl/sim/truth_log", "std_msgs/msg/String")
        bag.add_topic("/a/b/sim/truth", "std_msgs/msg/String")
        bad = truth_to_msg(records[0])
        bad.feature_values = bad.feature_values[:-1]
        bag.write("/reception/sim/truth", serialize_message(bad), 1)
        bag.write("/ward/sim/truth", serialize_message(String(data="not json")), 2)
    reader = BagReader(tmp_path / "bad")
    assert truth_topics(reader) == ["/reception/sim/truth", "/ward/sim/truth"]
    with pytest.raises(PearlError, match=r"topic /reception/sim/truth: message 0: 7 feature_names but 6 feature_values"):
        truth_records(reader, "/reception/sim/truth")
    with pytest.raises(PearlError, match=r"topic /ward/sim/truth: message 0: not a std_msgs/String holding a JSON"):
        truth_records(reader, "/ward/sim/truth")
    with pytest.raises(PearlError, match=r"two: 2 truth topics \(/reception/sim/truth, /ward/sim/truth\)"):
        episodes_from_bag(_with_belief(tmp_path / "bad", tmp_path / "two"))


def _with_belief(source: Path, out: Path) -> Path:
    """``source`` plus one old-style /pearl/belief_marginals step (the fit needs steps to get to the truth)."""
    reader = BagReader(source)
    with BagWriter(out) as bag:
        for name, info in reader.topics.items():
            bag.add_topic(name, info.type, definition=info.definition)
        bag.add_topic("/pearl/belief_marginals", "std_msgs/msg/String")
        for m in reader.messages:
            bag.write(m.topic, m.data, m.log_time)
        step = {"step": 1, "action": "DoNothing", "observation": "none"}
        bag.write("/pearl/belief_marginals", serialize_message(String(data=json.dumps(step))), 10)
    return out


def test_a_truth_topic_of_another_type_is_named(tmp_path):
    with BagWriter(tmp_path / "float") as bag:
        bag.add_topic(TRUTH, "std_msgs/msg/Float64")
        from std_msgs.msg import Float64

        bag.write(TRUTH, serialize_message(Float64(data=1.0)), 1)
    with pytest.raises(PearlError, match=r"topic /pearl/sim/truth: recorded as std_msgs/msg/Float64; a truth topic "
                                         r"is pearl_interfaces/msg/WorldTruth"):
        truth_records(BagReader(tmp_path / "float"), TRUTH)



def test_the_separate_process_simulator_publishes_the_typed_truth_over_dds(ros_context):
    """``pearl_sim_world`` (the nursing home as its own node) sends the same records as WorldTruth."""
    from rclpy.executors import SingleThreadedExecutor

    from pearl_interfaces.msg import Action
    from pearl_pomdp.nodes.conversions import WorldTruthMsg
    from pearl_sim.nodes import RELIABLE

    context, _ = ros_context
    node = _figure4_sim_world(context)
    listener = rclpy.create_node("truth_listener", context=context)
    got = []
    listener.create_subscription(WorldTruthMsg, TRUTH, got.append, RELIABLE)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(listener)

    spin_until = functools.partial(_spin_until, executor)

    try:
        spin_until(lambda: node.truth_pub.get_subscription_count() > 0, "the listener never matched /pearl/sim/truth")
        node.started = True
        for i, name in enumerate(["DoNothing", "GotoPatientRoom"]):     # as the graph would: action, then its step closed
            node._on_action(Action(name=name))
            while len(node.taken) <= i:
                node._tick()
            node.closed_steps = len(node.taken)
        spin_until(lambda: len(got) == 4, f"{len(got)} of 4 truth messages arrived")
    finally:
        executor.shutdown()
        listener.destroy_node()
        node.destroy_node()
    records = [msg_to_truth(m) for m in got]
    assert [(r["phase"], r["action"]) for r in records] == [
        ("start", "DoNothing"), ("end", "DoNothing"), ("start", "GotoPatientRoom"), ("end", "GotoPatientRoom")]
    assert records[2]["state"]["RobotLocation"] == "home" and records[3]["state"]["RobotLocation"] == "room"
    assert records[3]["state"] == node.world.truth() and records[3]["time"] == node.world.time > 0
    assert records[3]["wrong"] is None and "events" not in records[2]
    stamps = [m.stamp.sec + m.stamp.nanosec * 1e-9 for m in got]
    assert stamps == sorted(stamps) and abs(stamps[-1] - node.now) < 1e-6


def test_the_separate_process_simulator_publishes_through_the_frames_hardware(ros_context):
    """``pearl_sim_world`` publishes from its own node through ``pearl demo``'s simulated hardware
    (:class:`pearl_sim.nodes.SimulatedHardware`): the robot's pose with every true state, stamped
    alike, and what the resident said beside the recogniser's text; it brings no node of its own."""
    from geometry_msgs.msg import PoseStamped
    from rclpy.executors import SingleThreadedExecutor

    from pearl_interfaces.msg import Action, RecognisedSpeech
    from pearl_pomdp.nodes.conversions import WorldTruthMsg
    from pearl_sim.nodes import RELIABLE

    context, _ = ros_context
    node = _figure4_sim_world(context)
    listener = rclpy.create_node("hardware_listener", context=context)
    got: dict = {"truth": [], "pose": [], "said": [], "speech": []}
    listener.create_subscription(WorldTruthMsg, TRUTH, got["truth"].append, RELIABLE)
    listener.create_subscription(PoseStamped, "/pearl/pose", got["pose"].append, 10)
    listener.create_subscription(String, "/pearl/sim/said", got["said"].append, RELIABLE)
    listener.create_subscription(RecognisedSpeech, "/pearl/speech", got["speech"].append, RELIABLE)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(listener)

    spin_until = functools.partial(_spin_until, executor)

    try:
        assert node.hardware.nodes == [] and node.hardware.node is node
        spin_until(lambda: all(p.get_subscription_count() > 0 for p in
                               [node.truth_pub, node.hardware.pose, node.hardware.said, node.hardware.publishers["Speech"]]),
                   "the listener never matched the simulator's topics")
        node.started = True
        actions = ["DoNothing", "GotoPatientRoom", "RingDoorBell"]     # RingDoorBell: she answers "ok"
        for i, name in enumerate(actions):
            node._on_action(Action(name=name))
            while len(node.taken) <= i:
                node._tick()
            if i < len(actions) - 1:
                node.closed_steps = len(node.taken)   # the last step stays open: the clock runs to her answer
        while node.pending:
            node._tick()
        spin_until(lambda: len(got["truth"]) == 6 and len(got["pose"]) == 6 and got["said"] and got["speech"],
                   f"{[(k, len(v)) for k, v in got.items()]} arrived")
    finally:
        executor.shutdown()
        listener.destroy_node()
        node.destroy_node()
    assert [(p.header.stamp.sec, p.header.stamp.nanosec) for p in got["pose"]] == \
        [(t.stamp.sec, t.stamp.nanosec) for t in got["truth"]]
    xy = [(p.pose.position.x, p.pose.position.y) for p in got["pose"]]
    places = node.scenario.map
    assert xy == [tuple(map(float, places[w])) for w in ("home", "home", "home", "room", "room", "room")]
    assert [m.data for m in got["said"]] == ["ok"] and [m.text for m in got["speech"]] == ["ok"]


def _without_last_truth(source: Path, out: Path, drop: int) -> Path:
    """``source`` with its last ``drop`` truth messages left out (a run stopped before the world said them)."""
    reader = BagReader(source)
    truth = [m for m in reader.messages if m.topic == TRUTH]
    keep = set(id(m) for m in truth[:len(truth) - drop])
    with BagWriter(out) as bag:
        for name, info in reader.topics.items():
            bag.add_topic(name, info.type, definition=info.definition, type_hash=info.type_description_hash)
        for m in reader.messages:
            if m.topic != TRUTH or id(m) in keep:
                bag.write(m.topic, m.data, m.log_time, m.publish_time)
    return out


def test_a_bag_cut_before_the_last_state_loses_its_last_step_and_a_short_truth_is_refused(tmp_path):
    """The shipped bag holds 30 steps and 31 starts. Without the world's last state the last step's
    successor is unknown: 29 steps are counted against 30 states. With a whole action's records gone
    too, the truth no longer covers the steps: refused, naming the bag, the topic and the counts —
    and `--no-truth` (EM) still fits it."""
    whole = episodes_from_bag(OLD_BAGS[1])
    assert len(whole.actions) == 30 and len(whole.states) == 31
    cut = episodes_from_bag(_without_last_truth(OLD_BAGS[1], tmp_path / "cut", drop=1))
    assert cut.actions == whole.actions[:29] and cut.observations == whole.observations[:29]
    assert cut.states == whole.states[:30]
    short = _without_last_truth(OLD_BAGS[1], tmp_path / "short", drop=3)
    with pytest.raises(PearlError, match=r"short: /pearl/sim/truth holds 29 true state\(s\) at the start of an action "
                                         r"for 30 step\(s\) on /pearl/belief.*pearl fit --no-truth"):
        episodes_from_bag(short)
    untold = episodes_from_bag(short, truth=False)
    assert untold.states is None and untold.actions == whole.actions
    domain = load_domain(REPO / "config" / "pearl.domain.yaml")
    assert not fit_domain(domain, [untold], em_iterations=2).with_truth
    from pearl_pomdp.cli import main

    out = tmp_path / "fitted.yaml"
    assert main(["fit", str(REPO / "config" / "pearl.domain.yaml"), str(short), "--out", str(out)]) == 2
    assert main(["fit", str(REPO / "config" / "pearl.domain.yaml"), str(short), "--out", str(out), "--no-truth",
                 "--em-iterations", "2"]) == 0
    assert "EM without the true state" in out.read_text()
