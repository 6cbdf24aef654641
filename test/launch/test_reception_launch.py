"""launch_testing script: the reception robot with ``launch/pearl.launch.xml`` (run on a ROS 2 install).

    launch_test test/launch/test_reception_launch.py      # or: colcon test --packages-select pearl_pomdp

It includes the package's XML launch file as ``ros2 launch pearl_pomdp pearl.launch.xml
domain:=…/reception.domain.yaml hierarchy:=…/reception.hierarchy.yaml
params_file:=…/reception_nodes.yaml navigation:=false`` does (the policy is planned at start-up),
waits until the three nodes are ready, then, from a test node:

* publishes a ``sensor_msgs/BatteryState`` at 10 % on ``/battery_state`` (best effort, as battery
  drivers publish) and expects ``Dock`` on ``/pearl/action`` (the reception policy docks on a low
  battery with nobody at the desk: checked against the core in ``test/test_reception_graph.py``);
* after shutdown, checks every process exited with code 0.

launch_testing is not on PyPI, so in a pip-only venv this module is skipped at import; the same
graph is tested there by ``test/test_reception_graph.py`` with ``pearl launch``.
"""
import pytest

launch_testing = pytest.importorskip(
    "launch_testing",
    reason="launch_testing is not on PyPI: run this file with `launch_test` on a ROS 2 install "
           "(the pip-only equivalent is test/test_reception_graph.py)")
pytest.importorskip("launch_ros", reason="launch_ros is needed for $(find-pkg-share) in the launch file")

import time  # noqa: E402
import unittest  # noqa: E402

import launch  # noqa: E402
import launch_testing.actions  # noqa: E402
import launch_testing.asserts  # noqa: E402
import rclpy  # noqa: E402
from pearl_interfaces.msg import Action  # noqa: E402
from ament_index_python.packages import get_package_share_directory  # noqa: E402
from launch.actions import IncludeLaunchDescription  # noqa: E402
from launch.launch_description_sources import AnyLaunchDescriptionSource  # noqa: E402
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy  # noqa: E402
from sensor_msgs.msg import BatteryState  # noqa: E402

SHARE = get_package_share_directory("pearl_pomdp")
#: Start-up, planning included, on a slow CI machine.
READY_TIMEOUT = 120.0
#: The log line each node prints once it spins.
READY_LINES = ("tracking reception", "policy ready", "executing")
LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)
BEST_EFFORT = QoSProfile(depth=10, reliability=ReliabilityPolicy.BEST_EFFORT)


@pytest.mark.launch_test
def generate_test_description():
    reception = IncludeLaunchDescription(
        AnyLaunchDescriptionSource(f"{SHARE}/launch/pearl.launch.xml"),
        launch_arguments={"domain": f"{SHARE}/config/reception.domain.yaml",
                          "hierarchy": f"{SHARE}/config/reception.hierarchy.yaml",
                          "params_file": f"{SHARE}/config/reception_nodes.yaml",
                          "navigation": "false", "step_timeout": "0.0"}.items())  # 0: inputs only close steps
    return launch.LaunchDescription([reception, launch_testing.actions.ReadyToTest()]), {}


class TestReceptionGraph(unittest.TestCase):
    """Runs while the graph is up."""

    @classmethod
    def setUpClass(cls):
        rclpy.init()
        cls.node = rclpy.create_node("reception_launch_test")

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

    def test_2_a_low_battery_docks(self, proc_output):
        proc_output.assertWaitFor("policy ready", timeout=READY_TIMEOUT, stream="stderr")
        actions = []
        self.node.create_subscription(Action, "/pearl/action", lambda m: actions.append(m.name), LATCHED)
        battery = self.node.create_publisher(BatteryState, "/battery_state", BEST_EFFORT)
        self.assertTrue(self.spin_until(lambda: actions and battery.get_subscription_count() > 0, 30.0),
                        "no action on /pearl/action, or nobody subscribes /battery_state")
        first = len(actions)
        battery.publish(BatteryState(percentage=0.1))
        self.assertTrue(self.spin_until(lambda: len(actions) > first, 30.0), "no action after the battery reading")
        self.assertEqual(actions[-1], "Dock")


@launch_testing.post_shutdown_test()
class TestCleanShutdown(unittest.TestCase):
    """Runs after launch stopped the graph (SIGINT to every node)."""

    def test_every_process_exited_cleanly(self, proc_info):
        launch_testing.asserts.assertExitCodes(proc_info)
