"""A person in the loop over DDS: the three nodes in one process, the operator a probe node.

The domain is a small dialogue (ask which of two jobs is wanted, then do it) whose actions
carry categories: ``Ask`` is ``Talk``, ``DoA``/``DoB`` are ``Act``. Its policy is planned
here (policy-contingent, plan's default), and every expected action or belief comes from
the core: the policy's own ``execute_without`` for a veto, the Bayes filter for a command.
"""
from __future__ import annotations

import json
import time

import numpy as np
import pytest

from ros_helpers import Probe

pytestmark = pytest.mark.ros

import rclpy  # noqa: E402
from rclpy.qos import QoSProfile  # noqa: E402
from rclpy.serialization import deserialize_message  # noqa: E402
from std_msgs.msg import String  # noqa: E402
from std_srvs.srv import SetBool  # noqa: E402

from pearl_pomdp.belief import BeliefFilter  # noqa: E402
from pearl_pomdp.hierarchy import parse_hierarchy, plan  # noqa: E402
from pearl_pomdp.model.domain_yaml import parse_domain  # noqa: E402
from pearl_pomdp.nodes import conversions as cv  # noqa: E402
from pearl_pomdp.nodes.common import EVENT_QOS, LATCHED_QOS  # noqa: E402
from pearl_pomdp.nodes.graph import PearlGraph  # noqa: E402

DOMAIN = """
name: two_jobs
discount: 0.95
features:
  Goal: [a, b, done]
start: {Goal: {a: 0.5, b: 0.5}}
modalities:
  Answer:
    symbols: [sayA, sayB, silent]
    input: {kind: symbol, topic: /test/answer, type: std_msgs/msg/String}
actions:
  Ask: {category: Talk}
  DoA:
    category: Act
    effects: {Goal: {set: done}}
  DoB:
    category: Act
    effects: {Goal: {set: done}}
observations:
  Ask:
    parents: [Goal]
    table:
      a: {sayA: 0.85, sayB: 0.15}
      b: {sayA: 0.15, sayB: 0.85}
      done: silent
  default:
    parents: [Goal]
    table:
      "*": silent
rewards:
  - {action: DoA, when: {Goal: a}, reward: 10, why: right}
  - {action: DoA, when: {Goal: b}, reward: -100, why: wrong}
  - {action: DoB, when: {Goal: b}, reward: 10, why: right}
  - {action: DoB, when: {Goal: a}, reward: -100, why: wrong}
  - {action: Ask, reward: -1, why: asking costs}
"""
HIERARCHY = """
root: Top
defaults: {trials: 200}
subtasks:
  Top: {actions: [Ask, Do]}
  Do: {actions: [DoA, DoB]}
"""
OPERATOR_TOPICS = ["/pearl/operator/veto", "/pearl/operator/command", "/pearl/operator/events", "/pearl/proposal",
                   "/pearl/action"]


@pytest.fixture(scope="module")
def planned():
    domain = parse_domain(DOMAIN)
    return domain, domain.compile(), plan(domain, parse_hierarchy(HIERARCHY, domain.actions))


def _graph(context, planned, **policy):
    """The tracker and the policy, configured but not active: :func:`_probe` activates them once
    the test's readers are matched, so nothing they publish (b0, the first events) is missed."""
    domain, model, decider = planned
    g = PearlGraph(context=context, domain=domain, model=model, decider=decider, executor=False, params_file=None,
                   overrides={"belief_tracker": {"step_timeout": 0.0, "autostart": False},
                              "hierarchical_policy": {**policy, "autostart": False}})
    g.tracker.trigger_configure()
    g.policy.trigger_configure()
    return g


def _probe(g, record=None):
    """The operator's node (publishers, listeners, confirm client) and optionally a recorder
    ``(writer, topics)`` on it; matched both ways, then the nodes are activated (policy first:
    the tracker publishes b0 on activation) and b0's answer has arrived."""
    node = g.add_node(rclpy.create_node("operator_probe", context=g.context))
    probe = Probe(node)
    # Latched like the writers, but a deep reader queue: two messages between spins are both kept.
    latched = QoSProfile(depth=100, reliability=LATCHED_QOS.reliability, durability=LATCHED_QOS.durability)
    probe.listen("/pearl/action", cv.ActionMsg, latched)
    probe.listen("/pearl/proposal", cv.OperatorProposalMsg, latched)
    probe.listen("/pearl/belief", cv.BeliefMsg, latched)
    probe.listen("/pearl/decision", cv.DecisionMsg, EVENT_QOS)
    probe.listen("/pearl/operator/events", cv.OperatorEventMsg, EVENT_QOS)
    probe.listen("/diagnostics", cv.DiagnosticsMsg, EVENT_QOS)
    probe.publisher("/clock", cv.ClockMsg, 10)
    for topic in ("/test/answer", "/pearl/operator/veto", "/pearl/operator/command"):
        probe.publisher(topic, String, EVENT_QOS)
    client = node.create_client(SetBool, "/pearl/operator/confirm")
    recorder = None
    if record is not None:
        from pearl_pomdp.nodes.bag_recorder import Recorder

        writer, topics = record
        recorder = Recorder(node, writer, topics)
        assert g.spin_until(lambda: set(recorder.subscriptions) == set(topics), 15.0), recorder.subscriptions
    peers = [n for n in g.nodes if n is not node]
    assert g.spin_until(lambda: not probe.unmatched(peers) and client.service_is_ready(), 15.0), probe.unmatched(peers)
    # Matching is asymmetric: the writers must see every reader too.
    recorded = set() if recorder is None else set(recorder.subscriptions)
    writers = [(w, n + (w.topic_name in recorded)) for w, n in
               [(g.tracker.belief_pub, 2), (g.policy.action_pub, 2), (g.policy.operator_events_pub, 1),
                (g.policy.decision_pub, 1), (g.policy.proposal_pub, 1)]]
    assert g.spin_until(lambda: all(w.get_subscription_count() >= n for w, n in writers)
                        and (recorder is None or all(s.get_publisher_count() >= 1
                                                     for s in recorder.subscriptions.values())), 10.0)
    g.policy.trigger_activate()
    g.tracker.trigger_activate()
    assert g.spin_until(lambda: probe.received["/pearl/belief"] and probe.received["/pearl/operator/events"], 10.0)
    return probe, client, recorder


def _send(g, probe, topic, text):
    pub = probe.publishers[topic]
    assert g.spin_until(lambda: pub.get_subscription_count() >= 1, 10.0), f"{topic} not matched"
    pub.publish(String(data=text))


def _actions(probe):
    return [cv.msg_to_action(m) for m in probe.received["/pearl/action"]]


def _events(probe):
    return [cv.msg_to_operator_event(m) for m in probe.received["/pearl/operator/events"]]


def _answer(g, client, yes):
    future = client.call_async(SetBool.Request(data=yes))
    assert g.spin_until(future.done, 10.0), "no answer from /pearl/operator/confirm"
    return future.result()


def _set_clock(g, probe, t):
    clock = probe.publishers["/clock"]
    assert g.spin_until(lambda: clock.get_subscription_count() >= 2, 10.0)
    clock.publish(cv.clock_to_msg(t))
    assert g.spin_until(lambda: abs(g.policy.now_s() - t) < 1e-9, 10.0), f"the policy did not reach sim time {t}"


def test_confirm_publishes_a_confirmed_category_only_after_the_yes(ros_context, planned):
    context, _ = ros_context
    with _graph(context, planned, autonomy="confirm", confirm_categories=["Act"], confirm_timeout=5.0) as g:
        probe, client, _ = _probe(g)
        _set_clock(g, probe, 100.0)
        # b0: the policy asks (Talk: not confirmed), published at once.
        assert g.spin_until(lambda: _actions(probe) == ["Ask"], 10.0), _actions(probe)
        for _ in range(3):   # three answers "a" (P = 0.995): sure enough to act
            _send(g, probe, "/test/answer", "sayA")
        waiting = lambda: any(e["event"] == "waiting" and e["action"] == "DoA" for e in _events(probe))  # noqa: E731
        assert g.spin_until(waiting, 10.0), _events(probe)
        # Waiting: proposed, not published, and the tracker has no step open (no action reached it).
        assert cv.msg_to_proposal(probe.received["/pearl/proposal"][-1])["status"] == "waiting"
        assert not g.spin_until(lambda: len(_actions(probe)) > 3, 0.3)
        assert _actions(probe) == ["Ask"] * 3 and not g.tracker.core.step_open
        asked = time.perf_counter()
        reply = _answer(g, client, True)
        assert reply.success and reply.message == "published DoA"
        assert g.spin_until(lambda: _actions(probe)[-1:] == ["DoA"], 10.0)
        assert probe.arrival["/pearl/action"][-1] > asked
        assert g.spin_until(lambda: g.tracker.core.open_action == "DoA", 10.0)

        # After DoA the goal is done; the next Act action waits again, and 5 s of sim time
        # without an answer leaves it not acted (the belief stays: no step is opened).
        _send(g, probe, "/test/answer", "silent")
        assert g.spin_until(lambda: sum(e["event"] == "waiting" for e in _events(probe)) == 2, 10.0), _events(probe)
        belief = g.tracker.core.belief
        _set_clock(g, probe, 104.0)
        assert not g.spin_until(lambda: any(e["event"] == "timeout" for e in _events(probe)), 0.3)
        _set_clock(g, probe, 105.5)
        assert g.spin_until(lambda: any(e["event"] == "timeout" for e in _events(probe)), 10.0)
        assert _actions(probe)[-1] == "DoA" and len(_actions(probe)) == 4
        np.testing.assert_array_equal(g.tracker.core.belief, belief)
        assert not _answer(g, client, True).success     # too late: nothing waits


def test_veto_re_decides_command_moves_the_belief_and_the_bag_records_it(ros_context, planned, tmp_path):
    from pearl_pomdp.bags.reader import BagReader
    from pearl_pomdp.bags.writer import BagWriter

    context, _ = ros_context
    domain, model, decider = planned
    writer = BagWriter(tmp_path / "operator")
    with _graph(context, planned) as g:
        probe, _, recorder = _probe(g, (writer, OPERATOR_TOPICS))
        assert g.spin_until(lambda: _actions(probe) == ["Ask"], 10.0)
        _send(g, probe, "/test/answer", "sayA")
        assert g.spin_until(lambda: len(_actions(probe)) == 2, 10.0)
        belief = g.tracker.core.belief
        assert _actions(probe) == ["Ask", "Ask"] and belief[model.states.index("Goal=a")] == pytest.approx(0.85)

        # Veto the choice: the policy decides again at once, without it, by its own values.
        expected = decider.execute_without(belief, ["Ask"])
        assert expected.action_name == "DoA"
        _send(g, probe, "/pearl/operator/veto", "Ask")
        assert g.spin_until(lambda: len(_actions(probe)) == 3, 10.0)
        assert _actions(probe)[-1] == "DoA"
        assert g.spin_until(lambda: len(probe.received["/pearl/decision"]) == 3, 10.0)
        redecided = cv.msg_to_decision(probe.received["/pearl/decision"][-1])
        assert redecided["action"] == "DoA"
        assert redecided["trace"][0]["value"] == pytest.approx(expected.trace[0].value, abs=1e-12)
        assert g.spin_until(lambda: g.tracker.core.open_action == "DoA", 10.0)   # the robot does DoA now

        # An unknown action: one ERROR on /diagnostics naming the topic, nothing acted.
        _send(g, probe, "/pearl/operator/command", "Jump")
        operator_errors = lambda: [d for m in probe.received["/diagnostics"]  # noqa: E731
                                   for name, d in cv.msg_to_diagnostics(m).items() if name.endswith(": operator")]
        assert g.spin_until(lambda: operator_errors(), 10.0)
        [error] = operator_errors()
        assert error["level"] == cv.DIAG_ERROR
        assert error["message"].startswith("/pearl/operator/command: command refused: 'Jump' is not an action")
        assert len(_actions(probe)) == 3

        # The operator commands Ask: the tracker takes it as the robot's action, and the answer
        # that follows moves the belief as the filter says for (Ask, sayB).
        _send(g, probe, "/pearl/operator/command", "Ask")
        assert g.spin_until(lambda: g.tracker.core.open_action == "Ask", 10.0)
        _send(g, probe, "/test/answer", "sayB")
        assert g.spin_until(lambda: len(probe.received["/pearl/belief"]) >= 3, 10.0), \
            [list(cv.msg_to_belief(m)) for m in probe.received["/pearl/belief"]]
        expected_belief = BeliefFilter(model).update(belief, "Ask", "sayB")
        np.testing.assert_allclose(cv.msg_to_belief(probe.received["/pearl/belief"][-1]), expected_belief,
                                   rtol=0, atol=1e-12)
        assert g.spin_until(lambda: len(_actions(probe)) == 5 and len(_events(probe)) == 7, 10.0)
        kinds = [e["event"] for e in _events(probe)]
        assert kinds == ["acted", "acted", "vetoed", "acted", "rejected", "commanded", "acted"], kinds
        assert g.spin_until(lambda: recorder.counts.get("/pearl/operator/events", 0) == len(kinds), 10.0)
        recorder.stop()
    writer.close()
    recorded = {}
    for message in BagReader(tmp_path / "operator").read_messages():
        msg_type = {"/pearl/operator/events": cv.OperatorEventMsg, "/pearl/proposal": cv.OperatorProposalMsg,
                    "/pearl/decision": cv.DecisionMsg, "/pearl/action": cv.ActionMsg}.get(message.topic, String)
        recorded.setdefault(message.topic, []).append(deserialize_message(message.data, msg_type))
    recorded = {t: [m.data if isinstance(m, String) else m.name if isinstance(m, cv.ActionMsg) else m for m in ms]
                for t, ms in recorded.items()}
    assert recorded["/pearl/operator/veto"] == ["Ask"]
    assert recorded["/pearl/operator/command"] == ["Jump", "Ask"]
    assert [e.kind for e in recorded["/pearl/operator/events"]] == kinds
    assert recorded["/pearl/action"][-3:] == ["DoA", "Ask", _actions(probe)[-1]]
    # A reader that imports nothing of this project reads the operator's loop too (issue 39).
    from ros_helpers import decode_with_mcap_ros2_alone

    alone = decode_with_mcap_ros2_alone(tmp_path / "operator")
    assert {t: alone[t]["count"] for t in recorded} == {t: len(ms) for t, ms in recorded.items()}
    assert {t: alone[t]["type"] for t in ("/pearl/operator/events", "/pearl/proposal", "/pearl/action")} == {
        "/pearl/operator/events": "pearl_interfaces/msg/OperatorEvent",
        "/pearl/proposal": "pearl_interfaces/msg/OperatorProposal", "/pearl/action": "pearl_interfaces/msg/Action"}
    first = alone["/pearl/operator/events"]["first"]
    assert (first["kind"], first["action"]) == (kinds[0], recorded["/pearl/operator/events"][0].action)


def _call(g, probe, service: str, request):
    """Call one of the policy's operator services (pearl_interfaces) from the probe; its reply."""
    client = probe.node.create_client(_SERVICES[service], service)
    assert g.spin_until(client.service_is_ready, 10.0), f"{service} not ready"
    future = client.call_async(request)
    assert g.spin_until(future.done, 10.0), f"no answer from {service}"
    return future.result()


def _service_types():
    from pearl_interfaces.srv import Command, SetAutonomy, Veto

    return {"/pearl/operator/veto_action": Veto, "/pearl/operator/command_action": Command,
            "/pearl/operator/set_autonomy": SetAutonomy}


_SERVICES = _service_types()


@pytest.mark.parametrize("via", ["topics", "services"])
def test_a_recorded_run_with_an_operator_replays_and_explains(ros_context, planned, tmp_path, via):
    """Confirm, veto, no, command and a level change, recorded with /clock and the inputs; the
    replay (a fresh graph loading the saved policy) feeds the operator's inputs and re-does
    the level change and the answers: same actions, beliefs to 1e-12, same operator events.
    ``services``: the veto, the command and the level go through the policy's pearl_interfaces
    services (Veto, Command, SetAutonomy, what ``ros2 service call`` uses) and each reply says what
    happened; the bag holds only their events, and the replay does them again from those."""
    from pearl_interfaces.srv import Command, SetAutonomy, Veto
    from rclpy.parameter import Parameter

    from pearl_pomdp.bags.writer import BagWriter
    from pearl_pomdp.cli.replay import format_explanation
    from pearl_pomdp.nodes.bag_replay import replay_bag
    from ros_helpers import allocate_domain_id

    context, _ = ros_context
    domain, model, decider = planned
    (tmp_path / "two_jobs.domain.yaml").write_text(DOMAIN)
    decider.save(tmp_path / "policy")
    policy_params = {"autonomy": "confirm", "confirm_categories": ["Act"], "confirm_timeout": 5.0}
    writer = BagWriter(tmp_path / "bag", custom_data={
        "pearl.domain": "../two_jobs.domain.yaml", "pearl.policy": "../policy",
        # The replay reads the shipped params file: its Pearl-only tracker settings are undone here.
        "pearl.tracker_params": json.dumps({"step_timeout": 0.0, "stale_after": 0.0, "drive_speed": 0.0,
                                            "drive_category": "", "nav_failed_observation": "", "place_feature": "",
                                            "guide_actions": [""]}),
        "pearl.policy_params": json.dumps(policy_params)})
    topics = OPERATOR_TOPICS + ["/clock", "/test/answer", "/pearl/belief", "/pearl/decision"]
    with _graph(context, planned, **policy_params) as g:
        probe, client, recorder = _probe(g, (writer, topics))
        _set_clock(g, probe, 100.0)

        def n_events(n):
            """n operator events seen, and every belief and action of the probe in the bag too:
            the next input waits for them (a latched writer keeps only its latest message)."""
            return g.spin_until(lambda: recorder.counts["/pearl/operator/events"] == n and len(_events(probe)) == n
                                and recorder.counts["/pearl/belief"] == len(probe.received["/pearl/belief"])
                                and recorder.counts["/pearl/action"] == len(_actions(probe)), 10.0)

        assert n_events(1)                                   # b0: Ask acted
        _send(g, probe, "/test/answer", "sayA")
        assert n_events(2)                                   # Ask acted again
        if via == "topics":
            _send(g, probe, "/pearl/operator/veto", "Ask")
        else:
            reply = _call(g, probe, "/pearl/operator/veto_action", Veto.Request(action="Ask"))
            assert reply.accepted and reply.message == ("vetoed Ask (re-decided without Ask: DoA; by service); "
                                                        "waiting DoA (until 105.000 s)"), reply.message
        assert n_events(4)                                   # vetoed, DoA waiting
        reply = _answer(g, client, False)                    # declined: answered, not acted
        assert reply.success and reply.message == "declined (not acted) DoA"
        assert n_events(5)
        if via == "topics":
            _send(g, probe, "/pearl/operator/command", "Ask")
        else:
            assert _call(g, probe, "/pearl/operator/command_action", Command.Request(action="Ask")).accepted
        assert n_events(6)
        for n in (7, 8):
            _send(g, probe, "/test/answer", "sayA")
            assert n_events(n)                               # Ask acted, then DoA waiting
        if via == "topics":
            g.policy.set_parameters([Parameter("autonomy", value="full")])
        else:
            reply = _call(g, probe, "/pearl/operator/set_autonomy", SetAutonomy.Request(level="full"))
            assert reply.accepted and reply.message == "autonomy full"
        assert n_events(10)                                  # autonomy, DoA acted
        _send(g, probe, "/test/answer", "silent")
        assert n_events(11)
        assert g.spin_until(lambda: recorder.counts.get("/pearl/belief", 0) == len(probe.received["/pearl/belief"])
                            and recorder.counts["/pearl/action"] == len(_actions(probe)), 10.0), \
            (recorder.counts, len(probe.received["/pearl/belief"]), _actions(probe))
        live_actions, live_events = _actions(probe), [e["event"] for e in _events(probe)]
        recorder.stop()
        if via == "services":   # refused, each with the reason in the reply (not recorded: the bag is closed)
            refused = _call(g, probe, "/pearl/operator/veto_action", Veto.Request(action="Fly"))
            assert not refused.accepted and "Fly" in refused.message, refused.message
            bad = _call(g, probe, "/pearl/operator/set_autonomy", SetAutonomy.Request(level="sometimes"))
            assert not bad.accepted and "sometimes" in bad.message and g.policy.gate.autonomy == "full", bad.message
    writer.close()
    assert live_actions == ["Ask", "Ask", "Ask", "Ask", "DoA", "DoA"], live_actions
    assert live_events == ["acted", "acted", "vetoed", "waiting", "declined", "commanded", "acted", "waiting",
                           "autonomy", "acted", "acted"], live_events

    result = replay_bag(tmp_path / "bag", domain_id=allocate_domain_id(), explain=True)
    assert result.actions == result.expected_actions == live_actions and result.match
    assert result.beliefs_match and result.max_belief_difference <= 1e-12, \
        (result.beliefs, result.expected_beliefs, result.max_belief_difference)
    assert result.operator_events == result.expected_operator_events == live_events
    step1 = result.explanation[1]
    assert [e["event"] for e in step1["operator"]] == ["acted", "vetoed", "waiting", "declined", "commanded"]
    assert result.explanation[2]["operator"] == []     # the policy acted, nobody intervened
    assert step1["decision"]["action"] == "DoA"     # the re-decision after the veto is the one that stood
    text = format_explanation(result.explanation, result.divergence)
    via_service = "; by service" if via == "services" else ""
    assert f"operator: vetoed Ask (re-decided without Ask: DoA{via_service})" in text and "operator: declined DoA" in text
