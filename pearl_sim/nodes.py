"""rclpy nodes that stand in for Pearl's hardware and residents (DESIGN.md §7).

The physics of the nursing home is one :class:`~pearl_sim.world.World` (one
resident, one robot, one scheduler); each piece of hardware is a thin node that
publishes its own modality, as a simulator's sensor plugins would:

=====================  ===========================================================
node                   publishes
=====================  ===========================================================
``sim_navigation``     ``/pearl/laser`` (landmark reached), ``/pearl/pose``
                       (geometry_msgs/PoseStamped); follows ``/pearl/nav_goal``
``sim_user``           ``/pearl/touchscreen`` (the resident's screen presses) and
                       ``/pearl/sim/said`` (what she actually said, for transcripts)
``sim_speech``         ``/pearl/speech`` (recogniser text, with word errors)
``sim_reminder``       ``/pearl/reminder`` (scheduler: ``g_physio`` …)
``sim_clock``          ``/clock`` (rosgraph_msgs/Clock): the graph runs on sim time
=====================  ===========================================================

:class:`SimulatedHardware` builds them on a context and drives one step at a time:
the robot's action (``/pearl/action``) is applied to the world, the clock is moved
to the moment the answer arrives, and the answer is published by the node of its
modality. When nothing is heard, the clock runs on until the belief tracker's own
timeout closes the step (DESIGN.md §6). Everything is seeded, so a scenario replays
identically.
"""
from __future__ import annotations

import json
import math
from typing import Callable, List, Optional

from geometry_msgs.msg import PoseStamped
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock
from std_msgs.msg import String

from pearl_sim.world import StepResult, World

RELIABLE = QoSProfile(depth=50, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE)

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


class SimClockNode(Node):
    """Publishes ``/clock``; time moves only when :meth:`advance_to` is called."""

    def __init__(self, context, start: float = 0.0):
        super().__init__("sim_clock", context=context)
        self.pub = self.create_publisher(Clock, "/clock", 10)
        self.now = start
        self.publish()

    def publish(self) -> None:
        self.pub.publish(Clock(clock=_stamp(self.now)))

    def advance_to(self, t: float) -> None:
        if t > self.now:
            self.now = t
            self.publish()


class SimNavigationNode(Node):
    """The robot base: landmarks on ``/pearl/laser``, pose on ``/pearl/pose``; logs ``/pearl/nav_goal``."""

    def __init__(self, context, world: World):
        super().__init__("sim_navigation", context=context, parameter_overrides=[])
        self.world = world
        self.laser = self.create_publisher(String, MODALITY_TOPICS["Laser"], RELIABLE)
        self.pose = self.create_publisher(PoseStamped, "/pearl/pose", 10)
        self.goals: List[str] = []
        self.create_subscription(PoseStamped, "/pearl/nav_goal", self._on_goal, RELIABLE)

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


class SimSpeechNode(Node):
    """The speech recogniser: recognised text (with the scenario's word errors) on ``/pearl/speech``."""

    def __init__(self, context):
        super().__init__("sim_speech", context=context)
        self.pub = self.create_publisher(String, MODALITY_TOPICS["Speech"], RELIABLE)


class SimReminderNode(Node):
    """The appointment scheduler: ``g_physio``/``g_vitamin``/``g_checklist`` on ``/pearl/reminder``."""

    def __init__(self, context):
        super().__init__("sim_reminder", context=context)
        self.pub = self.create_publisher(String, MODALITY_TOPICS["Reminder"], RELIABLE)


class SimulatedHardware:
    """All simulated hardware nodes on one context, stepping a :class:`World`.

    Args:
        context: an initialised rclpy context (the same as the Pearl nodes').
        world: the simulated nursing home.
        on_step: called with each :class:`~pearl_sim.world.StepResult` after its message is published.

    Attributes:
        nodes: the rclpy nodes, to add to an executor.
        actions: actions received on ``/pearl/action`` and not yet applied.
    """

    def __init__(self, context, world: World, on_step: Optional[Callable[[StepResult], None]] = None):
        self.world = world
        self.on_step = on_step
        self.clock = SimClockNode(context)
        self.navigation = SimNavigationNode(context, world)
        self.user = SimUserNode(context)
        self.speech = SimSpeechNode(context)
        self.reminder = SimReminderNode(context)
        self.truth = self.clock.create_publisher(String, "/pearl/sim/truth", RELIABLE)
        self.nodes = [self.clock, self.navigation, self.user, self.speech, self.reminder]
        self.actions: List[str] = []
        self.clock.create_subscription(String, "/pearl/action", lambda m: self.actions.append(m.data), RELIABLE)

    def apply(self, action: str) -> StepResult:
        """Apply ``action`` to the world, move the clock to its answer and publish the answer."""
        self.clock.advance_to(self.world.time)
        result = self.world.step(action)
        if result.message is not None:
            self.clock.advance_to(result.message.time)
        self.navigation.publish_pose(self.clock.now)
        self.truth.publish(String(data=json.dumps({"time": self.world.time, "action": action,
                                                    "state": self.world.truth(), "events": result.events,
                                                    "wrong": result.wrong})))
        msg = result.message
        if msg is not None:
            if msg.said:
                self.user.said.publish(String(data=msg.said))
            publisher = {"Speech": self.speech.pub, "Touchscreen": self.user.touch,
                         "Laser": self.navigation.laser, "Reminder": self.reminder.pub}[msg.modality]
            publisher.publish(String(data=msg.text))
        if self.on_step is not None:
            self.on_step(result)
        return result

    def destroy(self) -> None:
        for node in self.nodes:
            node.destroy_node()
