"""The bag recorder waits for the loop's latched messages before a run starts (over DDS).

A run started before the recorder holds b0 loses it from the bag (the reason
``Recorder.wait_until_recording`` exists); these check both of its outcomes with a real
publisher and a real bag writer.
"""
from __future__ import annotations

import pytest

from ros_helpers import wait_for

pytestmark = pytest.mark.ros

import rclpy  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from std_msgs.msg import String  # noqa: E402

from pearl_pomdp.bags.reader import open_bag  # noqa: E402
from pearl_pomdp.bags.writer import BagWriter  # noqa: E402
from pearl_pomdp.errors import PearlError  # noqa: E402
from pearl_pomdp.nodes.bag_recorder import Recorder  # noqa: E402
from pearl_pomdp.nodes.common import LATCHED_QOS  # noqa: E402


def _spin_until(executor):
    return lambda condition, timeout_sec: wait_for(condition, timeout_sec, executor)


def test_a_latched_message_published_before_the_recorder_joined_is_waited_for_and_recorded(ros_context, tmp_path):
    context, _ = ros_context
    talker = rclpy.create_node("latched_talker", context=context)
    listener = rclpy.create_node("recorder", context=context)
    executor = SingleThreadedExecutor(context=context)
    for node in (talker, listener):
        executor.add_node(node)
    try:
        talker.create_publisher(String, "/test/b0", LATCHED_QOS).publish(String(data="b0"))
        writer = BagWriter(tmp_path / "bag")
        recorder = Recorder(listener, writer, topics=["/test/b0"])
        recorder.wait_until_recording(_spin_until(executor), 15.0, topics=["/test/b0"], latched=["/test/b0"])
        assert sum(recorder.counts.values()) == 1
        writer.close()
    finally:
        executor.shutdown()
        talker.destroy_node()
        listener.destroy_node()
    messages = list(open_bag(tmp_path / "bag").read_messages(["/test/b0"]))
    assert [deserialize(m) for m in messages] == ["b0"]


def test_a_topic_nobody_publishes_is_named_when_the_wait_times_out(ros_context, tmp_path):
    context, _ = ros_context
    listener = rclpy.create_node("recorder", context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(listener)
    writer = BagWriter(tmp_path / "bag")
    try:
        recorder = Recorder(listener, writer, topics=["/pearl/belief", "/pearl/action"])
        with pytest.raises(PearlError, match=r"did not get /pearl/belief, /pearl/decision, /pearl/action within 0.3 s"):
            recorder.wait_until_recording(_spin_until(executor), 0.3)
    finally:
        writer.close()
        executor.shutdown()
        listener.destroy_node()


def deserialize(message) -> str:
    from rclpy.serialization import deserialize_message
    return deserialize_message(message.data, String).data
