"""The action executor node: primitive actions → speech, screen and navigation goals.

What each action does is configuration, not code: per action a sentence to say, a text to
display and a named place to drive to; the places are poses in the map frame. The defaults
of all of it come from the package's params file (``config/pearl_nodes.yaml``, see
:mod:`pearl_pomdp.nodes.defaults`); this module names no action of any domain.

A drive is a ``nav2_msgs/action/NavigateToPose`` goal where ``nav2_msgs`` is installed (a robot
with Nav2; :mod:`pearl_pomdp.nodes.nav2_drive`: an aborted goal closes the drive at once, a new
decision cancels a goal it no longer wants), else a ``geometry_msgs/PoseStamped`` on
``/goal_pose`` (what Nav2's BT navigator and RViz's "2D Goal Pose" use); ``navigation`` chooses,
and configure says which is in use.

It is a managed (lifecycle) node like the tracker and the policy
(:mod:`pearl_pomdp.nodes.managed`): configure validates the tables and creates the topics,
activate starts executing, deactivate stops (actions are counted ``inactive_actions``,
nothing is said, shown or driven), cleanup releases the topics. ``autostart`` (default
true) does configure + activate at start-up.
"""
from __future__ import annotations

import datetime
import sys
import time
from typing import Any, Dict, List, Optional

from rclpy.parameter import Parameter

from pearl_pomdp.nodes import conversions as cv
from pearl_pomdp.nodes.common import EVENT_QOS, LATCHED_QOS, NodeSetupError, Param, run_node
from pearl_pomdp.nodes.defaults import FileDefaults
from pearl_pomdp.nodes.managed import AUTOSTART, ManagedPearlNode
from pearl_pomdp.nodes.nav2_drive import NAVIGATION_MODES, Nav2Drive, navigate_to_pose_type
from pearl_pomdp.navigation import places_from_parameters

__all__ = ["ActionExecutorNode", "ACTION_FIELDS", "main"]

#: What an action can do; ``actions.<Action>.<field>`` parameters.
ACTION_FIELDS = ("say", "display", "goal")


class _Template(dict):
    def __missing__(self, key):  # an unknown {field} stays as written rather than failing
        return "{" + key + "}"


class ActionExecutorNode(ManagedPearlNode):
    """Executes primitive actions by publishing what the robot says, shows and where it drives.

    Parameters (read-only; defaults from ``defaults_file``, see :mod:`pearl_pomdp.nodes.defaults`):
        * ``defaults_file`` (str): params file whose ``/**`` and ``action_executor`` sections
          give the defaults below (default ``config/pearl_nodes.yaml``; ``''``: none, and
          then nothing is configured unless given).
        * ``action_names`` (str[]): the actions to configure; an action on ``/pearl/action``
          that is not listed is counted and warned about, never executed.
        * ``actions.<Action>.say`` (str): sentence for speech synthesis; ``{time}`` is replaced
          by the node clock's time (HH:MM, UTC), ``{action}`` by the action name; empty: silent.
        * ``actions.<Action>.display`` (str): text for the touchscreen (same fields); empty: none.
        * ``actions.<Action>.goal`` (str): a name from ``location_names``; empty: no motion.
        * ``location_names`` (str[]): named places; ``locations.<name>`` (double[3]) is x, y (m),
          yaw (rad) in ``frame_id``; ``landmarks.<name>`` (str, '' none): the symbol a drive that
          Nav2 says arrived there is closed with on ``drive_result_topic`` (the landmark detector's table).
        * ``frame_id`` (str): frame of the goals (``map``).
        * ``action_topic``, ``say_topic``, ``display_topic``, ``goal_topic`` (str): topic names.
        * ``diagnostics_period`` (double, 0.01–3600 s).
        * ``use_sim_time`` (bool): follow /clock (stamps of goals, ``{time}``).
        * ``autostart`` (bool, default true): configure and activate at start-up; false: wait
          for ``ros2 lifecycle set /action_executor configure`` / ``activate``.

    Subscribers:
        * ``/pearl/action`` (pearl_interfaces/Action, volatile — a restarted executor does not repeat an
          old action).

    Publishers:
        * ``/pearl/say``, ``/pearl/display`` (std_msgs/String).
        * ``/goal_pose`` (geometry_msgs/PoseStamped in ``frame_id``, reliable, TRANSIENT_LOCAL
          depth 1: a navigator started late still gets the current goal; Nav2's volatile
          subscription matches it) — without nav2_msgs, or ``navigation:=topic``.
        * ``drive_result_topic`` (std_msgs/String, '' by default; Pearl: ``/pearl/laser``):
          ``nav_failed_observation`` when Nav2 aborts a drive, ``landmarks.<place>`` when it arrives
          (unless that landmark was heard there since the goal was sent: it subscribes to it too).
        * ``drive_progress_topic`` (pearl_interfaces/DriveProgress, ``/pearl/drive_progress``): Nav2's
          feedback on the running drive, at most every ``progress_period`` s — the tracker moves the
          drive's deadline by it.

    Action client (where nav2_msgs is installed, ``navigation`` auto or action):
        * ``/navigate_to_pose`` (nav2_msgs/action/NavigateToPose): one goal per drive, cancelled
          when a new decision no longer wants it (:mod:`pearl_pomdp.nodes.nav2_drive`).
        * ``/diagnostics`` (diagnostic_msgs/DiagnosticArray): executed and unknown actions.

    In-process use: ``ActionExecutorNode(context=ctx, parameter_overrides={"action_names": [...],
    "actions.Go.goal": "home", ...})``. :attr:`executed` counts actions per name.

    Raises:
        NodeSetupError: a goal names an unknown location, a location is not [x, y, yaw], the
            defaults file has a value of the wrong type or an ``actions.<A>.<field>`` other
            than say/display/goal.
    """

    DEFAULT_NAME = "action_executor"
    PARAMETERS = (
        Param("action_names", [], "Primitive actions this executor is configured for",
              type=Parameter.Type.STRING_ARRAY),
        Param("location_names", [], "Named navigation goals (see locations.<name>)", type=Parameter.Type.STRING_ARRAY),
        Param("frame_id", "map", "Frame of the navigation goals"),
        Param("action_topic", "/pearl/action", "Primitive action input (pearl_interfaces/Action)"),
        Param("say_topic", "/pearl/say", "Sentences to speak (std_msgs/String)"),
        Param("display_topic", "/pearl/display", "Touchscreen text (std_msgs/String)"),
        Param("goal_topic", "/goal_pose", "Navigation goals (geometry_msgs/PoseStamped, Nav2's goal topic)"),
        Param("navigation", "auto", "How drives go: auto (the NavigateToPose action where nav2_msgs is installed, "
                                    "else goal_topic), action (the action, required) or topic (goal_topic)"),
        Param("navigate_action", "/navigate_to_pose", "Nav2's NavigateToPose action server"),
        Param("drive_result_topic", "", "Where a drive that ended without arriving is reported as "
                                        "nav_failed_observation (std_msgs/String, the tracker's input); '': not"),
        Param("nav_failed_observation", "", "What is published on drive_result_topic when Nav2 aborts a drive"),
        Param("drive_progress_topic", "/pearl/drive_progress", "Nav2's feedback on the running drive "
              "(pearl_interfaces/DriveProgress; the tracker moves the drive's deadline by it); '': not published"),
        Param("progress_period", 0.5, "Seconds between two drive progress messages of one goal (the first goes "
                                      "at once)", range=(0.0, 60.0)),
        Param("diagnostics_period", 1.0, "Seconds between /diagnostics summaries", range=(0.01, 3600.0)),
        AUTOSTART,
    )

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        # Every parameter is declared here (read-only); configure checks the tables.
        self._defaults = defaults = FileDefaults(self)
        self.params = p = self.declare_table(defaults.apply(self.PARAMETERS))
        self._poses: Dict[str, List[float]] = {}
        #: place → the symbol an arrival there is closed with (``landmarks.<place>``; '' none).
        self.landmarks: Dict[str, str] = {}
        for name in p["location_names"]:
            table = [Param(f"locations.{name}", [0.0, 0.0, 0.0], f"Pose of {name}: x, y (m), yaw (rad) in frame_id"),
                     Param(f"landmarks.{name}", "", f"Symbol on drive_result_topic when Nav2 arrives at {name} "
                                                    "('': none)")]
            values = self.declare_table(defaults.apply(table))
            self._poses[name] = list(values[f"locations.{name}"])
            self.landmarks[name] = values[f"landmarks.{name}"]
        self._tables: Dict[str, Dict[str, str]] = {}
        for action in p["action_names"]:
            table = [Param(f"actions.{action}.say", "", f"What the robot says for {action}"),
                     Param(f"actions.{action}.display", "", f"What the screen shows for {action}"),
                     Param(f"actions.{action}.goal", "", f"Location the robot drives to for {action}")]
            values = self.declare_table(defaults.apply(table))
            self._tables[action] = {k: values[f"actions.{action}.{k}"] for k in ACTION_FIELDS}
        self.locations: Dict[str, List[float]] = {}
        self.behaviour: Dict[str, Dict[str, str]] = {}
        self.executed: Dict[str, int] = {}
        self.unknown = 0
        self.inactive_actions = 0  # actions that arrived while the node was not active (not executed)
        self.diag_pub = self.create_publisher(cv.DiagnosticsMsg, "/diagnostics", EVENT_QOS)
        self.nav: Optional[Nav2Drive] = None
        self.goal_pub: Any = None
        self.result_pub: Any = None
        self.progress_pub: Any = None
        #: symbol → monotonic second it was last heard on drive_result_topic (an arrival's echo check).
        self._results_heard: Dict[str, float] = {}
        self.drive_path = ""
        self.start(p["autostart"])

    # ----------------------------------------------------------- lifecycle
    def configure_node(self) -> None:
        """Check the places and the action table; create the topics and the diagnostics timer."""
        p, defaults = self.params, self._defaults
        try:
            places = places_from_parameters(list(self._poses), self._poses)   # the one place parser
        except ValueError as err:
            raise NodeSetupError(f"parameter {err}") from None
        self.locations = {name: [place.x, place.y, place.yaw] for name, place in places.items()}
        for key in defaults.under("actions"):
            action, _, field = key.rpartition(".")
            if field not in ACTION_FIELDS:
                raise NodeSetupError(f"{defaults.path}: {defaults.section}.actions.{key}: unknown field {field!r} "
                                     f"(expected one of {', '.join(ACTION_FIELDS)})")
        self.behaviour = {}
        for action, spec in self._tables.items():
            goal = spec["goal"]
            if goal and goal not in self.locations:
                raise NodeSetupError(f"parameter actions.{action}.goal: unknown location {goal!r} "
                                     f"(location_names: {', '.join(self.locations) or 'none'})")
            self.behaviour[action] = dict(spec)
        self.say_pub = self.lifecycle_publisher(cv.TextMsg, p["say_topic"], EVENT_QOS)
        self.display_pub = self.lifecycle_publisher(cv.TextMsg, p["display_topic"], EVENT_QOS)
        self._configure_navigation()
        self.managed_subscription(cv.ActionMsg, p["action_topic"], self._on_action, EVENT_QOS)
        self.managed_timer(p["diagnostics_period"], self.publish_diagnostics)
        if not self.behaviour:
            self.get_logger().warning("no action configured (action_names is empty): every action will be "
                                      "counted as unknown")
        self.get_logger().info(f"executing {len(self.behaviour)} actions; locations: "
                               f"{', '.join(self.locations) or 'none'}; drives through {self.drive_path}")

    def _configure_navigation(self) -> None:
        p = self.params
        mode = p["navigation"]
        if mode not in NAVIGATION_MODES:
            raise NodeSetupError(f"parameter navigation: {mode!r} is not one of {', '.join(NAVIGATION_MODES)}")
        action_type = navigate_to_pose_type() if mode != "topic" else None
        if mode == "action" and action_type is None:
            raise NodeSetupError("parameter navigation: 'action' needs nav2_msgs (NavigateToPose), which is not "
                                 "installed; 'auto' or 'topic' publishes goals on goal_topic")
        if p["drive_result_topic"] and not p["nav_failed_observation"]:
            raise NodeSetupError("parameter nav_failed_observation: needed when drive_result_topic is set "
                                 f"({p['drive_result_topic']})")
        # Only the action reports a failed drive (goal_topic has no answer to report).
        self.result_pub = (self.lifecycle_publisher(cv.TextMsg, p["drive_result_topic"], EVENT_QOS)
                           if p["drive_result_topic"] and action_type is not None else None)
        self.progress_pub = (self.lifecycle_publisher(cv.DriveProgressMsg, p["drive_progress_topic"], EVENT_QOS)
                             if p["drive_progress_topic"] and action_type is not None else None)
        if self.result_pub is not None:
            # A landmark detector beside Nav2 reports an arrival there too: heard, it is not said twice.
            self.managed_subscription(cv.TextMsg, p["drive_result_topic"], self._on_drive_result, EVENT_QOS)
        if action_type is not None:
            self.nav = Nav2Drive(self, action_type, p["navigate_action"], self._drive_failed,
                                 on_arrived=self._drive_arrived, on_progress=self._drive_progress,
                                 progress_period=p["progress_period"])
            self.goal_pub = None
            self.drive_path = f"the NavigateToPose action {p['navigate_action']}"
        else:
            self.nav = None
            self.goal_pub = self.lifecycle_publisher(cv.PoseMsg, p["goal_topic"], LATCHED_QOS)
            self.drive_path = f"goals on {p['goal_topic']}"

    def cleanup_node(self) -> None:
        if self.nav is not None:
            self.nav.destroy()
            self.nav = None

    def _drive_failed(self, place: str, why: str) -> None:
        """A wanted drive ended without arriving: said at once on drive_result_topic."""
        self.get_logger().warning(f"drive to {place} failed: {why}"
                                  + (f"; {self.params['nav_failed_observation']} on {self.params['drive_result_topic']}"
                                     if self.result_pub is not None else ""))
        if self.result_pub is not None and self.active:
            self.result_pub.publish(cv.text_to_msg(self.params["nav_failed_observation"]))
        self.publish_diagnostics()

    def _on_drive_result(self, msg) -> None:
        self._results_heard[cv.msg_to_text(msg).strip()] = time.monotonic()

    def _drive_arrived(self, action: str, place: str, sent_at: float) -> None:
        """Nav2 says the drive arrived: its landmark goes on drive_result_topic, unless it was heard
        there since the goal was sent (a landmark detector said it first)."""
        symbol = self.landmarks.get(place, "")
        if self.result_pub is None or not symbol or not self.active:
            return
        heard = self._results_heard.get(symbol)
        if heard is not None and heard >= sent_at:
            self.get_logger().info(f"drive to {place} arrived; {symbol} was already heard on "
                                   f"{self.params['drive_result_topic']}, not said again")
            return
        self.get_logger().info(f"drive to {place} arrived: {symbol} on {self.params['drive_result_topic']}")
        self.result_pub.publish(cv.text_to_msg(symbol))

    def _drive_progress(self, action: str, place: str, distance: float, eta: float) -> None:
        if self.progress_pub is not None and self.active:
            self.progress_pub.publish(cv.drive_progress_to_msg(action, place, distance, eta, self.now_s()))

    def _fields(self, action: str) -> _Template:
        now = datetime.datetime.fromtimestamp(self.now_s(), tz=datetime.timezone.utc)
        return _Template(time=now.strftime("%H:%M"), action=action)

    def _on_action(self, msg) -> None:
        if not self.active:
            self.inactive_actions += 1   # a deactivated executor does not act
            return
        action = cv.msg_to_action(msg)
        spec = self.behaviour.get(action)
        if spec is None:
            self.unknown += 1
            # At most one line a second: a stream of foreign actions must not become a log flood
            # (every one is counted on /diagnostics).
            self.get_logger().warning(f"unknown action {action!r}: not in action_names; nothing executed "
                                      f"(unknown actions: {self.unknown})", throttle_duration_sec=1.0)
            self.publish_diagnostics()
            return
        self.executed[action] = self.executed.get(action, 0) + 1
        fields = self._fields(action)
        if spec["say"]:
            self.say_pub.publish(cv.text_to_msg(spec["say"].format_map(fields)))
        if spec["display"]:
            self.display_pub.publish(cv.text_to_msg(spec["display"].format_map(fields)))
        if spec["goal"]:
            x, y, yaw = self.locations[spec["goal"]]
            pose = cv.pose_to_msg(x, y, yaw, self.params["frame_id"], self.now_s())
            if self.nav is not None:
                self.nav.drive(action, spec["goal"], pose)
            else:
                self.goal_pub.publish(pose)
        elif self.nav is not None:
            self.nav.stop(f"{action} does not drive")

    def publish_diagnostics(self) -> None:
        """Publish executed/unknown action counts on /diagnostics."""
        nav: Dict[str, Any] = {f"nav_{k}": v for k, v in self.nav.counts.items()} if self.nav is not None else {}
        if self.nav is not None:
            nav.update({f"nav_{k}": v for k, v in self.nav.feedback.items()})
        values = {"executed": sum(self.executed.values()), "unknown_actions": self.unknown,
                  "inactive_actions": self.inactive_actions, **nav,
                  **{f"executed_{k}": v for k, v in sorted(self.executed.items())}}
        level = cv.DIAG_WARN if self.unknown else cv.DIAG_OK
        self.diag_pub.publish(cv.diagnostics_to_msg(f"pearl: {self.get_name()}", "pearl", level,
                                                    f"{values['executed']} actions executed", values, self.now_s()))


def main(args: Optional[List[str]] = None) -> int:
    """Console script ``action_executor``: exit 0 on SIGINT/SIGTERM, 2 on a start-up error."""
    return run_node(ActionExecutorNode, args)


if __name__ == "__main__":
    sys.exit(main())
