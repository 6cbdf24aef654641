"""Drives through Nav2's NavigateToPose action (issue 39), against a stand-in server.

The stand-in is built in this test session from Nav2 Jazzy's ``NavigateToPose`` definition
(``test/data/nav2_stand_in/``: a ``nav2_msgs`` package with that one action) with cmake into the
session's temporary folder, and is never installed: while this module runs, ``nav2_msgs`` is
importable, so the action executor (``navigation:=auto``) drives through the action. Checked with
Pearl's own tracker and executor (their params file): an aborted goal closes the drive's step as
``navFailed`` within a second (the tracker's deadline would have said it after 40 s); a succeeded
goal closes it with the place's landmark (once: not again when the landmark detector said it
first); feedback reaches the tracker as ``/pearl/drive_progress`` and moves the drive's deadline
(later for a detour, earlier as the robot gets closer, never for standing still) and the step
closes at the moved deadline; a decision that changes the goal cancels the running one, whose end
is then not reported; ``navigation:=topic`` still publishes ``/goal_pose``.
"""
from __future__ import annotations

import ctypes
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

from ros_helpers import Probe

pytestmark = [pytest.mark.ros, pytest.mark.slow]

import rclpy  # noqa: E402

from pearl_pomdp.nodes import conversions as cv  # noqa: E402
from pearl_pomdp.nodes.common import EVENT_QOS, LATCHED_QOS  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
STAND_IN = REPO / "test" / "data" / "nav2_stand_in"
ROOM, HOME = (8.0, 3.5), (0.0, 0.0)      # Pearl's places (config/pearl_nodes.yaml)


def _build_stand_in(prefix: Path, work: Path) -> Path:
    """cmake-build the stand-in into ``prefix``; its site-packages folder."""
    env = {**os.environ, "AMENT_PREFIX_PATH": sys.prefix, "CMAKE_PREFIX_PATH": sys.prefix,
           "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}"}
    for cmd in ([shutil.which("cmake") or "cmake", "-S", str(STAND_IN), "-B", str(work), f"-DCMAKE_INSTALL_PREFIX={prefix}",
                 f"-DPython3_EXECUTABLE={sys.executable}", "-DBUILD_TESTING=OFF"],
                ["cmake", "--build", str(work), "--parallel", str(os.cpu_count() or 1)],
                ["cmake", "--install", str(work)]):
        done = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=600)
        assert done.returncode == 0, f"{' '.join(cmd[:2])}: {done.stdout[-3000:]}{done.stderr[-3000:]}"
    return next(prefix.glob("lib/python*/site-packages"))


@pytest.fixture(scope="module")
def navigate_to_pose(tmp_path_factory):
    """``nav2_msgs.action.NavigateToPose`` of the stand-in, importable for this module only."""
    prefix = tmp_path_factory.mktemp("nav2_stand_in")
    site = _build_stand_in(prefix / "install", prefix / "build")
    # The type support is dlopen'ed by file name: loaded here first, that name is found.
    libs = sorted((prefix / "install" / "lib").glob("libnav2_msgs__*.so"),
                  key=lambda p: ("generator_c" not in p.name, "typesupport_c.so" not in p.name, p.name))
    for lib in libs:
        ctypes.CDLL(str(lib), mode=ctypes.RTLD_GLOBAL)
    sys.path.insert(0, str(site))
    try:
        from nav2_msgs.action import NavigateToPose

        yield NavigateToPose
    finally:
        sys.path.remove(str(site))
        for name in [m for m in sys.modules if m == "nav2_msgs" or m.startswith("nav2_msgs.")]:
            del sys.modules[name]


class StandInServer:
    """A NavigateToPose server: per goal ``abort``, ``succeed`` (after one feedback), ``hold``
    (until cancelled) or ``("progress", distances)`` (one feedback per distance, 0.3 s apart, then
    hold), chosen by the goal's x. :attr:`feedback_at` holds when each feedback went out."""

    def __init__(self, node, action_type, plans, succeed_after=0.2):
        from rclpy.action import ActionServer, CancelResponse

        self.node, self.type, self.plans, self.succeed_after = node, action_type, plans, succeed_after
        self.goals, self.cancelled, self.aborted_at, self.feedback_at = [], [], [], []
        self.server = ActionServer(node, action_type, "/navigate_to_pose", execute_callback=self._execute,
                                   cancel_callback=lambda handle: CancelResponse.ACCEPT)

    def _sleep(self, seconds):
        from rclpy.task import Future

        future, timer = Future(), []

        def done():
            future.set_result(True)
            self.node.destroy_timer(timer[0])

        timer.append(self.node.create_timer(seconds, done))
        return future

    async def _execute(self, handle):
        pose = handle.request.pose.pose.position
        self.goals.append((pose.x, pose.y))
        plan = self.plans[round(pose.x, 3)]
        result = self.type.Result()
        if plan == "abort":
            await self._sleep(0.2)
            handle.abort()
            self.aborted_at.append(time.perf_counter())
            result.error_code, result.error_msg = 9000, "no path to the goal"
        elif plan == "succeed":
            fb = self.type.Feedback(distance_remaining=3.5)
            fb.estimated_time_remaining.sec = 7
            handle.publish_feedback(fb)
            await self._sleep(self.succeed_after)
            handle.succeed()
        else:
            for distance in (plan[1] if isinstance(plan, tuple) else ()):
                handle.publish_feedback(self.type.Feedback(distance_remaining=distance))
                self.feedback_at.append(time.perf_counter())
                await self._sleep(0.3)
            while not handle.is_cancel_requested:
                await self._sleep(0.02)
            self.cancelled.append((pose.x, pose.y))
            handle.canceled()
        return result


@pytest.fixture
def pearl_nodes(ros_context, request):
    """Pearl's tracker and executor (their params file, wall clock; the tracker's overrides from an
    indirect parameter), a probe node and one executor spinning them:
    ``(tracker, executor_node, probe_node, executor)``; all destroyed after."""
    from rclpy.executors import SingleThreadedExecutor

    from pearl_pomdp.nodes.action_executor import ActionExecutorNode
    from pearl_pomdp.nodes.belief_tracker import BeliefTrackerNode

    context, _ = ros_context
    overrides = {"step_timeout": 0.0, "use_sim_time": False, "journal": "", **getattr(request, "param", {})}
    nodes = [BeliefTrackerNode(context=context, parameter_overrides=overrides),
             ActionExecutorNode(context=context, parameter_overrides={"use_sim_time": False, "progress_period": 0.0}),
             rclpy.create_node("nav_probe", context=context)]
    ex = SingleThreadedExecutor(context=context)
    for n in nodes:
        ex.add_node(n)
    try:
        yield (*nodes, ex)
    finally:
        ex.shutdown()
        for n in nodes:
            n.destroy_node()


def _spin(executor, predicate, timeout):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if predicate():
            return True
        executor.spin_once(timeout_sec=0.02)
    return predicate()


def _ready(pearl_nodes, **listen):
    """A probe listening on ``listen`` (name → (topic, type, qos)) with a ``/pearl/action`` publisher, once
    it is matched with the tracker and the executor and the stand-in server is up: ``(action, received)``."""
    tracker, executor_node, node, ex = pearl_nodes
    probe = Probe(node)
    received = {name: probe.listen(topic, msg_type, qos) for name, (topic, msg_type, qos) in listen.items()}
    action = probe.publisher("/pearl/action", cv.ActionMsg, LATCHED_QOS)
    assert _spin(ex, lambda: not probe.unmatched([tracker, executor_node])
                 and executor_node.nav.client.server_is_ready(), 20.0)
    return action, received


def test_an_aborted_goal_closes_the_drive_as_navfailed_at_once(pearl_nodes, navigate_to_pose):
    tracker, executor_node, node, ex = pearl_nodes
    assert executor_node.nav is not None and "NavigateToPose action /navigate_to_pose" in executor_node.drive_path
    server = StandInServer(node, navigate_to_pose, {ROOM[0]: "abort", HOME[0]: "succeed"})
    action, got = _ready(pearl_nodes, beliefs=("/pearl/belief", cv.BeliefMsg, LATCHED_QOS))
    beliefs = got["beliefs"]
    assert _spin(ex, lambda: beliefs, 5.0)                  # b0
    action.publish(cv.action_to_msg("GotoPatientRoom"))
    assert _spin(ex, lambda: tracker.core.step_open and server.goals, 10.0), server.goals
    deadline = tracker.core.deadline()
    assert deadline is not None and deadline - tracker.now_s() > 30   # the drive's own deadline: 40.6 s
    assert _spin(ex, lambda: len(beliefs) >= 2, 5.0)
    closed = time.perf_counter()
    last = cv.msg_to_marginals(beliefs[-1])
    assert (last["action"], last["observation"]) == ("GotoPatientRoom", "navFailed")
    assert closed - server.aborted_at[0] < 1.0
    assert server.goals == [ROOM] and executor_node.nav.counts["failed"] == 1
    # A drive that arrives: its feedback kept, its step closed with home's landmark.
    action.publish(cv.action_to_msg("GoHome"))
    assert _spin(ex, lambda: len(beliefs) >= 3, 10.0), executor_node.nav.counts
    last = cv.msg_to_marginals(beliefs[-1])
    assert (last["action"], last["observation"]) == ("GoHome", "atHome")
    assert executor_node.nav.counts["succeeded"] == 1
    assert executor_node.nav.feedback == {"distance_remaining": 3.5, "estimated_time_remaining": 7.0}


def test_an_arrival_the_landmark_detector_said_first_is_not_said_again(pearl_nodes, navigate_to_pose):
    tracker, executor_node, node, ex = pearl_nodes
    server = StandInServer(node, navigate_to_pose, {ROOM[0]: "succeed"}, succeed_after=1.0)
    laser = Probe(node).publisher("/pearl/laser", cv.TextMsg, EVENT_QOS)
    action, got = _ready(pearl_nodes, laser=("/pearl/laser", cv.TextMsg, EVENT_QOS))
    laser_in = got["laser"]
    assert _spin(ex, lambda: laser.get_subscription_count() >= 3, 10.0)   # tracker, executor, laser_in
    action.publish(cv.action_to_msg("GotoPatientRoom"))
    assert _spin(ex, lambda: server.goals == [ROOM], 10.0)
    laser.publish(cv.text_to_msg("atRoom"))                 # the landmark detector, before Nav2's tolerance
    assert _spin(ex, lambda: executor_node.nav.counts["succeeded"] == 1, 10.0), executor_node.nav.counts
    assert not _spin(ex, lambda: len(laser_in) > 1, 0.5)
    assert [m.data for m in laser_in] == ["atRoom"] and tracker.core.step == 1


@pytest.mark.parametrize("pearl_nodes", [{"drive_margin": 1.0}], indirect=True)
def test_feedback_moves_the_drive_deadline_and_the_step_closes_at_the_moved_one(pearl_nodes, navigate_to_pose):
    """Feedback of 20 m (a detour), 8 m, 9 m (backing off), 0.3 m, with a 1 s drive margin (so the last
    deadline comes soon): later, earlier, unchanged, and the step closes ~1.75 s after the last."""
    tracker, executor_node, node, ex = pearl_nodes
    server = StandInServer(node, navigate_to_pose, {ROOM[0]: ("progress", (20.0, 8.0, 9.0, 0.3))})
    action, got = _ready(pearl_nodes, beliefs=("/pearl/belief", cv.BeliefMsg, LATCHED_QOS),
                         progress=("/pearl/drive_progress", cv.DriveProgressMsg, EVENT_QOS))
    beliefs, progress = got["beliefs"], got["progress"]
    assert _spin(ex, lambda: beliefs, 5.0)                  # b0
    action.publish(cv.action_to_msg("GotoPatientRoom"))
    assert _spin(ex, lambda: tracker.core.step_open and server.goals, 10.0)
    core = tracker.core
    first = core.deadline()
    assert first - core.opened_at == pytest.approx(1.0 + 2.1 * 8.7321 / 0.6, abs=1e-3)     # 31.56 s
    deadlines, left = [], []
    for n in range(1, 4):
        assert _spin(ex, lambda: core.counters()["drive_progress"] >= n, 5.0), core.counters()
        deadlines.append(core.deadline())
        left.append(core.deadline() - tracker.now_s())
    assert left[0] == pytest.approx(1.0 + 1.5 * 20.0 / 0.6, abs=0.3) and deadlines[0] > first + 15   # 51 s: later
    assert left[1] == pytest.approx(1.0 + 1.5 * 8.0 / 0.6, abs=0.3) and deadlines[1] < deadlines[0]  # 21 s: earlier
    assert deadlines[2] == deadlines[1]                                     # 9 m: backing off, not moved
    assert _spin(ex, lambda: len(progress) >= 3, 5.0)
    assert [round(m.distance_remaining, 3) for m in progress][:3] == [20.0, 8.0, 9.0]
    assert {m.action for m in progress} == {"GotoPatientRoom"} and {m.place for m in progress} == {"room"}
    # 0.3 m left: 1 + 0.75 s; the step closes with navFailed then, not 31.6 s after the drive began.
    assert _spin(ex, lambda: len(beliefs) >= 2, 5.0)
    closed = time.perf_counter()
    last = cv.msg_to_marginals(beliefs[-1])
    assert (last["action"], last["observation"]) == ("GotoPatientRoom", "navFailed")
    assert closed - server.feedback_at[3] == pytest.approx(1.75, abs=0.4)
    assert core.counters()["deadline_moves"] == 3
    action.publish(cv.action_to_msg("TellTime"))            # the goal is no longer wanted: cancelled
    assert _spin(ex, lambda: server.cancelled == [ROOM], 10.0)


def test_a_decision_that_changes_the_goal_cancels_the_running_one(pearl_nodes, navigate_to_pose):
    tracker, executor_node, node, ex = pearl_nodes
    server = StandInServer(node, navigate_to_pose, {ROOM[0]: "hold", HOME[0]: "hold"})
    action, got = _ready(pearl_nodes, laser=("/pearl/laser", cv.TextMsg, EVENT_QOS))
    laser = got["laser"]
    action.publish(cv.action_to_msg("GotoPatientRoom"))
    assert _spin(ex, lambda: server.goals == [ROOM], 10.0)
    action.publish(cv.action_to_msg("GotoPatientRoom"))      # the same drive again: the goal goes on
    assert not _spin(ex, lambda: len(server.goals) > 1 or server.cancelled, 0.5)
    action.publish(cv.action_to_msg("GoHome"))              # another place: the room's goal is cancelled
    assert _spin(ex, lambda: server.cancelled == [ROOM] and server.goals == [ROOM, HOME], 10.0), \
        (server.goals, server.cancelled)
    action.publish(cv.action_to_msg("TellTime"))            # no drive: home's goal is cancelled too
    assert _spin(ex, lambda: server.cancelled == [ROOM, HOME], 10.0), server.cancelled
    assert not _spin(ex, lambda: laser, 0.5)                # our own cancels are not failures
    assert executor_node.nav.counts == {"sent": 2, "succeeded": 0, "failed": 0, "cancelled": 2, "feedback": 0}
    assert tracker.core.step == 0                           # nothing closed a step


def test_navigation_topic_publishes_goal_pose_even_with_nav2_msgs(ros_context, navigate_to_pose):
    from pearl_pomdp.nodes.action_executor import ActionExecutorNode
    from pearl_pomdp.nodes.common import NodeSetupError

    context, _ = ros_context
    node = ActionExecutorNode(context=context, parameter_overrides={"navigation": "topic"})
    try:
        assert node.nav is None and node.goal_pub is not None and node.drive_path == "goals on /goal_pose"
    finally:
        node.destroy_node()
    with pytest.raises(NodeSetupError, match=r"parameter navigation: 'sometimes' is not one of auto, action, topic"):
        ActionExecutorNode(context=context, parameter_overrides={"navigation": "sometimes"})
