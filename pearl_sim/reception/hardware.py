"""The reception robot's simulated hardware over DDS: one publisher per input the domain declares.

Nothing here names a topic or a message type: every input of the domain (``modalities.<M>.input``)
gets a publisher on its topic with its type, and a world message of modality ``M`` goes out on it —
text as ``std_msgs/String``, a number channel's reading in the field the tracker reads
(``BatteryState.percentage`` …). What a visitor actually said and the true state go to
``/reception/sim/said`` and ``/reception/sim/truth`` (JSON) for the bag and transcripts.
"""
from __future__ import annotations

import json
from typing import Any, Dict, Optional, Tuple

from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import String

from pearl_sim.messages import Message, StepResult

__all__ = ["ReceptionHardware", "SAID_TOPIC", "TRUTH_TOPIC"]

SAID_TOPIC = "/reception/sim/said"
TRUTH_TOPIC = "/reception/sim/truth"
RELIABLE = QoSProfile(depth=50, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE)


def _set(msg: Any, path: str, value: float) -> None:
    *parents, last = path.split(".")
    for part in parents:
        msg = getattr(msg, part)
    setattr(msg, last, value)


class ReceptionHardware:
    """The sensors of the reception robot as one rclpy node (``sim_reception``) on ``context``.

    Args:
        context: an initialised rclpy context (the graph's).
        world: the :class:`~pearl_sim.reception.world.ReceptionWorld` whose messages go out.
        domain: the FactoredDomain whose inputs (topics, types) the publishers follow.
    """

    def __init__(self, context, world, domain):
        import rclpy

        from pearl_pomdp.nodes.channel_messages import reader_for

        self.world = world
        self.node = rclpy.create_node("sim_reception", context=context)
        self.nodes = [self.node]
        self.publishers: Dict[str, Any] = {}
        self._readers: Dict[str, Any] = {}
        for channel in domain.inputs:
            reader = reader_for(channel, domain.source)
            self._readers[channel.modality] = reader
            self.publishers[channel.modality] = self.node.create_publisher(reader.msg_type, channel.topic, RELIABLE)
        self.said = self.node.create_publisher(String, SAID_TOPIC, RELIABLE)
        self.truth = self.node.create_publisher(String, TRUTH_TOPIC, RELIABLE)

    def outgoing(self, message: Message) -> Tuple[Any, Any]:
        """``(publisher, ROS message)`` carrying ``message`` on its modality's input."""
        from pearl_pomdp.nodes.conversions import input_to_msg

        reader = self._readers[message.modality]
        if reader.channel.kind == "number":
            msg = reader.msg_type()
            _set(msg, reader.field, float(message.text))
        else:
            msg = input_to_msg(reader.channel.type, message.text)
        return self.publishers[message.modality], msg

    def publish_said(self, said: str) -> None:
        """What the visitor actually said (for transcripts)."""
        self.said.publish(String(data=said))

    def publish_truth(self, t: float, phase: str, action: str = "", result: Optional[StepResult] = None) -> None:
        """The true state (JSON) at the start or end of an action."""
        self.truth.publish(String(data=json.dumps(self.world.truth_record(phase, action, result))))

    def destroy(self) -> None:
        self.node.destroy_node()
