"""The ward robot as a user launches it: ``pearl launch launch/pearl.launch.xml
domain:=config/ward.domain.yaml policy:=online:5 params_file:=config/ward_nodes.yaml navigation:=false``
starts the three nodes as separate processes over DDS and plans online at every belief (233,280
states); with ``policy:=`` empty the policy node plans ``config/ward.hierarchy.yaml`` at start-up
(the residents' subtasks offline, the root online) and answers with the hierarchy. The test answers
every drive with its arrival and otherwise presses call buttons and speaks, and checks every belief
against the core's Bayes filter and every action against the core's decider on it — OnlineDecider
with the same trials, or the hierarchy planned here from the same files (a decision depends on the
belief alone). The test's reference is built while the nodes start, on the other core. Decision
times through the nodes are measured by ``bench/ward_launch.py``; start-up (compile ~2 s CPU, QMDP and blind
bounds by policy iteration ~2 s, in the node and once here for both references; the test's compilation is
the session's ``ward_domain``, shared by both launches) makes it the suite's slowest setup, so the test is marked slow."""
from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
from ros_helpers import DISCOVERY_TIMEOUT, Probe, Proc, allocate_domain_id, configure_test_process, ros_env, wait_for  # noqa: E402

pytestmark = [pytest.mark.ros, pytest.mark.slow]

import rclpy  # noqa: E402

from pearl_pomdp.belief import BeliefFilter  # noqa: E402
from pearl_pomdp.nodes import conversions as cv  # noqa: E402
from pearl_pomdp.nodes.common import EVENT_QOS, INPUT_QOS, LATCHED_QOS  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
PEARL = str(Path(sys.executable).parent / "pearl")
DOMAIN = REPO / "config" / "ward.domain.yaml"
STARTUP = 600.0      # s: compile (~2 s) and the online bounds (~2 s idle): a guard for a heavily loaded machine


#: The core's search bounds for the session's compiled ward (QMDP above, blind policies below: ~3 s of
#: CPU), computed once for both references: the hierarchical plan computes them for its online root
#: (``default_bounds`` of the full model), and the online decider takes the same ones. The hierarchical
#: launch runs first so that its plan's bounds are there when the online one needs them.
_REFERENCE_BOUNDS: dict = {}


@pytest.fixture(scope="module", params=["hierarchical", "online:5"])
def launched(request, tmp_path_factory, ward_domain):
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.signals import SignalHandlerOptions

    from pearl_pomdp.online.decider import OnlineDecider
    from pearl_pomdp.online.despot import DespotSettings

    tmp = tmp_path_factory.mktemp("ward_launch")
    domain = ward_domain                 # compiled once for the session (conftest.py)
    configure_test_process(tmp)
    domain_id = allocate_domain_id()
    context = Context()
    rclpy.init(context=context, domain_id=domain_id, signal_handler_options=SignalHandlerOptions.NO)
    node = rclpy.create_node("ward_probe", context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    probe = Probe(node)
    policy = request.param
    g = {"domain": domain, "policy": policy,
         "actions": probe.listen("/pearl/action", cv.ActionMsg, LATCHED_QOS),
         "beliefs": probe.listen("/pearl/belief", cv.BeliefMsg, LATCHED_QOS),
         "decisions": probe.listen("/pearl/decision", cv.DecisionMsg, EVENT_QOS),
         "arrived": node.create_publisher(cv.TextMsg, "/ward/arrived", INPUT_QOS),
         "call": node.create_publisher(cv.TextMsg, "/ward/call_button", INPUT_QOS),
         "speech": node.create_publisher(cv.RecognisedSpeechMsg, "/ward/speech", INPUT_QOS)}
    launch = Proc([PEARL, "launch", "launch/pearl.launch.xml", f"domain:={DOMAIN}",
                   f"policy:={policy if policy != 'hierarchical' else ''}",
                   f"hierarchy:={REPO / 'config' / 'ward.hierarchy.yaml'}",
                   f"params_file:={REPO / 'config' / 'ward_nodes.yaml'}", "navigation:=false", "step_timeout:=0.0"],
                  ros_env(domain_id, tmp), tmp, "launch")
    g["launch"] = launch
    g["wait"] = lambda predicate, timeout=DISCOVERY_TIMEOUT: wait_for(predicate, timeout, executor)
    try:
        # The reference, built while the nodes compile and plan in their own processes.
        g["model"] = model = domain.compile()
        g["filter"] = BeliefFilter(model)
        if policy == "hierarchical":
            from pearl_pomdp.hierarchy import load_hierarchy, plan

            g["decider"] = plan(domain, load_hierarchy(REPO / "config" / "ward.hierarchy.yaml", domain))
            _REFERENCE_BOUNDS.setdefault("ward", g["decider"].online_root.bounds)
        else:
            from pearl_pomdp.online.decider import default_bounds

            bounds = _REFERENCE_BOUNDS.get("ward") or _REFERENCE_BOUNDS.setdefault("ward", default_bounds(model))
            g["decider"] = OnlineDecider(model, bounds=bounds, settings=DespotSettings(trials=5))
        ready = g["wait"](lambda: launch.returncode is not None or (
            all(g[k].get_subscription_count() >= 1 for k in ("arrived", "call", "speech"))
            and len(g["actions"]) >= 1 and len(g["beliefs"]) >= 1), STARTUP)
        # (a launch that ended, e.g. a node killed, fails now rather than at the start-up guard)
        assert ready and launch.returncode is None, f"graph not ready: {launch.stderr()[-3000:]}"
        yield g
    finally:
        g["exit_code"] = launch.stop(timeout=15.0)
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown(context=context)


def _feed(g, publisher, text, symbol):
    model = g["model"]
    n_actions, n_beliefs = len(g["actions"]), len(g["beliefs"])
    before, action = cv.msg_to_belief(g["beliefs"][-1]), cv.msg_to_action(g["actions"][-1])
    g[publisher].publish(cv.speech_to_msg(text) if publisher == "speech" else cv.text_to_msg(text))
    assert g["wait"](lambda: len(g["actions"]) > n_actions and len(g["beliefs"]) > n_beliefs, 120.0), \
        f"no answer to {symbol}: {g['launch'].stderr()[-3000:]}"
    expected = g["filter"].update(before, model.actions.index(action), model.observations.index(symbol))
    np.testing.assert_allclose(cv.msg_to_belief(g["beliefs"][-1]), expected, atol=1e-9)
    answer = cv.msg_to_action(g["actions"][-1])
    assert answer == g["decider"].execute(expected).action_name
    return answer


def test_the_ward_plans_online_through_the_nodes_as_the_core_does(launched):
    g = launched
    first = cv.msg_to_action(g["actions"][0])
    assert first == g["decider"].execute(g["model"].b0).action_name
    action = first
    for step in range(4):
        if action.startswith("GoTo"):
            place = {"GoToStation": "station", "GoToRoomAnn": "room_ann", "GoToRoomBob": "room_bob",
                     "GoToRoomCleo": "room_cleo", "GoToLounge": "lounge"}[action]
            action = _feed(g, "arrived", f"at_{place}", f"at_{place}")
        elif step % 2 == 0:
            action = _feed(g, "call", "call_bob", "call_bob")
        else:
            action = _feed(g, "speech", "could i have some water", "water")
    record = cv.msg_to_decision(g["decisions"][-1])
    if g["policy"] == "hierarchical":
        # The root searched (20 trials, config/ward.hierarchy.yaml) and the trace starts at the root.
        assert record["trace"][0]["subtask"] == "Ward", record
        assert record["search"]["trials"] == 20 and "QMDP" in record["search"]["bounds"]
    else:
        assert record["search"]["trials"] == 5 and "QMDP" in record["search"]["bounds"]


def test_the_launch_stops_cleanly(launched):
    code = launched["launch"].stop(timeout=15.0)
    err = launched["launch"].stderr()
    assert code == 0, err[-3000:]
    assert "Traceback" not in err
