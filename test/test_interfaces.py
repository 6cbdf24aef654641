"""The typed ROS 2 interfaces (pearl_interfaces/, issue 39), as the README's one install command
built them into the venv: every message and service is importable with its fields (what
``ros2 interface show`` prints), its definition and type hash are installed where rosbag2 and the
bag writer look (``share/pearl_interfaces``), a message crosses DDS between two processes, and a bag
holding one decodes with ``mcap-ros2-support`` alone (a reader that imports nothing of this project)."""
from __future__ import annotations

import math
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from ros_helpers import Proc, allocate_domain_id, ros_env, wait_for

pytestmark = pytest.mark.ros

REPO = Path(__file__).resolve().parents[1]
SOURCE = REPO / "pearl_interfaces"


def _interface_names(kind: str):
    return sorted(p.stem for p in (SOURCE / kind).glob(f"*.{kind}"))


def test_every_interface_of_the_source_folder_is_installed_with_its_fields():
    import importlib

    msgs = importlib.import_module("pearl_interfaces.msg")
    srvs = importlib.import_module("pearl_interfaces.srv")
    assert _interface_names("msg") == ["Action", "Belief", "Decision", "DriveProgress", "FeatureMarginal",
                                       "GuidePace", "OperatorEvent", "OperatorProposal", "RecognisedSpeech",
                                       "SearchAction", "SearchBranch", "SearchStats", "TraceStep", "WorldTruth"]
    assert _interface_names("srv") == ["Command", "SetAutonomy", "Veto"]   # confirm: std_srvs/SetBool
    for name in _interface_names("msg"):
        assert hasattr(msgs, name), name
    for name in _interface_names("srv"):
        assert hasattr(getattr(srvs, name), "Request"), name
    assert msgs.Decision.get_fields_and_field_types() == {
        "stamp": "builtin_interfaces/Time", "step": "uint32", "belief_step": "uint32", "action": "string",
        "trace": "sequence<pearl_interfaces/TraceStep>", "expansions": "uint32", "latency_s": "double",
        "has_search": "boolean", "search": "pearl_interfaces/SearchStats"}
    assert msgs.Belief.get_fields_and_field_types() == {
        "stamp": "builtin_interfaces/Time", "step": "uint32", "run": "uint32", "action": "string",
        "observation": "string", "marginals": "sequence<pearl_interfaces/FeatureMarginal>",
        "state_names": "sequence<string>", "probabilities": "sequence<double>", "num_states": "uint32",
        "support": "sequence<uint32>", "outside_support": "double"}
    assert msgs.OperatorEvent.get_fields_and_field_types()["step"] == "int32"   # -1: before the first belief
    assert msgs.Action.get_fields_and_field_types() == {"stamp": "builtin_interfaces/Time", "name": "string"}
    assert msgs.RecognisedSpeech.get_fields_and_field_types() == {
        "stamp": "builtin_interfaces/Time", "text": "string", "confidence": "float", "symbol": "string"}
    assert msgs.WorldTruth.get_fields_and_field_types() == {
        "stamp": "builtin_interfaces/Time", "world_time": "double", "phase": "string", "action": "string",
        "feature_names": "sequence<string>", "feature_values": "sequence<string>", "has_outcome": "boolean",
        "events": "sequence<string>", "wrong": "string"}
    assert msgs.DriveProgress.get_fields_and_field_types() == {
        "stamp": "builtin_interfaces/Time", "action": "string", "place": "string", "distance_remaining": "float",
        "estimated_time_remaining": "float"}
    assert msgs.GuidePace.get_fields_and_field_types() == {
        "stamp": "builtin_interfaces/Time", "active": "string", "state": "string", "speed": "double",
        "nav_speed": "double", "pace": "double", "behind": "double", "waited": "double", "times_lost": "uint32"}
    assert srvs.SetAutonomy.Request.get_fields_and_field_types() == {
        "level": "string", "confirm_categories": "sequence<string>", "confirm_timeout": "double"}
    assert srvs.Veto.Response.get_fields_and_field_types() == {"accepted": "boolean", "message": "string"}


def test_the_definitions_and_type_hashes_are_installed_where_bags_look(ros_context):
    """share/pearl_interfaces/msg/*.msg and *.json under the venv: the bag writer's full ros2msg
    definition of a Decision names its nested types, and its RIHS01 hash is the one rclpy announces."""
    import rclpy
    from pearl_interfaces.msg import Decision

    from pearl_pomdp.bags import msgdefs

    text = msgdefs.message_definition("pearl_interfaces/msg/Decision")
    assert text.startswith((SOURCE / "msg" / "Decision.msg").read_text(encoding="utf-8"))
    for nested in ("MSG: builtin_interfaces/Time", "MSG: pearl_interfaces/SearchStats", "MSG: pearl_interfaces/TraceStep"):
        assert nested in text
    node = rclpy.create_node("hash_probe", context=ros_context[0])
    try:
        node.create_publisher(Decision, "/pearl/decision", 1)
        announced = str(node.get_publishers_info_by_topic("/pearl/decision")[0].topic_type_hash)
    finally:
        node.destroy_node()
    assert msgdefs.type_hash("pearl_interfaces/msg/Decision") == announced
    assert announced.startswith("RIHS01_") and len(announced) == 7 + 64


PUBLISHER = textwrap.dedent("""\
    import math, sys, time
    import rclpy
    from pearl_interfaces.msg import Decision, SearchStats, TraceStep
    rclpy.init()
    node = rclpy.create_node("decision_talker")
    pub = node.create_publisher(Decision, "/pearl/decision", 10)
    msg = Decision(step=4, belief_step=3, action="RemindPhysio", expansions=17, latency_s=0.0125, has_search=True,
                   trace=[TraceStep(subtask="Act", choice="Remind", value=12.5),
                          TraceStep(subtask="Remind", choice="RemindPhysio", value=math.nan)],
                   search=SearchStats(lower=1.0, upper=1.5, gap=0.5, trials=200, nodes=900, stop="gap"))
    deadline = time.monotonic() + 30
    while pub.get_subscription_count() == 0 and time.monotonic() < deadline:
        rclpy.spin_once(node, timeout_sec=0.05)
    for _ in range(50):
        pub.publish(msg)
        rclpy.spin_once(node, timeout_sec=0.1)
    node.destroy_node()
    rclpy.try_shutdown()
    """)


def test_a_decision_crosses_dds_between_two_processes_field_by_field(tmp_path):
    import rclpy
    from rclpy.context import Context
    from rclpy.signals import SignalHandlerOptions

    from pearl_interfaces.msg import Decision

    from ros_helpers import configure_test_process

    configure_test_process(tmp_path)
    domain_id = allocate_domain_id()
    context = Context()
    rclpy.init(context=context, domain_id=domain_id, signal_handler_options=SignalHandlerOptions.NO)
    proc = None
    try:
        node = rclpy.create_node("decision_listener", context=context)
        got = []
        node.create_subscription(Decision, "/pearl/decision", got.append, 10)
        from rclpy.executors import SingleThreadedExecutor

        executor = SingleThreadedExecutor(context=context)
        executor.add_node(node)
        proc = Proc([sys.executable, "-c", PUBLISHER], ros_env(domain_id, tmp_path), tmp_path, "talker")
        assert wait_for(lambda: bool(got), 60.0, executor), proc.stderr()[-2000:]
        msg = got[0]
        assert (msg.step, msg.belief_step, msg.action, msg.expansions, msg.latency_s) == (4, 3, "RemindPhysio", 17, 0.0125)
        assert [(t.subtask, t.choice) for t in msg.trace] == [("Act", "Remind"), ("Remind", "RemindPhysio")]
        assert msg.trace[0].value == 12.5 and math.isnan(msg.trace[1].value)
        assert msg.has_search and (msg.search.trials, msg.search.nodes, msg.search.stop) == (200, 900, "gap")
        executor.shutdown()
        node.destroy_node()
    finally:
        if proc is not None:
            proc.stop()
        rclpy.try_shutdown(context=context)


DECODER = textwrap.dedent("""\
    import sys
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory
    with open(sys.argv[1], "rb") as fh:
        for schema, channel, message, decoded in make_reader(fh, decoder_factories=[DecoderFactory()]).iter_decoded_messages():
            print(schema.name, channel.topic, decoded.step, decoded.action,
                  [(t.subtask, t.choice, t.value) for t in decoded.trace], decoded.search.stop)
    print("project modules:", sorted(m for m in sys.modules if m.startswith(("pearl", "rclpy"))))
    """)


def test_a_bag_of_decisions_decodes_with_mcap_ros2_support_alone(tmp_path):
    from pearl_interfaces.msg import Decision, TraceStep
    from rclpy.serialization import serialize_message

    from pearl_pomdp.bags.writer import BagWriter

    msg = Decision(step=2, action="GuideToPhysio", trace=[TraceStep(subtask="Act", choice="Guide", value=3.25)])
    msg.search.stop = "trials"
    with BagWriter(tmp_path / "bag") as bag:
        bag.add_topic("/pearl/decision", "pearl_interfaces/msg/Decision")
        bag.write("/pearl/decision", serialize_message(msg), 1_000_000_000)
    mcap_file = next((tmp_path / "bag").glob("*.mcap"))
    out = subprocess.run([sys.executable, "-c", DECODER, str(mcap_file)], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    assert out.stdout.splitlines() == [
        "pearl_interfaces/msg/Decision /pearl/decision 2 GuideToPhysio [('Act', 'Guide', 3.25)] trials",
        "project modules: []"]


def test_replay_reads_the_decisions_of_a_typed_bag_and_of_one_recorded_before_the_change(tmp_path):
    """``pearl replay --explain`` takes /pearl/decision as pearl_interfaces/msg/Decision, and still reads the
    JSON std_msgs/String of a bag recorded before the typed interfaces (the shipped bags): same plain form."""
    import json

    from rclpy.serialization import serialize_message
    from std_msgs.msg import String

    from pearl_pomdp.bags.reader import BagReader
    from pearl_pomdp.bags.writer import BagWriter
    from pearl_pomdp.nodes import conversions as cv
    from pearl_pomdp.nodes.bag_replay import _recorded_decisions

    typed = cv.decision_to_msg(1, "Remind", [{"subtask": "Act", "choice": "Remind", "value": 2.5}], 0.003, 4)
    plain = cv.msg_to_decision(typed)
    old = {k: v for k, v in plain.items() if k != "belief_step"}   # what the old JSON held
    for name, type_name, data in (("new", "pearl_interfaces/msg/Decision", serialize_message(typed)),
                                  ("old", "std_msgs/msg/String", serialize_message(String(data=json.dumps(old))))):
        with BagWriter(tmp_path / name) as bag:
            bag.add_topic("/pearl/decision", type_name)
            bag.write("/pearl/decision", data, 1_000)
            bag.write("/pearl/decision", data[:6], 2_000)   # truncated: no recorded trace for that step
    assert _recorded_decisions(BagReader(tmp_path / "new")) == [plain, {}]
    assert _recorded_decisions(BagReader(tmp_path / "old")) == [old, {}]
