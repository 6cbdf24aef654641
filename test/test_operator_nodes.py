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
from rclpy.serialization import deserialize_message  # noqa: E402
from std_msgs.msg import String  # noqa: E402
from std_srvs.srv import SetBool  # noqa: E402

from pearl_pomdp.belief import BeliefFilter  # noqa: E402
from pearl_pomdp.hierarchy import parse_hierarchy, plan  # noqa: E402
from pearl_pomdp.model.factored import parse_domain  # noqa: E402
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
    domain, model, decider = planned
    return PearlGraph(context=context, domain=domain, model=model, decider=decider, executor=False, params_file=None,
                      overrides={"belief_tracker": {"step_timeout": 0.0}, "hierarchical_policy": policy})


def _probe(g, recorder_topics=None):
    node = g.add_node(rclpy.create_node("operator_probe", context=g.context))
    probe = Probe(node)
    for topic in ("/pearl/action", "/pearl/proposal"):
        probe.listen(topic, String, LATCHED_QOS)
    probe.listen("/pearl/belief", cv.BeliefMsg, LATCHED_QOS)
    probe.listen("/pearl/decision", String, EVENT_QOS)
    probe.listen("/pearl/operator/events", String, EVENT_QOS)
    probe.listen("/diagnostics", cv.DiagnosticsMsg, EVENT_QOS)
    probe.publisher("/clock", cv.ClockMsg, 10)
    for topic in ("/test/answer", "/pearl/operator/veto", "/pearl/operator/command"):
        probe.publisher(topic, String, EVENT_QOS)
    client = node.create_client(SetBool, "/pearl/operator/confirm")
    peers = [n for n in g.nodes if n is not node]
    assert g.spin_until(lambda: not probe.unmatched(peers) and client.service_is_ready(), 15.0), probe.unmatched(peers)
    return probe, client


def _send(g, probe, topic, text):
    pub = probe.publishers[topic]
    assert g.spin_until(lambda: pub.get_subscription_count() >= 1, 10.0), f"{topic} not matched"
    pub.publish(String(data=text))


def _actions(probe):
    return [m.data for m in probe.received["/pearl/action"]]


def _events(probe):
    return [json.loads(m.data) for m in probe.received["/pearl/operator/events"]]


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
        probe, client = _probe(g)
        _set_clock(g, probe, 100.0)
        # b0: the policy asks (Talk: not confirmed), published at once.
        assert g.spin_until(lambda: _actions(probe) == ["Ask"], 10.0), _actions(probe)
        for _ in range(3):   # three answers "a" (P = 0.995): sure enough to act
            _send(g, probe, "/test/answer", "sayA")
        waiting = lambda: any(e["event"] == "waiting" and e["action"] == "DoA" for e in _events(probe))  # noqa: E731
        assert g.spin_until(waiting, 10.0), _events(probe)
        # Waiting: proposed, not published, and the tracker has no step open (no action reached it).
        assert json.loads(probe.received["/pearl/proposal"][-1].data)["status"] == "waiting"
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
    from pearl_pomdp.nodes.bag_recorder import Recorder

    context, _ = ros_context
    domain, model, decider = planned
    writer = BagWriter(tmp_path / "operator")
    with _graph(context, planned) as g:
        probe, _ = _probe(g)
        recorder = Recorder(probe.node, writer, OPERATOR_TOPICS)
        assert g.spin_until(lambda: set(recorder.subscriptions) == set(OPERATOR_TOPICS), 15.0), recorder.subscriptions
        assert g.spin_until(lambda: all(s.get_publisher_count() >= 1 for s in recorder.subscriptions.values()), 10.0)
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
        redecided = json.loads(probe.received["/pearl/decision"][-1].data)
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
        assert g.spin_until(lambda: len(probe.received["/pearl/belief"]) >= 3, 10.0)
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
        recorded.setdefault(message.topic, []).append(deserialize_message(message.data, String).data)
    assert recorded["/pearl/operator/veto"] == ["Ask"]
    assert recorded["/pearl/operator/command"] == ["Jump", "Ask"]
    assert [json.loads(e)["event"] for e in recorded["/pearl/operator/events"]] == kinds
    assert recorded["/pearl/action"][-3:] == ["DoA", "Ask", _actions(probe)[-1]]
