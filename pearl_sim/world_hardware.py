"""A world's simulated robot hardware over DDS: one publisher per input the domain declares.

Nothing here names a topic or a message type: every input of the domain (``modalities.<M>.input``)
gets a publisher on its topic with its type, and a world message of modality ``M`` goes out on it —
text as ``std_msgs/String``, a number channel's reading in the field the tracker reads
(``BatteryState.percentage`` …). What a person actually said and the true state go to
``/WORLD/sim/said`` (``std_msgs/String``) and ``/WORLD/sim/truth`` (``pearl_interfaces/WorldTruth``,
:func:`pearl_pomdp.nodes.conversions.truth_to_msg`; ``WORLD`` the world's name, e.g.
``/reception/sim/truth``) for the bag, transcripts and ``pearl fit``. Every world of the frame's ``pearl demo``
(:mod:`pearl_sim.world_demo`) uses it, the nursing home with the robot's pose
(:class:`pearl_sim.nodes.SimulatedHardware`), and so does the separate-process simulator
``pearl_sim_world`` (:mod:`pearl_sim.nursing_home.world_node`), from its own node.
"""
from __future__ import annotations

from typing import Any, Dict, Optional, Tuple

from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import String

from pearl_pomdp.world_truth import truth_topic
from pearl_sim.messages import Message, StepResult

__all__ = ["WorldHardware", "said_topic", "truth_topic"]

RELIABLE = QoSProfile(depth=50, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE)


def said_topic(world_name: str) -> str:
    """Where what a person actually said goes (JSON-free text)."""
    return f"/{world_name}/sim/said"


def _set(msg: Any, path: str, value: float) -> None:
    *parents, last = path.split(".")
    for part in parents:
        msg = getattr(msg, part)
    setattr(msg, last, value)


class WorldHardware:
    """The sensors of a world's robot as one rclpy node (``sim_NAME``) on ``context``, or on ``node``.

    Args:
        context: an initialised rclpy context (the graph's); unused when ``node`` is given.
        world: the simulated world (a :class:`~pearl_sim.world_base.StudyWorld`) whose messages go out.
        domain: the FactoredDomain whose inputs (topics, types) the publishers follow.
        name: the world's name (the node's and the said/truth topics').
        pose_topic: where the robot's pose goes with every true state (``geometry_msgs/PoseStamped``
            in the ``map`` frame, from the scenario's ``map`` of places; the nursing home's
            ``/pearl/pose``, which the live view draws); ``None``: none.
        node: the rclpy node to publish from (a simulator that is a node itself, ``pearl_sim_world``):
            its owner spins and destroys it, so :attr:`nodes` is empty; ``None``: a node of its own.

    Raises:
        PearlError: a world message of a modality the domain declares no input for (names both).
    """

    def __init__(self, context, world, domain, name: str, pose_topic: Optional[str] = None, node: Any = None):
        import rclpy

        from pearl_pomdp.nodes.channel_messages import reader_for

        self.world = world
        self._own_node = node is None
        self.node = rclpy.create_node(f"sim_{name}", context=context) if node is None else node
        self.nodes = [self.node] if self._own_node else []
        self.publishers: Dict[str, Any] = {}
        self._readers: Dict[str, Any] = {}
        for channel in domain.inputs:
            reader = reader_for(channel, domain.source)
            self._readers[channel.modality] = reader
            self.publishers[channel.modality] = self.node.create_publisher(reader.msg_type, channel.topic, RELIABLE)
        self.said = self.node.create_publisher(String, said_topic(name), RELIABLE)
        from pearl_pomdp.nodes.conversions import WorldTruthMsg

        self.truth = self.node.create_publisher(WorldTruthMsg, truth_topic(name), RELIABLE)
        self._domain_file = domain.source
        self.pose = None
        if pose_topic:
            from geometry_msgs.msg import PoseStamped

            self._Pose = PoseStamped
            self.pose = self.node.create_publisher(PoseStamped, pose_topic, 10)

    def outgoing(self, message: Message) -> Tuple[Any, Any]:
        """``(publisher, ROS message)`` carrying ``message`` on its modality's input."""
        from pearl_pomdp.nodes.conversions import input_to_msg

        from pearl_pomdp.errors import PearlError

        reader = self._readers.get(message.modality)
        if reader is None:
            raise PearlError(f"{self._domain_file}: the world sent a {message.modality!r} message and the domain "
                             f"declares no input for it (inputs: {', '.join(sorted(self._readers)) or 'none'})")
        if reader.channel.kind == "number":
            msg = reader.msg_type()
            _set(msg, reader.field, float(message.text))
        else:
            msg = input_to_msg(reader.channel.type, message.text)
        return self.publishers[message.modality], msg

    def publish_said(self, said: str) -> None:
        """What the person actually said (for transcripts)."""
        self.said.publish(String(data=said))

    def publish_truth(self, t: float, phase: str, action: str = "", result: Optional[StepResult] = None) -> None:
        """The true state (a ``WorldTruth`` stamped ``t``, sim seconds) at the start or end of an action
        (``phase`` ``start``: the state an action starts in, which ``pearl fit`` counts transitions
        between; ``end``: after it, with its events and whether it was wrong), and the robot's pose
        when there is a pose topic."""
        from pearl_pomdp.nodes.conversions import truth_to_msg

        if self.pose is not None:
            self.publish_pose(t)
        self.truth.publish(truth_to_msg(self.world.truth_record(phase, action, result), t))

    def publish_pose(self, t: float) -> None:
        """The robot's place in the scenario's map, stamped ``t`` (sim seconds)."""
        if self.pose is None:
            return
        from pearl_pomdp.nodes.conversions import seconds_to_time

        x, y = self.world.scenario.map[self.world.robot_at]
        msg = self._Pose()
        msg.header.frame_id = "map"
        # Rounded to the nanosecond as a whole, like the truth's stamp: a time a hair below a second
        # (1.9999999999999998, as a clock summed in ticks has) is 2 s, not 1 s.
        msg.header.stamp = seconds_to_time(t)
        msg.pose.position.x, msg.pose.position.y = float(x), float(y)
        msg.pose.orientation.w = 1.0
        self.pose.publish(msg)

    def destroy(self) -> None:
        """Destroy its own node (a node it was given is its owner's)."""
        if self._own_node:
            self.node.destroy_node()
