"""The landmark detector node: the robot's localised pose → Laser landmark observations.

On a robot the manager learns that a drive has arrived from localisation, not from a string
the navigation makes up: this node feeds every pose from ``/amcl_pose``
(geometry_msgs/PoseWithCovarianceStamped, Nav2 AMCL) and/or ``/odom`` (nav_msgs/Odometry) to
a :class:`pearl_pomdp.navigation.LandmarkDetector` and publishes the landmark's symbol
(``atPhysio``) on ``/pearl/laser`` once per arrival, with hysteresis (entry radius < exit
radius). Which symbol a place reports is a parameter (``landmarks.<place>``), and the places
are the ones the action executor drives to (``location_names`` / ``locations.<name>``).
"""
from __future__ import annotations

import math
import sys
from typing import Dict, List, Optional

from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from pearl_pomdp.navigation import Landmark, LandmarkDetector, places_from_parameters
from pearl_pomdp.nodes import conversions as cv
from pearl_pomdp.nodes.common import (EVENT_QOS, NodeSetupError, Param, PearlNode, load_domain_and_model,
                                      resolve_path, run_node)
from pearl_pomdp.nodes.defaults import FileDefaults

__all__ = ["LandmarkDetectorNode", "POSE_QOS", "main"]

#: Pose streams: best effort (matches reliable and best-effort publishers, AMCL's
#: TRANSIENT_LOCAL too), keep-last 10. A lost pose is replaced by the next one.
POSE_QOS = QoSProfile(depth=10, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.BEST_EFFORT,
                      durability=DurabilityPolicy.VOLATILE)


class LandmarkDetectorNode(PearlNode):
    """Publishes a Laser landmark symbol when the localised robot arrives at a place.

    Parameters (read-only; defaults from ``defaults_file``, see :mod:`pearl_pomdp.nodes.defaults`):
        * ``location_names`` (str[]), ``locations.<name>`` (double[3]: x, y m, yaw rad in ``frame_id``).
        * ``landmarks.<name>`` (str): the symbol reported on arrival at ``<name>``; empty: none.
        * ``entry_radius`` (double, 0.05–50 m, default 1.0): arrived within this distance.
        * ``exit_radius`` (double, 0.1–100 m, default 2.0; > ``entry_radius``): left beyond it.
        * ``max_position_stddev`` (double, 0–100 m, default 1.0): poses whose x/y standard
          deviation (from the covariance) is larger are ignored; 0 accepts every pose.
        * ``report_initial`` (bool, default false): report a place the first pose is in.
        * ``frame_id`` (str, ``map``): poses in another frame are ignored (no tf here).
        * ``domain`` (str): when set, every symbol must be a symbol of the domain's input on
          ``laser_topic`` (Pearl: its Laser modality), or of the domain when no input is on it.
        * ``pose_topic`` (``/amcl_pose``), ``odom_topic`` (``''``: off), ``laser_topic``
          (``/pearl/laser``) (str).
        * ``diagnostics_period`` (double, 0.01–3600 s).

    Subscribers: ``/amcl_pose`` (PoseWithCovarianceStamped), optional ``/odom`` (Odometry),
    both best effort (:data:`POSE_QOS`).

    Publishers: ``/pearl/laser`` (std_msgs/String, reliable volatile), ``/diagnostics``
    (poses taken, ignored by frame / uncertainty, arrivals per symbol).

    Raises:
        NodeSetupError: a landmark names no location, a symbol is not a Laser observation of
            ``domain``, ``exit_radius`` ≤ ``entry_radius``, or no landmark is configured.
    """

    DEFAULT_NAME = "landmark_detector"
    PARAMETERS = (
        Param("location_names", [], "Named places (see locations.<name>)", type=Parameter.Type.STRING_ARRAY),
        Param("frame_id", "map", "Frame of the places and of the accepted poses"),
        # 1 m: Nav2's default xy_goal_tolerance is 0.25 m, and 1 m also takes a stop in the doorway.
        Param("entry_radius", 1.0, "Metres from a place within which the robot has arrived", range=(0.05, 50.0)),
        # 1 m of hysteresis is well above AMCL's jitter (a few cm) and a turn in place.
        Param("exit_radius", 2.0, "Metres from a place beyond which the robot has left it (> entry_radius)",
              range=(0.1, 100.0)),
        # A pose less certain than 1 m cannot tell the door from the corridor.
        Param("max_position_stddev", 1.0, "Ignore poses less certain than this (m, x/y standard deviation; 0: off)",
              range=(0.0, 100.0)),
        Param("report_initial", False, "Report a place the first pose is already in"),
        Param("domain", "", "Domain whose Laser observations the symbols must be ('': no check)"),
        # Nav2's AMCL; set odom_topic: /odom (and pose_topic: '') for a robot localised by odometry in the map frame.
        Param("pose_topic", "/amcl_pose", "Localised pose input (PoseWithCovarianceStamped; '': off)"),
        Param("odom_topic", "", "Odometry input (nav_msgs/Odometry; '': off)"),
        Param("laser_topic", "/pearl/laser", "Landmark symbol output (std_msgs/String)"),
        Param("diagnostics_period", 1.0, "Seconds between /diagnostics summaries", range=(0.01, 3600.0)),
    )

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        defaults = FileDefaults(self)
        self.params = p = self.declare_table(defaults.apply(self.PARAMETERS))
        poses = {}
        symbols: Dict[str, str] = {}
        for name in p["location_names"]:
            values = self.declare_table(defaults.apply([
                Param(f"locations.{name}", [0.0, 0.0, 0.0], f"Pose of {name}: x, y (m), yaw (rad) in frame_id"),
                Param(f"landmarks.{name}", "", f"Laser symbol reported on arrival at {name} ('': none)")]))
            poses[name] = values[f"locations.{name}"]
            if values[f"landmarks.{name}"]:
                symbols[name] = values[f"landmarks.{name}"]
        unknown = sorted(set(defaults.under("landmarks")) - set(p["location_names"]))
        if unknown:
            raise NodeSetupError(f"{defaults.path}: {self.DEFAULT_NAME}.landmarks.{unknown[0]}: not in location_names "
                                 f"({', '.join(p['location_names']) or 'none'})")
        if p["exit_radius"] <= p["entry_radius"]:
            raise NodeSetupError(f"parameter exit_radius: must be > entry_radius ({p['entry_radius']} m) for "
                                 f"hysteresis, got {p['exit_radius']} m")
        try:
            places = places_from_parameters(p["location_names"], poses)
            landmarks = [Landmark(places[n], s, p["entry_radius"], p["exit_radius"]) for n, s in symbols.items()]
        except ValueError as err:
            raise NodeSetupError(f"parameter {err}") from None
        if not landmarks:
            raise NodeSetupError("no landmark configured: set landmarks.<place> to a Laser symbol for at least one "
                                 f"of location_names ({', '.join(p['location_names']) or 'none'})")
        if p["domain"]:
            domain, model = load_domain_and_model(resolve_path(p["domain"], "domain"))
            # The symbols of the domain's input this node publishes on (its declared topic).
            topic = self.resolve_topic_name(p["laser_topic"])
            inputs = [c for c in (domain.inputs if domain is not None else ()) if self.resolve_topic_name(c.topic) == topic]
            laser = list(inputs[0].symbols) if inputs else list(model.observations)
            what = f"a symbol of the {inputs[0].modality} input ({topic})" if inputs else "an observation"
            for name, symbol in symbols.items():
                if symbol not in laser:
                    raise NodeSetupError(f"parameter landmarks.{name}: {symbol!r} is not {what} of "
                                         f"{domain.name if domain else p['domain']} (valid: {', '.join(laser) or 'none'})")
        self.detector = LandmarkDetector(landmarks, report_initial=p["report_initial"])
        self.counts = {"poses": 0, "ignored_frame": 0, "ignored_uncertain": 0}
        self._warned_frames: set = set()
        self.laser_pub = self.create_publisher(cv.TextMsg, p["laser_topic"], EVENT_QOS)
        self.diag_pub = self.create_publisher(cv.DiagnosticsMsg, "/diagnostics", EVENT_QOS)
        topics = []
        if p["pose_topic"]:
            self.create_subscription(cv.LocalisedPoseMsg, p["pose_topic"], self._on_pose, POSE_QOS)
            topics.append(p["pose_topic"])
        if p["odom_topic"]:
            self.create_subscription(cv.OdometryMsg, p["odom_topic"], self._on_pose, POSE_QOS)
            topics.append(p["odom_topic"])
        if not topics:
            raise NodeSetupError("parameters pose_topic and odom_topic are both empty: no pose input")
        self.create_timer(p["diagnostics_period"], self.publish_diagnostics)
        described = ", ".join(f"{lm.place.name}→{lm.symbol}" for lm in landmarks)
        self.get_logger().info(f"landmarks {described} (entry {p['entry_radius']} m, exit {p['exit_radius']} m) "
                               f"from {', '.join(topics)} → {p['laser_topic']}")

    def _on_pose(self, msg) -> None:
        pose = cv.msg_to_planar_pose(msg)
        if pose["frame_id"] != self.params["frame_id"]:
            self.counts["ignored_frame"] += 1
            if pose["frame_id"] not in self._warned_frames:
                self._warned_frames.add(pose["frame_id"])
                self.get_logger().warning(f"ignoring poses in frame {pose['frame_id']!r}: places are in "
                                          f"{self.params['frame_id']!r} (no tf lookup here)")
            return
        limit = self.params["max_position_stddev"]
        if limit > 0 and not (pose["stddev"] <= limit):  # NaN counts as uncertain
            self.counts["ignored_uncertain"] += 1
            return
        if not (math.isfinite(pose["x"]) and math.isfinite(pose["y"])):
            self.counts["ignored_uncertain"] += 1
            return
        self.counts["poses"] += 1
        for symbol in self.detector.update(pose["x"], pose["y"]):
            self.laser_pub.publish(cv.text_to_msg(symbol))
            self.get_logger().info(f"arrived: {symbol} at ({pose['x']:.2f}, {pose['y']:.2f})")

    def arrivals(self) -> Dict[str, int]:
        """Arrivals reported so far, per symbol."""
        return dict(self.detector.reported)

    def publish_diagnostics(self) -> None:
        """Publish pose counters and arrivals per symbol on /diagnostics."""
        values = {**self.counts, **{f"arrived_{k}": v for k, v in sorted(self.detector.reported.items())},
                  "inside": ",".join(sorted(self.detector.inside))}
        ignored = self.counts["ignored_frame"] + self.counts["ignored_uncertain"]
        level = cv.DIAG_WARN if ignored and not self.counts["poses"] else cv.DIAG_OK
        self.diag_pub.publish(cv.diagnostics_to_msg(f"pearl: {self.get_name()}", "pearl", level,
                                                    f"{sum(self.detector.reported.values())} arrivals", values,
                                                    self.now_s()))


def main(args: Optional[List[str]] = None) -> int:
    """Console script ``landmark_detector``: exit 0 on SIGINT/SIGTERM, 2 on a start-up error."""
    return run_node(LandmarkDetectorNode, args)


if __name__ == "__main__":
    sys.exit(main())
