"""The belief tracker node: observations in, beliefs out (docs/design.md §6).

A thin rclpy wrapper of the core :class:`~pearl_pomdp.tracking.BeliefTracker` — the same
object the simulator and the study drive (input → symbol, what closes a step, queueing,
timeouts, stale input: all documented in :mod:`pearl_pomdp.tracking`). Subscriptions feed
it inputs and actions, a one-shot timer armed at the open step's deadline feeds it the
clock, and the belief is published after every closed step. It subscribes to exactly the
inputs the domain declares (``modalities.<M>.input``: :mod:`pearl_pomdp.channels`; message
types: :mod:`pearl_pomdp.nodes.channel_messages`), each on a topic and QoS that the
``inputs.<name>.*`` parameters can remap.

Run it with ``belief_tracker --ros-args -p domain:=config/pearl.domain.yaml`` (console
script), ``pearl run belief_tracker …``, ``ros2 run pearl_pomdp belief_tracker`` or from a
launch file; build it in a Python process with :class:`BeliefTrackerNode`.
"""
from __future__ import annotations

import sys
import time
from typing import Any, Callable, Dict, List, Optional

from pearl_pomdp.channels import RELIABILITIES, InputChannel
from pearl_pomdp.errors import SpecError
from pearl_pomdp.nodes import conversions as cv
from pearl_pomdp.nodes.channel_messages import qos_profile, reader_for
from pearl_pomdp.nodes.common import (EVENT_QOS, LATCHED_QOS, SETTINGS_TOPIC, NodeSetupError, Param,
                                      load_domain_and_model, resolve_path, run_node)
from pearl_pomdp.nodes.defaults import FileDefaults
from pearl_pomdp.nodes.journaling import JOURNAL_PARAMETERS, NodeJournal
from pearl_pomdp.nodes.managed import AUTOSTART, ManagedPearlNode
from pearl_pomdp.tracking import BeliefTracker, InputOutcome, StepSettings

__all__ = ["BeliefTrackerNode", "main", "step_parameters", "input_parameters"]


#: ROS cannot type an empty list from its value (``[]`` would be a byte array): an empty string
#: list is declared as ``[""]``, and :meth:`StepSettings.from_params` drops the ``""`` entries.
EMPTY_STRINGS = [""]


def step_parameters() -> List[Param]:
    """The node parameters of :class:`~pearl_pomdp.tracking.StepSettings`, generated from its
    fields (name, default, range, description; the ``live`` ones changeable at run time)."""
    return [Param(spec.name, spec.default if spec.default != [] else EMPTY_STRINGS,
                  spec.description + ("; changeable at run time" if spec.live else ""),
                  read_only=not spec.live, range=spec.range)
            for spec in StepSettings.parameters()]


def is_replayed_setting(name: str) -> bool:
    """A tracker parameter a replay must have to close the robot's steps as it did: a step rule
    (:class:`~pearl_pomdp.tracking.StepSettings`: the timeout, the drive deadlines …) or a place
    (``location_names``, ``locations.<name>``), which the drive deadlines are measured from."""
    return name in _STEP_RULES or name == "location_names" or name.startswith("locations.")


_STEP_RULES = frozenset(spec.name for spec in StepSettings.parameters())


def input_parameters(channel: InputChannel) -> List[Param]:
    """The node parameters of one input (declared at configure, when the domain is known): its
    topic, reliability and queue depth, defaulting to the domain's declaration."""
    prefix, what = f"inputs.{channel.name}", f"{channel.modality} input ({channel.kind}, {channel.type})"
    return [Param(f"{prefix}.topic", channel.topic, f"Topic of the {what}; default: the domain's"),
            Param(f"{prefix}.qos", channel.qos, f"Reliability of the {what}'s subscription: "
                                                f"{' or '.join(RELIABILITIES)} (a best-effort sensor driver needs "
                                                "best_effort); default: the domain's"),
            Param(f"{prefix}.depth", channel.depth, f"Keep-last queue depth of the {what}'s subscription",
                  range=(1, 1000))]


class BeliefTrackerNode(ManagedPearlNode):
    """Tracks the belief over the domain's states from the robot's inputs.

    Parameters (declared with descriptions and ranges; ``ros2 param describe`` shows them):
        * ``domain`` (str): factored domain ``.yaml`` or flat ``.pomdp``; relative paths are
          tried in the working directory, then in the package share directory.
        * The step rules: one parameter per field of :class:`~pearl_pomdp.tracking.StepSettings`
          (:func:`step_parameters`: the same names, defaults, ranges and descriptions) —
          ``step_timeout``, ``timeout_observation``, ``no_timeout_actions``, ``drive_category``, ``max_pending``,
          ``stale_after``, ``confidence_floor``, ``drive_speed``, ``guide_speed``,
          ``guide_actions``, ``drive_path_factor``, ``drive_slack``, ``drive_margin``,
          ``drive_max_seconds``, ``nav_failed_observation``, ``place_feature``.
          ``step_timeout``, ``stale_after`` and ``confidence_floor`` may change at run time
          (:meth:`~pearl_pomdp.tracking.BeliefTracker.set_live`); the others are read-only.
        * ``location_names`` (str[]), ``locations.<name>`` (double[3]): the places (shared ``/**``).
        * ``defaults_file`` (str, ``config/pearl_nodes.yaml``): the params file whose ``/**`` and
          ``belief_tracker`` sections give the defaults (:mod:`pearl_pomdp.nodes.defaults`), so
          ``ros2 run pearl_pomdp belief_tracker`` behaves as under the launch file; ``''``: none.
        * ``diagnostics_period`` (double, s, > 0): period of the /diagnostics summary.
        * ``inputs.<name>.topic`` (str), ``inputs.<name>.qos`` (str: ``reliable`` or
          ``best_effort``), ``inputs.<name>.depth`` (int): one set per input of the domain
          (:func:`input_parameters`; ``<name>`` is the modality's name in lower case), declared at
          configure with the domain's declaration as default — a remap of an input's topic or QoS.
        * ``action_topic``, ``belief_topic``, ``drive_progress_topic`` (str): topic names.
        * ``use_sim_time`` (bool): follow /clock (rclpy's own parameter).
        * ``journal`` (str, ``auto``), ``journal_max_age`` (double, s): the journal this node writes
          after every change and resumes from when restarted (:mod:`pearl_pomdp.nodes.journaling`:
          ``auto`` is ``$ROS_HOME/pearl/journal/domain<ID>/<node>.json``, ``''`` none); a journal older
          than ``journal_max_age`` or of another domain file is refused with one line;
          ``journal_sync`` (str, ``background``): when a write reaches the disk
          (:data:`pearl_pomdp.journal.SYNC_MODES`).

    Subscribers:
        * One per input the domain declares, on its topic with its message type and QoS
          (Pearl: ``/pearl/speech`` recognised text → keyword filter → Speech symbol;
          ``/pearl/touchscreen``, ``/pearl/laser``, ``/pearl/reminder`` symbols; all
          ``std_msgs/String``). A number input reads its message's number and discretises it.
          A flat model (no domain) has one input, ``observation`` on ``/pearl/observation``.
        * ``/pearl/action`` (pearl_interfaces/Action, TRANSIENT_LOCAL): the action that opens a step.
        * ``/pearl/drive_progress`` (pearl_interfaces/DriveProgress; ``drive_progress_topic``), when
          drives have deadlines: the open drive's remaining path moves its deadline
          (:meth:`~pearl_pomdp.tracking.BeliefTracker.on_drive_progress`).

    Publishers:
        * ``/pearl/belief`` (pearl_interfaces/Belief, TRANSIENT_LOCAL depth 1): ``b`` after each
          step with the step, the tracker's run, the step's action and observation and the per-feature
          marginals (see :mod:`pearl_pomdp.nodes.conversions`); ``b0`` (or the journal's belief) once
          at start so a late policy still gets it.
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
    (``model`` alone for a flat model). Once configured, :attr:`core` is the
    :class:`~pearl_pomdp.tracking.BeliefTracker` the node drives (read its belief, counters and
    deadline there; the node reaches it only through its public methods).

    Raises:
        NodeSetupError: missing or invalid domain file, an input the node cannot read (a message
            type that is not installed, a field it lacks), two inputs on one topic after
            remapping, or an invalid parameter combination (one line).
        rclpy.exceptions.ParameterException: an override of the wrong type or out of range.
    """

    DEFAULT_NAME = "belief_tracker"
    PARAMETERS = (
        Param("domain", "config/pearl.domain.yaml", "Factored domain (.yaml) or flat model (.pomdp) file"),
        *step_parameters(),
        Param("location_names", EMPTY_STRINGS, "Named places (locations.<name> = [x, y, yaw] in the map frame)"),
        Param("diagnostics_period", 1.0, "Seconds between /diagnostics summaries", range=(0.01, 3600.0)),
        Param("action_topic", "/pearl/action", "Primitive actions, which open steps (pearl_interfaces/Action)"),
        Param("belief_topic", "/pearl/belief", "Belief output (pearl_interfaces/Belief)"),
        Param("drive_progress_topic", "/pearl/drive_progress", "A running drive's progress (pearl_interfaces/"
              "DriveProgress, the action executor's from Nav2's feedback), which moves the drive's deadline; "
              "read when drives have deadlines (drive_speed > 0); '': not read"),
        Param("reset_service", "/pearl/reset", "std_srvs/Trigger service that returns the belief to b0"),
        *JOURNAL_PARAMETERS,
        AUTOSTART,
    )

    def __init__(self, *, domain=None, model=None, keyword_filter=None, channels=None, **kwargs):
        super().__init__(**kwargs)
        self._defaults = defaults = FileDefaults(self)
        self.params = p = self.declare_table(defaults.apply(self.PARAMETERS))
        for name in [n for n in p["location_names"] if n]:
            p.update(self.declare_table(defaults.apply([Param(f"locations.{name}", [0.0, 0.0, 0.0],
                                                              f"Pose of {name}: x, y (m), yaw (rad) in the map frame")])))
        self._preloaded = (domain, model, keyword_filter)
        self._preloaded_channels = channels
        #: The core tracker (:class:`~pearl_pomdp.tracking.BeliefTracker`) once configured, else ``None``.
        self.core: Optional[BeliefTracker] = None
        #: The journal (docs/reliability.md, "Crashes"), once configured.
        self.journal: Optional[NodeJournal] = None
        self._reported_warnings = 0
        self._event_logged: Dict[str, float] = {}   # kind → node-clock second it was last logged
        self.actions_received = 0  # /pearl/action messages taken (the sim-clock driver waits on it)
        self.inactive_inputs = 0   # inputs and actions that arrived while the node was not active (dropped)
        # Inputs DDS dropped before this node took them (a reader queue of INPUT_QOS depth
        # overflowing under a flood): gaps in each publisher's sequence numbers.
        self.lost_inputs = 0
        self._last_seq: Dict[str, int] = {}
        self._last_diag = -1.0
        self._deadline_timer: Optional[Any] = None
        self._flush_timer: Optional[Any] = None
        self._reset_srv: Optional[Any] = None
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
            try:
                domain, model = load_domain_and_model(resolve_path(p["domain"], "domain"))
            except SpecError as err:
                raise NodeSetupError(f"parameter domain: {err}") from None
        self.domain, self.model = domain, model
        try:
            self.core = core = BeliefTracker(model, domain, StepSettings.from_params(p), keyword_filter,
                                             self._preloaded_channels)
        except ValueError as err:
            raise NodeSetupError(f"parameter {str(err)}") from None
        inputs = self._input_subscriptions(core.channels, domain.source if domain is not None else p["domain"])
        for event in core.startup_events:
            self._log(event.level, event.text)
        self.journal = NodeJournal(self, "belief_tracker", p, model, domain.source if domain is not None else p["domain"])
        self.journal.resume(self._resume)

        self.belief_pub = self.lifecycle_publisher(cv.BeliefMsg, p["belief_topic"], LATCHED_QOS)
        self.settings_pub = self.lifecycle_publisher(cv.SettingsMsg, SETTINGS_TOPIC, LATCHED_QOS)
        for reader, topic, qos in inputs:
            key = reader.channel.name
            callback = self._on_speech(key) if reader.channel.kind == "speech" else self._input_callback(key)
            self.managed_subscription(reader.msg_type, topic, self._counted(key, callback, reader.read), qos)
        self.managed_subscription(cv.ActionMsg, p["action_topic"], self._on_action, LATCHED_QOS)
        if core.drive_timer is not None and p["drive_progress_topic"]:
            self.managed_subscription(cv.DriveProgressMsg, p["drive_progress_topic"], self._on_drive_progress,
                                      EVENT_QOS)
        # One-shot timer for the open step's deadline (node clock, so sim time in replay and demo):
        # armed when a step opens, cancelled when it closes, so a step times out exactly
        # step_timeout after its action, as in the core loop the simulator runs.
        self._deadline_timer = None
        self._armed_for = None
        self._configured_timeout = p["step_timeout"] > 0
        if p["step_timeout"] > 0 or core.drive_timer is not None:
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
        drives = core.drive_timer
        listening = ", ".join(f"{r.channel.name} ({r.channel.kind}) on {topic}" for r, topic, _ in inputs)
        self.get_logger().info(f"tracking {model.name}: {model.num_states} states, {model.num_observations} "
                               f"observations; inputs: {listening}; step_timeout {p['step_timeout']} s → "
                               f"{core.timeout_observation!r}; "
                               + (f"drives {', '.join(drives.goals)} timed at {p['drive_speed']} m/s → "
                                  f"{p['nav_failed_observation']!r}" if drives is not None else "drives have no deadline"))

    def _input_subscriptions(self, channels, source: str) -> list:
        """``(reader, topic, qos)`` of every input: the domain's declaration, remapped by the
        ``inputs.<name>.*`` parameters (declared here, once: the domain is known only now).

        Raises:
            NodeSetupError: an unreadable message type or field, an unknown qos, two inputs on one topic.
        """
        out = []
        owner: Dict[str, str] = {}
        for channel in channels:
            reader = reader_for(channel, source)
            table = input_parameters(channel)
            if not self.has_parameter(table[0].name):
                self.params.update(self.declare_table(self._defaults.apply(table)))
            values = {param.name: self.get_parameter(param.name).value for param in table}
            topic, qos, depth = values[table[0].name], values[table[1].name], values[table[2].name]
            if qos not in RELIABILITIES:
                raise NodeSetupError(f"parameter {table[1].name}: {qos!r} is not one of {', '.join(RELIABILITIES)}")
            resolved = self.resolve_topic_name(topic)
            if resolved in owner:
                raise NodeSetupError(f"parameter {table[0].name}: topic {resolved} is already the topic of input "
                                     f"{owner[resolved]!r}; each input needs its own topic")
            owner[resolved] = channel.name
            out.append((reader, topic, qos_profile(qos, depth)))
        return out

    def activate_node(self) -> None:
        """Publish the current belief (b0 at first, or the journal's): the policy answers it (once:
        it knows the run and step it answered) and the loop runs; a resumed step's deadline is armed.
        The step rules and places go out first, latched (:data:`~pearl_pomdp.nodes.common.SETTINGS_TOPIC`),
        for a recorder."""
        settings = {name: value for name, value in self.params.items() if is_replayed_setting(name)}
        self.settings_pub.publish(cv.settings_to_msg(self.get_fully_qualified_name(), settings, self.now_s()))
        self._publish_belief()
        self._arm_deadline()

    def deactivate_node(self) -> None:
        """Stop tracking; keep the belief. An open step is abandoned (no update): the robot
        stops doing what it was doing, and on activation the policy decides afresh."""
        if self.core is not None:
            self._handle(self.core.abandon_step())

    def cleanup_node(self) -> None:
        self._flush_timer = None
        if self._reset_srv is not None:
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
        self._publish_belief()
        self._journal()
        response.success = True
        response.message = f"belief reset to b0 of {self.model.name}" + ("" if self.active else " (inactive)")
        self.get_logger().info(response.message)
        return response

    def _on_set_parameters(self, params):
        """Run-time changes of the live step settings (step_timeout, stale_after, confidence_floor),
        checked by the core before any is applied; the others are read-only."""
        from rcl_interfaces.msg import SetParametersResult

        live = {param.name: param.value for param in params if param.name in StepSettings.live_names()}
        if not live or self.core is None:
            return SetParametersResult(successful=True)   # not configured: the value is read at configure
        if live.get("step_timeout", 0) > 0 and not self._configured_timeout:
            return SetParametersResult(successful=False, reason="step_timeout: this node was configured "
                                       "without a timeout (0); set it before configure")
        try:
            self.core.set_live(**live)
        except ValueError as err:
            return SetParametersResult(successful=False, reason=str(err))
        if "step_timeout" in live:
            # The one-shot timer is re-armed for the open step's new deadline.
            self._armed_for = None
            self._arm_deadline()
        return SetParametersResult(successful=True)

    # ----------------------------------------------------------- callbacks
    def _counted(self, key: str, callback: Callable, read: Callable) -> Callable:
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
            callback(read(msg))

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
        assert self.core is not None  # _inactive() is True otherwise
        self._handle(self.core.on_action(cv.msg_to_action(msg), self.now_s()))

    def _on_drive_progress(self, msg) -> None:
        """The navigation's progress on a drive: the core moves that drive's deadline (and the timer follows)."""
        if self._inactive():
            return
        assert self.core is not None
        self._handle(self.core.on_drive_progress(msg.action, msg.distance_remaining, self.now_s()))

    def _on_speech(self, key: str) -> Callable:
        def callback(text: str) -> None:
            if self._inactive():
                return
            assert self.core is not None
            outcome = self.core.on_input(key, text, self.now_s())
            if outcome.heard == "no_keyword":
                self.get_logger().info(f"{key} {outcome.text!r} has no keyword: observation {outcome.symbol!r} "
                                       f"({self.core.counters()['unknown_speech']} such texts so far)",
                                       throttle_duration_sec=1.0)
            if outcome.kind == "invalid":
                self.get_logger().warning(f"{key} {outcome.text!r} maps to no observation symbol of {self.model.name}; "
                                          f"ignored (invalid {key} inputs: {self.core.counters()[f'invalid_{key}']})",
                                          throttle_duration_sec=1.0)
                self._diagnostics_soon()
                return
            self._handle(outcome)

        return callback

    def _input_callback(self, key: str) -> Callable:
        """A symbol or number input's callback (``data``: the text, or the message's number)."""
        def callback(data) -> None:
            if self._inactive():
                return
            assert self.core is not None
            outcome = self.core.on_input(key, data, self.now_s())
            if outcome.kind == "invalid":
                channel = next(c for c in self.core.channels if c.name == key)
                valid = (", ".join(sorted(self.core.symbols(key))) if channel.kind == "symbol"
                         else f"a number in {list(channel.range or ())}, or one of {', '.join(channel.symbols)}")
                self.get_logger().warning(f"{key} input {data!r} is not a {key} {channel.kind} "
                                          f"(valid: {valid}); ignored (invalid {key} inputs: "
                                          f"{self.core.counters()[f'invalid_{key}']})", throttle_duration_sec=1.0)
                self._diagnostics_soon()
                return
            self._handle(outcome)

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
    def _handle(self, outcome: InputOutcome) -> None:
        """Act on what the core did: publish a closed step's belief, follow the deadline, log."""
        # The belief goes out first: logging and diagnostics must not delay the policy. The journal
        # comes before it: a tracker killed after publishing must not resume a step behind what
        # the policy answered (the policy would answer the older step again).
        if outcome.closed is not None:
            self._journal()
            self._publish_belief(outcome.closed.action, outcome.closed.observation)
        self._arm_deadline()
        for event in outcome.events:
            # One line per event; a flood of one kind is cut to one line per second of the
            # node's clock (sim time under /clock, so a fast-forwarded demo still shows each
            # of its events; rclpy's own throttle counts wall time). The counters are exact.
            if self._event_due(event.kind or event.text, self.now_s()):
                self._log(event.level, event.text)
        if self._warning_total() > self._reported_warnings:
            self._diagnostics_soon()
        self._journal()

    def _resume(self, state) -> str:
        """Carry on from a journal's state (the core checks it); what was resumed, for the log."""
        assert self.core is not None
        self.core.resume(state)
        return (f"step {self.core.step}, open step {self.core.open_action or 'none'}, "
                f"{self.core.pending} observation(s) queued")

    def _journal(self) -> None:
        """Journal the core's state when it changed (after the belief went out)."""
        core = self.core
        if self.journal is not None and core is not None:
            key = (core.run, core.step, core.open_action, core.opened_at, core.deadline(), core.pending,
                   core.counters()["queued"])
            self.journal.write(key, core.journal_state)

    def _log(self, level: str, text: str) -> None:
        if level == "warn":
            self.get_logger().warning(text)
        else:
            self.get_logger().info(text)

    def _arm_deadline(self) -> None:
        """Keep the one-shot timer in step with the core's deadline (armed while a step can time out)."""
        timer = self._deadline_timer
        deadline = self.core.deadline() if self.core is not None else None
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

    def _publish_belief(self, action: Optional[str] = None, observation: Optional[str] = None) -> None:
        """The current belief and its marginals (with the step's action and observation, if one closed).

        Without ``state_names``: the marginals' features and values name every state already (the
        state order is their mixed radix; a flat model's one feature lists its states), and Pearl's
        576 names of ~133 characters made each message 85 kB instead of 4.7 kB."""
        assert self.core is not None
        belief = self.core.belief
        self.belief_pub.publish(cv.belief_to_msg(belief, self.core.marginals(belief), self.core.step, action,
                                                 observation, (), self.now_s(), run=self.core.run))

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
        step, open_action, pending = self.core.snapshot()
        values = {"step": step, "open_action": open_action or "", "pending": pending, **self.counters()}
        if self.core.last_nav_failure:
            values["last_nav_failure"] = self.core.last_nav_failure
        if self.journal is not None:
            values.update(self.journal.diagnostics())
        level = cv.DIAG_WARN if warnings else cv.DIAG_OK
        text = f"{warnings} input(s) dropped, invalid or recovered" if warnings else "tracking"
        nav = values.get("nav_failures", 0)
        if nav:
            text = f"{text}; {nav} drive(s) missed their deadline (last: {self.core.last_nav_failure})"
        self.diag_pub.publish(cv.diagnostics_to_msg(f"pearl: {self.get_name()}", self.model.name, level, text,
                                                    values, self.now_s()))


def main(args: Optional[List[str]] = None) -> int:
    """Console script ``belief_tracker``: exit 0 on SIGINT/SIGTERM, 2 on a start-up error."""
    return run_node(BeliefTrackerNode, args)


if __name__ == "__main__":
    sys.exit(main())
