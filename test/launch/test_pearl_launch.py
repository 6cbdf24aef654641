"""launch_testing script for ``launch/pearl.launch.xml`` (run on a ROS 2 install).

    launch_test test/launch/test_pearl_launch.py          # or: colcon test --packages-select pearl_pomdp

It includes the package's XML launch file exactly as ``ros2 launch pearl_pomdp
pearl.launch.xml`` does (the policy is planned at start-up), waits until every node has
logged that it is ready, then, from a test node:

* publishes an utterance on ``/pearl/speech`` and expects a new action on ``/pearl/action``
  (a primitive action of ``config/pearl.domain.yaml``);
* drives a localised pose into the physiotherapy entrance on ``/amcl_pose`` and expects
  ``atPhysio`` on ``/pearl/laser`` once;
* after shutdown, checks every process exited with code 0 (a clean SIGINT stop).

launch_testing, launch and launch_ros are not on PyPI, so where they cannot be imported
(a pip-only venv) this module is skipped at import with that reason; the same graph is
tested there by ``test/test_nodes_multiprocess.py`` and ``test/test_shutdown.py`` with
``pearl launch``.
"""
import pytest

launch_testing = pytest.importorskip(
    "launch_testing",
    reason="launch_testing is not on PyPI: run this file with `launch_test` on a ROS 2 install "
           "(the pip-only equivalent is test/test_nodes_multiprocess.py)")
pytest.importorskip("launch_ros", reason="launch_ros is needed for $(find-pkg-share) in the launch file")

import time  # noqa: E402
import unittest  # noqa: E402

import launch  # noqa: E402
import launch_testing.actions  # noqa: E402
import launch_testing.asserts  # noqa: E402
import rclpy  # noqa: E402
from pearl_interfaces.msg import Action  # noqa: E402
import yaml  # noqa: E402
from ament_index_python.packages import get_package_share_directory  # noqa: E402
from geometry_msgs.msg import PoseWithCovarianceStamped  # noqa: E402
from pearl_interfaces.msg import RecognisedSpeech  # noqa: E402
from launch.actions import IncludeLaunchDescription  # noqa: E402
from launch.launch_description_sources import AnyLaunchDescriptionSource  # noqa: E402
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy  # noqa: E402
from std_msgs.msg import String  # noqa: E402

SHARE = get_package_share_directory("pearl_pomdp")
#: Start-up, planning included, on a slow CI machine.
READY_TIMEOUT = 120.0
#: The log line each node prints once it spins.
READY_LINES = ("tracking pearl", "policy ready", "executing", "landmarks", "guide pace for")
LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)
RELIABLE = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)


@pytest.mark.launch_test
def generate_test_description():
    pearl = IncludeLaunchDescription(
        AnyLaunchDescriptionSource(f"{SHARE}/launch/pearl.launch.xml"),
        launch_arguments={"step_timeout": "0.0"}.items())  # 0: no silence timeout, answers only
    return launch.LaunchDescription([pearl, launch_testing.actions.ReadyToTest()]), {}


def _domain_actions():
    with open(f"{SHARE}/config/pearl.domain.yaml", encoding="utf-8") as f:
        return set(yaml.safe_load(f)["actions"])


class TestPearlGraph(unittest.TestCase):
    """Runs while the graph is up."""

    @classmethod
    def setUpClass(cls):
        rclpy.init()
        cls.node = rclpy.create_node("pearl_launch_test")

    @classmethod
    def tearDownClass(cls):
        cls.node.destroy_node()
        rclpy.shutdown()

    def spin_until(self, predicate, timeout):
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if predicate():
                return True
            rclpy.spin_once(self.node, timeout_sec=0.05)
        return predicate()

    def test_1_every_node_is_ready(self, proc_output):
        for line in READY_LINES:
            proc_output.assertWaitFor(line, timeout=READY_TIMEOUT, stream="stderr")

    def test_2_an_utterance_gets_an_action(self, proc_output):
        proc_output.assertWaitFor("policy ready", timeout=READY_TIMEOUT, stream="stderr")
        actions = []
        self.node.create_subscription(Action, "/pearl/action", lambda m: actions.append(m.name), LATCHED)
        speech = self.node.create_publisher(RecognisedSpeech, "/pearl/speech", RELIABLE)   # the domain's type
        # The policy's answer to b0 (latched) opens the first step; the tracker must hear us.
        self.assertTrue(self.spin_until(lambda: actions and speech.get_subscription_count() > 0, 30.0),
                        "no action on /pearl/action, or nobody subscribes /pearl/speech")
        first = len(actions)
        speech.publish(RecognisedSpeech(text="what time is it", confidence=1.0))
        self.assertTrue(self.spin_until(lambda: len(actions) > first, 30.0), "no action after the utterance")
        self.assertIn(actions[-1], _domain_actions())

    def test_3_arriving_at_physio_is_reported_once(self, proc_output):
        proc_output.assertWaitFor("landmarks", timeout=READY_TIMEOUT, stream="stderr")
        laser = []
        self.node.create_subscription(String, "/pearl/laser", lambda m: laser.append(m.data), RELIABLE)
        pose = self.node.create_publisher(PoseWithCovarianceStamped, "/amcl_pose", RELIABLE)
        self.assertTrue(self.spin_until(lambda: pose.get_subscription_count() > 0, 30.0))
        for x, y in [(30.0, 30.0)] + [(15.0 + 0.5 * i, -4.0) for i in range(13)] + [(20.1, -4.0), (21.0, -4.0)] * 5:
            msg = PoseWithCovarianceStamped()
            msg.header.frame_id = "map"
            msg.pose.pose.position.x, msg.pose.pose.position.y = x, y
            msg.pose.pose.orientation.w = 1.0
            msg.pose.covariance[0] = msg.pose.covariance[7] = 0.01
            pose.publish(msg)
            self.spin_until(lambda: False, 0.05)
        self.assertTrue(self.spin_until(lambda: laser, 10.0), "no landmark on /pearl/laser")
        self.spin_until(lambda: False, 1.0)
        self.assertEqual(laser, ["atPhysio"])


@launch_testing.post_shutdown_test()
class TestCleanShutdown(unittest.TestCase):
    """Runs after launch stopped the graph (SIGINT to every node)."""

    def test_every_process_exited_cleanly(self, proc_info):
        launch_testing.asserts.assertExitCodes(proc_info)
