"""The belief tracker node: observations in, beliefs out (docs/design.md §6).

A thin rclpy wrapper of the core :class:`~pearl_pomdp.tracking.BeliefTracker` — the same
object the simulator and the study drive (input → symbol, what closes a step, queueing,
timeouts, stale input: all documented in :mod:`pearl_pomdp.tracking`). Subscriptions feed
it inputs and actions, a one-shot timer armed at the open step's deadline feeds it the
clock, and the belief is published after every closed step.

Run it with ``belief_tracker --ros-args -p domain:=config/pearl.domain.yaml`` (console
script), ``pearl run belief_tracker …``, ``ros2 run pearl_pomdp belief_tracker`` or from a
launch file; build it in a Python process with :class:`BeliefTrackerNode`.
"""
from __future__ import annotations

import sys
import time
from typing import Callable, Dict, List, Optional

import numpy as np

from pearl_pomdp.nodes import conversions as cv
from pearl_pomdp.nodes.common import (EVENT_QOS, INPUT_QOS, LATCHED_QOS, NodeSetupError, Param,
                                      load_domain_and_model, resolve_path, run_node)
from pearl_pomdp.nodes.managed import AUTOSTART, ManagedPearlNode
from pearl_pomdp.tracking import SYMBOL_INPUTS, BeliefTracker, ObservationMapper, StepResult, StepSettings

__all__ = ["BeliefTrackerNode", "ObservationMapper", "main", "SYMBOL_INPUTS"]


class BeliefTrackerNode(ManagedPearlNode):
    """Tracks the belief over the domain's states from the robot's inputs.

    Parameters (all read-only, declared with descriptions and ranges):
        * ``domain`` (str): factored domain ``.yaml`` or flat ``.pomdp``; relative paths are
          tried in the working directory, then in the package share directory.
        * ``step_timeout`` (double, s, ≥ 0): close an open step with ``timeout_observation``
          after this long without input; 0 waits forever.
        * ``timeout_observation`` (str): the symbol used on timeout (default ``unknown``).
        * ``no_timeout_actions`` (str[]): actions never timed out (empty: the domain's
          ``category: Move`` actions).
        * ``confidence_floor`` (double, 0–1): speech recognised with a lower confidence
          counts as ``unknown`` (see :mod:`pearl_pomdp.tracking`).
        * ``max_pending`` (int, 0–1000): observations that may wait for the next action.
        * ``stale_after`` (double, s, ≥ 0): drop a waiting observation older than this; 0 never.
        * ``drive_speed`` (double, 0–5 m/s): drives get a deadline at this speed
          (:class:`~pearl_pomdp.navigation.DriveTimer`) and are closed with
          ``nav_failed_observation`` when it passes; 0: drives have no deadline.
        * ``guide_speed`` (double, 0.005–3 m/s), ``guide_actions`` (str[]): guidances are timed
          at the slowest resident's pace.
        * ``drive_path_factor`` (≥ 1), ``drive_slack`` (≥ 1), ``drive_margin`` (s),
          ``drive_max_seconds`` (s): the rest of :class:`~pearl_pomdp.navigation.DriveDeadline`.
        * ``nav_failed_observation`` (str, ``navFailed``), ``place_feature`` (str, ``RobotLocation``).
        * ``location_names`` (str[]), ``locations.<name>`` (double[3]): the places (shared ``/**``).
        * ``diagnostics_period`` (double, s, > 0): period of the /diagnostics summary.
        * ``speech_topic``, ``touchscreen_topic``, ``laser_topic``, ``reminder_topic``,
          ``action_topic``, ``belief_topic``, ``marginals_topic`` (str): topic names.
        * ``use_sim_time`` (bool): follow /clock (rclpy's own parameter).

    Subscribers:
        * ``/pearl/speech`` (std_msgs/String): recognised text → keyword filter → Speech symbol.
        * ``/pearl/touchscreen``, ``/pearl/laser``, ``/pearl/reminder`` (std_msgs/String): symbols.
        * ``/pearl/action`` (std_msgs/String, TRANSIENT_LOCAL): the action that opens a step.

    Publishers:
        * ``/pearl/belief`` (std_msgs/Float64MultiArray, TRANSIENT_LOCAL depth 1): ``b`` after each
          step; ``b0`` once at start so a late policy still gets it.
        * ``/pearl/belief_marginals`` (std_msgs/String JSON, TRANSIENT_LOCAL depth 1): step, action,
          observation and per-feature marginals (see :mod:`pearl_pomdp.nodes.conversions`).
        * ``/diagnostics`` (diagnostic_msgs/DiagnosticArray): counters (updates, timeouts,
          queued/dropped observations, speech without keywords, invalid inputs, zero-likelihood
          recoveries, ``lost_inputs``: input messages DDS dropped before the node took them,
          from gaps in each publisher's sequence numbers); WARN level once anything was
          dropped, invalid, lost or recovered. Sent every ``diagnostics_period`` and at once
          (at most every 0.1 s) when a warning counter grows. Per-input log lines are
          throttled to one per second per kind; the counters stay exact.

    In-process use (tests, replay): ``BeliefTrackerNode(context=ctx,
    parameter_overrides={"domain": path, "use_sim_time": True}, domain=dom, model=model)``;
    ``domain``/``model`` are optional preloaded objects that skip loading the file
    (``model`` alone for a flat model). After construction, :attr:`protocol` is the
    :class:`~pearl_pomdp.tracking.StepProtocol` (belief, counters), :attr:`mapper` the
    :class:`~pearl_pomdp.tracking.ObservationMapper` and :attr:`core` the :class:`~pearl_pomdp.tracking.BeliefTracker`.

    Raises:
        NodeSetupError: missing domain file or invalid parameter combination (one line).
        rclpy.exceptions.ParameterException: an override of the wrong type or out of range.
    """

    DEFAULT_NAME = "belief_tracker"
    PARAMETERS = (
        Param("domain", "config/pearl.domain.yaml", "Factored domain (.yaml) or flat model (.pomdp) file"),
        Param("step_timeout", 10.0, "Seconds without input after an action before the step is closed "
                                    "with timeout_observation (0: wait forever; changeable at run time)",
              range=(0.0, 3600.0), read_only=False),
        Param("timeout_observation", "unknown", "Observation symbol that closes a step on timeout"),
        Param("no_timeout_actions", [""],
              "Actions whose step only an input closes (drives end with a laser landmark); "
              "empty: the domain's category: Move actions; names the model does not have are ignored"),
        Param("max_pending", 8, "Observations that may wait for the next action (FIFO)", range=(0, 1000)),
        Param("stale_after", 0.0, "Drop a waiting observation older than this many seconds (0: never; "
                                  "changeable at run time)", range=(0.0, 3600.0), read_only=False),
        Param("confidence_floor", 0.0, "Speech recognised with a lower confidence counts as unknown "
                                       "(changeable at run time)", range=(0.0, 1.0), read_only=False),
        Param("drive_speed", 0.0, "Drives get a deadline from distance at this speed (m/s) and are closed "
                                  "with nav_failed_observation when it passes; 0: no drive deadline",
              range=(0.0, 5.0)),
        Param("guide_speed", 0.03, "Speed (m/s) guide_actions are timed at: the slowest pace, rests included, "
                                   "of a resident the robot still guides", range=(0.005, 3.0)),
        Param("guide_actions", [""], "Drives that walk the resident along (timed at guide_speed)"),
        Param("drive_path_factor", 1.4, "Path length over straight-line distance", range=(1.0, 10.0)),
        Param("drive_slack", 1.5, "Multiplier on a drive's expected time", range=(1.0, 10.0)),
        Param("drive_margin", 10.0, "Seconds added to every drive's deadline", range=(0.0, 3600.0)),
        Param("drive_max_seconds", 1800.0, "No drive deadline is longer than this (s)", range=(1.0, 86400.0)),
        Param("nav_failed_observation", "navFailed", "Observation symbol that closes a drive at its deadline"),
        Param("place_feature", "RobotLocation", "State feature whose values are the places the drives go to"),
        Param("location_names", [""], "Named places (locations.<name> = [x, y, yaw] in the map frame)"),
        Param("diagnostics_period", 1.0, "Seconds between /diagnostics summaries", range=(0.01, 3600.0)),
        Param("speech_topic", "/pearl/speech", "Recognised speech text (std_msgs/String)"),
        Param("touchscreen_topic", "/pearl/touchscreen", "Touchscreen symbols (std_msgs/String)"),
        Param("laser_topic", "/pearl/laser", "Landmark symbols from navigation (std_msgs/String)"),
        Param("reminder_topic", "/pearl/reminder", "Reminder goal symbols (std_msgs/String)"),
        Param("action_topic", "/pearl/action", "Primitive actions, which open steps (std_msgs/String)"),
        Param("belief_topic", "/pearl/belief", "Belief output (std_msgs/Float64MultiArray)"),
        Param("marginals_topic", "/pearl/belief_marginals", "Per-feature marginals output (JSON String)"),
        Param("reset_service", "/pearl/reset", "std_srvs/Trigger service that returns the belief to b0"),
        AUTOSTART,
    )

    def __init__(self, *, domain=None, model=None, keyword_filter=None, **kwargs):
        super().__init__(**kwargs)
        self.params = p = self.declare_table(self.PARAMETERS)
        for name in [n for n in p["location_names"] if n]:
            p.update(self.declare_table([Param(f"locations.{name}", [0.0, 0.0, 0.0],
                                               f"Pose of {name}: x, y (m), yaw (rad) in the map frame")]))
        self._preloaded = (domain, model, keyword_filter)
        self.core = None
        self._reported_warnings = 0
        self._event_logged: Dict[str, float] = {}   # kind → node-clock second it was last logged
        self.actions_received = 0  # /pearl/action messages taken (the sim-clock driver waits on it)
        self.inactive_inputs = 0   # inputs and actions that arrived while the node was not active (dropped)
        # Inputs DDS dropped before this node took them (a reader queue of INPUT_QOS depth
        # overflowing under a flood): gaps in each publisher's sequence numbers.
        self.lost_inputs = 0
        self._last_seq: Dict[str, int] = {}
        self._last_diag = -1.0
        self._deadline_timer = None
        self._flush_timer = None
        self._armed_for: Optional[float] = None
        self.diag_pub = self.create_publisher(cv.DiagnosticsMsg, "/diagnostics", EVENT_QOS)
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self.start(p["autostart"])

    # ----------------------------------------------------------- lifecycle
    def configure_node(self) -> None:
        """Load the domain, build the core tracker, create topics, timers and /pearl/reset."""
        p = self.params
        domain, model, keyword_filter = self._preloaded
        if model is None:
            domain, model = load_domain_and_model(resolve_path(p["domain"], "domain"))
        self.domain, self.model = domain, model
        try:
            given = [name for name in p["no_timeout_actions"] if name]
            settings = StepSettings.from_params({**p, "no_timeout_actions": given,
                                                 "location_names": [n for n in p["location_names"] if n]})
            self.core = BeliefTracker(model, domain, settings, keyword_filter)
        except ValueError as err:
            raise NodeSetupError(f"parameter {str(err)}") from None
        self.protocol = self.core.protocol
        self.mapper = self.core.mapper

        self.belief_pub = self.lifecycle_publisher(cv.BeliefMsg, p["belief_topic"], LATCHED_QOS)
        self.marginals_pub = self.lifecycle_publisher(cv.TextMsg, p["marginals_topic"], LATCHED_QOS)
        self.managed_subscription(cv.TextMsg, p["speech_topic"], self._counted("speech", self._on_speech), INPUT_QOS)
        for key in SYMBOL_INPUTS:
            self.managed_subscription(cv.TextMsg, p[f"{key}_topic"], self._counted(key, self._symbol_callback(key)),
                                      INPUT_QOS)
        self.managed_subscription(cv.TextMsg, p["action_topic"], self._on_action, LATCHED_QOS)
        # One-shot timer for the open step's deadline (node clock, so sim time in replay and demo):
        # armed when a step opens, cancelled when it closes, so a step times out exactly
        # step_timeout after its action, as in the core loop the simulator runs.
        self._deadline_timer = None
        self._armed_for = None
        self._configured_timeout = p["step_timeout"] > 0
        if p["step_timeout"] > 0 or self.core.drive_timer is not None:
            self._deadline_timer = self.managed_timer(p["step_timeout"] or 1.0, self._on_tick)
            self._deadline_timer.cancel()
        self.managed_timer(p["diagnostics_period"], self.publish_diagnostics)
        # Warnings held back by the 0.1 s limit go out 0.1 s of wall time later (even when sim
        # time stands still): a one-shot timer, armed only then, so the node does not wake ten
        # times a second (each wake is a full executor spin, which a step arriving then waits for).
        from rclpy.clock import Clock, ClockType

        self._flush_timer = self.managed_timer(0.1, self._flush_diagnostics,
                                               clock=Clock(clock_type=ClockType.STEADY_TIME))
        self._flush_timer.cancel()
        from std_srvs.srv import Trigger

        self._reset_srv = self.create_service(Trigger, p["reset_service"], self._on_reset)
        drives = self.core.drive_timer
        self.get_logger().info(f"tracking {model.name}: {model.num_states} states, {model.num_observations} "
                               f"observations; step_timeout {p['step_timeout']} s → {p['timeout_observation']!r}; "
                               + (f"drives {', '.join(drives.goals)} timed at {p['drive_speed']} m/s → "
                                  f"{p['nav_failed_observation']!r}" if drives is not None else "drives have no deadline"))

    def activate_node(self) -> None:
        """Publish the current belief (b0 at first): the policy answers it and the loop runs."""
        self._publish_belief(None)

    def deactivate_node(self) -> None:
        """Stop tracking; keep the belief. An open step is abandoned (no update): the robot
        stops doing what it was doing, and on activation the policy decides afresh."""
        if self.core is not None:
            self.core.protocol.current_action = None
            self.core.protocol.opened_at = None
            self._arm_deadline()

    def cleanup_node(self) -> None:
        self._flush_timer = None
        if getattr(self, "_reset_srv", None) is not None:
            self.destroy_service(self._reset_srv)
            self._reset_srv = None
        self.core = None

    def _on_reset(self, request, response):
        """``/pearl/reset`` (std_srvs/Trigger): back to b0 with nothing open or queued; counters zeroed."""
        if self.core is None:
            response.success, response.message = False, "not configured: nothing to reset"
            return response
        self.core.reset()
        self._arm_deadline()
        self._publish_belief(None)
        response.success = True
        response.message = f"belief reset to b0 of {self.model.name}" + ("" if self.active else " (inactive)")
        self.get_logger().info(response.message)
        return response

    def _on_set_parameters(self, params):
        """Run-time changes of step_timeout, stale_after and confidence_floor, validated; others are read-only."""
        from rcl_interfaces.msg import SetParametersResult

        for param in params:
            if param.name == "step_timeout" and self.core is not None and not self._configured_timeout \
                    and param.value > 0:
                return SetParametersResult(successful=False, reason="step_timeout: this node was configured "
                                           "without a timeout (0); set it before configure")
            if param.name == "confidence_floor" and not 0.0 <= param.value <= 1.0:
                return SetParametersResult(successful=False, reason=f"confidence_floor must be in [0, 1], "
                                                                    f"got {param.value}")
        for param in params:
            if self.core is None:
                continue
            if param.name == "step_timeout":
                self.core.protocol.step_timeout = float(param.value)
                # The one-shot timer is re-armed for the open step's new deadline.
                self._armed_for = None
                self._arm_deadline()
            elif param.name == "stale_after":
                self.core.protocol.stale_after = float(param.value)
            elif param.name == "confidence_floor":
                self.core.mapper.confidence_floor = float(param.value)
        return SetParametersResult(successful=True)

    # ----------------------------------------------------------- callbacks
    def _counted(self, key: str, callback: Callable) -> Callable:
        """Wrap an input callback: count messages lost before it (sequence-number gaps).

        rclpy's message info has the writer's sequence number but not the writer's id, so
        gaps are tracked per topic: exact with one publisher per input topic (the Pearl
        graph); with several publishers on one topic a restart can make ``lost_inputs`` over-count.
        """
        def on_input(msg, info) -> None:
            seq = info.get("publication_sequence_number") if isinstance(info, dict) else None
            if seq:
                last = self._last_seq.get(key)
                if last is not None and seq > last + 1:
                    self.lost_inputs += seq - last - 1
                self._last_seq[key] = seq
            callback(msg)

        return on_input

    def _inactive(self) -> bool:
        """Inputs while not active are dropped (counted): a deactivated tracker does not track."""
        if self.active and self.core is not None:
            return False
        self.inactive_inputs += 1
        return True

    def _on_action(self, msg) -> None:
        if self._inactive():
            return
        self.actions_received += 1
        self._handle(self.core.on_action(cv.msg_to_action(msg), self.now_s()))

    def _on_speech(self, msg) -> None:
        if self._inactive():
            return
        before = self.mapper.unknown_speech
        outcome = self.core.on_input("speech", cv.msg_to_text(msg), self.now_s())
        if self.mapper.unknown_speech > before:
            self.get_logger().info(f"speech {outcome.text!r} has no keyword: observation {outcome.symbol!r} "
                                   f"({self.mapper.unknown_speech} such texts so far)", throttle_duration_sec=1.0)
        if outcome.symbol is None:
            self.get_logger().warning(f"speech {outcome.text!r} maps to no observation symbol of {self.model.name}; "
                                      f"ignored (invalid speech inputs: {self.mapper.invalid['speech']})",
                                      throttle_duration_sec=1.0)
            self._diagnostics_soon()
            return
        self._handle(outcome.closed)

    def _symbol_callback(self, key: str) -> Callable:
        def callback(msg) -> None:
            if self._inactive():
                return
            outcome = self.core.on_input(key, cv.msg_to_text(msg), self.now_s())
            if outcome.symbol is None:
                valid = ", ".join(sorted(self.mapper.allowed[key]))
                self.get_logger().warning(f"{key} input {cv.msg_to_text(msg)!r} is not a {key} symbol "
                                          f"(valid: {valid}); ignored (invalid {key} inputs: "
                                          f"{self.mapper.invalid[key]})", throttle_duration_sec=1.0)
                self._diagnostics_soon()
                return
            self._handle(outcome.closed)

        return callback

    def _event_due(self, kind: str, now: float) -> bool:
        """True unless an event of this kind was logged less than a second (node clock) ago."""
        last = self._event_logged.get(kind)
        if last is not None and 0.0 <= now - last < 1.0:
            return False
        self._event_logged[kind] = now
        return True

    def _on_tick(self) -> None:
        if self.active and self.core is not None:
            self._handle(self.core.on_tick(self.now_s()))

    # -------------------------------------------------------------- output
    def _handle(self, result: Optional[StepResult]) -> None:
        # The belief goes out first: logging and diagnostics must not delay the policy.
        if result is not None:
            self._publish_belief(result)
        self._arm_deadline()
        logger = self.get_logger()
        for event in self.protocol.take_events():
            # One line per event; a flood of one kind is cut to one line per second of the
            # node's clock (sim time under /clock, so a fast-forwarded demo still shows each
            # of its events; rclpy's own throttle counts wall time). The counters are exact.
            if not self._event_due(event.kind or event.text, self.now_s()):
                continue
            if event.level == "warn":
                logger.warning(event.text)
            else:
                logger.info(event.text)
        if self._warning_total() > self._reported_warnings:
            self._diagnostics_soon()

    def _arm_deadline(self) -> None:
        """Keep the one-shot timer in step with the core's deadline (armed while a step can time out)."""
        timer = self._deadline_timer
        deadline = self.core.deadline()
        if timer is None or deadline == self._armed_for:
            return
        self._armed_for = deadline
        if deadline is None:
            timer.cancel()
        else:
            # One timer for step timeouts and drive deadlines: its period is set to fire exactly at
            # the deadline's nanosecond (as /clock carries it), then it is restarted from now.
            now_ns = self.get_clock().now().nanoseconds
            timer.timer_period_ns = max(1, int(round(deadline * 1e9)) - now_ns)
            timer.reset()

    def _flush_diagnostics(self) -> None:
        if self._flush_timer is not None:
            self._flush_timer.cancel()  # one-shot: _diagnostics_soon arms it again
        if self._warning_total() > self._reported_warnings:
            self.publish_diagnostics()

    def _diagnostics_soon(self) -> None:
        """Publish /diagnostics now, unless done in the last 0.1 s (then within 0.1 s of wall time)."""
        now = time.monotonic()
        if now - self._last_diag >= 0.1:
            self.publish_diagnostics()
        elif self._flush_timer is not None and self._flush_timer.is_canceled():
            self._flush_timer.reset()

    def _publish_belief(self, result: Optional[StepResult]) -> None:
        belief = self.protocol.belief
        self.belief_pub.publish(cv.belief_to_msg(belief))
        self.marginals_pub.publish(cv.marginals_to_msg(self.marginals(belief), self.protocol.step,
                                                       result.action if result else None,
                                                       result.observation if result else None))

    def marginals(self, belief: np.ndarray) -> Dict[str, Dict[str, float]]:
        """``{feature: {value: P}}``; a flat model reports the pseudo-feature ``"state"``."""
        return self.core.marginals(belief)

    def counters(self) -> Dict[str, int]:
        """Every counter reported on /diagnostics."""
        out = self.core.counters() if self.core is not None else {}
        out["lost_inputs"] = self.lost_inputs
        out["inactive_inputs"] = self.inactive_inputs
        return out

    def _warning_total(self) -> int:
        return (self.core.warnings() if self.core is not None else 0) + self.lost_inputs

    def publish_diagnostics(self) -> None:
        """Publish the counters on /diagnostics (WARN once any input was dropped/invalid/recovered)."""
        if self.core is None:
            return  # not configured: nothing to report
        warnings = self._warning_total()
        self._reported_warnings = warnings
        self._last_diag = time.monotonic()
        step, open_action, pending = self.protocol.snapshot()
        values = {"step": step, "open_action": open_action or "", "pending": pending, **self.counters()}
        if self.protocol.last_nav_failure:
            values["last_nav_failure"] = self.protocol.last_nav_failure
        level = cv.DIAG_WARN if warnings else cv.DIAG_OK
        text = f"{warnings} input(s) dropped, invalid or recovered" if warnings else "tracking"
        nav = self.protocol.counters.get("nav_failures", 0)
        if nav:
            text = f"{text}; {nav} drive(s) missed their deadline (last: {self.protocol.last_nav_failure})"
        self.diag_pub.publish(cv.diagnostics_to_msg(f"pearl: {self.get_name()}", self.model.name, level, text,
                                                    values, self.now_s()))


def main(args: Optional[List[str]] = None) -> int:
    """Console script ``belief_tracker``: exit 0 on SIGINT/SIGTERM, 2 on a start-up error."""
    return run_node(BeliefTrackerNode, args)


if __name__ == "__main__":
    sys.exit(main())
