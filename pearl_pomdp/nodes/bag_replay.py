"""Replay a bag's recorded inputs through the belief tracker and hierarchical policy.

One process, one executor, simulated time (docs/design.md §6 "One loop, and in one process", §8): the real
node classes of :mod:`pearl_pomdp.nodes` (built by :class:`~pearl_pomdp.nodes.graph.PearlGraph`)
receive, in file order,

* every ``/clock`` message of the bag (``rosgraph_msgs/Clock``), and
* every message of the tracker's input topics — the inputs its domain declares (Pearl's:
  ``/pearl/speech``, ``/pearl/touchscreen``, ``/pearl/laser``, ``/pearl/reminder``), each with its
  declared message type — and the drives' progress (``/pearl/drive_progress``, which moves a
  drive's deadline, when the bag has it),

published as the recorded bytes (``publish`` of raw CDR: nothing is re-serialised). The
actions the policy publishes on ``/pearl/action`` are collected and compared with the
``/pearl/action`` messages recorded in the bag, and the beliefs the tracker publishes on
``/pearl/belief`` with the recorded ones (``max_belief_difference``: the parity check of a
change to the tracker — the shipped bags replay to the same beliefs within 1e-12).

Lock-step, not wall-clock pacing: after each ``/clock`` the replay waits until the nodes'
clocks show the new time and every timer that became due has run; after each input it
waits until the tracker has consumed it (one of its counters moved) and, when that closed
a step, until the policy's answer has been published and has reached the tracker again.
So the result does not depend on machine speed; a missing answer ends the wait after
``step_timeout_s`` wall seconds and shows up as a mismatch, never as a hang.

Clock coalescing (default; ``coalesce_clock=False`` turns it off): of a run of ``/clock``
messages with no input between them, only those that cross the next node-timer deadline
(read from the nodes' own timers) and the last one before an input are fed. Node
callbacks only run on messages and timers, so the nodes see the same clock at every input
and every timer fires at the same sim time as with every /clock fed — but
a bag with /clock at a simulator's rate replays several times faster. ``clock_skipped``
counts the /clock messages not fed.

The nodes' ``diagnostics_period`` is set to an hour during a replay: /diagnostics is not
compared, and its timers would only add stops to the lock-step.

The graph's configuration comes from the bag's ``custom_data`` (written by the recording
script): ``pearl.domain``, ``pearl.policy`` (paths relative to the bag directory; a policy may also be
the spec ``online[:TRIALS]``, planned again at every belief),
``pearl.tracker_params`` (JSON of belief-tracker parameter overrides; a bag without it — ``pearl record``
beside a launched graph — uses the step rules and places the tracker published on
``/belief_tracker/settings`` or declared on ``/parameter_events``: :func:`recorded_tracker_parameters`;
``pearl.domain``, ``pearl.policy`` and ``pearl.policy_params`` likewise come from what the policy node
published on ``/hierarchical_policy/settings`` when the bag lacks them: :func:`recorded_settings`)
and, optionally,
``pearl.policy_params`` (JSON of policy-node overrides: the autonomy level the run started with)
and ``pearl.params_file`` (the robot's node params file, relative to the bag directory; empty: the
nodes' code defaults, as a world without a params file ran them; absent: the shipped one, as for
the nursing-home robot).

A person in the loop (docs/ros-nodes.md, "Operator") is replayed too: the recorded vetoes and
commands (``/pearl/operator/veto``, ``/pearl/operator/command``) are fed to the policy in
bag order, and of the recorded operator events (``/pearl/operator/events``) the operator's
own acts that are not topics are done again at their place: ``autonomy`` sets the recorded
settings, ``confirmed``/``declined`` answer yes/no. A confirmation timeout happens by itself
on the recorded /clock. With ``explain`` each step lists the operator events of the replay.
"""
from __future__ import annotations

import json
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Dict, List, Optional, Tuple, Union

from pearl_pomdp.bags import well_known as wk
from pearl_pomdp.bags.reader import BagError, BagReader, cdr_string
from pearl_pomdp.errors import BeliefError, PearlError
from pearl_pomdp.operator import BY_SERVICE

ACTION_TOPIC = "/pearl/action"
#: The action's message type, and the types a replay reads it as (a bag recorded before the typed
#: action holds the name in a std_msgs/String).
ACTION_TYPE = "pearl_interfaces/msg/Action"
ACTION_TYPES = (ACTION_TYPE, wk.STRING_TYPE)
BELIEF_TOPIC = "/pearl/belief"
#: Beliefs equal to this (max abs difference) count as the same in :attr:`ReplayResult.beliefs_match`.
BELIEF_TOLERANCE = 1e-12
DECISION_TOPIC = "/pearl/decision"
DRIVE_PROGRESS_TYPE = "pearl_interfaces/msg/DriveProgress"
#: custom_data keys of a replayable bag.
KEY_DOMAIN, KEY_POLICY, KEY_TRACKER = "pearl.domain", "pearl.policy", "pearl.tracker_params"
KEY_POLICY_PARAMS = "pearl.policy_params"
KEY_PARAMS_FILE = "pearl.params_file"
OPERATOR_EVENTS_TOPIC = "/pearl/operator/events"
PARAMETER_EVENTS_TOPIC = "/parameter_events"
#: Recorded operator events a replay does again (the others follow from them and the inputs).
REENACTED = ("autonomy", "confirmed", "declined")


@dataclass
class ReplayResult:
    """What a replay produced.

    Attributes:
        actions: actions the policy published during the replay, in order.
        expected_actions: the ``/pearl/action`` messages recorded in the bag.
        match: ``actions == expected_actions``.
        messages: bag messages replayed (inputs and /clock fed, recorded outputs compared).
        fed: messages published into the graph (inputs + /clock).
        clock_skipped: /clock messages not fed because a later one made them unobservable.
        seconds: wall time of the replay loop (graph start-up and planning excluded).
        messages_per_second: ``messages / seconds``.
        first_mismatch: index of the first differing action, or ``None``.
        counters: the tracker's counters at the end (updates, timeouts, unknown words, …).
        beliefs: how many beliefs the tracker published (b0 and one per closed step).
        expected_beliefs: how many ``/pearl/belief`` messages the bag holds.
        max_belief_difference: the largest ``|b_replayed − b_recorded|`` over the beliefs both have
            (``None`` when the bag recorded none).
        beliefs_match: as many beliefs as recorded, each within :data:`BELIEF_TOLERANCE`.
        operator_events: the kinds of the operator events the replay produced, in order.
        expected_operator_events: the kinds recorded on ``/pearl/operator/events``.
        tracker_params_from: where the tracker's step rules and places came from: ``custom_data``
            (``pearl.tracker_params``), ``belief_tracker/settings`` or ``/parameter_events`` (what
            the recorded tracker published), or ``defaults`` (the params file's: the bag says nothing).
    """

    bag: str
    actions: List[str]
    expected_actions: List[str]
    match: bool
    messages: int
    fed: int
    seconds: float
    messages_per_second: float
    first_mismatch: Optional[int] = None
    counters: Dict[str, int] = field(default_factory=dict)
    clock_skipped: int = 0
    explanation: Optional[List[Dict[str, Any]]] = None
    divergence: Optional[Dict[str, Any]] = None
    beliefs: int = 0
    expected_beliefs: int = 0
    max_belief_difference: Optional[float] = None
    beliefs_match: bool = False
    operator_events: List[str] = field(default_factory=list)
    expected_operator_events: List[str] = field(default_factory=list)
    tracker_params_from: str = "custom_data"

    def to_dict(self) -> Dict[str, Any]:
        out = {"bag": self.bag, "match": self.match, "actions": self.actions,
               "expected_actions": self.expected_actions, "first_mismatch": self.first_mismatch,
               "messages": self.messages, "fed": self.fed, "seconds": round(self.seconds, 6),
               "messages_per_second": round(self.messages_per_second, 1), "clock_skipped": self.clock_skipped,
               "counters": self.counters, "beliefs": self.beliefs, "expected_beliefs": self.expected_beliefs,
               "max_belief_difference": self.max_belief_difference, "beliefs_match": self.beliefs_match,
               "tracker_params_from": self.tracker_params_from}
        if self.operator_events or self.expected_operator_events:
            out["operator_events"] = self.operator_events
            out["expected_operator_events"] = self.expected_operator_events
        if self.explanation is not None:
            out["steps"] = self.explanation
            out["divergence"] = self.divergence
        return out


def _clock_ns(data: bytes) -> int:
    """The time in a CDR-encoded rosgraph_msgs/Clock, in ns."""
    import struct

    if len(data) < 12:
        raise ValueError(f"{len(data)} bytes is shorter than a CDR Clock (12)")
    fmt = "<iI" if data[1] == 1 else ">iI"
    sec, nsec = struct.unpack_from(fmt, data, 4)
    return sec * 1_000_000_000 + nsec


def recorded_beliefs(reader: BagReader) -> List[List[float]]:
    """The ``/pearl/belief`` messages recorded in the bag, in order, each the complete ``b(s)``:
    pearl_interfaces/msg/Belief's (complete or by its support; a bag recorded before the support
    holds complete ones, read by the definition it stores: ``conversions.recorded_belief_msg``), or the
    std_msgs/msg/Float64MultiArray of a bag recorded before the typed interfaces."""
    from rclpy.serialization import deserialize_message

    if BELIEF_TOPIC not in reader.topics:
        return []
    if reader.topics[BELIEF_TOPIC].type == "std_msgs/msg/Float64MultiArray":
        from std_msgs.msg import Float64MultiArray

        return [_belief_values(deserialize_message(m.data, Float64MultiArray)) for m in reader.read_messages([BELIEF_TOPIC])]
    from pearl_pomdp.nodes import conversions as cv

    where = f"{reader.path}: topic {BELIEF_TOPIC}"
    definition = reader.topics[BELIEF_TOPIC].definition
    try:
        return [cv.msg_to_belief(cv.recorded_belief_msg(m.data, definition, where)).tolist()
                for m in reader.read_messages([BELIEF_TOPIC])]
    except BeliefError as err:
        raise BagError(str(err) if str(err).startswith(where) else f"{where}: {err}") from None


def _belief_values(msg) -> List[float]:
    """A ``Float64MultiArray`` belief's ``b(s)`` (a bag recorded before the typed Belief), without
    any padding before it (``layout.data_offset``)."""
    return list(msg.data)[msg.layout.data_offset:]


def expected_actions(reader: BagReader) -> List[str]:
    """The recorded ``/pearl/action`` names: ``pearl_interfaces/msg/Action``, or the ``std_msgs/msg/String``
    of a bag recorded before the typed action (BagError naming the offending message)."""
    recorded = reader.topics[ACTION_TOPIC].type if ACTION_TOPIC in reader.topics else ACTION_TYPE
    if recorded not in ACTION_TYPES:
        raise BagError(f"{reader.path}: topic {ACTION_TOPIC}: recorded as {recorded}, replay reads "
                       f"{' or '.join(ACTION_TYPES)}")
    offset = 8 if recorded == ACTION_TYPE else 0     # the Action's stamp comes before its name
    out = []
    for i, m in enumerate(reader.read_messages([ACTION_TOPIC])):
        try:
            out.append(cdr_string(m.data, offset).strip())
        except (ValueError, UnicodeDecodeError) as err:
            raise BagError(f"{reader.path}: topic {ACTION_TOPIC}: message {i} (log time {m.log_time}) "
                           f"is not a {recorded}: {err}") from None
    return out


def _check_topics(reader: BagReader, inputs: Optional[Dict[str, str]] = None) -> None:
    """The recorded types of the action, clock and (given ``{topic: type}``) input topics."""
    want = dict(inputs or {})
    want[wk.CLOCK_TOPIC] = wk.CLOCK_TYPE
    for name, info in reader.topics.items():
        if name in want and info.type != want[name]:
            raise BagError(f"{reader.path}: topic {name}: recorded as {info.type}, replay needs {want[name]}")
    if ACTION_TOPIC not in reader.topics:
        raise BagError(f"{reader.path}: topic {ACTION_TOPIC} was not recorded: nothing to compare the replay with")
    if reader.topics[ACTION_TOPIC].type not in ACTION_TYPES:
        raise BagError(f"{reader.path}: topic {ACTION_TOPIC}: recorded as {reader.topics[ACTION_TOPIC].type}, "
                       f"replay needs {' or '.join(ACTION_TYPES)}")


def recorded_settings(reader: BagReader) -> Dict[str, Dict[str, Any]]:
    """Node name (its namespace dropped) → what it published, latched, on its
    :data:`~pearl_pomdp.nodes.common.SETTINGS_TOPIC` when it was activated: the first readable such
    message of the bag per node, in one pass over it. A bag from before the nodes published them has none."""
    from rclpy.serialization import deserialize_message

    from pearl_pomdp.nodes import conversions as cv
    from pearl_pomdp.nodes.common import SETTINGS_TOPIC

    suffix = "/" + SETTINGS_TOPIC.lstrip("~/")
    out: Dict[str, Dict[str, Any]] = {}
    for m in reader.messages:
        if m.topic.endswith(suffix):
            node = m.topic[:-len(suffix)].rsplit("/", 1)[-1]
            if node not in out:
                try:
                    out[node] = cv.msg_to_settings(deserialize_message(m.data, cv.SettingsMsg))
                except Exception:   # a damaged message: as if there were none
                    continue
    return out


def recorded_tracker_parameters(reader: BagReader, published: Optional[Dict[str, Dict[str, Any]]] = None,
                                node: str = "belief_tracker") -> Tuple[Dict[str, Any], str]:
    """The belief tracker's step rules and places as the bag recorded them, and where from:

    * ``<node>/settings``: what the tracker published, latched, when it was activated
      (``published``, :func:`recorded_settings` of the bag when not given; a recorder started late gets
      it too);
    * else ``/parameter_events``: each setting's last value the node (in any namespace) declared or set
      before the bag's first belief or action (a recorder that matched only later misses them);
    * else nothing (``"defaults"``: the replay runs the params file's values).

    So a bag that ``pearl record`` made beside a launched graph replays with the step timeout and the
    places the robot ran with, not the shipped defaults (the simulator's launch file sets an 8 s step
    timeout where the shipped params file has 10 s: every silent step then closed at another time)."""
    from rclpy.serialization import deserialize_message

    from pearl_pomdp.nodes import conversions as cv
    from pearl_pomdp.nodes.belief_tracker import is_replayed_setting

    own = (recorded_settings(reader) if published is None else published).get(node)
    if own is not None:
        return {k: v for k, v in own.items() if is_replayed_setting(k)}, f"{node}/settings"
    events: Dict[str, Any] = {}
    for m in reader.messages:
        if m.topic in (ACTION_TOPIC, BELIEF_TOPIC):
            break   # later changes (a live parameter set mid-run) are not the run's start
        if m.topic != PARAMETER_EVENTS_TOPIC:
            continue
        try:
            event = deserialize_message(m.data, cv.SettingsMsg)
        except Exception:
            continue
        if event.node.rsplit("/", 1)[-1] == node:
            renamed = cv.SettingsMsg(new_parameters=list(event.new_parameters) + list(event.changed_parameters))
            events.update({k: v for k, v in cv.msg_to_settings(renamed).items() if is_replayed_setting(k)})
    return (events, PARAMETER_EVENTS_TOPIC) if events else ({}, "defaults")


def replay_config(reader: BagReader, domain: Optional[str] = None, policy: Optional[str] = None) -> Dict[str, Any]:
    """Domain, policy and tracker parameters for replaying ``reader``'s bag (PearlError if missing).

    The tracker's parameters are the bag's ``pearl.tracker_params``; a bag without that key (one
    ``pearl record`` made beside a launched graph) replays with those the tracker published or declared
    in it (:func:`recorded_tracker_parameters`); ``tracker_params_from`` says which."""
    from pearl_pomdp.online.decider import online_trials

    custom = (reader.metadata or {}).get("custom_data") or {}
    base = reader.path if reader.path.is_dir() else reader.path.parent
    # The policy node's own record of its domain, policy and starting autonomy (absolute paths of the
    # machine that recorded): what a bag of `pearl record` beside `pearl launch` replays with.
    published = recorded_settings(reader)
    policy_node = published.get("hierarchical_policy", {})

    def path_of(key: str, given: Optional[str]) -> str:
        value = given if given is not None else custom.get(key) or policy_node.get(key.split(".")[1])
        if not value:
            raise PearlError(f"{reader.path}: custom_data has no {key!r} and the policy node published none: "
                             f"pass --{key.split('.')[1]} to replay it")
        if key == KEY_POLICY and online_trials(value, key) is not None:
            return value      # planned online at every belief (a spec, not a file)
        p = Path(value)
        if given is None and not p.is_absolute():
            p = base / p
        if not p.exists():
            raise PearlError(f"{reader.path}: custom_data {key}: {p} does not exist")
        return str(p)

    def params_of(key: str) -> Dict[str, Any]:
        try:
            value = json.loads(custom.get(key) or "{}")
            if not isinstance(value, dict):
                raise ValueError("not a JSON object")
        except ValueError as err:
            raise PearlError(f"{reader.path}: custom_data {key}: {err}") from None
        return value

    if KEY_TRACKER in custom:
        tracker, source = params_of(KEY_TRACKER), "custom_data"
    else:
        tracker, source = recorded_tracker_parameters(reader, published)
    policy_params = (params_of(KEY_POLICY_PARAMS) if KEY_POLICY_PARAMS in custom
                     else {k: policy_node[k] for k in ("autonomy", "confirm_categories") if k in policy_node})
    return {"domain": path_of(KEY_DOMAIN, domain), "policy": path_of(KEY_POLICY, policy),
            "tracker_params": tracker, "tracker_params_from": source, "policy_params": policy_params,
            # Another robot's node params (its tracker rules); recorded empty: the nodes' code defaults
            # (a world without a params file); absent (an older bag): the shipped file.
            "params_file": (path_of(KEY_PARAMS_FILE, None) if custom.get(KEY_PARAMS_FILE)
                            else None if KEY_PARAMS_FILE in custom else "default")}


def _graph_options() -> Dict[str, Any]:
    """PearlGraph options for a replay: no parameter services (nobody calls them, and twelve
    fewer services make every executor wait cheaper), where this PearlGraph supports it."""
    import inspect

    from pearl_pomdp.nodes.graph import PearlGraph

    return {"parameter_services": False} if "parameter_services" in inspect.signature(PearlGraph).parameters else {}


def _recorded_decisions(reader: BagReader) -> List[Dict[str, Any]]:
    """The ``/pearl/decision`` messages of the bag in their plain form (``conversions.msg_to_decision``):
    ``pearl_interfaces/msg/Decision``, or the JSON ``std_msgs/msg/String`` of a bag recorded before
    the typed interfaces (same keys). Empty when not recorded; ``{}`` for a message that does not decode."""
    if DECISION_TOPIC not in reader.topics:
        return []
    from pearl_pomdp.nodes import conversions as cv

    decode = _plain_decoder(reader, DECISION_TOPIC, "DecisionMsg", cv.msg_to_decision)
    out = []
    for m in reader.read_messages([DECISION_TOPIC]):
        try:
            out.append(decode(m.data))
        except Exception:   # a truncated or foreign message: that step shows no recorded trace
            out.append({})
    return out


def _top_marginals(marginals: Dict[str, Dict[str, float]]) -> Dict[str, List[Any]]:
    """Per feature its most probable value and that probability."""
    out = {}
    for feature, values in marginals.items():
        value, p = max(values.items(), key=lambda kv: kv[1])
        out[feature] = [value, round(float(p), 4)]
    return out


def _decision_record(d: Dict[str, Any]) -> Dict[str, Any]:
    """What --explain keeps of one /pearl/decision: the action, the trace and, for an online
    search, its record (size, root bounds and gap, seconds, the top of the tree)."""
    out = {"action": d.get("action"), "trace": d.get("trace", [])}
    if d.get("search") is not None:
        out["search"] = d["search"]
    return out


def explain_steps(history, decisions: List[Dict[str, Any]], marginals_of,
                  operator_events: Optional[List[Dict[str, Any]]] = None) -> List[Dict[str, Any]]:
    """Why each action was taken: per closed step, what closed it, the belief after, and the
    EXECUTE trace (with values) of the decision that answered that belief.

    Args:
        history: the tracker's closed :class:`~pearl_pomdp.tracking.StepResult` s, in order.
        decisions: the policy's ``/pearl/decision`` objects (decision 0 answers ``b0``). A
            decision with ``belief_step`` answers that belief; of several (a veto's re-decision)
            the last is the one that stood.
        marginals_of: belief → ``{feature: {value: p}}``.
        operator_events: the policy's ``/pearl/operator/events`` objects; each step lists those
            of its belief (``step``) when the operator did anything there.
    """
    by_step: Dict[int, Dict[str, Any]] = {}
    for i, d in enumerate(decisions):
        by_step[int(d.get("belief_step", i))] = d
    events: Dict[int, List[Dict[str, Any]]] = {}
    for e in operator_events or []:
        events.setdefault(int(e.get("step", -1)), []).append(
            {k: e.get(k) for k in ("event", "action", "stamp", "autonomy", "detail")})
    for k in [k for k, listed in events.items() if all(e["event"] == "acted" for e in listed)]:
        del events[k]   # the policy acted, nobody intervened: nothing to say
    steps = []
    if decisions:
        d0 = by_step.get(0, {})
        steps.append({"step": 0, "closed_by": None, "belief": None,
                      "decision": _decision_record(d0),
                      "operator": events.get(0, [])})
    for k, r in enumerate(history, start=1):
        d = by_step.get(k, {})
        steps.append({
            "step": k, "time": round(r.time, 6), "action": r.action,
            "closed_by": {"input": r.source, "text": r.text, "symbol": r.observation,
                          "confidence": r.confidence, "zero_likelihood": r.zero_likelihood},
            "belief": _top_marginals(marginals_of(r.belief)),
            "decision": _decision_record(d),
            "operator": events.get(k, []),
        })
    return steps


def _plain_decoder(reader: BagReader, topic: str, msg_type_name: str, to_plain) -> Any:
    """``bytes -> plain dict`` for ``topic`` of the bag: the typed message (``msg_type_name`` of
    ``conversions``, read by ``to_plain``), or the JSON std_msgs/String of a bag recorded before the
    typed interfaces."""
    if reader.topics[topic].type == wk.STRING_TYPE:
        return lambda data: json.loads(cdr_string(data))
    from rclpy.serialization import deserialize_message

    from pearl_pomdp.nodes import conversions as cv

    msg_type = getattr(cv, msg_type_name)
    return lambda data: to_plain(deserialize_message(data, msg_type))


def _recorded_operator_events(reader: BagReader) -> List[Any]:
    """The recorded operator events in their plain form (``conversions.msg_to_operator_event``)."""
    if OPERATOR_EVENTS_TOPIC not in reader.topics:
        return []
    from pearl_pomdp.nodes import conversions as cv

    decode = _plain_decoder(reader, OPERATOR_EVENTS_TOPIC, "OperatorEventMsg", cv.msg_to_operator_event)
    out = []
    for m in reader.read_messages([OPERATOR_EVENTS_TOPIC]):
        try:
            out.append(decode(m.data))
        except Exception as err:   # (CDR or JSON): the bag is not what a replay can redo
            raise BagError(f"{reader.path}: topic {OPERATOR_EVENTS_TOPIC}: message at log time {m.log_time} "
                           f"is not an operator event: {err}") from None
    return out


def _reenacted(event: Dict[str, Any]) -> bool:
    """An operator act the bag holds only as its event: an autonomy change, a yes/no, and a veto or
    command given through the policy's service (the topics' are fed from their own messages)."""
    kind = event.get("event")
    return kind in REENACTED or (kind in ("vetoed", "commanded")
                                 and str(event.get("detail", "")).endswith(BY_SERVICE))


def _reenact(driver, event: Dict[str, Any]) -> None:
    """Do again an operator act the bag holds only as an event (see the module doc)."""
    kind = event.get("event")
    if kind == "autonomy":
        from rclpy.parameter import Parameter

        settings = event.get("settings") or {"autonomy": event.get("autonomy")}
        params = [Parameter("autonomy", Parameter.Type.STRING, str(settings["autonomy"]))]
        if "confirm_categories" in settings:
            params.append(Parameter("confirm_categories", Parameter.Type.STRING_ARRAY,
                                    [str(c) for c in settings["confirm_categories"]]))
        if "confirm_timeout" in settings:
            params.append(Parameter("confirm_timeout", Parameter.Type.DOUBLE, float(settings["confirm_timeout"])))
        driver.graph.policy.set_parameters_atomically(params)
        driver.settle()
    elif kind in ("confirmed", "declined"):
        driver.answer(kind == "confirmed")
    elif kind in ("vetoed", "commanded"):
        what = "veto" if kind == "vetoed" else "command"
        policy = driver.graph.policy
        policy.operator_request(what, str(event.get("action")), policy.params[f"{what}_service"], by_service=True)
        driver.settle()


def replay_bag(path: Union[str, Path], *, domain: Optional[str] = None, policy: Optional[str] = None,
               domain_id: Optional[int] = None, step_timeout_s: float = 10.0, progress: bool = False,
               coalesce_clock: bool = True, explain: bool = False) -> ReplayResult:
    """Replay ``path`` (bag directory or .mcap) and compare the actions; see the module doc.

    Args:
        domain, policy: override the bag's ``custom_data`` paths.
        domain_id: ROS domain of the private context (default: ``ROS_DOMAIN_ID`` / 0).
        step_timeout_s: wall seconds to wait for the graph's reaction to one message.
        progress: tqdm bar on stderr.
        coalesce_clock: skip a /clock that is followed by another /clock before any input
            and before the next node timer falls due (see the module doc); ``False`` feeds
            every /clock.
        explain: also say why (:func:`explain_steps`: per step the input that closed it, the
            belief after, the EXECUTE trace with its values) and where replay and recording
            first differ, with both traces when the bag recorded ``/pearl/decision``.

    Raises:
        BagError / PearlError: unreadable, truncated or wrong-typed bag; missing configuration.
    """
    reader = BagReader(path, salvage=False)
    _check_topics(reader)
    expected = expected_actions(reader)
    cfg = replay_config(reader, domain, policy)

    from std_msgs.msg import String

    from pearl_pomdp.nodes import conversions as cv
    from pearl_pomdp.nodes.common import EVENT_QOS
    from pearl_pomdp.nodes.graph import PearlGraph
    from pearl_pomdp.nodes.sim_clock import SimClockDriver

    # Diagnostics are not compared; slowing their timers keeps them out of the lock-step
    # (fewer timer deadlines to stop at). Nothing else about the nodes changes.
    quiet = {"diagnostics_period": 3600.0}
    overrides = {"belief_tracker": {**quiet, **dict(cfg["tracker_params"])},
                 "hierarchical_policy": {**quiet, **dict(cfg["policy_params"])}}
    graph = PearlGraph(domain_id=domain_id, use_sim_time=True, executor=False,
                       args=["--ros-args", "--disable-external-lib-logs", "--disable-rosout-logs", "--log-level", "warn"],
                       shared={"domain": cfg["domain"], "policy": cfg["policy"]}, overrides=overrides,
                       params_file=cfg.get("params_file", "default"), **_graph_options())
    try:
        # Phases of the shared sim-clock driver (pearl_pomdp.nodes.sim_clock): match, then per
        # bag message set_time (/clock, coalesced) or feed (an input), each settling the graph.
        driver = SimClockDriver(graph, wait_s=step_timeout_s)
        actions = driver.actions
        node = driver.node
        decisions: List[Dict[str, Any]] = []
        from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

        beliefs: List[List[float]] = []
        # Transient-local: b0, published when the tracker activated, arrives on matching.
        keep_all = QoSProfile(depth=100_000, reliability=ReliabilityPolicy.RELIABLE,
                              durability=DurabilityPolicy.TRANSIENT_LOCAL)
        belief_sub = node.create_subscription(cv.BeliefMsg, BELIEF_TOPIC,
                                              lambda m: beliefs.append(cv.msg_to_belief(m).tolist()), keep_all)
        core = graph.tracker.core
        assert core is not None  # the graph's tracker is configured (autostart)
        # The inputs are the tracker's (its domain's declarations, as its parameters remap them).
        from pearl_pomdp.nodes.channel_messages import reader_for

        input_types = {}
        for channel in core.channels:
            topic = graph.tracker.resolve_topic_name(graph.tracker.get_parameter(f"inputs.{channel.name}.topic").value)
            input_types[topic] = (channel.type, reader_for(channel, cfg["domain"]).msg_type)
        _check_topics(reader, {t: type_name for t, (type_name, _) in input_types.items()})
        if core.drive_timer is not None and graph.tracker.get_parameter("drive_progress_topic").value:
            # The navigation's progress moves drive deadlines: fed like an input (a bag recorded
            # through Nav2's action has it; one of the string era has not).
            topic = graph.tracker.resolve_topic_name(graph.tracker.get_parameter("drive_progress_topic").value)
            input_types.setdefault(topic, (DRIVE_PROGRESS_TYPE, cv.DriveProgressMsg))
        if explain:
            core.keep_history()
            node.create_subscription(cv.DecisionMsg, DECISION_TOPIC, lambda m: decisions.append(cv.msg_to_decision(m)),
                                     1000)
        replayed_events: List[Dict[str, Any]] = []
        node.create_subscription(cv.OperatorEventMsg, OPERATOR_EVENTS_TOPIC,
                                 lambda m: replayed_events.append(cv.msg_to_operator_event(m)),
                                 QoSProfile(depth=100_000, reliability=ReliabilityPolicy.RELIABLE,
                                            durability=DurabilityPolicy.VOLATILE))
        pubs = {t: node.create_publisher(msg_type, t, EVENT_QOS) for t, (_, msg_type) in input_types.items()
                if t in reader.topics}
        # The operator's topics (the policy's parameters name them): fed to the policy.
        policy_node = graph.policy
        operator_pubs = {}
        for param in ("veto_topic", "command_topic"):
            if policy_node.has_parameter(param):
                topic = policy_node.resolve_topic_name(policy_node.get_parameter(param).value)
                if topic in reader.topics:
                    operator_pubs[topic] = node.create_publisher(String, topic, EVENT_QOS)
        recorded_events = iter(_recorded_operator_events(reader))
        driver.wait_until_matched(list(pubs.values()) + list(operator_pubs.values()))
        # b0 before any input: the latched writer keeps only the latest belief.
        driver.wait(lambda: belief_sub.get_publisher_count() > 0 and bool(beliefs), "the tracker's b0")

        messages = fed = skipped = 0
        pending = None  # (bytes, t) of a /clock not yet fed: see coalesce_clock
        deadline = driver.next_timer_deadline()
        bar = None
        if progress:
            from tqdm import tqdm

            bar = tqdm(total=reader.message_count, unit="msg", desc="replay", file=__import__("sys").stderr)
        start = time.perf_counter()
        for m in reader.messages:
            messages += 1
            if bar is not None:
                bar.update(1)
            if m.topic == wk.CLOCK_TOPIC:
                try:
                    t = _clock_ns(m.data)
                except ValueError as err:
                    raise BagError(f"{reader.path}: topic {wk.CLOCK_TOPIC}: message at log time {m.log_time} "
                                   f"is not a rosgraph_msgs/Clock: {err}") from None
                if coalesce_clock:
                    if pending is not None:
                        skipped += 1  # superseded: no callback can run between the two
                        pending = None
                    if deadline is None or t < deadline:
                        # No node timer falls due by t: only the latest such /clock can
                        # matter, before the next input or the next due timer.
                        pending = (m.data, t)
                        continue
                driver.set_time(t, raw=m.data)
                fed += 1
                deadline = driver.next_timer_deadline()
            elif m.topic in pubs or m.topic in operator_pubs or m.topic == OPERATOR_EVENTS_TOPIC:
                event: Optional[Dict[str, Any]] = None
                if m.topic == OPERATOR_EVENTS_TOPIC:
                    event = next(recorded_events, {})
                if event is not None and not _reenacted(event):
                    continue   # an outcome: the replay makes its own
                if pending is not None:
                    driver.set_time(pending[1], raw=pending[0])
                    fed += 1
                    pending = None
                if event is not None:
                    _reenact(driver, event)
                elif m.topic in operator_pubs:
                    driver.feed_operator(operator_pubs[m.topic], m.data)
                else:
                    driver.feed(pubs[m.topic], m.data)
                fed += 1
                deadline = driver.next_timer_deadline()
        if pending is not None:
            driver.set_time(pending[1], raw=pending[0])
            fed += 1
        tracker = graph.tracker
        driver.wait(lambda: len(beliefs) >= 1 + core.step, "the beliefs")
        gate = getattr(graph.policy, "gate", None)
        if gate is not None:
            driver.wait(lambda: len(replayed_events) >= sum(gate.counts.values()), "the operator events")
        explanation = None
        if explain:
            driver.wait(lambda: len(decisions) >= graph.policy.decisions, "the decision traces")
            explanation = explain_steps(list(core.history or []), decisions, core.marginals, replayed_events)
        seconds = time.perf_counter() - start
        if bar is not None:
            bar.close()
        counters = dict(tracker.counters())
        operator_events = [str(e.get("event")) for e in replayed_events]
    finally:
        graph.shutdown()
    recorded = recorded_beliefs(reader)
    differences = [max((abs(x - y) for x, y in zip(a, b)), default=0.0) if len(a) == len(b) else float("inf")
                   for a, b in zip(beliefs, recorded)]
    max_difference = max(differences) if differences else None
    beliefs_match = (len(beliefs) == len(recorded) and
                     (max_difference is None or max_difference <= BELIEF_TOLERANCE))
    mismatch = next((i for i, (a, b) in enumerate(zip(actions, expected)) if a != b), None)
    if mismatch is None and len(actions) != len(expected):
        mismatch = min(len(actions), len(expected))
    divergence = None
    if explain and mismatch is not None:
        recorded_traces = _recorded_decisions(reader)
        divergence = {"action_index": mismatch,
                      "replayed": actions[mismatch] if mismatch < len(actions) else None,
                      "recorded": expected[mismatch] if mismatch < len(expected) else None,
                      "replayed_trace": (explanation[mismatch]["decision"]["trace"]
                                         if explanation and mismatch < len(explanation) else None),
                      "recorded_trace": (recorded_traces[mismatch].get("trace")
                                         if mismatch < len(recorded_traces) else None),
                      "closed_by": (explanation[mismatch]["closed_by"]
                                    if explanation and mismatch < len(explanation) else None)}
    return ReplayResult(bag=str(path), actions=actions, expected_actions=expected, match=actions == expected,
                        messages=messages, fed=fed, seconds=seconds,
                        messages_per_second=messages / seconds if seconds > 0 else 0.0,
                        first_mismatch=mismatch, counters=counters, clock_skipped=skipped,
                        explanation=explanation, divergence=divergence, beliefs=len(beliefs),
                        expected_beliefs=len(recorded), max_belief_difference=max_difference,
                        beliefs_match=beliefs_match, operator_events=operator_events,
                        expected_operator_events=[str(e.get("event")) for e in _recorded_operator_events(reader)],
                        tracker_params_from=cfg["tracker_params_from"])
