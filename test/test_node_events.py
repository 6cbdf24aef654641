"""The Pearl nodes' QoS event handlers: the incompatible-QoS warning per publisher and
subscription, no incompatible-type handler (each waitable costs every executor spin), and a
held-back diagnostics warning still goes out within 0.1 s of wall time (one-shot flush timer).
"""
from __future__ import annotations

import time

import pytest

from ros_helpers import REPO, wait_for

pytestmark = pytest.mark.ros

import rclpy

from rclpy.event_handler import QoSPublisherEventType, QoSSubscriptionEventType  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402

from pearl_pomdp.nodes import conversions as cv  # noqa: E402
from pearl_pomdp.nodes.belief_tracker import BeliefTrackerNode  # noqa: E402
from pearl_pomdp.nodes.common import EVENT_QOS, INPUT_QOS  # noqa: E402

TYPE_EVENTS = {QoSPublisherEventType.RCL_PUBLISHER_INCOMPATIBLE_TYPE,
               QoSSubscriptionEventType.RCL_SUBSCRIPTION_INCOMPATIBLE_TYPE}
QOS_EVENTS = {QoSPublisherEventType.RCL_PUBLISHER_OFFERED_INCOMPATIBLE_QOS,
              QoSSubscriptionEventType.RCL_SUBSCRIPTION_REQUESTED_INCOMPATIBLE_QOS}


def test_tracker_keeps_the_qos_warning_and_drops_the_type_handler(ros_context):
    context, _ = ros_context
    node = BeliefTrackerNode(context=context, parameter_overrides={
        "domain": str(REPO / "config" / "pearl.domain.yaml"), "step_timeout": 0.0})
    try:
        kinds = [w.event_type for w in node.waitables]
        subscriptions = list(node.subscriptions)
        assert not TYPE_EVENTS & set(kinds)
        # One incompatible-QoS handler per subscription (4 inputs + action + drive progress: Pearl's
        # drives have deadlines) and per publisher created through rclpy's Python API (belief, step
        # settings, diagnostics, parameter events).
        assert len(subscriptions) == 4 + 1 + 1
        assert sum(k in QOS_EVENTS for k in kinds) == len(subscriptions) + 4
        assert len(kinds) == len(subscriptions) + 4
    finally:
        node.destroy_node()


def test_a_held_back_warning_goes_out_within_a_tenth_of_a_second(ros_context):
    """Two invalid inputs 10 ms apart: the first warning at once, the second (held back by
    the 0.1 s limit) from the one-shot flush timer ~0.1 s later — and then no more wake-ups."""
    context, _ = ros_context
    node = BeliefTrackerNode(context=context, parameter_overrides={
        "domain": str(REPO / "config" / "pearl.domain.yaml"), "step_timeout": 0.0,
        "diagnostics_period": 3600.0})
    probe = rclpy.create_node("events_probe", context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    executor.add_node(probe)
    got = []
    probe.create_subscription(cv.DiagnosticsMsg, "/diagnostics",
                              lambda m: got.append((time.monotonic(), cv.msg_to_diagnostics(m))), EVENT_QOS)
    pub = probe.create_publisher(cv.TextMsg, "/pearl/touchscreen", INPUT_QOS)
    try:
        assert wait_for(lambda: pub.get_subscription_count() >= 1 and probe.count_publishers("/diagnostics") >= 1,
                        10.0, executor)
        assert node._flush_timer.is_canceled()
        got.clear()
        pub.publish(cv.text_to_msg("not_a_symbol"))
        assert wait_for(lambda: len(got) >= 1, 10.0, executor)
        pub.publish(cv.text_to_msg("still_not_a_symbol"))
        assert wait_for(lambda: node.core.counters()["invalid_touchscreen"] == 2, 10.0, executor)
        assert wait_for(lambda: len(got) >= 2, 10.0, executor)
        first, second = got[0], got[1]
        values = next(iter(second[1].values()))["values"]
        assert values["invalid_touchscreen"] == "2"
        assert 0.05 <= second[0] - first[0] <= 1.0
        assert node._flush_timer.is_canceled()   # one-shot: disarmed again
        wait_for(lambda: False, 0.3, executor)
        assert len(got) == 2
    finally:
        executor.shutdown()
        probe.destroy_node()
        node.destroy_node()
