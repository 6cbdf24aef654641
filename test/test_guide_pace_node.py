"""The guide_pace node over DDS: pass-through, pace filtering during a guidance, "resident lost".

A probe publishes the navigation's command (/cmd_vel_nav, 20 Hz), the resident's position
(PointStamped in base_link) and the manager's actions, and records /cmd_vel and /pearl/laser.
"""
from __future__ import annotations

import time

import pytest

from ros_helpers import Probe, wait_for

pytestmark = [pytest.mark.ros]
import rclpy

from rclpy.executors import SingleThreadedExecutor  # noqa: E402

from pearl_pomdp.nodes import conversions as cv  # noqa: E402
from pearl_pomdp.nodes.common import EVENT_QOS, LATCHED_QOS, NodeSetupError  # noqa: E402
from pearl_pomdp.nodes.guide_pace import CMD_QOS, GuidePaceNode  # noqa: E402
from pearl_pomdp.nodes.landmark_detector import POSE_QOS  # noqa: E402


class Rig:
    def __init__(self, context, overrides=None):
        self.node = GuidePaceNode(context=context, parameter_overrides=overrides or {})
        self.probe = Probe(rclpy.create_node("guide_probe", context=context))
        self.out = self.probe.listen("/cmd_vel", cv.TwistMsg, CMD_QOS)
        self.laser = self.probe.listen("/pearl/laser", cv.TextMsg, EVENT_QOS)
        self.state = self.probe.listen("/pearl/guide_pace", cv.GuidePaceMsg, EVENT_QOS)
        self.nav = self.probe.publisher("/cmd_vel_nav", cv.TwistMsg, CMD_QOS)
        self.person = self.probe.publisher("/pearl/resident_position", cv.PointMsg, POSE_QOS)
        self.action = self.probe.publisher("/pearl/action", cv.ActionMsg, LATCHED_QOS)
        self.executor = SingleThreadedExecutor(context=context)
        for n in (self.node, self.probe.node):
            self.executor.add_node(n)
        assert wait_for(lambda: not self.probe.unmatched([self.node]), 10.0, self.executor)

    def drive(self, seconds, behind=None, vx=0.6, wz=0.3, frame="base_link"):
        """Publish nav commands (and her position ``behind`` m behind) at 20 Hz for ``seconds``."""
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            self.nav.publish(cv.twist_to_msg(vx, wz))
            if behind is not None:
                self.person.publish(cv.point_to_msg(-behind, 0.0, frame, 0.0))
            wait_for(lambda: False, 0.05, self.executor)

    def act(self, name):
        self.action.publish(cv.action_to_msg(name))
        assert wait_for(lambda: self.node.active == (name if name in self.node.params["guide_actions"] else None),
                        5.0, self.executor)

    def close(self):
        self.executor.shutdown()
        self.node.destroy_node()
        self.probe.node.destroy_node()


@pytest.fixture
def rig(ros_context):
    r = Rig(ros_context[0], {"lost_timeout": 1.0})
    yield r
    r.close()


def test_commands_pass_through_unchanged_outside_a_guidance(rig):
    rig.drive(0.5)
    assert len(rig.out) >= 5
    assert all(cv.msg_to_twist(m) == {"linear_x": 0.6, "linear_y": 0.0, "angular_z": 0.3} for m in rig.out)
    assert rig.node.counts["passed_through"] == len(rig.out)


def test_during_a_guidance_the_robot_waits_for_her_and_reports_her_lost_once(rig):
    rig.act("GuideToPhysio")
    # She is right behind: the robot accelerates to the navigation's speed, turning on the same path.
    rig.drive(6.0, behind=0.5)  # her pace estimate settles in ~4 s (time constant 3 s)
    last = cv.msg_to_twist(rig.out[-1])
    assert last["linear_x"] == pytest.approx(0.6, abs=0.01)
    assert last["angular_z"] / last["linear_x"] == pytest.approx(0.5)  # same curvature as the navigation's
    first = cv.msg_to_twist(rig.out[0])
    assert first["linear_x"] < 0.6  # starts gently: her pace is unknown at first
    assert first["angular_z"] / first["linear_x"] == pytest.approx(0.5)
    # She falls 4 m behind: stop (zero twist, turning too) and, after lost_timeout (1 s), lost — once.
    n = len(rig.out)
    rig.drive(2.0, behind=4.0)
    stopped = [cv.msg_to_twist(m) for m in rig.out[n + 2:]]
    assert stopped and all(t == {"linear_x": 0.0, "linear_y": 0.0, "angular_z": 0.0} for t in stopped)
    assert [m.data for m in rig.laser] == ["userLost"]
    assert rig.node.counts["lost"] == 1
    states = [cv.msg_to_guide_pace(m) for m in rig.state]
    assert states[-1]["state"] == "lost" and states[-1]["active"] == "GuideToPhysio"
    assert states[-1]["behind"] == pytest.approx(4.0) and states[-1]["times_lost"] == 1
    # She catches up: the robot drives on; then the guidance ends and commands pass through again.
    rig.drive(1.0, behind=0.8)
    assert cv.msg_to_twist(rig.out[-1])["linear_x"] > 0.0
    rig.act("TerminateGuidance")
    n = len(rig.out)
    rig.drive(0.3)
    assert cv.msg_to_twist(rig.out[-1]) == {"linear_x": 0.6, "linear_y": 0.0, "angular_z": 0.3}
    assert [m.data for m in rig.laser] == ["userLost"]


def test_a_resident_position_in_another_frame_is_not_seen(rig):
    rig.act("GuideToPhysio")
    rig.drive(1.5, behind=0.5, frame="map")
    assert rig.node.counts["ignored_frame"] > 0
    assert rig.node.pace.state in ("waiting", "lost")
    assert cv.msg_to_twist(rig.out[-1])["linear_x"] == 0.0


@pytest.mark.parametrize("overrides, message", [
    ({"resume_gap": 0.9}, "parameter resume_gap must be > follow_gap (1.0 m), got 0.9"),
    ({"stop_gap": 1.2}, "parameter stop_gap must be > resume_gap (1.5 m), got 1.2"),
])
def test_bad_gaps_are_one_clear_error(ros_context, overrides, message):
    with pytest.raises(NodeSetupError) as err:
        GuidePaceNode(context=ros_context[0], parameter_overrides=overrides)
    assert str(err.value) == message
