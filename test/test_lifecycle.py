"""Managed nodes (issue 14): the tracker and the policy as separate processes with autostart:=false,
driven over DDS through configure → activate → deactivate → activate → shutdown by
lifecycle_msgs/ChangeState; no action while inactive; the belief survives deactivate;
/pearl/reset (std_srvs/Trigger) returns the tracker to b0."""
from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np
import pytest

import ros_helpers
from ros_helpers import (DISCOVERY_TIMEOUT, DOMAIN, Probe, Proc, allocate_domain_id, answer_within,
                         call_service, configure_test_process, ros_env, wait_for)

pytestmark = [pytest.mark.ros]

import rclpy

from lifecycle_msgs.msg import Transition  # noqa: E402
from lifecycle_msgs.srv import ChangeState, GetState  # noqa: E402
from std_srvs.srv import Trigger  # noqa: E402

from pearl_pomdp.model.domain_yaml import load_domain  # noqa: E402
from pearl_pomdp.nodes import conversions as cv  # noqa: E402
from pearl_pomdp.nodes.common import INPUT_QOS, LATCHED_QOS  # noqa: E402

BIN = Path(sys.executable).parent
#: What the executor says for TellWeather (config/pearl_nodes.yaml).
WEATHER = "Here is today's weather forecast."


#: The transitions these tests make: (the state they start from, the state they lead to).
TRANSITIONS = {
    Transition.TRANSITION_CONFIGURE: ("unconfigured", "inactive"),
    Transition.TRANSITION_ACTIVATE: ("inactive", "active"),
    Transition.TRANSITION_DEACTIVATE: ("active", "inactive"),
    Transition.TRANSITION_ACTIVE_SHUTDOWN: ("active", "finalized"),
}
#: A node's states while it runs a transition's callback.
IN_TRANSITION = {"configuring", "cleaningup", "shuttingdown", "activating", "deactivating", "errorprocessing"}


def transition(node, executor, name, transition_id):
    """Ask ``name`` to make a transition; whether it succeeded.

    A transition must not be requested twice (the second would fail from the new state), so a lost
    answer (see ``call_service``) is not re-sent: the request arrived (its writer had matched), and
    the node's state, once out of the transition, says whether the transition happened."""
    start, goal = TRANSITIONS[transition_id]
    client = node.create_client(ChangeState, f"/{name}/change_state")
    try:
        assert wait_for(client.service_is_ready, DISCOVERY_TIMEOUT, executor), f"{client.srv_name} never came up"
        req = ChangeState.Request()
        req.transition.id = transition_id
        answer = answer_within(client, req, ros_helpers.ANSWER_WAIT, executor)
        if answer is not None:
            return answer.success
        deadline = time.monotonic() + DISCOVERY_TIMEOUT
        while True:
            label = state(node, executor, name)
            if label != start and label not in IN_TRANSITION:
                return label == goal
            assert time.monotonic() < deadline, f"{client.srv_name} did not answer and {name} stayed {label!r}"
            wait_for(lambda: False, 0.1, executor)
    finally:
        node.destroy_client(client)


def state(node, executor, name):
    client = node.create_client(GetState, f"/{name}/get_state")
    try:
        return call_service(client, GetState.Request(), executor).current_state.label
    finally:
        node.destroy_client(client)


def test_lifecycle_over_dds(tmp_path, pearl_policy):
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.signals import SignalHandlerOptions

    configure_test_process(tmp_path)
    domain_id = allocate_domain_id()
    env = ros_env(domain_id, tmp_path)
    model = load_domain(DOMAIN).compile()
    tracker = Proc([str(BIN / "belief_tracker"), "--ros-args", "-p", f"domain:={DOMAIN}", "-p", "autostart:=false",
                    "-p", "step_timeout:=0.0"], env, tmp_path, "tracker")
    policy = Proc([str(BIN / "hierarchical_policy"), "--ros-args", "-p", f"domain:={DOMAIN}",
                   "-p", f"policy:={pearl_policy}", "-p", "autostart:=false"], env, tmp_path, "policy")
    context = Context()
    rclpy.init(context=context, domain_id=domain_id, signal_handler_options=SignalHandlerOptions.NO)
    executor = SingleThreadedExecutor(context=context)
    node = rclpy.create_node("lifecycle_probe", context=context)
    executor.add_node(node)
    try:
        probe = Probe(node)
        actions = probe.listen("/pearl/action", cv.ActionMsg, LATCHED_QOS)
        beliefs = probe.listen("/pearl/belief", cv.BeliefMsg, LATCHED_QOS)
        speech = probe.publisher("/pearl/speech", cv.RecognisedSpeechMsg, INPUT_QOS)
        for name in ("belief_tracker", "hierarchical_policy"):
            assert state(node, executor, name) == "unconfigured"
            assert transition(node, executor, name, Transition.TRANSITION_CONFIGURE)
            assert state(node, executor, name) == "inactive"
        # Configured but inactive: nothing is published, nothing acts — checked once the probe's
        # listeners see the nodes' publishers (which configure creates), so silence means something.
        assert wait_for(lambda: not probe.unmatched(), DISCOVERY_TIMEOUT, executor), probe.unmatched()
        assert not wait_for(lambda: actions or beliefs, 1.0, executor)
        for name in ("hierarchical_policy", "belief_tracker"):
            assert transition(node, executor, name, Transition.TRANSITION_ACTIVATE)
        assert wait_for(lambda: actions and beliefs, DISCOVERY_TIMEOUT, executor), "no first action after activate"
        np.testing.assert_allclose(cv.msg_to_belief(beliefs[0]), model.b0)
        assert wait_for(lambda: not probe.unmatched(), DISCOVERY_TIMEOUT, executor)
        # One step: the answer moves the belief away from b0.
        n = len(beliefs)
        speech.publish(cv.speech_to_msg("what time is it"))
        assert wait_for(lambda: len(beliefs) > n and len(actions) >= 2, DISCOVERY_TIMEOUT, executor)
        stepped = cv.msg_to_belief(beliefs[-1])
        assert not np.allclose(stepped, model.b0)
        # Deactivated: inputs change nothing, no action goes out.
        assert transition(node, executor, "hierarchical_policy", Transition.TRANSITION_DEACTIVATE)
        assert transition(node, executor, "belief_tracker", Transition.TRANSITION_DEACTIVATE)
        seen_actions, seen_beliefs = len(actions), len(beliefs)
        speech.publish(cv.speech_to_msg("give me the weather forecast for tomorrow"))
        assert not wait_for(lambda: len(actions) > seen_actions or len(beliefs) > seen_beliefs, 1.5, executor)
        # Active again: the kept belief (not b0) is published and answered.
        assert transition(node, executor, "hierarchical_policy", Transition.TRANSITION_ACTIVATE)
        assert transition(node, executor, "belief_tracker", Transition.TRANSITION_ACTIVATE)
        assert wait_for(lambda: len(beliefs) > seen_beliefs and len(actions) > seen_actions, DISCOVERY_TIMEOUT,
                        executor)
        np.testing.assert_allclose(cv.msg_to_belief(beliefs[-1]), stepped, atol=1e-12)
        # /pearl/reset: back to b0.
        reset = node.create_client(Trigger, "/pearl/reset")
        answer = call_service(reset, Trigger.Request(), executor)   # resetting twice is harmless
        assert answer.success and "b0" in answer.message
        assert wait_for(lambda: np.allclose(cv.msg_to_belief(beliefs[-1]), model.b0), DISCOVERY_TIMEOUT, executor)
        for name in ("belief_tracker", "hierarchical_policy"):
            assert transition(node, executor, name, Transition.TRANSITION_ACTIVE_SHUTDOWN)
            assert state(node, executor, name) == "finalized"
    finally:
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown(context=context)
        codes = [tracker.stop(5.0), policy.stop(5.0)]
        print(tracker.stderr()[-3000:], policy.stderr()[-3000:])   # pytest shows it if the test failed
    assert codes == [0, 0], tracker.stderr()[-2000:] + policy.stderr()[-2000:]


def test_action_executor_lifecycle_over_dds(tmp_path):
    """The executor as a managed node in its own process: nothing is said, shown or driven
    before activate and after deactivate (counted), it acts while active, and shuts down."""
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.signals import SignalHandlerOptions

    from pearl_pomdp.nodes.common import EVENT_QOS

    configure_test_process(tmp_path)
    domain_id = allocate_domain_id()
    env = ros_env(domain_id, tmp_path)
    executor_proc = Proc([str(BIN / "action_executor"), "--ros-args", "-p", "autostart:=false"], env, tmp_path,
                         "executor")
    context = Context()
    rclpy.init(context=context, domain_id=domain_id, signal_handler_options=SignalHandlerOptions.NO)
    executor = SingleThreadedExecutor(context=context)
    node = rclpy.create_node("executor_probe", context=context)
    executor.add_node(node)
    name = "action_executor"
    try:
        probe = Probe(node)
        said = probe.listen("/pearl/say", cv.TextMsg, EVENT_QOS)
        goals = probe.listen("/goal_pose", cv.PoseMsg, LATCHED_QOS)
        action = probe.publisher("/pearl/action", cv.ActionMsg, EVENT_QOS)

        def act_and_count(text):
            before = (len(said), len(goals))
            action.publish(cv.action_to_msg(text))
            return before

        assert state(node, executor, name) == "unconfigured"
        assert transition(node, executor, name, Transition.TRANSITION_CONFIGURE)
        assert state(node, executor, name) == "inactive"
        # Its topics exist once configured: wait until every one matches the probe on both ends
        # (the /pearl/say and /goal_pose listeners too), or "nothing said" would prove nothing.
        assert wait_for(lambda: not probe.unmatched(), DISCOVERY_TIMEOUT, executor), probe.unmatched()
        act_and_count("TellTime")
        act_and_count("GoHome")
        assert not wait_for(lambda: said or goals, 1.0, executor), "an inactive executor acted"
        assert transition(node, executor, name, Transition.TRANSITION_ACTIVATE)
        assert wait_for(lambda: not probe.unmatched(), DISCOVERY_TIMEOUT, executor)
        act_and_count("TellTime")
        assert wait_for(lambda: said, DISCOVERY_TIMEOUT, executor), "no sentence after activate"
        assert said[0].data.startswith("It is ")
        act_and_count("GoHome")
        assert wait_for(lambda: goals, DISCOVERY_TIMEOUT, executor), "no goal pose after activate"
        assert (goals[0].pose.position.x, goals[0].pose.position.y) == (0.0, 0.0)   # home in the params file
        assert transition(node, executor, name, Transition.TRANSITION_DEACTIVATE)
        n_said, n_goals = len(said), len(goals)
        act_and_count("TellWeather")
        act_and_count("GotoPatientRoom")
        # What those two would give: the weather sentence, a goal away from home. Not "any message":
        # /goal_pose is latched, and a probe that re-matches the executor (its lease run out on a loaded
        # machine) receives the home goal again. A parallel CI run at load ~10 failed the any-message
        # check once; which message came was not recorded, so the re-sent home goal is the likely cause.
        home = (goals[0].pose.position.x, goals[0].pose.position.y)
        assert not wait_for(lambda: any(m.data == WEATHER for m in said[n_said:])
                            or any((g.pose.position.x, g.pose.position.y) != home for g in goals[n_goals:]),
                            1.5, executor), "an inactive executor acted"
        assert transition(node, executor, name, Transition.TRANSITION_ACTIVATE)
        act_and_count("TellWeather")
        assert wait_for(lambda: len(said) > n_said, DISCOVERY_TIMEOUT, executor)
        assert said[-1].data == WEATHER
        assert transition(node, executor, name, Transition.TRANSITION_ACTIVE_SHUTDOWN)
        assert state(node, executor, name) == "finalized"
    finally:
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown(context=context)
        code = executor_proc.stop(5.0)
        print(executor_proc.stderr()[-3000:])   # pytest shows it if the test failed
    assert code == 0, executor_proc.stderr()[-2000:]
