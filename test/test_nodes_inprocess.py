"""The three nodes in one process on one executor under sim time (/clock published by the test).

The tiger problem (Kaelbling, Littman & Cassandra 1998) gives hand-computed beliefs: listening
from uniform and hearing the tiger on the left gives [0.85, 0.15]; twice gives
[0.7225, 0.0225] / 0.745 = [0.969799, 0.030201]. A test-local threshold policy (listen until
one side is above 0.9, then open the other door) is the decider, so every action is known.
The Pearl tests at the end run the real domain and hierarchical policy.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import List

import numpy as np
import pytest

from ros_helpers import Probe

pytestmark = pytest.mark.ros

import rclpy

from pearl_pomdp.channels import SPEECH_TYPE, TEXT_TYPE, InputChannel  # noqa: E402
from pearl_pomdp.model.pomdp import Pomdp  # noqa: E402
from pearl_pomdp.nodes import conversions as cv  # noqa: E402
from pearl_pomdp.nodes.common import EVENT_QOS, LATCHED_QOS  # noqa: E402
from pearl_pomdp.nodes.graph import PearlGraph  # noqa: E402


def tiger() -> Pomdp:
    S, A, Z = ["tiger-left", "tiger-right"], ["listen", "open-left", "open-right"], ["hear-left", "hear-right"]
    T = [np.eye(2), np.full((2, 2), 0.5), np.full((2, 2), 0.5)]
    O = np.array([[[0.85, 0.15], [0.15, 0.85]], [[0.5, 0.5], [0.5, 0.5]], [[0.5, 0.5], [0.5, 0.5]]])
    R = np.array([[-1.0, -100.0, 10.0], [-1.0, 10.0, -100.0]])
    return Pomdp.create(S, A, Z, T, O, R, discount=0.95, name="tiger")


@dataclass
class _Step:
    subtask: str
    choice: str
    value: float


@dataclass
class _Decision:
    action: int
    action_name: str
    trace: List[_Step] = field(default_factory=list)


class ThresholdDecider:
    """Listen until P(one side) > 0.9, then open the other door."""

    def __init__(self, model: Pomdp):
        self.model = model
        self.seen: List[np.ndarray] = []

    def execute(self, belief):
        self.seen.append(np.array(belief))
        if belief[0] > 0.9:
            name = "open-right"
        elif belief[1] > 0.9:
            name = "open-left"
        else:
            name = "listen"
        return _Decision(self.model.actions.index(name), name, [_Step("root", name, float(belief.max()))])


#: The tiger's inputs: four that each carry either symbol (a flat model alone has one input,
#: ``observation``), so the tests can show which input a message came in on.
TIGER_INPUTS = [InputChannel(name, name, "speech" if name == "speech" else "symbol", ("hear-left", "hear-right"),
                             f"/pearl/{name}", type=SPEECH_TYPE if name == "speech" else TEXT_TYPE)
                for name in ("speech", "touchscreen", "laser", "reminder")]


def _graph(context, model, decider, tracker=None, executor_params=None):
    executor = {"location_names": ["left", "right"], "locations.left": [1.0, 2.0, 0.0],
                "locations.right": [3.0, -1.0, 1.5707963267948966],
                "actions.open-right.say": "opening the right door at {time}",
                "actions.open-right.goal": "right", "actions.listen.display": "listening"}
    executor.update(executor_params or {})
    channels = TIGER_INPUTS if model.name == "tiger" else None
    return PearlGraph(context=context, model=model, decider=decider, shared={"use_sim_time": True}, channels=channels,
                      overrides={"belief_tracker": {"step_timeout": 0.0, **(tracker or {})},
                                 "action_executor": executor})


def _probe(graph):
    node = graph.add_node(rclpy.create_node("probe", context=graph.context))
    probe = Probe(node)
    probe.listen("/pearl/action", cv.ActionMsg, LATCHED_QOS)
    probe.listen("/pearl/belief", cv.BeliefMsg, LATCHED_QOS)
    probe.listen("/pearl/decision", cv.DecisionMsg, EVENT_QOS)
    probe.listen("/pearl/say", cv.TextMsg, EVENT_QOS)
    probe.listen("/pearl/display", cv.TextMsg, EVENT_QOS)
    probe.listen("/goal_pose", cv.PoseMsg, LATCHED_QOS)
    probe.listen("/diagnostics", cv.DiagnosticsMsg, EVENT_QOS)
    probe.publisher("/clock", cv.ClockMsg, 10)
    probe.publisher("/pearl/speech", cv.RecognisedSpeechMsg, EVENT_QOS)   # Pearl's domain declares it typed
    for topic in ("touchscreen", "laser", "reminder"):
        probe.publisher(f"/pearl/{topic}", cv.TextMsg, EVENT_QOS)
    peers = [n for n in graph.nodes if n is not node]
    assert graph.spin_until(lambda: not probe.unmatched(peers), 15.0), f"not matched: {probe.unmatched(peers)}"
    return probe


def _set_clock(graph, probe, t):
    clock = probe.publishers["/clock"]
    # The three nodes subscribe /clock (use_sim_time); a message sent before matching is lost.
    assert graph.spin_until(lambda: clock.get_subscription_count() >= 3, 10.0)
    clock.publish(cv.clock_to_msg(t))
    assert graph.spin_until(lambda: abs(graph.tracker.now_s() - t) < 1e-9 and abs(graph.executor_node.now_s() - t) < 1e-9,
                            10.0), f"nodes did not reach sim time {t}"


def _say(probe, topic, text, graph):
    pub = probe.publishers[f"/pearl/{topic}"]
    assert graph.spin_until(lambda: pub.get_subscription_count() >= 1, 10.0), f"/pearl/{topic} not matched"
    pub.publish(cv.speech_to_msg(text) if topic == "speech" else cv.text_to_msg(text))


def _steps(g, probe, n):
    """Spin until the probe holds n actions, beliefs and marginals (topics arrive in any order)."""
    return g.spin_until(lambda: all(len(probe.received[t]) >= n for t in
                                    ("/pearl/action", "/pearl/belief")), 10.0)


def _actions(probe):
    return [cv.msg_to_action(m) for m in probe.received["/pearl/action"]]


def test_tiger_dialogue_in_one_process(ros_context):
    context, _ = ros_context
    model = tiger()
    decider = ThresholdDecider(model)
    with _graph(context, model, decider) as g:
        probe = _probe(g)
        _set_clock(g, probe, 100.0)
        # b0 is published at start; the policy answers it.
        assert _steps(g, probe, 1)
        assert _actions(probe) == ["listen"]
        np.testing.assert_allclose(cv.msg_to_belief(probe.received["/pearl/belief"][0]), [0.5, 0.5])
        assert g.spin_until(lambda: probe.received["/pearl/display"], 10.0)
        assert probe.received["/pearl/display"][0].data == "listening"

        _say(probe, "speech", "hear-left", g)
        assert _steps(g, probe, 2)
        np.testing.assert_allclose(cv.msg_to_belief(probe.received["/pearl/belief"][-1]), [0.85, 0.15])
        assert _actions(probe) == ["listen", "listen"]

        _set_clock(g, probe, 130.0)
        _say(probe, "touchscreen", "hear-left", g)
        assert _steps(g, probe, 3)
        np.testing.assert_allclose(cv.msg_to_belief(probe.received["/pearl/belief"][-1]),
                                   [0.7225 / 0.745, 0.0225 / 0.745], rtol=1e-12)
        assert _actions(probe) == ["listen", "listen", "open-right"]
        # The executor: sentence with the sim time (130 s after the epoch is 00:02 UTC), goal pose.
        assert g.spin_until(lambda: probe.received["/pearl/say"] and probe.received["/goal_pose"], 10.0)
        assert probe.received["/pearl/say"][-1].data == "opening the right door at 00:02"
        pose = cv.msg_to_pose(probe.received["/goal_pose"][-1])
        assert pose["x"] == 3.0 and pose["y"] == -1.0 and pose["frame_id"] == "map"
        assert pose["yaw"] == pytest.approx(np.pi / 2) and pose["stamp"] == pytest.approx(130.0)

        # Marginals: one pseudo-feature for a flat model, with the step's action and observation.
        assert g.spin_until(lambda: cv.msg_to_marginals(probe.received["/pearl/belief"][-1])["step"] == 2, 5)
        last = cv.msg_to_marginals(probe.received["/pearl/belief"][-1])
        assert last["action"] == "listen" and last["observation"] == "hear-left"
        assert last["marginals"]["state"]["tiger-left"] == pytest.approx(0.7225 / 0.745)
        # The decision trace and the decider saw exactly the published beliefs.
        assert g.spin_until(lambda: len(probe.received["/pearl/decision"]) >= 3, 5)
        decision = cv.msg_to_decision(probe.received["/pearl/decision"][2])
        assert decision["step"] == 2 and decision["action"] == "open-right"
        assert decision["trace"] == [{"subtask": "root", "choice": "open-right",
                                      "value": pytest.approx(0.7225 / 0.745)}]
        assert decision["latency_s"] > 0
        assert len(decider.seen) == 3
        assert g.tracker.core.counters()["updates"] == 2


def test_invalid_and_early_inputs_are_counted_not_lost(ros_context):
    context, _ = ros_context
    model = tiger()
    with _graph(context, model, ThresholdDecider(model)) as g:
        probe = _probe(g)
        _set_clock(g, probe, 5.0)
        assert _steps(g, probe, 1)
        _say(probe, "touchscreen", "bogus", g)  # not a symbol: counted, reported, no step closed
        _say(probe, "speech", "the tiger is somewhere", g)  # flat model: speech must be a symbol
        assert g.spin_until(lambda: g.tracker.core.counters()["invalid_touchscreen"] == 1
                            and g.tracker.core.counters()["invalid_speech"] == 1, 10.0)
        assert g.spin_until(lambda: any(
            cv.msg_to_diagnostics(m).get("pearl: belief_tracker", {}).get("values", {}).get("invalid_touchscreen") == "1"
            for m in probe.received["/diagnostics"]), 10.0)
        diag = [cv.msg_to_diagnostics(m)["pearl: belief_tracker"] for m in probe.received["/diagnostics"]
                if "pearl: belief_tracker" in cv.msg_to_diagnostics(m)][-1]
        assert diag["level"] == cv.DIAG_WARN and diag["values"]["updates"] == "0"
        # Two observations in one step: the first closes it, the second waits for the next action.
        assert g.spin_until(lambda: g.tracker.core.step_open, 10.0)
        _say(probe, "laser", "hear-right", g)
        _say(probe, "laser", "hear-right", g)
        assert _steps(g, probe, 3)
        assert g.tracker.core.counters()["queued"] == 1
        assert g.tracker.core.counters()["updates"] == 2
        np.testing.assert_allclose(g.tracker.core.belief, [0.0225 / 0.745, 0.7225 / 0.745], rtol=1e-12)
        assert _actions(probe) == ["listen", "listen", "open-left"]


def test_step_timeout_follows_sim_time(ros_context):
    context, _ = ros_context
    model = tiger()
    with _graph(context, model, ThresholdDecider(model),
                tracker={"step_timeout": 2.0, "timeout_observation": "hear-right"}) as g:
        probe = _probe(g)
        _set_clock(g, probe, 10.0)
        assert _steps(g, probe, 1)
        assert g.spin_until(lambda: g.tracker.core.step_open, 10.0)  # the tracker got the action too
        opened = g.tracker.core.opened_at
        assert opened == pytest.approx(10.0)
        # Wall time passing does nothing while /clock stands still ...
        assert not g.spin_until(lambda: g.tracker.core.counters()["timeouts"] > 0, 0.5)
        # ... 1.5 s of sim time is not enough, 2.5 s is.
        _set_clock(g, probe, 11.5)
        assert not g.spin_until(lambda: g.tracker.core.counters()["timeouts"] > 0, 0.3)
        _set_clock(g, probe, 12.5)
        assert g.spin_until(lambda: g.tracker.core.counters()["timeouts"] == 1, 10.0)
        assert _steps(g, probe, 2)
        np.testing.assert_allclose(g.tracker.core.belief, [0.15, 0.85])
        last = cv.msg_to_marginals(probe.received["/pearl/belief"][-1])
        assert last["observation"] == "hear-right" and last["step"] == 1


def test_pearl_inputs_map_to_modality_symbols(ros_context, pearl_policy):
    """The real Pearl domain: speech through the keyword filter, modality checks on symbol inputs."""
    from pearl_pomdp.belief import BeliefFilter
    from pearl_pomdp.hierarchy import load_hierarchical_policy
    from pearl_pomdp.model.domain_yaml import load_domain
    from ros_helpers import DOMAIN

    context, _ = ros_context
    domain = load_domain(DOMAIN)
    model = domain.compile()
    policy = load_hierarchical_policy(pearl_policy, domain)
    with PearlGraph(context=context, domain=domain, model=model, decider=policy,
                    overrides={"belief_tracker": {"step_timeout": 0.0}}) as g:
        probe = _probe(g)
        _set_clock(g, probe, 50.0)
        assert _steps(g, probe, 1)
        assert g.spin_until(lambda: g.tracker.core.step_open, 10.0)
        a0 = _actions(probe)[0]
        _say(probe, "touchscreen", "yes", g)  # a Speech symbol is not a Touchscreen symbol: invalid
        _say(probe, "speech", "Could you tell me what TIME it is?", g)
        assert _steps(g, probe, 2)
        assert g.tracker.core.counters()["invalid_touchscreen"] == 1
        last = cv.msg_to_marginals(probe.received["/pearl/belief"][-1])
        assert (last["action"], last["observation"]) == (a0, "time")
        expected = BeliefFilter(model).update(model.b0, model.actions.index(a0), model.observations.index("time"))
        np.testing.assert_allclose(cv.msg_to_belief(probe.received["/pearl/belief"][-1]), expected, atol=1e-12)
        for feature, marginal in domain.feature_marginals(expected).items():
            values = [str(v) for v in next(f.values for f in domain.features if f.name == feature)]
            assert [last["marginals"][feature][v] for v in values] == pytest.approx(marginal.tolist(), abs=1e-12)
        assert _actions(probe)[1] == policy.execute(expected).action_name
        # The message names no state itself: its marginals' features and values, in mixed radix (first
        # feature most significant), spell every state's name, and it stays small (85 kB with names).
        from itertools import product

        from rclpy.serialization import serialize_message

        message = probe.received["/pearl/belief"][-1]
        assert list(message.state_names) == [] and len(serialize_message(message)) < 8000
        spelled = [",".join(f"{m.feature}={v}" for m, v in zip(message.marginals, values))
                   for values in product(*[list(m.values) for m in message.marginals])]
        assert spelled == list(model.states)
        # Speech with no keyword is the `unknown` observation, counted (not a warning, not dropped).
        assert g.spin_until(lambda: g.tracker.core.step_open, 10.0)
        _say(probe, "speech", "hmm", g)
        assert _steps(g, probe, 3)
        assert cv.msg_to_marginals(probe.received["/pearl/belief"][-1])["observation"] == "unknown"
        assert g.tracker.counters()["unknown_speech"] == 1


class _Seen:
    """A decider that keeps every belief the policy node hands it, then decides as ``inner``."""

    def __init__(self, inner):
        self.inner = inner
        self.seen: List[np.ndarray] = []

    def execute(self, belief):
        self.seen.append(np.array(belief))
        return self.inner.execute(belief)

    def __getattr__(self, name):
        return getattr(self.inner, name)


def test_pearl_beliefs_cross_dds_by_their_support_bit_for_bit_and_bad_ones_are_refused(ros_context, pearl_policy):
    """Pearl's beliefs have few states with b > 0 (b0: 2 of 576): the tracker sends them by their support,
    and the probe and the policy node read, through DDS, the tracker's belief bit for bit. A message whose
    support is out of range, disagrees in length with its values, is not increasing or has another number
    of states is refused by the policy node, logged with the topic and field, and the node answers the next."""
    from pearl_pomdp.hierarchy import load_hierarchical_policy
    from pearl_pomdp.model.domain_yaml import load_domain
    from ros_helpers import DOMAIN

    context, _ = ros_context
    domain = load_domain(DOMAIN)
    model = domain.compile()
    decider = _Seen(load_hierarchical_policy(pearl_policy, domain))
    with PearlGraph(context=context, domain=domain, model=model, decider=decider,
                    overrides={"belief_tracker": {"step_timeout": 0.0}}) as g:
        probe = _probe(g)
        _set_clock(g, probe, 50.0)
        assert _steps(g, probe, 1)
        _say(probe, "speech", "Could you tell me what TIME it is?", g)
        assert _steps(g, probe, 2) and g.spin_until(lambda: len(decider.seen) == 2, 10.0)
        tracked = [model.b0, g.tracker.core.belief]
        for msg, belief, seen in zip(probe.received["/pearl/belief"], tracked, decider.seen):
            support = np.flatnonzero(belief)
            assert support.size < 576 * 2 / 3 and list(msg.support) == support.tolist() and msg.num_states == 576
            assert len(msg.probabilities) == support.size
            assert cv.msg_to_belief(msg, 576).tobytes() == belief.tobytes() == seen.tobytes()

        errors: List[str] = []
        logger = g.policy.get_logger()
        original_error = logger.error
        logger.error = lambda text, **kw: (errors.append(text), original_error(text, **kw))[1]
        bad = probe.publisher("/pearl/belief", cv.BeliefMsg, LATCHED_QOS)
        assert g.spin_until(lambda: not probe.unmatched([g.policy]), 10.0)

        def sent(support, values, states=576, step=90):
            msg = cv.belief_to_msg(model.b0, step=step)
            msg.support, msg.probabilities, msg.num_states = support, values, states
            return msg

        refusals = [(sent([0, 576], [0.5, 0.5]), "support[1] = 576 is not a state (num_states 576)"),
                    (sent([0, 1], [1.0]), "support has 2 indices but probabilities 1 values"),
                    (sent([7, 3], [0.5, 0.5]), "support is not increasing: support[0] = 7, support[1] = 3"),
                    (sent([3, 3], [0.5, 0.5]), "support is not increasing: support[0] = 3, support[1] = 3"),
                    (sent([3], [1.0], states=4), "num_states is 4, the model has 576")]
        for k, (msg, problem) in enumerate(refusals, start=1):
            bad.publish(msg)
            assert g.spin_until(lambda: g.policy.rejected == k, 10.0), errors
            assert errors[-1] == f"rejected belief on /pearl/belief: belief message: {problem}"
        answered = g.policy.beliefs_answered
        good = cv.belief_to_msg(g.tracker.core.belief, step=91)
        assert len(good.support) > 0
        bad.publish(good)
        assert g.spin_until(lambda: g.policy.beliefs_answered == answered + 1, 10.0)
        assert decider.seen[-1].tobytes() == g.tracker.core.belief.tobytes()


def test_the_tracker_publishes_its_step_rules_and_places_latched_for_a_late_recorder(ros_context, pearl_policy):
    """A recorder that joins after activation still gets the tracker's step rules and places on
    ``/belief_tracker/settings`` (TRANSIENT_LOCAL): what a replay of its bag needs to close the
    robot's steps as it did (pearl_pomdp.nodes.bag_replay.recorded_tracker_parameters)."""
    from pearl_pomdp.hierarchy import load_hierarchical_policy
    from pearl_pomdp.model.domain_yaml import load_domain
    from ros_helpers import DOMAIN

    context, _ = ros_context
    domain = load_domain(DOMAIN)
    model = domain.compile()
    policy = load_hierarchical_policy(pearl_policy, domain)
    places = {"location_names": ["home", "room", "physio"], "locations.home": [0.0, 0.0, 0.0],
              "locations.room": [15.0, 0.0, 0.0], "locations.physio": [15.0, 30.0, 0.0]}
    with PearlGraph(context=context, domain=domain, model=model, decider=policy,
                    overrides={"belief_tracker": {"step_timeout": 7.5, **places}}) as g:
        probe = _probe(g)
        assert _steps(g, probe, 1)                      # active: b0 answered
        late = Probe(g.add_node(rclpy.create_node("late_recorder", context=g.context)))
        late.listen("/belief_tracker/settings", cv.SettingsMsg, LATCHED_QOS)
        assert g.spin_until(lambda: late.received["/belief_tracker/settings"], 10.0)
        (msg,) = late.received["/belief_tracker/settings"]
        settings = cv.msg_to_settings(msg)
        assert msg.node == "/belief_tracker" and settings["step_timeout"] == 7.5
        assert {k: settings[k] for k in places} == places
        assert not any(k.startswith(("inputs.", "journal", "diagnostics")) for k in settings)
