"""The belief tracker node on a domain's own inputs over DDS (issue 25): a battery level as
sensor_msgs/BatteryState on a remapped, best-effort topic and speech text, each belief the node
publishes equal to the core filter's on the same inputs; and the node's configure errors."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import List

import numpy as np
import pytest

from ros_helpers import Probe
from test_channels import BATTERY

pytestmark = pytest.mark.ros

import rclpy  # noqa: E402
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy  # noqa: E402
from sensor_msgs.msg import BatteryState  # noqa: E402

from pearl_pomdp.model.domain_yaml import parse_domain  # noqa: E402
from pearl_pomdp.nodes import conversions as cv  # noqa: E402
from pearl_pomdp.nodes.belief_tracker import BeliefTrackerNode  # noqa: E402
from pearl_pomdp.nodes.common import EVENT_QOS, LATCHED_QOS, NodeSetupError  # noqa: E402
from pearl_pomdp.nodes.graph import PearlGraph  # noqa: E402
from pearl_pomdp.tracking import BeliefTracker, StepSettings  # noqa: E402


@dataclass
class _Decision:
    action: int
    action_name: str
    trace: list = field(default_factory=list)


class WaitDecider:
    """Always ``Wait`` (the beliefs are what is checked)."""

    def __init__(self, model):
        self.index = model.actions.index("Wait")

    def execute(self, belief):
        return _Decision(self.index, "Wait")


def _domain(tmp_path, text=BATTERY):
    path = tmp_path / "battery.domain.yaml"
    path.write_text(text)
    return path


def test_a_battery_level_over_dds_gives_the_core_filters_beliefs(ros_context, tmp_path):
    context, _ = ros_context
    path = _domain(tmp_path)
    domain = parse_domain(BATTERY, source=str(path))
    model = domain.compile()
    remap = {"domain": str(path), "step_timeout": 0.0, "inputs.charge.topic": "/base/battery",
             "inputs.charge.qos": "best_effort"}
    with PearlGraph(context=context, domain=domain, model=model, decider=WaitDecider(model), executor=False,
                    use_sim_time=False, params_file=None, overrides={"belief_tracker": remap}) as g:
        node = g.add_node(rclpy.create_node("probe", context=context))
        probe = Probe(node)
        probe.listen("/pearl/belief", cv.BeliefMsg, LATCHED_QOS)
        probe.listen("/pearl/action", cv.ActionMsg, LATCHED_QOS)
        # A battery driver publishes best effort; the remapped input's QoS must match it.
        battery = probe.publisher("/base/battery", BatteryState,
                                  QoSProfile(depth=10, reliability=ReliabilityPolicy.BEST_EFFORT,
                                             durability=DurabilityPolicy.VOLATILE))
        speech = probe.publisher("/robot/speech", cv.RecognisedSpeechMsg, EVENT_QOS)   # a declared speech input's type
        assert g.spin_until(lambda: battery.get_subscription_count() >= 1 and speech.get_subscription_count() >= 1
                            and probe.received["/pearl/belief"], 15.0)
        assert g.tracker.get_parameter("inputs.charge.topic").value == "/base/battery"

        oracle = BeliefTracker(model, domain, StepSettings(step_timeout=0.0))
        inputs: List[tuple] = [("charge", 0.12), ("charge", 0.18), ("charge", 0.9), ("voice", "hi robot")]
        expected = [oracle.belief]
        for key, data in inputs:
            oracle.on_action("Wait", 0.0)
            closed = oracle.on_input(key, data, 0.0).closed
            if closed is None:       # 0.18 keeps battery_low: no observation, the step stays open
                oracle.abandon_step()
                continue
            expected.append(closed.belief)
        assert len(expected) == 4

        for key, data in inputs:
            assert g.spin_until(lambda: g.tracker.core.step_open, 10.0)
            before = g.tracker.core.counters()
            if key == "charge":
                battery.publish(BatteryState(percentage=float(data)))
            else:
                speech.publish(cv.speech_to_msg(data))
            assert g.spin_until(lambda: g.tracker.core.counters() != before, 10.0), f"{key} {data} not taken"
        assert g.spin_until(lambda: len(probe.received["/pearl/belief"]) >= len(expected), 10.0)
        got = [cv.msg_to_belief(m) for m in probe.received["/pearl/belief"]]
        assert len(got) == len(expected)
        for b_node, b_core in zip(got, expected):
            np.testing.assert_allclose(b_node, b_core, rtol=1e-12, atol=1e-15)
        # Step 1 by hand: P(Battery=low | battery_low) = 0.2·0.8 / (0.2·0.8 + 0.8·0.1) = 2/3.
        low = domain.states_matching({"Battery": "low"})
        assert got[1][low].sum() == pytest.approx(2 / 3, abs=1e-12)
        counters = g.tracker.core.counters()
        assert (counters["updates"], counters["unchanged_charge"], counters["invalid_charge"]) == (3, 1, 0)


def test_the_node_names_the_file_and_field_of_an_input_it_cannot_read(ros_context, tmp_path):
    context, _ = ros_context
    path = _domain(tmp_path, BATTERY.replace("type: sensor_msgs/msg/BatteryState", "type: sensor_msgs/msg/Battery"))
    with pytest.raises(NodeSetupError, match=rf"{path}: modalities.Charge.input.type: sensor_msgs/msg/Battery is "
                                             r"not an installed message type"):
        BeliefTrackerNode(context=context, parameter_overrides={"domain": str(path), "defaults_file": ""})
    path = _domain(tmp_path, BATTERY.replace("range: [0.0, 1.0]", "range: [0.0, 1.0]\n      field: voltage_mv"))
    with pytest.raises(NodeSetupError, match=r"modalities.Charge.input.field: sensor_msgs/msg/BatteryState has no "
                                             r"field 'voltage_mv'"):
        BeliefTrackerNode(context=context, parameter_overrides={"domain": str(path), "defaults_file": ""})
    path = _domain(tmp_path)
    with pytest.raises(NodeSetupError, match=r"parameter inputs.voice.topic: topic /robot/battery_state is already "
                                             r"the topic of input 'charge'"):
        BeliefTrackerNode(context=context, parameter_overrides={"domain": str(path), "defaults_file": "",
                                                                "inputs.voice.topic": "/robot/battery_state"})
    path = _domain(tmp_path, BATTERY.replace("kind: number", "kind: gauge"))
    with pytest.raises(NodeSetupError, match=rf"parameter domain: {path}:\d+: modalities.Charge.input.kind: unknown "
                                             r"kind 'gauge'"):
        BeliefTrackerNode(context=context, parameter_overrides={"domain": str(path), "defaults_file": ""})
