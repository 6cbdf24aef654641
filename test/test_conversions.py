"""Message conversions: each pair round-trips, with the wire layout written down in the module doc."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

import rclpy  # noqa: F401  (a missing install fails, it is not skipped)

from rclpy.serialization import deserialize_message, serialize_message  # noqa: E402

from pearl_pomdp.errors import BeliefError  # noqa: E402
from pearl_pomdp.nodes import conversions as cv  # noqa: E402
from ros_helpers import REPO  # noqa: E402


def test_belief_layout_and_round_trip_through_cdr():
    b = np.array([0.1, 0.2, 0.3, 0.4])
    msg = cv.belief_to_msg(b, {"A": {"x": 0.3, "y": 0.7}}, step=2, action="Go", observation="seen",
                           state_names=["s0", "s1", "s2", "s3"], stamp_s=1.5)
    assert list(msg.state_names) == ["s0", "s1", "s2", "s3"] and (msg.step, msg.action, msg.observation) == (2, "Go", "seen")
    assert (msg.stamp.sec, msg.stamp.nanosec) == (1, 500_000_000)
    wire = deserialize_message(serialize_message(msg), cv.BeliefMsg)
    np.testing.assert_array_equal(cv.msg_to_belief(wire, num_states=4), b)  # float64 on the wire: exact
    assert cv.msg_to_marginals(wire) == {"step": 2, "action": "Go", "observation": "seen",
                                         "marginals": {"A": {"x": 0.3, "y": 0.7}}}
    # A model larger than MAX_NAMED_STATES: its states unnamed (this uniform belief goes by its first
    # state and the value of all the others).
    big = np.full(cv.MAX_NAMED_STATES + 1, 1.0 / (cv.MAX_NAMED_STATES + 1))
    msg = cv.belief_to_msg(big, state_names=[f"s{i}" for i in range(big.size)])
    assert list(msg.state_names) == [] and msg.num_states == big.size and list(msg.support) == [0]
    assert cv.msg_to_belief(msg).tobytes() == big.tobytes()


@pytest.mark.parametrize("mutate, problem", [
    (lambda m: setattr(m, "state_names", ["a", "b", "c"]), "names 3 states but carries 4 values"),
    (lambda m: (setattr(m, "probabilities", []), setattr(m, "state_names", [])),
     r"num_states is 4 but probabilities \(complete: support is empty\) holds 0 values"),
    (lambda m: (setattr(m, "probabilities", []), setattr(m, "state_names", []), setattr(m, "num_states", 0)),
     "not a distribution"),
    (lambda m: setattr(m, "probabilities", [0.5, 0.5, 0.5, 0.5]), "not a distribution"),
    (lambda m: setattr(m, "probabilities", [1.5, -0.5, 0.0, 0.0]), "not a distribution"),
    (lambda m: setattr(m, "probabilities", [math.nan, 0.5, 0.5, 0.0]), "not a distribution"),
])
def test_bad_belief_messages_are_rejected_with_the_reason(mutate, problem):
    msg = cv.belief_to_msg([0.1, 0.2, 0.3, 0.4], state_names=["a", "b", "c", "d"])   # complete
    assert list(msg.support) == []
    mutate(msg)
    with pytest.raises(BeliefError, match=problem):
        cv.msg_to_belief(msg)


def _pearl_b0():
    from pearl_pomdp.model.domain_yaml import load_domain

    return load_domain(REPO / "config" / "pearl.domain.yaml").compile().b0


def test_a_belief_goes_by_its_support_when_that_is_smaller_and_round_trips_bit_for_bit():
    b0 = _pearl_b0()                       # Pearl's b0: 2 of its 576 states (b = 0.9, 0.1)
    msg = cv.belief_to_msg(b0, step=0)
    assert msg.num_states == 576 and list(msg.support) == np.flatnonzero(b0).tolist() and len(msg.support) == 2
    assert list(msg.probabilities) == [0.9, 0.1]
    assert len(serialize_message(msg)) < 200 < 8 * 576
    wire = deserialize_message(serialize_message(msg), cv.BeliefMsg)
    assert cv.msg_to_belief(wire, num_states=576).tobytes() == b0.tobytes()
    # Complete when the support is not smaller: 12 bytes a state in it against 8 a state.
    b = np.zeros(6)
    b[:4] = [0.1, 0.2, 0.3, 0.4]           # 4 of 6: not below two thirds
    msg = cv.belief_to_msg(b)
    assert list(msg.support) == [] and len(msg.probabilities) == 6 and msg.num_states == 6
    b[3], b[2] = 0.0, 0.7                  # 3 of 6: by its support
    msg = cv.belief_to_msg(b)
    assert list(msg.support) == [0, 1, 2] and list(msg.probabilities) == [0.1, 0.2, 0.7]
    assert cv.msg_to_belief(deserialize_message(serialize_message(msg), cv.BeliefMsg)).tobytes() == b.tobytes()


def test_a_belief_with_a_floor_goes_by_the_states_above_it():
    """After a zero-likelihood recovery every state has b > 0 (the uniform floor), most of them the same
    smallest value: the message lists the others and gives that value once, and reads back bit for bit."""
    from pearl_pomdp.belief import BeliefFilter
    from pearl_pomdp.model.domain_yaml import load_domain

    model = load_domain(REPO / "config" / "pearl.domain.yaml").compile()
    tracker = BeliefFilter(model, log_recoveries=False)
    b, recovered = model.b0, None
    for a in range(model.num_actions):          # the first action and observation the belief rules out
        for o in range(model.num_observations):
            after = tracker.update(b, a, o) if recovered is None else None
            if after is not None and np.count_nonzero(after) == after.size:
                recovered = after
    assert recovered is not None and np.count_nonzero(recovered) == recovered.size == 576
    floor = recovered.min()
    listed = np.flatnonzero(recovered != floor)
    assert 0 < listed.size < 576 * 2 / 3
    msg = cv.belief_to_msg(recovered)
    assert msg.outside_support == floor > 0 and list(msg.support) == listed.tolist()
    wire = deserialize_message(serialize_message(msg), cv.BeliefMsg)
    assert cv.msg_to_belief(wire, 576).tobytes() == recovered.tobytes()
    # A uniform belief: its first state listed, the others at its value.
    uniform = cv.belief_to_msg(np.full(576, 1 / 576))
    assert list(uniform.support) == [0] and uniform.outside_support == 1 / 576
    assert cv.msg_to_belief(uniform).tobytes() == np.full(576, 1 / 576).tobytes()
    # Most states at no one value: complete.
    spread = np.linspace(1.0, 2.0, 9)
    assert list(cv.belief_to_msg(spread / spread.sum()).support) == []


def test_a_belief_by_its_support_and_the_complete_one_read_the_same():
    b0 = _pearl_b0()
    by_support = cv.belief_to_msg(b0, step=3, run=5)
    complete = cv.belief_to_msg(b0, step=3, run=5)
    complete.support = []
    complete.probabilities = b0.tolist()
    assert len(by_support.support) == 2 and len(complete.probabilities) == 576
    assert cv.msg_to_belief(by_support, 576).tobytes() == cv.msg_to_belief(complete, 576).tobytes() == b0.tobytes()
    complete.num_states = 0                # as recorded before num_states: the length of probabilities
    assert cv.msg_to_belief(complete, 576).tobytes() == b0.tobytes()


def _by_support(support, probabilities, num_states=4, outside_support=0.0):
    msg = cv.belief_to_msg([0.1, 0.2, 0.3, 0.4])
    msg.support, msg.probabilities, msg.num_states = support, probabilities, num_states
    msg.outside_support = outside_support
    return msg


@pytest.mark.parametrize("msg, problem, model_states", [
    (_by_support([0, 4], [0.5, 0.5]), r"support\[1\] = 4 is not a state \(num_states 4\)", None),
    (_by_support([0, 1], [1.0]), "support has 2 indices but probabilities 1 values", None),
    (_by_support([2, 1], [0.5, 0.5]), r"support is not increasing: support\[0\] = 2, support\[1\] = 1", None),
    (_by_support([1, 1], [0.5, 0.5]), r"support is not increasing: support\[0\] = 1, support\[1\] = 1", None),
    (_by_support([1], [1.0], num_states=0), "support has 1 indices but num_states is 0", None),
    (_by_support([], [0.25] * 4, num_states=5), r"num_states is 5 but probabilities \(complete", None),
    (_by_support([0, 1], [0.5, 0.25]), "not a distribution", None),
    (_by_support([0, 1], [0.5, 0.5], outside_support=math.nan), "outside_support is nan, not a probability", None),
    (_by_support([0, 1], [0.5, 0.5], outside_support=-0.25), "outside_support is -0.25, not a probability", None),
    (_by_support([1], [1.0], num_states=4), "num_states is 4, the model has 576", 576),
])
def test_a_bad_belief_by_its_support_is_refused_naming_the_field(msg, problem, model_states):
    with pytest.raises(BeliefError, match=problem):
        cv.msg_to_belief(msg, model_states)


def test_a_message_recorded_before_the_support_reads_as_the_complete_belief():
    """The shipped bags were recorded with Belief as it was before num_states and support: the bag's own
    definition says so, and their bytes read as complete beliefs — the same values a decoder of that
    definition alone (mcap-ros2-support) reads."""
    from mcap.records import Schema
    from mcap_ros2.decoder import DecoderFactory

    from pearl_pomdp.bags.reader import BagReader

    reader = BagReader(REPO / "bags" / "figure4_guidance")
    topic = reader.topics["/pearl/belief"]
    assert "support" not in topic.definition and "float64[] probabilities" in topic.definition
    data = next(reader.read_messages(["/pearl/belief"])).data
    with pytest.raises(Exception, match="deserialize"):   # today's layout is longer
        deserialize_message(data, cv.BeliefMsg)
    msg = cv.recorded_belief_msg(data, topic.definition)
    assert msg.num_states == 0 and list(msg.support) == [] and msg.step == 0
    alone = DecoderFactory().decoder_for("cdr", Schema(id=1, name=topic.type, encoding="ros2msg",
                                                       data=topic.definition.encode()))(data)
    assert list(msg.probabilities) == list(alone.probabilities) and len(alone.probabilities) == 576
    assert cv.msg_to_belief(msg, 576).tobytes() == np.array(alone.probabilities).tobytes()
    # A message recorded with today's definition reads as it is, by its support.
    from pearl_pomdp.bags.msgdefs import message_definition

    today = message_definition("pearl_interfaces/msg/Belief")      # what a bag records now
    b0 = _pearl_b0()
    now = cv.recorded_belief_msg(serialize_message(cv.belief_to_msg(b0)), today)
    assert len(now.support) == 2 and cv.msg_to_belief(now, 576).tobytes() == b0.tobytes()
    with pytest.raises(BeliefError, match="/pearl/belief: recorded as a pearl_interfaces/Belief with the fields "
                                          "stamp, step, belief"):
        cv.recorded_belief_msg(data, "builtin_interfaces/Time stamp\nuint32 step\nfloat64[] belief\n")


def test_belief_size_must_match_the_model():
    with pytest.raises(BeliefError, match="has 4 states, the model has 576"):
        cv.msg_to_belief(cv.belief_to_msg([0.1, 0.2, 0.3, 0.4]), num_states=576)            # complete
    with pytest.raises(BeliefError, match="num_states is 4, the model has 576"):
        cv.msg_to_belief(cv.belief_to_msg([0.5, 0.5, 0.0, 0.0]), num_states=576)            # by its support
    with pytest.raises(BeliefError, match="one-dimensional"):
        cv.belief_to_msg(np.eye(2) / 2)


def test_marginals_of_b0_have_no_action_and_stay_json_ready():
    msg = cv.belief_to_msg([0.9, 0.1], {"Battery": {"ok": 0.9, "low": np.float64(0.1)}}, step=0)
    body = cv.msg_to_marginals(msg)
    assert body == {"step": 0, "action": None, "observation": None, "marginals": {"Battery": {"ok": 0.9, "low": 0.1}}}
    assert json.loads(json.dumps(body)) == body


def test_decision_trace_from_objects_and_dicts():
    class Step:
        def __init__(self, subtask, choice, value):
            self.subtask, self.choice, self.value = subtask, choice, value

    msg = cv.decision_to_msg(7, "TellTime", [Step("Act", "Assist", 12.5), {"subtask": "Inform", "choice": "TellTime",
                                                                          "value": float("nan")}], 0.00025, 12,
                             belief_step=6, stamp_s=3.5)
    assert type(msg).__name__ == "Decision" and (msg.stamp.sec, msg.stamp.nanosec) == (3, 500_000_000)
    assert math.isnan(msg.trace[1].value) and not msg.has_search
    assert cv.msg_to_decision(msg) == {"step": 7, "belief_step": 6, "action": "TellTime", "latency_s": 0.00025,
                                       "expansions": 12, "trace": [
        {"subtask": "Act", "choice": "Assist", "value": 12.5},
        {"subtask": "Inform", "choice": "TellTime", "value": None}]}  # NaN is not JSON: null
    # Through CDR and back (what a subscriber or a bag gets).
    from rclpy.serialization import deserialize_message, serialize_message

    assert cv.msg_to_decision(deserialize_message(serialize_message(msg), cv.DecisionMsg)) == cv.msg_to_decision(msg)


def test_decision_trace_carries_each_levels_runner_up_through_cdr():
    from rclpy.serialization import deserialize_message, serialize_message

    from pearl_pomdp.interfaces import TraceStep

    trace = [TraceStep("Act", "DoNothing", 19.1, "Rest→GoHome", 18.25), TraceStep("Rest", "GoHome", 3.0)]
    msg = cv.decision_to_msg(3, "DoNothing", trace, 0.001)
    got = cv.msg_to_decision(deserialize_message(serialize_message(msg), cv.DecisionMsg))["trace"]
    assert got == [t.as_dict() for t in trace] == [
        {"subtask": "Act", "choice": "DoNothing", "value": 19.1, "runner_up": "Rest→GoHome", "runner_up_value": 18.25},
        {"subtask": "Rest", "choice": "GoHome", "value": 3.0}]   # no runner-up: no key


def test_pose_quaternion_and_stamp():
    msg = cv.pose_to_msg(8.0, 3.5, math.pi / 2, "map", 12.25)
    assert msg.pose.orientation.z == pytest.approx(math.sqrt(0.5))
    assert msg.pose.orientation.w == pytest.approx(math.sqrt(0.5))
    assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == (12, 250_000_000)
    for yaw in (0.0, 1.0, -2.5, math.pi - 1e-9):
        assert cv.msg_to_pose(cv.pose_to_msg(0, 0, yaw, "map", 0))["yaw"] == pytest.approx(yaw)
    wire = deserialize_message(serialize_message(msg), cv.PoseMsg)
    assert cv.msg_to_pose(wire) == {"x": 8.0, "y": 3.5, "yaw": pytest.approx(math.pi / 2), "frame_id": "map",
                                    "stamp": 12.25}


def test_time_and_clock():
    t = cv.seconds_to_time(1.5)
    assert (t.sec, t.nanosec) == (1, 500_000_000)
    assert cv.time_to_seconds(cv.seconds_to_time(1795465705.871285522)) == pytest.approx(1795465705.871285522)
    assert cv.clock_to_msg(2.000000001).clock.nanosec == 1
    with pytest.raises(ValueError, match=">= 0"):
        cv.seconds_to_time(-1.0)


def test_diagnostics_round_trip():
    msg = cv.diagnostics_to_msg("pearl: belief_tracker", "pearl", cv.DIAG_WARN, "2 inputs dropped",
                                {"updates": 5, "invalid_touchscreen": 2}, 3.0)
    wire = deserialize_message(serialize_message(msg), cv.DiagnosticsMsg)
    assert cv.msg_to_diagnostics(wire) == {"pearl: belief_tracker": {
        "level": 1, "message": "2 inputs dropped", "values": {"updates": "5", "invalid_touchscreen": "2"}}}
    assert (cv.DIAG_OK, cv.DIAG_WARN, cv.DIAG_ERROR) == (0, 1, 2)


def test_strings_and_observations():
    assert cv.msg_to_action(cv.action_to_msg(" TellTime \n")) == "TellTime"
    assert cv.msg_to_text(cv.text_to_msg("what time is it")) == "what time is it"


def test_operator_event_and_proposal_round_trip_their_plain_forms():
    from rclpy.serialization import deserialize_message, serialize_message

    from pearl_pomdp.operator import OperatorEvent

    change = OperatorEvent("autonomy", "", 3, 12.5, "confirm", "", {"autonomy": "confirm",
                                                                     "confirm_categories": ["Move"],
                                                                     "confirm_timeout": 20.0})
    plain = OperatorEvent("vetoed", "Ask", 4, 13.0, "full", "re-decided without Ask: DoA")
    for event in (change, plain):
        msg = deserialize_message(serialize_message(cv.operator_event_to_msg(event)), cv.OperatorEventMsg)
        assert cv.msg_to_operator_event(msg) == event.as_dict()
    waiting = {"step": 2, "action": "DoA", "source": "policy", "status": "waiting", "autonomy": "confirm",
               "vetoed": ["Ask"], "deadline": 105.0}
    for proposal in (waiting, {**waiting, "status": "acted", "vetoed": [], "deadline": None}):
        msg = deserialize_message(serialize_message(cv.proposal_to_msg(proposal)), cv.OperatorProposalMsg)
        assert cv.msg_to_proposal(msg) == proposal


def test_a_trackers_belief_carries_its_run_and_step_and_a_replays_carries_none():
    """A policy answers each (run, step) once (docs/reliability.md, "Crashes"): the typed Belief's run
    and step are the key; run 0 (a replay, a graph without a journal) is no key at all."""
    msg = cv.belief_to_msg([0.5, 0.5], step=3, run=7)
    assert (msg.run, msg.step) == (7, 3) and cv.msg_to_belief_key(msg) == (7, 3)
    assert cv.msg_to_belief_key(cv.belief_to_msg([0.5, 0.5], step=3)) is None
    with pytest.raises(BeliefError, match="run"):
        cv.belief_to_msg([0.5, 0.5], run=-1)


def test_action_speech_progress_and_guide_pace_round_trip_through_cdr():
    """The typed forms of issue 39: what a node publishes is what a subscriber reads back."""
    def through_cdr(msg):
        return deserialize_message(serialize_message(msg), type(msg))

    action = through_cdr(cv.action_to_msg(" GuideToPhysio ", 12.5))
    assert cv.msg_to_action(action) == "GuideToPhysio" and cv.time_to_seconds(action.stamp) == 12.5
    heard = cv.msg_to_speech(through_cdr(cv.speech_to_msg("what time is it", 0.62, stamp_s=3.0)))
    assert (heard.text, heard.confidence, heard.symbol) == ("what time is it", pytest.approx(0.62), "")
    assert cv.speech_to_msg("yes", 7.0).confidence == 1.0 and cv.speech_to_msg("yes", float("nan")).confidence == 1.0
    # A simulated world's text: plain (confidence 1) or the JSON with its confidence, as the input's type needs.
    assert cv.msg_to_speech(cv.input_to_msg("pearl_interfaces/msg/RecognisedSpeech",
                                            json.dumps({"text": "yes", "confidence": 0.3}))).confidence == \
        pytest.approx(0.3)
    assert cv.input_to_msg("std_msgs/msg/String", "t_yes").data == "t_yes"
    with pytest.raises(ValueError, match="std_msgs/msg/Float32 is not fed text"):
        cv.input_to_msg("std_msgs/msg/Float32", "0.5")
    progress = cv.msg_to_drive_progress(through_cdr(cv.drive_progress_to_msg("GoHome", "home", 3.5, 7.0, 2.0)))
    assert progress == {"action": "GoHome", "place": "home", "distance_remaining": 3.5,
                        "estimated_time_remaining": 7.0, "stamp": 2.0}
    state = {"active": "GuideToPhysio", "state": "waiting", "speed": 0.0, "nav_speed": 0.4, "pace": 0.25,
             "behind": 2.5, "waited": 1.5, "times_lost": 0}
    assert cv.msg_to_guide_pace(through_cdr(cv.guide_pace_to_msg(state, 4.0))) == state
    idle = {**state, "active": None, "behind": None}
    assert cv.msg_to_guide_pace(through_cdr(cv.guide_pace_to_msg(idle))) == idle
