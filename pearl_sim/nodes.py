"""rclpy nodes that stand in for Pearl's hardware and residents (docs/design.md §7).

The physics of the nursing home is one :class:`~pearl_sim.nursing_home.world.World` (one
resident, one robot, one scheduler); each piece of hardware is a thin node that
publishes its own modality, as a simulator's sensor plugins would:

=====================  ===========================================================
node                   publishes
=====================  ===========================================================
``sim_navigation``     ``/pearl/laser`` (landmark reached), ``/pearl/pose``
                       (geometry_msgs/PoseStamped); follows ``/goal_pose`` (Nav2's topic)
``sim_user``           ``/pearl/touchscreen`` (the resident's screen presses) and
                       ``/pearl/sim/said`` (what she actually said, for transcripts)
``sim_speech``         ``/pearl/speech`` (recogniser text, with word errors, as the domain's
                       speech input declares it: pearl_interfaces/RecognisedSpeech)
``sim_reminder``       ``/pearl/reminder`` (scheduler: ``g_physio`` …)
=====================  ===========================================================

:class:`SimulatedHardware` builds them on a context; :class:`GraphBackend` makes the
real Pearl graph the robot of the episode loop (:func:`pearl_sim.loop.run_episode`): each
message the world produces is published by the node of its modality at its time, with
``/clock`` moved there first by the graph's
:class:`~pearl_pomdp.nodes.sim_clock.SimClockDriver`; when nothing is heard the clock
moves to the tracker's own deadline and its timer closes the step (docs/design.md §6).
Everything is seeded, so a scenario replays identically.
"""
from __future__ import annotations

import json
import math
from typing import TYPE_CHECKING, List, Optional

from geometry_msgs.msg import PoseStamped
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import String

from pearl_sim.messages import StepResult

if TYPE_CHECKING:   # the nursing home's world; GraphBackend serves any world's hardware
    from pearl_sim.nursing_home.world import World

RELIABLE = QoSProfile(depth=50, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE)

#: The message type of ``/pearl/speech`` when no domain is given: what Pearl's domains declare.
SPEECH_TYPE = "pearl_interfaces/msg/RecognisedSpeech"

MODALITY_TOPICS = {
    "Speech": "/pearl/speech",
    "Touchscreen": "/pearl/touchscreen",
    "Laser": "/pearl/laser",
    "Reminder": "/pearl/reminder",
}


def _stamp(seconds: float):
    from builtin_interfaces.msg import Time

    sec = int(math.floor(seconds))
    return Time(sec=sec, nanosec=int(round((seconds - sec) * 1e9)) % 1_000_000_000)


class SimNavigationNode(Node):
    """The robot base: landmarks on ``/pearl/laser``, pose on ``/pearl/pose``; logs ``/goal_pose``."""

    def __init__(self, context, world: World):
        super().__init__("sim_navigation", context=context, parameter_overrides=[])
        self.world = world
        self.laser = self.create_publisher(String, MODALITY_TOPICS["Laser"], RELIABLE)
        self.pose = self.create_publisher(PoseStamped, "/pearl/pose", 10)
        self.goals: List[str] = []
        self.create_subscription(PoseStamped, "/goal_pose", self._on_goal, RELIABLE)

    def _on_goal(self, msg: PoseStamped) -> None:
        self.goals.append(f"({msg.pose.position.x:.1f}, {msg.pose.position.y:.1f})")

    def publish_pose(self, t: float) -> None:
        x, y = self.world.scenario.map[self.world.robot_at]
        msg = PoseStamped()
        msg.header.frame_id = "map"
        msg.header.stamp = _stamp(t)
        msg.pose.position.x, msg.pose.position.y = float(x), float(y)
        msg.pose.orientation.w = 1.0
        self.pose.publish(msg)


class SimUserNode(Node):
    """The resident: touchscreen presses, and what she said (ground truth for transcripts)."""

    def __init__(self, context):
        super().__init__("sim_user", context=context)
        self.touch = self.create_publisher(String, MODALITY_TOPICS["Touchscreen"], RELIABLE)
        self.said = self.create_publisher(String, "/pearl/sim/said", RELIABLE)


def speech_type(domain=None) -> str:
    """The message type of ``domain``'s speech input on ``/pearl/speech`` (a bag's copy of an older
    domain: ``std_msgs/msg/String``), or :data:`SPEECH_TYPE` without a domain."""
    for channel in getattr(domain, "inputs", ()):
        if channel.kind == "speech" and channel.topic == MODALITY_TOPICS["Speech"]:
            return channel.type
    return SPEECH_TYPE


class SimSpeechNode(Node):
    """The speech recogniser: recognised text (with the scenario's word errors) on ``/pearl/speech``,
    as ``type_name`` (a :func:`speech_type`)."""

    def __init__(self, context, type_name: str = SPEECH_TYPE):
        from pearl_pomdp.nodes.bag_recorder import message_class

        super().__init__("sim_speech", context=context)
        self.type_name = type_name
        self.pub = self.create_publisher(message_class(type_name), MODALITY_TOPICS["Speech"], RELIABLE)


class SimReminderNode(Node):
    """The appointment scheduler: ``g_physio``/``g_vitamin``/``g_checklist`` on ``/pearl/reminder``."""

    def __init__(self, context):
        super().__init__("sim_reminder", context=context)
        self.pub = self.create_publisher(String, MODALITY_TOPICS["Reminder"], RELIABLE)


class SimulatedHardware:
    """All simulated hardware nodes on one context, publishing what a :class:`World` produces.

    Args:
        context: an initialised rclpy context (the same as the Pearl nodes').
        world: the simulated nursing home.
        domain: the domain the graph runs, whose speech input's message type ``/pearl/speech``
            follows (default: :data:`SPEECH_TYPE`, Pearl's).

    Attributes:
        nodes: the rclpy nodes, to add to an executor. ``/clock`` is published by the
            graph's :class:`~pearl_pomdp.nodes.sim_clock.SimClockDriver`, not here.
    """

    def __init__(self, context, world: World, domain=None):
        self.world = world
        self.navigation = SimNavigationNode(context, world)
        self.user = SimUserNode(context)
        self.speech = SimSpeechNode(context, speech_type(domain))
        self.reminder = SimReminderNode(context)
        self.truth = self.navigation.create_publisher(String, "/pearl/sim/truth", RELIABLE)
        self.nodes = [self.navigation, self.user, self.speech, self.reminder]
        self.publishers = {"Speech": self.speech.pub, "Touchscreen": self.user.touch,
                           "Laser": self.navigation.laser, "Reminder": self.reminder.pub}

    def outgoing(self, message) -> tuple:
        """``(publisher, message)`` that carries a world message: its modality's node, as text (speech
        as its input's type: the world's JSON text with confidence becomes a typed RecognisedSpeech)."""
        from pearl_pomdp.nodes.conversions import input_to_msg

        if message.modality == "Speech":
            return self.speech.pub, input_to_msg(self.speech.type_name, message.text)
        return self.publishers[message.modality], String(data=message.text)

    def publish_said(self, said: str) -> None:
        """What the resident actually said, for transcripts (``/pearl/sim/said``)."""
        self.user.said.publish(String(data=said))

    def publish_truth(self, t: float, phase: str, action: str = "", result: Optional[StepResult] = None) -> None:
        """The true state on ``/pearl/sim/truth`` (JSON), and the robot's pose.

        ``phase`` ``"start"``: the state an action starts in (``pearl fit`` counts transitions
        between consecutive starts; one more follows the last action); ``"end"``: after the
        action, with its events and whether it was wrong.
        """
        self.navigation.publish_pose(t)
        self.truth.publish(String(data=json.dumps(self.world.truth_record(phase, action, result))))

    def destroy(self) -> None:
        for node in self.nodes:
            node.destroy_node()


class GraphBackend:
    """The real Pearl nodes as the robot of :func:`pearl_sim.loop.run_episode` (over DDS, under /clock).

    ``hardware`` is any simulated hardware with ``publishers`` (to wait for), ``outgoing(message)``
    → ``(publisher, ROS message)`` and ``publish_said(text)``: :class:`SimulatedHardware` (the
    nursing home), :class:`pearl_sim.world_hardware.WorldHardware` (every world of the frame).
    Each world message is published by the simulated node of its modality at its time
    (the :class:`~pearl_pomdp.nodes.sim_clock.SimClockDriver` moves ``/clock`` there first
    and waits for the graph's answer); a deadline is reached by moving ``/clock`` to it, so
    the tracker node's own timer closes the step.

    Raises:
        PearlError: the graph did not answer within the driver's wait (names the phase).
    """

    def __init__(self, graph, hardware, driver):
        self.graph, self.hardware, self.driver = graph, hardware, driver
        self.now_ns = 0

    def start(self) -> List[str]:
        from pearl_pomdp.errors import PearlError

        if not self.driver.wait_until_matched(list(self.hardware.publishers.values())):
            raise PearlError("the Pearl graph gave no first action (is the policy node running?)")
        return list(self.driver.actions)

    def _advance(self, t_ns: int) -> None:
        from pearl_pomdp.errors import PearlError

        if t_ns > self.now_ns:
            if not self.driver.set_time(t_ns):
                raise PearlError(f"the Pearl graph did not settle at sim time {t_ns * 1e-9:.3f} s")
            self.now_ns = t_ns

    def deliver(self, message) -> List[str]:
        from pearl_pomdp.errors import PearlError
        from pearl_sim.loop import clock_ns

        self._advance(clock_ns(message.time))
        before = len(self.driver.actions)
        if message.said:
            self.hardware.publish_said(message.said)
        publisher, msg = self.hardware.outgoing(message)
        if not self.driver.feed(publisher, msg):
            raise PearlError(f"the Pearl graph did not take {message.modality} {message.text!r} "
                             f"at {message.time:.3f} s")
        return self.driver.actions[before:]

    def tick(self, t_ns: int) -> List[str]:
        before = len(self.driver.actions)
        self._advance(t_ns)
        return self.driver.actions[before:]

    def deadline(self):
        return self.graph.tracker.core.deadline()
