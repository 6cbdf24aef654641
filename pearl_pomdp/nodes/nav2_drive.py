"""Drives through Nav2's ``NavigateToPose`` action (the action executor's navigation, when installed).

Nav2's users drive a robot with the ``nav2_msgs/action/NavigateToPose`` action: a goal, feedback
(distance remaining, estimated time), a result, and cancel. Where ``nav2_msgs`` is installed, the
action executor (:mod:`pearl_pomdp.nodes.action_executor`, ``navigation:=auto`` or ``action``)
hands each drive to a :class:`Nav2Drive`:

* a drive action sends its place's pose as a goal; the same place while that goal runs keeps it;
* a new decision that no longer wants it (another place, or an action that does not drive)
  cancels the running goal — that goal's end is not reported;
* an aborted goal, one cancelled by someone else, one the server rejects, or a drive with no
  server to take it closes the drive at once: the executor publishes ``nav_failed_observation`` on
  ``drive_result_topic`` (Pearl: ``navFailed`` on ``/pearl/laser``, what the tracker's deadline
  would have said only at the deadline);
* a succeeded goal closes the drive with its place's arrival landmark (``landmarks.<place>``,
  Pearl: ``atRoom`` on ``/pearl/laser``) — unless that landmark was heard on ``drive_result_topic``
  since the goal was sent (a landmark detector beside Nav2 reports it first: its entry radius is
  wider than Nav2's goal tolerance), so one arrival closes one step;
* feedback (distance remaining, estimated time remaining) is kept, counted on /diagnostics, and
  passed on (at most one every ``progress_period`` seconds per goal, the first at once) as a
  ``pearl_interfaces/DriveProgress`` on ``drive_progress_topic``: the belief tracker moves the
  drive's deadline by it.

Without ``nav2_msgs`` (``navigation:=auto``) or with ``navigation:=topic`` the executor publishes the
goal on ``/goal_pose`` as before.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any, Callable, Dict, Optional

__all__ = ["NAVIGATION_MODES", "navigate_to_pose_type", "Nav2Drive"]

#: ``navigation`` parameter values: the action when nav2_msgs is installed, the action (required),
#: or the goal topic.
NAVIGATION_MODES = ("auto", "action", "topic")

#: action_msgs/GoalStatus values (the ones a drive ends with).
STATUS_SUCCEEDED, STATUS_CANCELED, STATUS_ABORTED = 4, 5, 6


def navigate_to_pose_type() -> Any:
    """``nav2_msgs.action.NavigateToPose``, or ``None`` when ``nav2_msgs`` is not installed."""
    try:
        from nav2_msgs.action import NavigateToPose
    except ImportError:
        return None
    return NavigateToPose


@dataclass
class _Goal:
    action: str
    place: str
    sent_at: float = 0.0       # monotonic seconds
    handle: Any = None
    wanted: bool = True        # False once a new decision cancelled it: its end is not reported
    progress_at: Optional[float] = None   # monotonic seconds of the last progress passed on


@dataclass
class Nav2Drive:
    """One executor's drives through a ``NavigateToPose`` action server.

    Args:
        node: the executor node (the action client is its).
        action_type: the ``NavigateToPose`` class.
        action_name: the server's name (``/navigate_to_pose``).
        on_failed: called with ``(place, why)`` when a wanted drive ended without arriving.
        on_arrived: called with ``(action, place, sent_at)`` when a wanted drive's goal succeeded
            (``sent_at``: when the goal was sent, ``time.monotonic()`` seconds).
        on_progress: called with ``(action, place, distance_remaining, estimated_time_remaining)``
            for the feedback of a wanted drive, at most once every ``progress_period`` seconds per goal.
        progress_period: seconds between two progress calls of one goal (the first comes at once).
    """

    node: Any
    action_type: Any
    action_name: str
    on_failed: Callable[[str, str], None]
    on_arrived: Callable[[str, str, float], None] = lambda action, place, sent_at: None
    on_progress: Callable[[str, str, float, float], None] = lambda action, place, distance, eta: None
    progress_period: float = 0.5
    counts: Dict[str, int] = field(default_factory=lambda: {"sent": 0, "succeeded": 0, "failed": 0,
                                                            "cancelled": 0, "feedback": 0})
    #: The latest feedback: ``distance_remaining`` (m) and ``estimated_time_remaining`` (s).
    feedback: Dict[str, float] = field(default_factory=dict)
    current: Optional[_Goal] = None

    def __post_init__(self):
        from rclpy.action import ActionClient

        self.client = ActionClient(self.node, self.action_type, self.action_name)

    def destroy(self) -> None:
        self.client.destroy()

    def drive(self, action: str, place: str, pose: Any) -> None:
        """Drive to ``place`` (its ``PoseStamped`` ``pose``) for ``action``; see the module doc."""
        if self.current is not None and self.current.wanted and self.current.place == place:
            self.current.action = action              # the same drive goes on (for this action now)
            return
        self.stop(f"a new decision drives to {place}")
        goal = _Goal(action, place, time.monotonic())
        self.current = goal
        if not self.client.server_is_ready():
            self.current = None
            self.counts["failed"] += 1
            self.on_failed(place, f"no NavigateToPose server on {self.action_name}")
            return
        self.counts["sent"] += 1
        future = self.client.send_goal_async(self.action_type.Goal(pose=pose),
                                             feedback_callback=lambda msg: self._on_feedback(goal, msg))
        future.add_done_callback(lambda f: self._on_response(goal, f))

    def stop(self, why: str) -> None:
        """Cancel the running goal (a decision that no longer wants it); its end is not reported."""
        goal, self.current = self.current, None
        if goal is None or not goal.wanted:
            return
        goal.wanted = False
        self.counts["cancelled"] += 1
        self.node.get_logger().info(f"cancelling the drive to {goal.place}: {why}")
        if goal.handle is not None:
            goal.handle.cancel_goal_async()

    def _on_response(self, goal: _Goal, future) -> None:
        handle = future.result()
        if handle is None or not handle.accepted:
            self._ended(goal, f"the server on {self.action_name} rejected the goal")
            return
        goal.handle = handle
        if not goal.wanted:                           # cancelled before the server took it
            handle.cancel_goal_async()
            return
        handle.get_result_async().add_done_callback(lambda f: self._on_result(goal, f))

    def _on_result(self, goal: _Goal, future) -> None:
        result = future.result()
        status = getattr(result, "status", None)
        if status == STATUS_SUCCEEDED:
            if goal.wanted:
                goal.wanted = False
                self.counts["succeeded"] += 1
                if self.current is goal:
                    self.current = None
                self.on_arrived(goal.action, goal.place, goal.sent_at)
            return
        error = getattr(getattr(result, "result", None), "error_msg", "") or ""
        what = {STATUS_ABORTED: "aborted", STATUS_CANCELED: "cancelled by the navigator"}.get(int(status or 0),
                                                                                           f"status {status}")
        self._ended(goal, what + (f": {error}" if error else ""))

    def _ended(self, goal: _Goal, why: str) -> None:
        if not goal.wanted:
            return                                    # our own cancel: the step it served is closed
        goal.wanted = False
        if self.current is goal:
            self.current = None
        self.counts["failed"] += 1
        self.on_failed(goal.place, why)

    def _on_feedback(self, goal: _Goal, msg) -> None:
        fb = msg.feedback
        eta = fb.estimated_time_remaining
        self.feedback = {"distance_remaining": float(fb.distance_remaining),
                         "estimated_time_remaining": eta.sec + eta.nanosec * 1e-9}
        self.counts["feedback"] += 1
        now = time.monotonic()
        if goal.wanted and (goal.progress_at is None or now - goal.progress_at >= self.progress_period):
            goal.progress_at = now
            self.on_progress(goal.action, goal.place, self.feedback["distance_remaining"],
                             self.feedback["estimated_time_remaining"])
