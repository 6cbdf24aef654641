"""The guide_pace node: during a guidance, the navigation's velocity slowed to the resident's pace.

It sits between Nav2's controller and the base, the way Nav2's velocity smoother and
collision monitor do: ``/cmd_vel_nav`` (geometry_msgs/Twist) in, ``/cmd_vel`` out. While no
guidance runs it passes every command through unchanged. When the manager starts a guidance
(an action listed in ``guide_actions`` on ``/pearl/action``) it runs
:class:`pearl_pomdp.guide_pace.GuidePace` at ``control_rate`` on the resident's position from
a people tracker (geometry_msgs/PointStamped in the robot's base frame) and scales the
navigation's command to the speed she can follow; any other action ends the guidance. When
she is lost it publishes ``lost_symbol`` on ``lost_topic`` once.
"""
from __future__ import annotations

import math
import sys
from typing import List, Optional

from rclpy.parameter import Parameter

from pearl_pomdp.guide_pace import FOLLOWING, GuidePace, GuidePaceConfig
from pearl_pomdp.nodes import conversions as cv
from pearl_pomdp.nodes.common import (EVENT_QOS, LATCHED_QOS, NodeSetupError, Param, PearlNode,
                                      load_domain_and_model, resolve_path, run_node)
from pearl_pomdp.nodes.defaults import FileDefaults
from pearl_pomdp.nodes.landmark_detector import POSE_QOS

#: The filter's default settings (the one source of the parameters' defaults below).
_CONFIG = GuidePaceConfig()

__all__ = ["GuidePaceNode", "main"]

#: Velocity commands: reliable, volatile, keep-last 1 (only the newest command matters).
CMD_QOS = EVENT_QOS


class GuidePaceNode(PearlNode):
    """Filters ``/cmd_vel_nav`` → ``/cmd_vel`` to the resident's pace during a guidance.

    Parameters (read-only; defaults from ``defaults_file``, see :mod:`pearl_pomdp.nodes.defaults`):
        * ``guide_actions`` (str[]): actions during which the robot guides (a guidance starts
          when one is published on ``action_topic`` and ends with any other action).
        * ``cruise_speed`` (0.05–3 m/s, 0.6), ``follow_gap`` (0.2–10 m, 1.0), ``resume_gap``
          (0.3–20 m, 1.5; > follow_gap), ``stop_gap`` (0.5–30 m, 2.5; > resume_gap), ``gain``
          (0.01–10 1/s, 0.5), ``pace_time_constant`` (0.1–60 s, 3.0), ``lost_timeout``
          (1–3600 s, 60): the :class:`~pearl_pomdp.guide_pace.GuidePaceConfig` settings.
        * ``person_topic`` (``/pearl/resident_position``), ``person_frame`` (``base_link``):
          the resident's position, x forward / y left in metres; her distance behind is
          ``hypot(x, y)``. Points in another frame are ignored (no tf here).
        * ``person_timeout`` (0.05–10 s, 1.0): an older position means "not seen".
        * ``cmd_in_topic`` (``/cmd_vel_nav``), ``cmd_out_topic`` (``/cmd_vel``).
        * ``cmd_timeout`` (0.05–10 s, 0.5): an older navigation command is not repeated.
        * ``control_rate`` (1–100 Hz, 20): filter steps per second during a guidance.
        * ``lost_topic`` (``/pearl/laser``), ``lost_symbol`` (``''``: not published; Pearl's
          params file: ``userLost``). With ``domain`` set, a symbol that is not an observation of the domain
          is warned about (the tracker counts it as invalid until the domain has it).
        * ``action_topic`` (``/pearl/action``), ``state_topic`` (``/pearl/guide_pace``),
          ``diagnostics_period`` (0.01–3600 s).

    Subscribers: ``/cmd_vel_nav`` (Twist), person topic (PointStamped, best effort),
    ``/pearl/action`` (pearl_interfaces/Action, TRANSIENT_LOCAL: a restarted node resumes a running guidance).

    Publishers: ``/cmd_vel`` (Twist), ``lost_topic`` (String), ``/pearl/guide_pace``
    (pearl_interfaces/GuidePace: ``active``, ``state``, ``speed``, ``nav_speed``, ``pace``, ``behind``
    — NaN: not seen —, ``waited``, ``times_lost``; at most 4 Hz during a guidance), ``/diagnostics``.
    """

    DEFAULT_NAME = "guide_pace"
    #: The filter's settings are GuidePaceConfig's fields: their defaults and reasons live there.
    PARAMETERS = (
        Param("guide_actions", [], "Actions during which the robot guides the resident",
              type=Parameter.Type.STRING_ARRAY),
        Param("cruise_speed", _CONFIG.cruise_speed, "m/s when the navigation gives none", range=(0.05, 3.0)),
        Param("follow_gap", _CONFIG.follow_gap, "m behind the robot at which she is held", range=(0.2, 10.0)),
        Param("resume_gap", _CONFIG.resume_gap, "m: waiting ends once she is this close (> follow_gap)", range=(0.3, 20.0)),
        Param("stop_gap", _CONFIG.stop_gap, "m: the robot stops when she is farther behind (> resume_gap)", range=(0.5, 30.0)),
        Param("gain", _CONFIG.gain, "1/s: speed per metre she is closer than follow_gap", range=(0.01, 10.0)),
        Param("pace_time_constant", _CONFIG.pace_time_constant, "s: smoothing of her pace estimate", range=(0.1, 60.0)),
        Param("lost_timeout", _CONFIG.lost_timeout, "s of waiting after which she is lost", range=(1.0, 3600.0)),
        Param("person_topic", "/pearl/resident_position", "Resident position (PointStamped, robot frame)"),
        Param("person_frame", "base_link", "Frame the resident position must be in"),
        Param("person_timeout", 1.0, "s: an older position means she is not seen", range=(0.05, 10.0)),
        Param("cmd_in_topic", "/cmd_vel_nav", "Navigation velocity input (Twist)"),
        Param("cmd_out_topic", "/cmd_vel", "Velocity output to the base (Twist)"),
        Param("cmd_timeout", 0.5, "s: an older navigation command is not repeated", range=(0.05, 10.0)),
        Param("control_rate", 20.0, "Filter steps per second during a guidance (Hz)", range=(1.0, 100.0)),
        Param("lost_topic", "/pearl/laser", "Where 'resident lost' is reported (String)"),
        Param("lost_symbol", "", "Observation published when she is lost, a symbol of the domain ('': none)"),
        Param("domain", "", "Domain whose observations lost_symbol should be ('': no check)"),
        Param("action_topic", "/pearl/action", "Primitive actions (pearl_interfaces/Action)"),
        Param("state_topic", "/pearl/guide_pace", "Filter state for viewers (pearl_interfaces/GuidePace)"),
        Param("diagnostics_period", 1.0, "Seconds between /diagnostics summaries", range=(0.01, 3600.0)),
    )

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        defaults = FileDefaults(self)
        self.params = p = self.declare_table(defaults.apply(self.PARAMETERS))
        try:
            self.config = GuidePaceConfig(**{k: p[k] for k in ("cruise_speed", "follow_gap", "resume_gap", "stop_gap",
                                                               "gain", "pace_time_constant", "lost_timeout")})
        except ValueError as err:
            raise NodeSetupError(f"parameter {str(err).replace('guide_pace ', '', 1)}") from None
        if not p["guide_actions"]:
            self.get_logger().warning("guide_actions is empty: every command passes through unchanged")
        if p["lost_symbol"] and p["domain"]:
            domain, model = load_domain_and_model(resolve_path(p["domain"], "domain"))
            if p["lost_symbol"] not in model.observations:
                self.get_logger().warning(f"lost_symbol {p['lost_symbol']!r} is not an observation of {model.name}: "
                                          f"the belief tracker will count it as invalid until the domain has it")
        self.pace = GuidePace(self.config)
        self.active: Optional[str] = None
        self.progress = 0.0
        self._last_step: Optional[float] = None
        self._nav: Optional[tuple] = None       # (received at, Twist)
        self._person: Optional[tuple] = None    # (received at, distance behind)
        self._last_state_pub = -math.inf
        self.counts = {"guidances": 0, "passed_through": 0, "filtered": 0, "lost": 0, "ignored_frame": 0,
                       "stops": 0}
        self.cmd_pub = self.create_publisher(cv.TwistMsg, p["cmd_out_topic"], CMD_QOS)
        self.lost_pub = self.create_publisher(cv.TextMsg, p["lost_topic"], EVENT_QOS)
        self.state_pub = self.create_publisher(cv.GuidePaceMsg, p["state_topic"], EVENT_QOS)
        self.diag_pub = self.create_publisher(cv.DiagnosticsMsg, "/diagnostics", EVENT_QOS)
        self.create_subscription(cv.TwistMsg, p["cmd_in_topic"], self._on_cmd, CMD_QOS)
        self.create_subscription(cv.PointMsg, p["person_topic"], self._on_person, POSE_QOS)
        self.create_subscription(cv.ActionMsg, p["action_topic"], self._on_action, LATCHED_QOS)
        self.create_timer(1.0 / p["control_rate"], self._control)
        self.create_timer(p["diagnostics_period"], self.publish_diagnostics)
        self.get_logger().info(f"guide pace for {', '.join(p['guide_actions']) or 'no action'}: "
                               f"{p['cmd_in_topic']} → {p['cmd_out_topic']}, resident on {p['person_topic']}")

    # ------------------------------------------------------------------ inputs
    def _on_action(self, msg) -> None:
        action = cv.msg_to_action(msg)
        if action in self.params["guide_actions"]:
            if self.active != action:
                self.pace.reset()
                self.progress, self._last_step, self.active = 0.0, None, action
                self.counts["guidances"] += 1
                self.get_logger().info(f"guidance {action}: adapting to the resident's pace")
        elif self.active is not None:
            self.get_logger().info(f"guidance {self.active} ended ({action}): {self.pace.stops} stops, "
                                   f"lost {self.pace.times_lost} times; passing commands through")
            self.active = None
            self._publish_state(force=True)

    def _on_person(self, msg) -> None:
        point = cv.msg_to_point(msg)
        if point["frame_id"] != self.params["person_frame"]:
            self.counts["ignored_frame"] += 1
            return
        behind = math.hypot(point["x"], point["y"])
        if math.isfinite(behind):
            self._person = (self.now_s(), behind)

    def _on_cmd(self, msg) -> None:
        if self.active is None:
            self.counts["passed_through"] += 1
            self.cmd_pub.publish(msg)
            return
        self._nav = (self.now_s(), msg)

    # ----------------------------------------------------------------- control
    def _control(self) -> None:
        if self.active is None:
            return
        now = self.now_s()
        if self._last_step is None:
            self._last_step = now
            return
        dt = now - self._last_step
        if dt <= 0:
            return  # sim time stopped or jumped back: nothing to integrate
        self._last_step = now
        p = self.params
        nav = self._nav[1] if self._nav is not None and now - self._nav[0] <= p["cmd_timeout"] else None
        behind = self._person[1] if self._person is not None and now - self._person[0] <= p["person_timeout"] else None
        nav_speed = max(0.0, nav.linear.x) if nav is not None else 0.0
        stops = self.pace.stops
        speed = self.pace.step(dt, self.progress, behind, nav_speed=nav_speed)
        self.counts["stops"] += self.pace.stops - stops
        self.progress += speed * dt
        if self.pace.became_lost:
            self.counts["lost"] += 1
            self.get_logger().warning(f"resident lost during {self.active}: not within {self.config.resume_gap} m "
                                      f"for {self.config.lost_timeout} s")
            if p["lost_symbol"]:
                self.lost_pub.publish(cv.text_to_msg(p["lost_symbol"]))
        if nav is not None:
            self.counts["filtered"] += 1
            self.cmd_pub.publish(self._scaled(nav, speed))
        self._publish_state(nav_speed=nav_speed, behind=behind)

    def _scaled(self, nav, speed: float):
        """The navigation's command at ``speed`` forward, turning on the same path (same curvature)."""
        v = cv.msg_to_twist(nav)
        if self.pace.state != FOLLOWING:
            return cv.twist_to_msg(0.0, 0.0)
        if v["linear_x"] <= 1e-6:
            return nav  # turning in place or reversing: the resident is not the limit
        factor = min(1.0, speed / v["linear_x"])
        return cv.twist_to_msg(v["linear_x"] * factor, v["angular_z"] * factor, v["linear_y"] * factor)

    def _publish_state(self, nav_speed: float = 0.0, behind: Optional[float] = None, force: bool = False) -> None:
        now = self.now_s()
        if not force and now - self._last_state_pub < 0.25:
            return
        self._last_state_pub = now
        state = {"active": self.active, "state": self.pace.state, "speed": round(self.pace.speed, 4),
                 "nav_speed": round(nav_speed, 4), "pace": round(self.pace.pace, 4),
                 "behind": None if behind is None else round(behind, 3), "waited": round(self.pace.waited, 2),
                 "times_lost": self.pace.times_lost}
        self.state_pub.publish(cv.guide_pace_to_msg(state, now))

    def publish_diagnostics(self) -> None:
        """Publish guidance counters on /diagnostics (WARN while the resident is lost)."""
        values = {**self.counts, "active": self.active or "", "state": self.pace.state}
        level = cv.DIAG_WARN if self.active and self.pace.state == "lost" else cv.DIAG_OK
        self.diag_pub.publish(cv.diagnostics_to_msg(f"pearl: {self.get_name()}", "pearl", level,
                                                    f"{self.counts['guidances']} guidances", values, self.now_s()))


def main(args: Optional[List[str]] = None) -> int:
    """Console script ``guide_pace``: exit 0 on SIGINT/SIGTERM, 2 on a start-up error."""
    return run_node(GuidePaceNode, args)


if __name__ == "__main__":
    sys.exit(main())
