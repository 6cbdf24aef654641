"""The landmark detector node over DDS: a pose stream on /amcl_pose → /pearl/laser.

The stream is the generated one of ``test_navigation`` (room → physio at 10 Hz, ending on
the entry circle with ±15 cm jitter), sent as PoseWithCovarianceStamped one message at a
time; /pearl/laser must carry ``atPhysio`` exactly once. Poses in another frame or less
certain than ``max_position_stddev`` are counted and ignored. Configuration errors are one
line naming the parameter.
"""
from __future__ import annotations

import numpy as np
import pytest

from ros_helpers import Probe, wait_for

pytestmark = [pytest.mark.ros]
import rclpy

from rclpy.executors import SingleThreadedExecutor  # noqa: E402

from pearl_pomdp.nodes import conversions as cv  # noqa: E402
from pearl_pomdp.nodes.common import EVENT_QOS, NodeSetupError  # noqa: E402
from pearl_pomdp.nodes.landmark_detector import POSE_QOS, LandmarkDetectorNode  # noqa: E402
from test_navigation import PHYSIO, ROOM, crossings, drive  # noqa: E402


class Rig:
    def __init__(self, context, overrides=None):
        self.node = LandmarkDetectorNode(context=context, parameter_overrides=overrides or {})
        self.probe = Probe(rclpy.create_node("landmark_probe", context=context))
        self.laser = self.probe.listen("/pearl/laser", cv.TextMsg, EVENT_QOS)
        self.pose = self.probe.publisher("/amcl_pose", cv.LocalisedPoseMsg, POSE_QOS)
        self.executor = SingleThreadedExecutor(context=context)
        for n in (self.node, self.probe.node):
            self.executor.add_node(n)
        assert wait_for(lambda: not self.probe.unmatched([self.node]), 10.0, self.executor)

    def taken(self) -> int:
        return sum(self.node.counts.values())

    def send(self, x, y, frame="map", stddev=0.1, t=0.0):
        n = self.taken()
        self.pose.publish(cv.localised_pose_to_msg(x, y, 0.0, frame, t, stddev))
        assert wait_for(lambda: self.taken() > n, 5.0, self.executor)

    def close(self):
        self.executor.shutdown()
        self.node.destroy_node()
        self.probe.node.destroy_node()


@pytest.fixture
def rig(ros_context):
    r = Rig(ros_context[0])
    yield r
    r.close()


def test_a_jittery_arrival_at_physio_yields_atphysio_once(rig):
    points = drive(ROOM, PHYSIO, stop_short=1.0, rng=np.random.default_rng(3))
    assert crossings(points, PHYSIO, 1.0) >= 20
    for i, (x, y) in enumerate(points):
        rig.send(x, y, t=i * 0.1)
    # every pose handled and the arrival heard (under load, later than any fixed sleep), then a settle
    # in which a second, wrong arrival would be heard
    assert wait_for(lambda: rig.node.counts["poses"] == len(points) and rig.laser, 10.0, rig.executor)
    wait_for(lambda: False, 0.2, rig.executor)
    assert [m.data for m in rig.laser] == ["atPhysio"]
    assert rig.node.counts == {"poses": len(points), "ignored_frame": 0, "ignored_uncertain": 0}
    assert rig.node.arrivals() == {"atPhysio": 1}


def test_poses_in_another_frame_or_too_uncertain_are_ignored(rig):
    rig.send(30.0, 30.0)                         # the start: nowhere
    rig.send(21.0, -4.0, frame="odom")           # right place, wrong frame
    rig.send(21.0, -4.0, stddev=3.0)             # right place, localisation lost
    rig.send(21.0, -4.0, stddev=float("nan"))
    assert wait_for(lambda: sum(rig.node.counts.values()) == 4, 10.0, rig.executor)
    assert rig.laser == []
    assert rig.node.counts == {"poses": 1, "ignored_frame": 1, "ignored_uncertain": 2}
    rig.send(21.0, -4.0)
    assert wait_for(lambda: rig.laser, 5.0, rig.executor)
    assert [m.data for m in rig.laser] == ["atPhysio"]


@pytest.mark.parametrize("overrides, message", [
    ({"landmarks.physio": "atGym"},
     "parameter landmarks.physio: 'atGym' is not a symbol of the Laser input (/pearl/laser) of pearl (valid: "
     "atRoom, atPhysio, atHome, navFailed, userLost)"),
    ({"entry_radius": 2.0, "exit_radius": 1.5},
     "parameter exit_radius: must be > entry_radius (2.0 m) for hysteresis, got 1.5 m"),
    ({"landmarks.home": "", "landmarks.room": "", "landmarks.physio": ""},
     "no landmark configured: set landmarks.<place> to a Laser symbol for at least one of location_names "
     "(home, room, physio)"),
    ({"pose_topic": ""}, "parameters pose_topic and odom_topic are both empty: no pose input"),
    ({"locations.room": [1.0, 2.0]}, "parameter locations.room: expected [x, y, yaw] (finite numbers), got [1.0, 2.0]"),
])
def test_bad_configuration_is_one_clear_error(ros_context, overrides, message):
    with pytest.raises(NodeSetupError) as err:
        LandmarkDetectorNode(context=ros_context[0], parameter_overrides=overrides)
    assert str(err.value) == message
