"""Conversions between the core's Python values and ROS 2 messages.

This is the only module of the project that builds or reads ROS message objects; the
nodes call the pairs below (``belief_to_msg`` / ``msg_to_belief``, …) so that message
types stay at the edge (py_trees_ros ``conversions.py`` style). The message classes the
nodes create publishers and subscriptions with are exported here too.

Wire formats (common_interfaces, and this project's pearl_interfaces):

* **belief** — ``pearl_interfaces/Belief``: the step it closes, that step's action and observation
  (empty for ``b0``), one ``FeatureMarginal`` per feature (value names and probabilities; a flat
  model without features reports one pseudo-feature ``"state"``), the model's ``num_states`` and the
  belief in the model's state order (for a factored domain: mixed radix, first feature most
  significant): complete (``probabilities[s] = b(s)``, ``support`` empty) or, when fewer than
  :data:`SPARSE_BELOW` of the states differ from one value — 0, or the uniform floor's after a
  zero-likelihood recovery —, by the states that do (``probabilities[i] = b(support[i])``, every
  other state ``outside_support``). :func:`belief_to_msg` names the states in ``state_names`` when
  asked (up to :data:`MAX_NAMED_STATES`), the tracker does not (the marginals name them already).
  A message recorded before ``num_states``, ``support`` and ``outside_support`` reads as complete
  (:func:`recorded_belief_msg`).
* **speech** — ``pearl_interfaces/RecognisedSpeech``: the recognised text, the recogniser's
  confidence in [0, 1] and, when the recogniser mapped it, the speech symbol; stamped. (Bags recorded
  before it hold the JSON ``{"text", "confidence"}`` in a ``std_msgs/String``.)
* **action** — ``pearl_interfaces/Action``: the primitive action's name, stamped (bags recorded
  before it hold the name in a ``std_msgs/String``).
* **touchscreen** / **laser** / **reminder** / **say** / **display** / the operator's veto and
  command — ``std_msgs/String``.
* **decision** — ``pearl_interfaces/Decision`` (``pearl_interfaces/msg/Decision.msg``): the step,
  the belief step it answers, the action, the EXECUTE trace root → … → primitive (``TraceStep``:
  subtask, choice, value; NaN: no α-vector), the forward search's expansions, ``latency_s`` (belief
  received → action published, wall clock) and an online search's ``SearchStats`` (``has_search``);
  ``step`` counts the beliefs this policy node answered before (0 for ``b0``).
* **world truth** — ``pearl_interfaces/WorldTruth`` (``/WORLD/sim/truth``, a simulator's): a world's
  truth record (:mod:`pearl_pomdp.world_truth`) field by field — its time, phase, action, the state as
  parallel feature-name and value arrays and, closing an action, its events and why it was wrong;
  stamped with the sim clock. (Bags recorded before it hold the record as JSON in a ``std_msgs/String``.)
* **nav goal** — ``geometry_msgs/PoseStamped`` (position x, y; orientation from yaw).
* **guide pace** — ``pearl_interfaces/GuidePace``: the guide_pace node's filter state (the guidance,
  the state, speeds, how far behind she is — NaN: not seen —, the wait, the times lost), stamped.
* **drive progress** — ``pearl_interfaces/DriveProgress``: the drive's action and place, Nav2's
  distance remaining (m) and estimated time remaining (s), stamped.
* **localised pose** — ``geometry_msgs/PoseWithCovarianceStamped`` (``/amcl_pose``) or
  ``nav_msgs/Odometry`` (``/odom``): planar x, y, yaw and the x/y standard deviation.
* **velocity** — ``geometry_msgs/Twist`` (``/cmd_vel_nav``, ``/cmd_vel``): linear.x, angular.z.
* **person** — ``geometry_msgs/PointStamped`` in the robot's base frame (x forward, y left).
* **diagnostics** — ``diagnostic_msgs/DiagnosticArray`` with one ``DiagnosticStatus``
  whose ``values`` are the node's counters.
"""
from __future__ import annotations

import array
import math
from typing import Any, Dict, Mapping, Optional, Sequence, Tuple

import numpy as np
from builtin_interfaces.msg import Time as TimeMsg
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import PoseStamped
from geometry_msgs.msg import PointStamped, PoseWithCovarianceStamped, Twist
from nav_msgs.msg import Odometry
from pearl_interfaces.msg import Action as ActionMsg
from pearl_interfaces.msg import Belief as BeliefMsg
from pearl_interfaces.msg import Decision as DecisionMsg
from pearl_interfaces.msg import DriveProgress as DriveProgressMsg
from pearl_interfaces.msg import FeatureMarginal as FeatureMarginalMsg
from pearl_interfaces.msg import GuidePace as GuidePaceMsg
from pearl_interfaces.msg import OperatorEvent as OperatorEventMsg
from pearl_interfaces.msg import OperatorProposal as OperatorProposalMsg
from pearl_interfaces.msg import RecognisedSpeech as RecognisedSpeechMsg
from pearl_interfaces.msg import SearchAction as SearchActionMsg
from pearl_interfaces.msg import SearchBranch as SearchBranchMsg
from pearl_interfaces.msg import SearchStats as SearchStatsMsg
from pearl_interfaces.msg import TraceStep as TraceStepMsg
from pearl_interfaces.msg import WorldTruth as WorldTruthMsg
from rcl_interfaces.msg import ParameterEvent
from rosgraph_msgs.msg import Clock
from std_msgs.msg import String

from pearl_pomdp.channels import SPEECH_TYPE, TEXT_TYPE
from pearl_pomdp.errors import BeliefError
from pearl_pomdp.speech import Utterance, parse_speech_message, utterance
from pearl_pomdp.world_truth import truth_from_msg

__all__ = [
    "MAX_NAMED_STATES", "ActionMsg", "BeliefMsg", "TextMsg", "DecisionMsg", "OperatorEventMsg", "OperatorProposalMsg",
    "operator_event_to_msg", "msg_to_operator_event", "proposal_to_msg", "msg_to_proposal", "PoseMsg", "DiagnosticsMsg", "ClockMsg",
    "SPARSE_BELOW", "belief_to_msg", "msg_to_belief", "msg_to_belief_key", "msg_to_marginals", "recorded_belief_msg",
    "text_to_msg", "msg_to_text", "action_to_msg", "msg_to_action",
    "decision_to_msg", "msg_to_decision", "pose_to_msg", "msg_to_pose",
    "diagnostics_to_msg", "msg_to_diagnostics", "seconds_to_time", "time_to_seconds",
    "clock_to_msg", "DIAG_OK", "DIAG_WARN", "DIAG_ERROR",
    "DriveProgressMsg", "drive_progress_to_msg", "msg_to_drive_progress",
    "RecognisedSpeechMsg", "speech_to_msg", "msg_to_speech", "input_to_msg",
    "GuidePaceMsg", "guide_pace_to_msg", "msg_to_guide_pace",
    "WorldTruthMsg", "truth_to_msg", "msg_to_truth",
]

#: Message classes used by the nodes (import them from here, not from the message packages).
TextMsg = String
#: A node's settings as one latched message (``~/settings``: nodes.common.SETTINGS_TOPIC): rcl_interfaces'
#: parameter event, its ``new_parameters`` the values.
SettingsMsg = ParameterEvent
PoseMsg = PoseStamped
DiagnosticsMsg = DiagnosticArray
ClockMsg = Clock

#: A belief message names its states (``state_names``) up to this many; a larger model's order is
#: the mixed radix of its features (first most significant), as the marginals list them.
MAX_NAMED_STATES = 4096

#: A belief goes by the states that differ from ``outside_support`` (index and value, 12 bytes a
#: state) when they are fewer than this fraction of its states; otherwise complete (8 bytes a state),
#: whichever is smaller.
SPARSE_BELOW = 2.0 / 3.0

#: The fields ``pearl_interfaces/Belief`` gained after bags were recorded with it, all at its end, with
#: their CDR (size, alignment): a message recorded before them is the prefix of today's layout
#: (:func:`recorded_belief_msg`).
BELIEF_FIELDS_ADDED = {"num_states": (4, 4), "support": (4, 4), "outside_support": (8, 8)}

#: ``DiagnosticStatus`` levels as ints (the message field is one byte).
DIAG_OK, DIAG_WARN, DIAG_ERROR = (DiagnosticStatus.OK[0], DiagnosticStatus.WARN[0], DiagnosticStatus.ERROR[0])


# ------------------------------------------------------------------------ time
def seconds_to_time(seconds: float) -> TimeMsg:
    """``builtin_interfaces/Time`` for a time in seconds (≥ 0), rounded to the nanosecond."""
    total = int(round(float(seconds) * 1e9))
    if total < 0:
        raise ValueError(f"time must be >= 0 s, got {seconds}")
    return TimeMsg(sec=total // 1_000_000_000, nanosec=total % 1_000_000_000)


def time_to_seconds(stamp: TimeMsg) -> float:
    """Seconds of a ``builtin_interfaces/Time``."""
    return stamp.sec + stamp.nanosec * 1e-9


def clock_to_msg(seconds: float) -> Clock:
    """``rosgraph_msgs/Clock`` for sim time ``seconds`` (what a sim-time driver publishes on /clock)."""
    return Clock(clock=seconds_to_time(seconds))


# ---------------------------------------------------------------------- belief
def belief_to_msg(belief: np.ndarray, marginals: Optional[Mapping[str, Mapping[str, float]]] = None, step: int = 0,
                  action: Optional[str] = None, observation: Optional[str] = None,
                  state_names: Sequence[str] = (), stamp_s: float = 0.0, run: int = 0) -> BeliefMsg:
    """A ``[S]`` belief as a ``pearl_interfaces/Belief``: ``probabilities`` in the model's state order
    (named by ``state_names`` when given and at most :data:`MAX_NAMED_STATES` long) — the states with
    ``b(s) != 0`` (or, when every state is above 0, those above the smallest value, ``outside_support``)
    and their ``support`` when they are fewer than :data:`SPARSE_BELOW` of the states, else every state,
    ``support`` empty (the values are ``b``'s, bit for bit) —, the per-feature
    ``marginals`` ``{feature: {value: p}}``, the step it closes and that step's action and observation;
    ``run`` the tracker's run (0: none), so a policy answers each ``(run, step)`` once even when a
    restarted tracker publishes it again (docs/reliability.md, "Crashes")."""
    b = np.asarray(belief, dtype=float)
    if b.ndim != 1:
        raise BeliefError(f"belief must be one-dimensional [S], got shape {b.shape}")
    if run < 0:
        raise BeliefError(f"belief run must be a whole number >= 0, got {run}")
    msg = BeliefMsg(stamp=seconds_to_time(max(0.0, stamp_s)), step=int(step), action=action or "",
                    observation=observation or "", run=int(run), num_states=b.size)
    support = np.flatnonzero(b)
    outside = 0.0
    if support.size == b.size:
        # Every state > 0 (a zero-likelihood recovery's uniform floor): most may share the smallest value.
        outside = float(b.min())
        # (A uniform belief lists its first state: an empty support would say "complete".)
        support = np.flatnonzero(b != outside) if (b != outside).any() else np.zeros(1, dtype=np.int64)
    # array('d') / array('I') are taken as is by the generated setters (a list is checked element by element).
    if support.size < SPARSE_BELOW * b.size:
        msg.support = array.array("I", support.astype(np.uint32).tobytes())
        msg.probabilities = array.array("d", b[support].tobytes())
        msg.outside_support = outside
    else:
        msg.probabilities = array.array("d", np.ascontiguousarray(b).tobytes())
    if state_names and len(state_names) <= MAX_NAMED_STATES:
        msg.state_names = [str(n) for n in state_names]
    msg.marginals = [FeatureMarginalMsg(feature=str(f), values=[str(v) for v in vals],
                                        probabilities=[float(p) for p in vals.values()])
                     for f, vals in (marginals or {}).items()]
    return msg


def msg_to_belief_key(msg: BeliefMsg) -> Optional[Tuple[int, int]]:
    """The ``(run, step)`` a tracker's belief message carries, or ``None`` (``run`` 0: no run, e.g. replay)."""
    run = int(getattr(msg, "run", 0))
    return (run, int(msg.step)) if run > 0 else None


def msg_to_belief(msg: BeliefMsg, num_states: Optional[int] = None) -> np.ndarray:
    """The ``[S]`` belief of a ``pearl_interfaces/Belief``: its ``probabilities``, complete or by its
    ``support`` (every state outside it ``outside_support``). A message without ``num_states`` and
    ``support`` (decoded with a definition from before them) is complete.

    Raises:
        BeliefError: (naming the field) ``support`` and ``probabilities`` differ in length, an index of
            ``support`` is not below ``num_states`` or not above the one before it, ``num_states``
            disagrees with a complete ``probabilities``, the state names disagree in number with the
            states, the size disagrees with ``num_states``, or the data is not a distribution.
    """
    values = np.asarray(msg.probabilities, dtype=float)
    support = getattr(msg, "support", ())
    states = int(getattr(msg, "num_states", 0))
    if len(support):
        if num_states is not None and states != num_states:   # (checked before a vector of that size is made)
            raise BeliefError(f"belief message: num_states is {states}, the model has {num_states}")
        b = _from_support(np.asarray(support, dtype=np.int64), values, states,
                          float(getattr(msg, "outside_support", 0.0)))
    else:
        b = values
        if states and b.size != states:
            raise BeliefError(f"belief message: num_states is {states} but probabilities (complete: support is empty) "
                              f"holds {b.size} values")
    if len(msg.state_names) and len(msg.state_names) != b.size:
        raise BeliefError(f"belief message names {len(msg.state_names)} states but carries {b.size} values")
    if num_states is not None and b.size != num_states:
        raise BeliefError(f"belief has {b.size} states, the model has {num_states}")
    if b.size == 0 or not np.isfinite(b).all() or (b < -1e-12).any() or abs(b.sum() - 1.0) > 1e-6:
        raise BeliefError(f"belief message is not a distribution (sum {b.sum():.9g}, min {b.min(initial=0):.3g})")
    return b


def _from_support(support: np.ndarray, values: np.ndarray, states: int, outside: float) -> np.ndarray:
    """The ``[states]`` belief with ``values`` at ``support`` and ``outside`` elsewhere (BeliefError
    naming the field)."""
    if support.size != values.size:
        raise BeliefError(f"belief message: support has {support.size} indices but probabilities {values.size} values")
    if states <= 0:
        raise BeliefError(f"belief message: support has {support.size} indices but num_states is 0")
    outside_range = (support >= states) | (support < 0)
    if outside_range.any():
        i = int(np.flatnonzero(outside_range)[0])
        raise BeliefError(f"belief message: support[{i}] = {int(support[i])} is not a state (num_states {states})")
    steps = np.diff(support)
    if (steps <= 0).any():
        i = int(np.flatnonzero(steps <= 0)[0]) + 1
        raise BeliefError(f"belief message: support is not increasing: support[{i - 1}] = {int(support[i - 1])}, "
                          f"support[{i}] = {int(support[i])}")
    if not (math.isfinite(outside) and outside >= 0.0):
        raise BeliefError(f"belief message: outside_support is {outside}, not a probability")
    b = np.full(states, outside)
    b[support] = values
    return b


def _root_fields(definition: str) -> Tuple[str, ...]:
    """The field names of a ``.msg`` definition as rosbag2 stores it (the root type's part, before the
    first ``====`` line of its dependencies; comments, constants and blank lines left out)."""
    names = []
    for line in definition.splitlines():
        if line.startswith("=" * 10):
            break
        text = line.split("#", 1)[0].strip()
        parts = text.split()
        if len(parts) >= 2 and "=" not in parts[1] and "=" not in parts[0]:
            names.append(parts[1])
    return tuple(names)


def recorded_belief_msg(data: bytes, definition: str, where: str = "/pearl/belief") -> BeliefMsg:
    """A recorded ``pearl_interfaces/Belief`` (its CDR bytes) read as today's message, by the definition
    the bag stores for it (``BagReader``'s ``TopicInfo.definition``): a message recorded before
    :data:`BELIEF_FIELDS_ADDED` lacks only those, at its end, so it reads with them at their defaults
    (``num_states`` 0, ``support`` empty, ``outside_support`` 0: its ``probabilities`` are the complete
    belief).

    Raises:
        BeliefError: (naming ``where``) the definition has other fields than today's or today's
            without the added ones, or the bytes do not decode as the message.
    """
    from rclpy.serialization import deserialize_message

    current = tuple(BeliefMsg.get_fields_and_field_types())
    older = tuple(f for f in current if f not in BELIEF_FIELDS_ADDED)
    recorded = _root_fields(definition) if definition.strip() else current
    if recorded == older:
        # Each added field at its default (zero bytes), aligned as CDR aligns it: from the payload's
        # start, after the 4-byte encapsulation header.
        out = bytearray(data)
        for size, align in BELIEF_FIELDS_ADDED.values():
            out += b"\0" * ((-(len(out) - 4)) % align + size)
        data = bytes(out)
    elif recorded != current:
        raise BeliefError(f"{where}: recorded as a pearl_interfaces/Belief with the fields {', '.join(recorded)}; "
                          f"this version reads {', '.join(current)} (or without {', '.join(BELIEF_FIELDS_ADDED)})")
    try:
        return deserialize_message(data, BeliefMsg)
    except Exception as err:   # rclpy's RMWError: the bytes are not this layout
        raise BeliefError(f"{where}: a recorded message does not decode as pearl_interfaces/Belief ({err})") from None


def msg_to_marginals(msg: BeliefMsg) -> dict:
    """The plain per-step form of a belief message: ``{"step", "action", "observation", "marginals":
    {feature: {value: p}}}`` (``action``/``observation`` ``None`` for ``b0``) — what the behaviour-tree
    baseline, the demos, ``pearl fit`` and the live view read."""
    return {"step": int(msg.step), "action": msg.action or None, "observation": msg.observation or None,
            "marginals": {m.feature: {v: float(p) for v, p in zip(m.values, m.probabilities)} for m in msg.marginals}}


# ---------------------------------------------------------------------- strings
def text_to_msg(text: str) -> String:
    """A ``std_msgs/String``."""
    return String(data=str(text))


def msg_to_text(msg: String) -> str:
    """The text of a ``std_msgs/String``."""
    return msg.data


def action_to_msg(action_name: str, stamp_s: float = 0.0) -> ActionMsg:
    """The primitive action as a ``pearl_interfaces/Action`` (its name, stamped ``stamp_s``)."""
    return ActionMsg(stamp=seconds_to_time(max(0.0, stamp_s)), name=str(action_name))


def msg_to_action(msg: ActionMsg) -> str:
    """The action name of an ``/pearl/action`` message (surrounding blanks removed)."""
    return msg.name.strip()


# ---------------------------------------------------------------------- speech
def speech_to_msg(text: str, confidence: float = 1.0, symbol: str = "", stamp_s: float = 0.0) -> RecognisedSpeechMsg:
    """What the recogniser heard as a ``pearl_interfaces/RecognisedSpeech`` (confidence clamped to [0, 1])."""
    conf = min(1.0, max(0.0, float(confidence))) if math.isfinite(float(confidence)) else 1.0
    return RecognisedSpeechMsg(stamp=seconds_to_time(max(0.0, stamp_s)), text=str(text), confidence=conf,
                               symbol=str(symbol))


def msg_to_speech(msg: RecognisedSpeechMsg) -> Utterance:
    """The :class:`~pearl_pomdp.speech.Utterance` of a ``pearl_interfaces/RecognisedSpeech``."""
    return utterance(msg.text, msg.confidence, msg.symbol)


def input_to_msg(type_name: str, data: str) -> Any:
    """The message an input of message type ``type_name`` carries for ``data``, a simulated world's
    text: a ``RecognisedSpeech`` for the typed speech input (``data`` plain text, or the JSON of
    :func:`pearl_pomdp.speech.speech_message` with its confidence), a ``std_msgs/String`` otherwise.

    Raises:
        ValueError: ``type_name`` is neither (a number input is not fed text).
    """
    if type_name == SPEECH_TYPE:
        text, confidence = parse_speech_message(data)
        return speech_to_msg(text, confidence)
    if type_name == TEXT_TYPE:
        return String(data=str(data))
    raise ValueError(f"an input of type {type_name} is not fed text (expected {SPEECH_TYPE} or {TEXT_TYPE})")


# ----------------------------------------------------------------- world truth
def truth_to_msg(record: Mapping[str, Any], stamp_s: float = 0.0) -> WorldTruthMsg:
    """A world's truth record (:mod:`pearl_pomdp.world_truth`: ``time``, ``phase``, ``action``, ``state``
    and, closing an action, ``events`` and ``wrong``) as a ``pearl_interfaces/WorldTruth`` stamped
    ``stamp_s`` (the sim clock); :func:`msg_to_truth` gives the record back."""
    state = record["state"]
    outcome = "events" in record or "wrong" in record
    return WorldTruthMsg(stamp=seconds_to_time(max(0.0, stamp_s)), world_time=float(record["time"]),
                         phase=str(record["phase"]), action=str(record.get("action") or ""),
                         feature_names=[str(f) for f in state], feature_values=[str(v) for v in state.values()],
                         has_outcome=outcome, events=[str(e) for e in record.get("events") or []],
                         wrong=str(record.get("wrong") or ""))


def msg_to_truth(msg: WorldTruthMsg) -> Dict[str, Any]:
    """The truth record of a ``pearl_interfaces/WorldTruth`` (:func:`pearl_pomdp.world_truth.truth_from_msg`)."""
    return truth_from_msg(msg, "WorldTruth")


def decision_to_msg(step: int, action_name: str, trace: Sequence, latency_s: float, expansions: int = 0,
                    belief_step: Optional[int] = None, search: Optional[Mapping] = None,
                    stamp_s: float = 0.0) -> DecisionMsg:
    """A ``pearl_interfaces/Decision``: the EXECUTE trace (root → … → primitive) and its record.

    Args:
        trace: items with ``subtask``, ``choice`` and ``value`` attributes (``TraceStep``) or dicts
            (a value ``None`` is NaN: no α-vector).
        expansions: beliefs the decision's forward search expanded (``Decision.expansions``).
        belief_step: the belief this decision answers (0: ``b0``), when it may differ from
            ``step`` (an operator's veto makes the policy decide again at the same belief);
            ``None``: ``step``.
        search: an online search's record (``SearchResult.as_dict()``), or ``None``.
        stamp_s: the node's clock (s).
    """
    steps = []
    for t in trace:
        get = (lambda k, d=None: t.get(k, d)) if isinstance(t, Mapping) else (lambda k, d=None: getattr(t, k, d))
        value, rival_value = get("value"), get("runner_up_value")
        steps.append(TraceStepMsg(subtask=str(get("subtask")), choice=str(get("choice")),
                                  value=math.nan if value is None else float(value),
                                  runner_up=str(get("runner_up") or ""),
                                  runner_up_value=math.nan if rival_value is None else float(rival_value)))
    msg = DecisionMsg(stamp=seconds_to_time(max(0.0, stamp_s)), step=int(step),
                      belief_step=int(step if belief_step is None else belief_step), action=str(action_name),
                      trace=steps, expansions=int(expansions), latency_s=float(latency_s))
    if search is not None:
        msg.has_search = True
        msg.search = _search_to_msg(search)
    return msg


_SEARCH_FIELDS = ("lower", "upper", "gap", "trials", "nodes", "expansions", "seconds", "stop")
_BRANCH_FIELDS = ("observation", "share", "lower", "upper", "expanded")


def _search_action(a: Mapping) -> SearchActionMsg:
    return SearchActionMsg(action=str(a["action"]), lower=float(a["lower"]), upper=float(a["upper"]),
                           reward=float(a.get("reward", math.nan)),
                           children=[SearchBranchMsg(observation=int(c["observation"]), share=float(c["share"]),
                                                     lower=float(c["lower"]), upper=float(c["upper"]),
                                                     expanded=bool(c["expanded"])) for c in a.get("children", ())])


def _search_to_msg(search: Mapping) -> SearchStatsMsg:
    top = search.get("top") or {}
    return SearchStatsMsg(lower=float(search.get("lower", math.nan)), upper=float(search.get("upper", math.nan)),
                          gap=float(search.get("gap", math.nan)), trials=int(search.get("trials", 0)),
                          nodes=int(search.get("nodes", 0)), expansions=int(search.get("expansions", 0)),
                          seconds=float(search.get("seconds", 0.0)), stop=str(search.get("stop", "")),
                          bounds=str(search.get("bounds", "")), scenarios=int(top.get("scenarios", 0)),
                          top=[_search_action(a) for a in top.get("actions", ())],
                          action_bounds=[_search_action(a) for a in search.get("action_bounds", ())])


def _search_from_msg(msg: SearchStatsMsg) -> dict:
    def action(a) -> dict:
        out = {"action": a.action, "lower": a.lower, "upper": a.upper,
               "children": [{k: getattr(c, k) for k in _BRANCH_FIELDS} for c in a.children]}
        if math.isfinite(a.reward):
            out["reward"] = a.reward
        return out

    body = {k: getattr(msg, k) for k in _SEARCH_FIELDS}
    body.update(bounds=msg.bounds, top={"lower": msg.lower, "upper": msg.upper, "scenarios": msg.scenarios,
                                        "actions": [action(a) for a in msg.top]},
                action_bounds=[{"action": a.action, "lower": a.lower, "upper": a.upper} for a in msg.action_bounds])
    return body


def _trace_step_from_msg(t) -> dict:
    """One ``TraceStep`` as :meth:`pearl_pomdp.interfaces.TraceStep.as_dict` gives it (a bag from
    before the runner-up fields decodes them empty: no ``runner_up`` key)."""
    out = {"subtask": t.subtask, "choice": t.choice, "value": t.value if math.isfinite(t.value) else None}
    rival = getattr(t, "runner_up", "")
    if rival:
        rival_value = float(getattr(t, "runner_up_value", math.nan))
        out["runner_up"] = rival
        out["runner_up_value"] = rival_value if math.isfinite(rival_value) else None
    return out


def msg_to_decision(msg: DecisionMsg) -> dict:
    """The plain form of a ``/pearl/decision`` message: ``{"step", "belief_step", "action", "trace":
    [{"subtask", "choice", "value"[, "runner_up", "runner_up_value"]}], "latency_s", "expansions"}`` (a NaN value is ``None``) and,
    for an online search, ``"search"`` (``lower, upper, gap, trials, nodes, expansions, seconds, stop,
    bounds, top, action_bounds``: the form ``OnlineDecider`` records)."""
    body = {"step": int(msg.step), "belief_step": int(msg.belief_step), "action": msg.action,
            "trace": [_trace_step_from_msg(t) for t in msg.trace],
            "latency_s": float(msg.latency_s), "expansions": int(msg.expansions)}
    if msg.has_search:
        body["search"] = _search_from_msg(msg.search)
    return body


# -------------------------------------------------------------------- operator
def operator_event_to_msg(event) -> OperatorEventMsg:
    """An :class:`~pearl_pomdp.operator.OperatorEvent` as a ``pearl_interfaces/OperatorEvent``."""
    msg = OperatorEventMsg(kind=event.kind, action=event.action, step=int(event.step), stamp=float(event.stamp),
                           autonomy=event.autonomy, detail=event.detail)
    if event.settings is not None:
        msg.has_settings = True
        msg.confirm_categories = [str(c) for c in event.settings.get("confirm_categories", ())]
        msg.confirm_timeout = float(event.settings.get("confirm_timeout", math.nan))
    return msg


def msg_to_operator_event(msg: OperatorEventMsg) -> dict:
    """The plain form of an operator event (``OperatorEvent.as_dict``: ``event, action, step, stamp,
    autonomy, detail`` and, for ``autonomy`` events, ``settings``)."""
    out = {"event": msg.kind, "action": msg.action, "step": int(msg.step), "stamp": float(msg.stamp),
           "autonomy": msg.autonomy, "detail": msg.detail}
    if msg.has_settings:
        out["settings"] = {"autonomy": msg.autonomy, "confirm_categories": list(msg.confirm_categories),
                           "confirm_timeout": float(msg.confirm_timeout)}
    return out


def proposal_to_msg(proposal: Mapping[str, Any]) -> OperatorProposalMsg:
    """``OperatorGate.proposal()`` as a ``pearl_interfaces/OperatorProposal`` (no deadline: NaN)."""
    deadline = proposal.get("deadline")
    return OperatorProposalMsg(step=int(proposal["step"]), action=str(proposal["action"]),
                               source=str(proposal["source"] or ""), status=str(proposal["status"] or ""),
                               autonomy=str(proposal["autonomy"]), vetoed=[str(v) for v in proposal["vetoed"]],
                               deadline=math.nan if deadline is None else float(deadline))


def msg_to_proposal(msg: OperatorProposalMsg) -> dict:
    """The plain form of a proposal (``OperatorGate.proposal()``; a NaN deadline is ``None``)."""
    return {"step": int(msg.step), "action": msg.action, "source": msg.source, "status": msg.status,
            "autonomy": msg.autonomy, "vetoed": list(msg.vetoed),
            "deadline": msg.deadline if math.isfinite(msg.deadline) else None}


# ------------------------------------------------------------- drive progress
def drive_progress_to_msg(action: str, place: str, distance_remaining: float, estimated_time_remaining: float,
                          stamp_s: float) -> DriveProgressMsg:
    """A running drive's progress (Nav2's feedback) as a ``pearl_interfaces/DriveProgress``."""
    return DriveProgressMsg(stamp=seconds_to_time(max(0.0, stamp_s)), action=str(action), place=str(place),
                            distance_remaining=float(distance_remaining),
                            estimated_time_remaining=float(estimated_time_remaining))


def msg_to_drive_progress(msg: DriveProgressMsg) -> Dict[str, Any]:
    """The plain form of a drive progress message: ``action, place, distance_remaining,
    estimated_time_remaining, stamp`` (seconds)."""
    return {"action": msg.action, "place": msg.place, "distance_remaining": float(msg.distance_remaining),
            "estimated_time_remaining": float(msg.estimated_time_remaining), "stamp": time_to_seconds(msg.stamp)}


# ----------------------------------------------------------------- guide pace
def guide_pace_to_msg(state: Mapping[str, Any], stamp_s: float = 0.0) -> GuidePaceMsg:
    """The guide_pace node's state ``{"active", "state", "speed", "nav_speed", "pace", "behind",
    "waited", "times_lost"}`` (``active``/``behind`` ``None``: no guidance / not seen) as a
    ``pearl_interfaces/GuidePace``."""
    behind = state.get("behind")
    return GuidePaceMsg(stamp=seconds_to_time(max(0.0, stamp_s)), active=str(state.get("active") or ""),
                        state=str(state["state"]), speed=float(state["speed"]), nav_speed=float(state["nav_speed"]),
                        pace=float(state["pace"]), behind=math.nan if behind is None else float(behind),
                        waited=float(state["waited"]), times_lost=int(state["times_lost"]))


def msg_to_guide_pace(msg: GuidePaceMsg) -> Dict[str, Any]:
    """The plain form of a ``pearl_interfaces/GuidePace`` (the JSON the topic carried before; what the
    live view's ``/pearl/guide_pace`` channel takes)."""
    return {"active": msg.active or None, "state": msg.state, "speed": msg.speed, "nav_speed": msg.nav_speed,
            "pace": msg.pace, "behind": None if math.isnan(msg.behind) else msg.behind, "waited": msg.waited,
            "times_lost": int(msg.times_lost)}


# ------------------------------------------------------------------------ poses
def pose_to_msg(x: float, y: float, yaw: float, frame_id: str, stamp_s: float) -> PoseStamped:
    """A planar goal (x, y in metres, yaw in radians about z) as a ``PoseStamped``."""
    msg = PoseStamped()
    msg.header.frame_id = frame_id
    msg.header.stamp = seconds_to_time(stamp_s)
    msg.pose.position.x = float(x)
    msg.pose.position.y = float(y)
    msg.pose.orientation.z = math.sin(yaw / 2.0)
    msg.pose.orientation.w = math.cos(yaw / 2.0)
    return msg


def msg_to_pose(msg: PoseStamped) -> Dict[str, float]:
    """``{"x", "y", "yaw", "frame_id", "stamp"}`` of a planar ``PoseStamped``."""
    q = msg.pose.orientation
    yaw = math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))
    return {"x": msg.pose.position.x, "y": msg.pose.position.y, "yaw": yaw,
            "frame_id": msg.header.frame_id, "stamp": time_to_seconds(msg.header.stamp)}


# ------------------------------------------------------------------ diagnostics
def diagnostics_to_msg(name: str, hardware_id: str, level: int, message: str,
                       values: Mapping[str, object], stamp_s: float) -> DiagnosticArray:
    """One ``DiagnosticStatus`` (counters as key/value strings) in a ``DiagnosticArray``."""
    status = DiagnosticStatus(name=name, hardware_id=hardware_id, message=message)
    status.level = bytes([level])
    status.values = [KeyValue(key=str(k), value=str(v)) for k, v in values.items()]
    arr = DiagnosticArray()
    arr.header.stamp = seconds_to_time(stamp_s)
    arr.status = [status]
    return arr


def msg_to_diagnostics(msg: DiagnosticArray) -> Dict[str, dict]:
    """``{status name: {"level": int, "message": str, "values": {key: value}}}``."""
    out = {}
    for st in msg.status:
        level = st.level[0] if isinstance(st.level, (bytes, bytearray)) else int(st.level)
        out[st.name] = {"level": level, "message": st.message,
                        "values": {kv.key: kv.value for kv in st.values}}
    return out


# --------------------------------------------- localisation, velocity, people (issue 14)
#: ``/amcl_pose`` (Nav2 AMCL), ``/odom``, ``/cmd_vel_nav`` → ``/cmd_vel``, people tracker.
LocalisedPoseMsg = PoseWithCovarianceStamped
OdometryMsg = Odometry
TwistMsg = Twist
PointMsg = PointStamped
__all__ += ["LocalisedPoseMsg", "OdometryMsg", "TwistMsg", "PointMsg", "localised_pose_to_msg",
            "msg_to_planar_pose", "twist_to_msg", "msg_to_twist", "point_to_msg", "msg_to_point"]


def _yaw(q) -> float:
    return math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))


def localised_pose_to_msg(x: float, y: float, yaw: float, frame_id: str, stamp_s: float,
                          stddev: float = 0.0) -> PoseWithCovarianceStamped:
    """A planar pose as AMCL publishes it; ``stddev`` (m) on x and y, the rest of the covariance 0."""
    msg = PoseWithCovarianceStamped()
    msg.header.frame_id = frame_id
    msg.header.stamp = seconds_to_time(stamp_s)
    msg.pose.pose.position.x = float(x)
    msg.pose.pose.position.y = float(y)
    msg.pose.pose.orientation.z = math.sin(yaw / 2.0)
    msg.pose.pose.orientation.w = math.cos(yaw / 2.0)
    cov = [0.0] * 36
    cov[0] = cov[7] = float(stddev) ** 2
    msg.pose.covariance = cov
    return msg


def msg_to_planar_pose(msg) -> Dict[str, float]:
    """``{"x", "y", "yaw", "frame_id", "stamp", "stddev"}`` of a PoseWithCovarianceStamped or Odometry.

    ``stddev`` is the larger standard deviation of x and y (m) from the covariance
    (row-major 6×6: x, y, z, roll, pitch, yaw); NaN when the covariance is negative or NaN.
    """
    pose = msg.pose.pose  # both messages hold a PoseWithCovariance in .pose
    cov = msg.pose.covariance
    var = max(float(cov[0]), float(cov[7]))
    stddev = math.sqrt(var) if var >= 0 else float("nan")
    return {"x": pose.position.x, "y": pose.position.y, "yaw": _yaw(pose.orientation),
            "frame_id": msg.header.frame_id, "stamp": time_to_seconds(msg.header.stamp), "stddev": stddev}


def twist_to_msg(linear_x: float, angular_z: float, linear_y: float = 0.0) -> Twist:
    """A planar velocity command (m/s forward, m/s left, rad/s about z)."""
    msg = Twist()
    msg.linear.x = float(linear_x)
    msg.linear.y = float(linear_y)
    msg.angular.z = float(angular_z)
    return msg


def msg_to_twist(msg: Twist) -> Dict[str, float]:
    """``{"linear_x", "linear_y", "angular_z"}`` of a Twist (other components are not used by a planar base)."""
    return {"linear_x": msg.linear.x, "linear_y": msg.linear.y, "angular_z": msg.angular.z}


def point_to_msg(x: float, y: float, frame_id: str, stamp_s: float) -> PointStamped:
    """A person's position (m) in ``frame_id`` (the robot's base frame: x forward, y left)."""
    msg = PointStamped()
    msg.header.frame_id = frame_id
    msg.header.stamp = seconds_to_time(stamp_s)
    msg.point.x = float(x)
    msg.point.y = float(y)
    return msg


def msg_to_point(msg: PointStamped) -> Dict[str, float]:
    """``{"x", "y", "frame_id", "stamp"}`` of a PointStamped."""
    return {"x": msg.point.x, "y": msg.point.y, "frame_id": msg.header.frame_id,
            "stamp": time_to_seconds(msg.header.stamp)}


def settings_to_msg(node: str, values: Mapping[str, Any], stamp_s: float) -> ParameterEvent:
    """``values`` (name → bool, int, float, str or a list of one of them) as a parameter event of
    ``node`` whose ``new_parameters`` hold them, in name order."""
    from rclpy.parameter import Parameter

    msg = ParameterEvent(node=node, stamp=seconds_to_time(stamp_s))
    msg.new_parameters = [Parameter(name, value=values[name]).to_parameter_msg() for name in sorted(values)]
    return msg


def msg_to_settings(msg: ParameterEvent) -> Dict[str, Any]:
    """The values of a :func:`settings_to_msg` (lists as lists)."""
    from rclpy.parameter import parameter_value_to_python

    out: Dict[str, Any] = {}
    for parameter in msg.new_parameters:
        value = parameter_value_to_python(parameter.value)
        out[parameter.name] = list(value) if isinstance(value, (list, tuple, array.array)) else value
    return out
