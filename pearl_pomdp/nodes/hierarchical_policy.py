"""The hierarchical policy node: beliefs in, primitive actions out (docs/design.md §4, §6).

For every belief it runs EXECUTE top-down (root → … → primitive) and publishes the
primitive action and the trace. All planning happens at start-up, before spinning: a
callback only evaluates α-vectors (py_trees#420: a tick must be near-instant).

A person in the loop (docs/ros-nodes.md, "Operator"): every decision goes through the core's
:class:`~pearl_pomdp.operator.OperatorGate` — the autonomy level (``full`` / ``confirm`` /
``off``), the operator's yes/no, veto and command — and every operator input and what became
of it is published on the events topic, so a bag records it.
"""
from __future__ import annotations

import collections
import os
import sys
import time
from dataclasses import replace
from typing import Any, Deque, List, Optional, Tuple

import numpy as np
from rclpy.parameter import Parameter

from pearl_pomdp.errors import BeliefError, PolicyError
from pearl_pomdp.online.decider import DEFAULT_TIME_GUARD
from pearl_pomdp.nodes import conversions as cv
from pearl_pomdp.nodes.common import (EVENT_QOS, LATCHED_QOS, SETTINGS_TOPIC, NodeSetupError, Param,
                                      load_domain_and_model, resolve_path, run_node)
from pearl_pomdp.nodes.defaults import FileDefaults
from pearl_pomdp.nodes.journaling import JOURNAL_PARAMETERS, NodeJournal
from pearl_pomdp.nodes.managed import AUTOSTART, ManagedPearlNode
from pearl_pomdp.operator import AUTONOMY_LEVELS, BY_SERVICE, GateOutput, OperatorGate
from pearl_pomdp.sros2_policy import OPERATOR_PARAMETERS, security_notice

#: The parameters an operator may change while the node runs (``ros2 param set``).
OPERATOR_LIVE = ("autonomy", "confirm_categories", "confirm_timeout")

__all__ = ["HierarchicalPolicyNode", "load_decider", "main"]


def resolve_policy(policy: str) -> str:
    """The ``policy`` parameter as the node loads it: a file or directory looked up as every node
    parameter is (:func:`~pearl_pomdp.nodes.common.resolve_path`), an ``online[:TRIALS]`` spec or ``""``
    as given.

    Raises:
        NodeSetupError: no such file or directory. PolicyError: a malformed ``online`` spec.
    """
    from pearl_pomdp.online.decider import online_trials

    if policy and online_trials(policy, "parameter policy") is None:
        return str(resolve_path(policy, "policy", kind="policy file or directory"))
    return policy


def load_decider(model, domain, policy: str, hierarchy: str, logger=None, time_guard: Optional[float] = None):
    """The decider the node runs: :func:`pearl_pomdp.deciders.load_decider` (the one reader of a
    policy spec: a saved hierarchical policy directory, a flat ``.npz`` policy, ``online[:TRIALS]``,
    or empty to PLAN now from ``hierarchy``), with what a node adds: a relative path is looked up as
    every node parameter is (:func:`~pearl_pomdp.nodes.common.resolve_path`), the errors name the
    node's parameters, and planning at start-up is logged.

    Raises:
        NodeSetupError: nothing to load, a missing file, a malformed spec or time guard.
    """
    from pearl_pomdp.deciders import load_decider as load_spec

    hierarchy_path = None
    try:
        policy = resolve_policy(policy)
        if not policy:
            if not hierarchy:
                raise NodeSetupError("parameters policy and hierarchy are both empty: give a planned policy "
                                     "(policy:=DIR from `pearl plan --out DIR`) or a hierarchy to plan at start-up")
            hierarchy_path = resolve_path(hierarchy, "hierarchy")
            if logger is not None:
                logger.info(f"planning {hierarchy_path} at start-up (pass policy:=DIR to skip)")
        start = time.perf_counter()
        decider = load_spec(policy, model, domain, hierarchy=hierarchy_path, time_guard=time_guard,
                            where="parameter policy", guard_where="parameter online_time_guard")
    except PolicyError as err:
        raise NodeSetupError(str(err)) from None
    if hierarchy_path is not None and logger is not None:
        logger.info(f"planned in {time.perf_counter() - start:.2f} s")
    return decider


class HierarchicalPolicyNode(ManagedPearlNode):
    """Answers each belief with a primitive action (EXECUTE of the hierarchical policy).

    Parameters (read-only):
        * ``domain`` (str): factored domain ``.yaml`` (or flat ``.pomdp`` with a flat policy).
        * ``hierarchy`` (str): action hierarchy ``.yaml``; planned at start-up when ``policy`` is empty.
        * ``policy`` (str): a planned policy — a directory from ``pearl plan --out DIR``
          (hierarchical) or an ``.npz`` file (flat); empty: plan at start-up.
        * ``diagnostics_period`` (double, s): period of the /diagnostics summary.
        * ``belief_topic``, ``action_topic``, ``decision_topic`` (str): topic names.
        * ``defaults_file`` (str, ``config/pearl_nodes.yaml``): params file giving the defaults
          (:mod:`pearl_pomdp.nodes.defaults`; ``''``: none).
        * ``use_sim_time`` (bool): follow /clock.
        * ``journal`` (str, ``auto``), ``journal_max_age`` (double, s): the journal of the step last
          acted and the operator's level (:mod:`pearl_pomdp.nodes.journaling`); a restarted node
          does not answer that step's belief again and keeps the level the operator set;
          ``journal_sync`` (str, ``background``) as the tracker's.

    Parameters (changeable at run time, the operator's):
        * ``autonomy`` (str): ``full`` (act), ``confirm`` (wait for a yes) or ``off`` (propose only).
        * ``confirm_categories`` (str[]): under ``confirm``, the action categories that wait
          (the domain's ``category:`` tags); empty: every action.
        * ``confirm_timeout`` (double, s): how long an action waits for the answer; then it is not acted.
        * ``veto_topic``, ``command_topic``, ``confirm_service``, ``proposal_topic``,
          ``operator_events_topic`` (str, read-only): the operator interfaces' names.

    Subscribers:
        * ``/pearl/belief`` (pearl_interfaces/Belief, TRANSIENT_LOCAL): the tracker's belief.

    Publishers:
        * ``/pearl/action`` (pearl_interfaces/Action, TRANSIENT_LOCAL depth 1): the primitive action.
        * ``/pearl/decision`` (pearl_interfaces/Decision): the step, the belief step it answers, the
          action, the EXECUTE trace (subtask, choice, value), the decision's latency (belief message
          received → action published, wall clock), the beliefs its forward search expanded (0: the
          one-step choice only) and an online search's record (``has_search``, ``search``).
        * ``/diagnostics`` (diagnostic_msgs/DiagnosticArray): decisions, rejected beliefs and
          latency p50/p99/max over the last 1000 decisions; one ERROR status per refused operator input.
        * ``/pearl/proposal`` (pearl_interfaces/OperatorProposal, TRANSIENT_LOCAL depth 1): the step's current
          action and its status (:meth:`~pearl_pomdp.operator.OperatorGate.proposal`).
        * ``/pearl/operator/events`` (pearl_interfaces/OperatorEvent): every operator event
          (:class:`~pearl_pomdp.operator.OperatorEvent`).

    Operator inputs:
        * ``/pearl/operator/veto`` (std_msgs/String): an action name; masked for this step, the
          policy re-decides at once when it was the choice.
        * ``/pearl/operator/command`` (std_msgs/String): an action name, published as the robot's action.
        * ``/pearl/operator/confirm`` (std_srvs/SetBool service): yes/no to the waiting action.
        * ``/pearl/operator/set_autonomy`` (pearl_interfaces/SetAutonomy service): the level, and the
          confirm categories / timeout when given; set as the parameters (a bad level is refused).
        * ``/pearl/operator/veto_action``, ``/pearl/operator/command_action`` (pearl_interfaces/Veto,
          Command services): the veto and command with a reply (accepted, what happened or why not).

    In-process use: ``HierarchicalPolicyNode(context=ctx, parameter_overrides={...}, domain=dom,
    model=model, decider=d)`` — ``decider`` (anything with ``.execute(belief) -> Decision``)
    skips loading/planning; ``domain``/``model`` skip loading the domain file.

    Raises:
        NodeSetupError: missing file, nothing to plan from (one line).
    """

    DEFAULT_NAME = "hierarchical_policy"
    PARAMETERS = (
        Param("domain", "config/pearl.domain.yaml", "Factored domain (.yaml) or flat model (.pomdp) file"),
        Param("hierarchy", "config/pearl.hierarchy.yaml", "Action hierarchy (.yaml); planned at start-up "
                                                         "when policy is empty"),
        Param("policy", "", "Planned policy: directory from `pearl plan --out DIR`, or flat .npz; "
                            "online or online:TRIALS: plan online (DESPOT) at every belief; empty: plan at start-up"),
        Param("online_time_guard", DEFAULT_TIME_GUARD, "With policy online: wall-clock seconds after which a "
                                                       "decision's search stops at its next expansion (a guard; "
                                                       "the budget is TRIALS); 0: no guard", range=(0.0, 3600.0)),
        Param("diagnostics_period", 1.0, "Seconds between /diagnostics summaries", range=(0.01, 3600.0)),
        Param("belief_topic", "/pearl/belief", "Belief input (pearl_interfaces/Belief)"),
        Param("action_topic", "/pearl/action", "Primitive action output (pearl_interfaces/Action)"),
        Param("decision_topic", "/pearl/decision", "EXECUTE trace output (pearl_interfaces/Decision)"),
        Param("autonomy", "full", f"Autonomy level: {' / '.join(AUTONOMY_LEVELS)} (full acts, confirm waits for "
                                  "the operator's yes, off only proposes); changeable at run time", read_only=False),
        Param("confirm_categories", [], "Under confirm, the action categories that wait for a yes (the domain's "
                                          "category: tags); empty: every action; changeable at run time",
              read_only=False, type=Parameter.Type.STRING_ARRAY),
        Param("confirm_timeout", 30.0, "Seconds an action waits for the operator's answer before it is not acted; "
                                       "changeable at run time", read_only=False, range=(0.001, 86400.0)),
        Param("veto_topic", "/pearl/operator/veto", "Operator's veto: an action name (std_msgs/String)"),
        Param("command_topic", "/pearl/operator/command", "Operator's command: an action name, acted as the "
                                                          "robot's (std_msgs/String)"),
        Param("confirm_service", "/pearl/operator/confirm", "Operator's yes/no to the waiting action "
                                                            "(std_srvs/SetBool)"),
        Param("set_autonomy_service", "/pearl/operator/set_autonomy", "Operator's autonomy level (and confirm "
                                                                      "settings) (pearl_interfaces/SetAutonomy)"),
        Param("veto_service", "/pearl/operator/veto_action", "Operator's veto with a reply (pearl_interfaces/Veto)"),
        Param("command_service", "/pearl/operator/command_action", "Operator's command with a reply "
                                                                  "(pearl_interfaces/Command)"),
        Param("proposal_topic", "/pearl/proposal", "The step's action and its status "
                                                   "(pearl_interfaces/OperatorProposal)"),
        Param("operator_events_topic", "/pearl/operator/events", "Every operator event "
                                                                 "(pearl_interfaces/OperatorEvent)"),
        *JOURNAL_PARAMETERS,
        AUTOSTART,
    )

    def __init__(self, *, domain=None, model=None, decider=None, **kwargs):
        super().__init__(**kwargs)
        # Defaults from the params file's /** and hierarchical_policy sections (``defaults_file``),
        # so a node started alone behaves as under the launch file.
        self.params = p = self.declare_table(FileDefaults(self).apply(self.PARAMETERS))
        self._preloaded = (domain, model, decider)
        self.decider = None
        self.decisions = 0
        self.rejected = 0
        self.inactive_beliefs = 0  # beliefs that arrived while not active (not answered)
        self.latencies: Deque[float] = collections.deque(maxlen=1000)
        self.last_decision = None
        self.gate: Optional[OperatorGate] = None
        self.operator_rejected = 0      # operator inputs refused (unknown action, nothing to veto …)
        self.operator_inputs = 0        # operator inputs taken (veto, command, yes/no; refused ones too)
        self.beliefs_answered = 0       # beliefs the gate decided at (the veto's re-decisions not counted)
        self.actions_published = 0      # actions put on action_topic (policy's, confirmed, commanded)
        self.inactive_operator = 0      # operator inputs while not active (not acted)
        self._confirm_srv: Optional[Any] = None
        self._operator_srvs: List[Any] = []
        self._confirm_timer: Optional[Any] = None
        self.repeated_beliefs = 0       # beliefs of a (run, step) already answered (a restarted tracker's)
        self._held_belief: Optional[Any] = None   # the latest belief that came while inactive
        self._belief_key: Optional[Tuple[int, int]] = None   # (run, step) of the belief being answered
        self._acted_key: Optional[Tuple[int, int]] = None    # … of the last one an action was published for
        self.journal: Optional[NodeJournal] = None
        self.diag_pub = self.create_publisher(cv.DiagnosticsMsg, "/diagnostics", EVENT_QOS)
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self._security_said = False
        self.start(p["autostart"])

    def _say_if_unsecured(self) -> None:
        """Once, when the operator's topics and services first come up: without DDS security anyone
        on the domain may command the robot; say so."""
        if self._security_said:
            return
        self._security_said = True
        names = ([self.resolve_topic_name(self.params[p]) for p in OPERATOR_PARAMETERS["publishes"]]
                 + [self.resolve_service_name(self.params[p]) for p in OPERATOR_PARAMETERS["calls"]])
        notice = security_notice(os.environ, self.context.get_domain_id(), names)
        if notice:
            self.get_logger().warning(notice)

    def configure_node(self) -> None:
        """Load the domain and the policy (or PLAN it); create the topics."""
        p = self.params
        domain, model, decider = self._preloaded
        if model is None:
            domain, model = load_domain_and_model(resolve_path(p["domain"], "domain"))
        self.domain, self.model = domain, model
        self.decider = decider if decider is not None else load_decider(model, domain, p["policy"],
                                                                        p["hierarchy"], self.get_logger(),
                                                                        time_guard=p["online_time_guard"])
        categories = getattr(domain, "categories", {}) if domain is not None else {}
        try:
            self.gate = OperatorGate(self.decider, model.actions, categories, autonomy=p["autonomy"],
                                     confirm_categories=_categories(p["confirm_categories"]),
                                     confirm_timeout=p["confirm_timeout"])
        except ValueError as err:
            raise NodeSetupError(f"parameter {err}") from None
        self.journal = NodeJournal(self, "hierarchical_policy", p, model,
                                   domain.source if domain is not None else p["domain"])
        self.journal.resume(self._resume)
        self.settings_pub = self.lifecycle_publisher(cv.SettingsMsg, SETTINGS_TOPIC, LATCHED_QOS)
        self.action_pub = self.lifecycle_publisher(cv.ActionMsg, p["action_topic"], LATCHED_QOS)
        self.decision_pub = self.lifecycle_publisher(cv.DecisionMsg, p["decision_topic"], EVENT_QOS)
        self.proposal_pub = self.lifecycle_publisher(cv.OperatorProposalMsg, p["proposal_topic"], LATCHED_QOS)
        # Depth 100: a burst of events (a veto re-deciding, a command withdrawing) reaches the recorder.
        self.operator_events_pub = self.lifecycle_publisher(cv.OperatorEventMsg, p["operator_events_topic"],
                                                            _deep(EVENT_QOS, 100))
        self.managed_subscription(cv.BeliefMsg, p["belief_topic"], self._on_belief, LATCHED_QOS)
        self.managed_subscription(cv.TextMsg, p["veto_topic"], self._operator_input("veto"), EVENT_QOS)
        self.managed_subscription(cv.TextMsg, p["command_topic"], self._operator_input("command"), EVENT_QOS)
        from std_srvs.srv import SetBool

        from pearl_interfaces.srv import Command, SetAutonomy, Veto

        self._confirm_srv = self.create_service(SetBool, p["confirm_service"], self._on_confirm)
        self._operator_srvs = [
            self.create_service(SetAutonomy, p["set_autonomy_service"], self._on_set_autonomy),
            self.create_service(Veto, p["veto_service"], self._operator_service("veto")),
            self.create_service(Command, p["command_service"], self._operator_service("command"))]
        self._say_if_unsecured()
        # One-shot timer for the waiting action's deadline (node clock: sim time under /clock).
        self._confirm_timer = self.managed_timer(p["confirm_timeout"], self._on_confirm_deadline)
        self._confirm_timer.cancel()
        self.managed_timer(p["diagnostics_period"], self.publish_diagnostics)
        self.get_logger().info(f"policy ready for {model.name} ({type(self.decider).__name__}); autonomy "
                               f"{self.gate.autonomy}")

    def cleanup_node(self) -> None:
        self._held_belief = None
        self.decider = None
        self.gate = None
        if self._confirm_srv is not None:
            self.destroy_service(self._confirm_srv)
            self._confirm_srv = None
        for srv in self._operator_srvs:
            self.destroy_service(srv)
        self._operator_srvs = []
        self._confirm_timer = None

    def replay_settings(self) -> dict:
        """What a replay of a recorded bag needs from this node: the domain and the policy it runs (as
        files it resolved, or the ``online`` spec; the policy ``""`` when planned from the hierarchy at
        start-up, which a replay cannot redo) and the operator settings it starts with."""
        p = self.params
        try:   # configure loaded both from these, so they resolve; a preloaded graph's may not
            domain, policy = str(resolve_path(p["domain"], "domain")), resolve_policy(p["policy"])
        except (NodeSetupError, PolicyError):
            domain, policy = str(p["domain"]), str(p["policy"])
        return {"domain": domain, "policy": policy,
                "autonomy": self.gate.autonomy if self.gate is not None else str(p["autonomy"]),
                "confirm_categories": list(p["confirm_categories"]) or [""]}

    def activate_node(self) -> None:
        """Publish :meth:`replay_settings` (latched, for a recorder), then answer the latest belief
        that came while inactive (a restarted node gets the tracker's latched belief between
        configure and activate): a step nobody answered would stall."""
        self.settings_pub.publish(cv.settings_to_msg(self.get_fully_qualified_name(), self.replay_settings(),
                                                     self.now_s()))
        held, self._held_belief = self._held_belief, None
        if held is not None:
            self._on_belief(held)

    def _on_belief(self, msg) -> None:
        if not self.active or self.decider is None:
            self.inactive_beliefs += 1   # a deactivated policy does not act now; the latest is answered on activate
            self._held_belief = msg
            return
        start = time.perf_counter()
        try:
            belief = cv.msg_to_belief(msg, self.model.num_states)
        except BeliefError as err:
            self.rejected += 1
            self.get_logger().error(f"rejected belief on {self.params['belief_topic']}: {err}")
            self.publish_diagnostics()
            return
        assert self.gate is not None   # configured with the decider
        key = cv.msg_to_belief_key(msg)
        if key is not None and key in (self._belief_key, self._acted_key):
            # A restarted tracker publishes the belief it resumed; this step has its answer already.
            self.repeated_beliefs += 1
            self.get_logger().info(f"belief of run {key[0]} step {key[1]} was answered already: not again")
            return
        self._belief_key = key
        self.beliefs_answered += 1
        self._apply(self.gate.on_belief(belief, self.now_s()), start)

    # ------------------------------------------------------------ operator
    def _apply(self, out: GateOutput, start: float) -> None:
        """Publish what the gate decided: actions first (the loop waits on them), then the record."""
        assert self.gate is not None
        for action in out.publish:
            self.action_pub.publish(cv.action_to_msg(action, self.now_s()))
            self.actions_published += 1
            self._acted_key = self._belief_key
        try:
            self._publish_record(out, time.perf_counter() - start)
        finally:
            # Whatever happens to the record (a stop signal shuts the context down under this
            # callback, and the next publish raises), what went out is journaled: a restarted
            # policy must not act on this belief again.
            self._journal_acted()

    def _publish_record(self, out: GateOutput, latency: float) -> None:
        """The decisions, the operator's proposal and events, and the confirmation deadline."""
        assert self.gate is not None
        for decision in out.decisions:
            self.latencies.append(latency)
            self.decision_pub.publish(cv.decision_to_msg(self.decisions, decision.action_name, decision.trace,
                                                         latency, getattr(decision, "expansions", 0),
                                                         belief_step=self.gate.step,
                                                         search=getattr(decision, "search", None),
                                                         stamp_s=self.now_s()))
            self.decisions += 1
            self.last_decision = decision
        if out.proposal_changed:
            self.proposal_pub.publish(cv.proposal_to_msg(self.gate.proposal()))
        for event in out.events:
            self.operator_events_pub.publish(cv.operator_event_to_msg(event))
            if event.kind not in ("acted", "rejected"):
                self.get_logger().info(f"operator: {event.kind} {event.action}"
                                       + (f" ({event.detail})" if event.detail else ""))
        self._arm_confirm_deadline()

    def _journal_acted(self) -> None:
        """Journal the step last acted on and the operator's settings, when they changed."""
        if self.journal is not None and self.gate is not None:
            gate = self.gate
            settings = (gate.autonomy, tuple(gate.confirm_categories), gate.confirm_timeout)
            self.journal.write((self._acted_key, settings), lambda: {
                "acted": list(self._acted_key) if self._acted_key is not None else None,
                "autonomy": settings[0], "confirm_categories": list(settings[1]), "confirm_timeout": settings[2]})

    def _resume(self, state) -> str:
        """Carry on from a journal: the step last acted (its belief is not answered again) and the
        operator's level (set as the parameters too). Raises ``ValueError`` when it does not fit."""
        assert self.gate is not None
        try:
            acted = state.get("acted")
            key = None if acted is None else (int(acted[0]), int(acted[1]))
            autonomy, categories = str(state["autonomy"]), _categories(state["confirm_categories"])
            timeout = float(state["confirm_timeout"])
        except (KeyError, TypeError, ValueError, IndexError) as err:
            raise ValueError(f"journal state: missing or malformed field ({type(err).__name__}: {err})") from None
        self.gate.set_level(self.now_s(), autonomy, categories, timeout)   # checked: ValueError names the setting
        self._acted_key = key
        self.set_parameters([Parameter("autonomy", Parameter.Type.STRING, autonomy),
                             Parameter("confirm_categories", Parameter.Type.STRING_ARRAY, categories or [""]),
                             Parameter("confirm_timeout", Parameter.Type.DOUBLE, timeout)])
        step = "none" if key is None else f"run {key[0]} step {key[1]}"
        return f"last acted {step}; autonomy {autonomy}"

    def _operator_input(self, what: str):
        def callback(msg) -> None:
            self.operator_request(what, cv.msg_to_text(msg).strip(), self.params[f"{what}_topic"])

        return callback

    def _operator_service(self, what: str):
        def handler(request, response):
            response.accepted, response.message = self.operator_request(what, request.action.strip(),
                                                                        self.params[f"{what}_service"], by_service=True)
            return response

        return handler

    def operator_request(self, what: str, action: str, via: str, by_service: bool = False) -> Tuple[bool, str]:
        """The operator's veto or command of ``action``, received on ``via`` (a topic or, ``by_service``,
        a service: then its vetoed/commanded event's detail ends with :data:`BY_SERVICE`, so that a
        replay, which has no record of the call, does it again from the event) → ``(accepted, message)``."""
        if not self.active or self.gate is None:
            self.inactive_operator += 1   # a deactivated policy does not act
            return False, "not active: the policy does not act"
        start = time.perf_counter()
        self.operator_inputs += 1
        out = self.gate.veto(action, self.now_s()) if what == "veto" else self.gate.command(action, self.now_s())
        if by_service:
            out.events = [replace(e, detail=f"{e.detail}; {BY_SERVICE}" if e.detail else BY_SERVICE)
                          if e.kind in ("vetoed", "commanded") else e for e in out.events]
        self._apply(out, start)
        if out.error is not None:
            self._refused(f"{via}: {out.error}")
            return False, out.error
        return True, "; ".join(f"{e.kind} {e.action}" + (f" ({e.detail})" if e.detail else "") for e in out.events)

    def _on_set_autonomy(self, request, response):
        """``/pearl/operator/set_autonomy`` (pearl_interfaces/SetAutonomy): the level (and, when given,
        the confirm categories and timeout), set as the node's parameters (checked by the core)."""
        from rclpy.parameter import Parameter

        params = [Parameter("autonomy", Parameter.Type.STRING, request.level.strip())]
        if request.confirm_categories:
            params.append(Parameter("confirm_categories", Parameter.Type.STRING_ARRAY, list(request.confirm_categories)))
        if request.confirm_timeout > 0:
            params.append(Parameter("confirm_timeout", Parameter.Type.DOUBLE, float(request.confirm_timeout)))
        result = self.set_parameters_atomically(params)
        response.accepted = bool(result.successful)
        response.message = (f"autonomy {self.get_parameter('autonomy').value}" if result.successful
                            else f"{self.params['set_autonomy_service']}: {result.reason}")
        return response

    def _refused(self, text: str) -> None:
        """One operator input was refused: one ERROR status on /diagnostics, naming the topic."""
        self.operator_rejected += 1
        self.get_logger().error(text)
        values = {"operator_rejected": self.operator_rejected}
        self.diag_pub.publish(cv.diagnostics_to_msg(f"pearl: {self.get_name()}: operator", self.model.name,
                                                    cv.DIAG_ERROR, text, values, self.now_s()))

    def _on_confirm(self, request, response):
        """``/pearl/operator/confirm`` (std_srvs/SetBool): yes publishes the waiting action, no drops it."""
        response.success, response.message = self.answer(bool(request.data))
        return response

    def answer(self, yes: bool):
        """The operator's yes/no to the waiting action (what the confirm service calls; a replay
        calls it too) → ``(success, message)``."""
        if not self.active or self.gate is None:
            return False, "not active: nothing is waiting for a confirmation"
        self.operator_inputs += 1
        waiting = self.gate.current
        out = self.gate.answer(yes, self.now_s())
        self._apply(out, time.perf_counter())
        if out.error is not None:
            self.get_logger().warning(f"{self.params['confirm_service']}: {out.error}")
            return False, out.error
        return True, f"{'published' if yes else 'declined (not acted)'} {waiting}"

    def _arm_confirm_deadline(self) -> None:
        timer, gate = self._confirm_timer, self.gate
        if timer is None or gate is None:
            return
        deadline = gate.deadline()
        if deadline is None:
            timer.cancel()
            return
        now_ns = self.get_clock().now().nanoseconds
        timer.timer_period_ns = max(1, int(round(deadline * 1e9)) - now_ns)
        timer.reset()

    def _on_confirm_deadline(self) -> None:
        if self._confirm_timer is not None:
            self._confirm_timer.cancel()   # one-shot; re-armed by _apply
        if self.gate is not None:
            self._apply(self.gate.on_tick(self.now_s()), time.perf_counter())

    def _on_set_parameters(self, params):
        """Run-time changes of the autonomy level and its settings, checked by the core first."""
        from rcl_interfaces.msg import SetParametersResult

        live = {param.name: param.value for param in params if param.name in OPERATOR_LIVE}
        if not live or self.gate is None:
            return SetParametersResult(successful=True)   # not configured: the value is read at configure
        if "confirm_categories" in live:
            live["confirm_categories"] = _categories(live["confirm_categories"])
        try:
            out = self.gate.set_level(self.now_s(), **live)
        except ValueError as err:
            return SetParametersResult(successful=False, reason=str(err))
        if self.active:
            self._apply(out, time.perf_counter())
        return SetParametersResult(successful=True)

    def publish_diagnostics(self) -> None:
        """Publish decision count, rejected beliefs and latency percentiles on /diagnostics."""
        lat = np.array(self.latencies) if self.latencies else np.zeros(1)
        values = {"decisions": self.decisions, "rejected_beliefs": self.rejected,
                  "latency_p50_ms": f"{np.percentile(lat, 50) * 1e3:.3f}",
                  "latency_p99_ms": f"{np.percentile(lat, 99) * 1e3:.3f}",
                  "latency_max_ms": f"{lat.max() * 1e3:.3f}"}
        values["inactive_beliefs"] = self.inactive_beliefs
        values["repeated_beliefs"] = self.repeated_beliefs
        if self.journal is not None:
            values.update(self.journal.diagnostics())
        if self.gate is not None:
            values.update(autonomy=self.gate.autonomy, operator_rejected=self.operator_rejected,
                          inactive_operator=self.inactive_operator,
                          **{f"operator_{k}": v for k, v in sorted(self.gate.counts.items())})
        level = cv.DIAG_WARN if self.rejected or self.operator_rejected else cv.DIAG_OK
        self.diag_pub.publish(cv.diagnostics_to_msg(f"pearl: {self.get_name()}", self.model.name, level,
                                                    f"{self.decisions} decisions", values, self.now_s()))


def _categories(values) -> List[str]:
    """A string-array parameter's categories (blank entries dropped: ``[""]`` is none, as in a YAML file)."""
    return [v for v in (values or []) if v]


def _deep(qos, depth: int):
    from rclpy.qos import QoSProfile

    return QoSProfile(depth=depth, history=qos.history, reliability=qos.reliability, durability=qos.durability)


def main(args: Optional[List[str]] = None) -> int:
    """Console script ``hierarchical_policy``: exit 0 on SIGINT/SIGTERM, 2 on a start-up error."""
    return run_node(HierarchicalPolicyNode, args)


if __name__ == "__main__":
    sys.exit(main())
