"""The reception robot as a user launches it: ``pearl launch launch/pearl.launch.xml
domain:=config/reception.domain.yaml policy:=… params_file:=config/reception_nodes.yaml
navigation:=false`` starts the three nodes as separate processes over DDS (the same XML that
``ros2 launch pearl_pomdp pearl.launch.xml`` reads); the test publishes on the reception robot's
own inputs — a ``sensor_msgs/BatteryState`` (best effort), the navigation's arrival, the person
detector — and checks every belief against the core's Bayes filter and every action against the
core's EXECUTE on it: a low battery docks, a detected visitor is answered as the policy says."""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
from ros_helpers import DISCOVERY_TIMEOUT, Probe, Proc, allocate_domain_id, configure_test_process, ros_env, wait_for  # noqa: E402

pytestmark = [pytest.mark.ros, pytest.mark.slow]

import rclpy  # noqa: E402

from pearl_pomdp.belief import BeliefFilter  # noqa: E402
from pearl_pomdp.hierarchy import load_hierarchical_policy  # noqa: E402
from pearl_pomdp.model.domain_yaml import load_domain  # noqa: E402
from pearl_pomdp.nodes import conversions as cv  # noqa: E402
from pearl_pomdp.nodes.channel_messages import qos_profile  # noqa: E402
from pearl_pomdp.nodes.common import INPUT_QOS, LATCHED_QOS  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
PEARL = str(Path(sys.executable).parent / "pearl")
DOMAIN = REPO / "config" / "reception.domain.yaml"


@pytest.fixture(scope="module")
def launched(tmp_path_factory):
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.signals import SignalHandlerOptions
    from sensor_msgs.msg import BatteryState

    from pearl_pomdp.hierarchy import load_hierarchy, plan

    tmp = tmp_path_factory.mktemp("reception_launch")
    domain = load_domain(DOMAIN)
    policy_dir = plan(domain, load_hierarchy(REPO / "config/reception.hierarchy.yaml", domain)).save(tmp / "policy")
    configure_test_process(tmp)
    domain_id = allocate_domain_id()
    context = Context()
    rclpy.init(context=context, domain_id=domain_id, signal_handler_options=SignalHandlerOptions.NO)
    node = rclpy.create_node("reception_probe", context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    probe = Probe(node)
    g = {"domain": domain, "model": domain.compile(), "policy": load_hierarchical_policy(policy_dir, domain),
         "actions": probe.listen("/pearl/action", cv.ActionMsg, LATCHED_QOS),
         "beliefs": probe.listen("/pearl/belief", cv.BeliefMsg, LATCHED_QOS),
         "battery": node.create_publisher(BatteryState, "/battery_state", qos_profile("best_effort", 10)),
         "arrived": node.create_publisher(cv.TextMsg, "/reception/arrived", INPUT_QOS),
         "person": node.create_publisher(cv.TextMsg, "/reception/person", INPUT_QOS)}
    launch = Proc([PEARL, "launch", "launch/pearl.launch.xml", f"domain:={DOMAIN}", f"policy:={policy_dir}",
                   f"params_file:={REPO / 'config' / 'reception_nodes.yaml'}", "navigation:=false",
                   "step_timeout:=0.0"], ros_env(domain_id, tmp), tmp, "launch")
    g["launch"] = launch

    def wait(predicate, timeout=DISCOVERY_TIMEOUT):
        return wait_for(predicate, timeout, executor)

    g["wait"] = wait
    try:
        ready = wait(lambda: all(g[k].get_subscription_count() >= 1 for k in ("battery", "arrived", "person"))
                     and len(g["actions"]) >= 1 and len(g["beliefs"]) >= 1, 3 * DISCOVERY_TIMEOUT)
        assert ready, f"graph not ready: {launch.stderr()[-3000:]}"
        yield g
    finally:
        g["exit_code"] = launch.stop(timeout=15.0)
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown(context=context)


def _feed(g, publisher, msg, symbol):
    """Publish one input; check the new belief and action against the core; return the action."""
    model = g["model"]
    n_actions, n_beliefs = len(g["actions"]), len(g["beliefs"])
    before, action = cv.msg_to_belief(g["beliefs"][-1]), cv.msg_to_action(g["actions"][-1])
    g[publisher].publish(msg)
    assert g["wait"](lambda: len(g["actions"]) > n_actions and len(g["beliefs"]) > n_beliefs), \
        f"no answer to {symbol}: {g['launch'].stderr()[-3000:]}"
    expected = BeliefFilter(model).update(before, model.actions.index(action), model.observations.index(symbol))
    np.testing.assert_allclose(cv.msg_to_belief(g["beliefs"][-1]), expected, atol=1e-12)
    answer = cv.msg_to_action(g["actions"][-1])
    assert answer == g["policy"].execute(expected).action_name
    return answer


def test_a_low_battery_reading_docks_and_a_visitor_is_answered(launched):
    from sensor_msgs.msg import BatteryState

    g = launched
    assert cv.msg_to_action(g["actions"][0]) == g["policy"].execute(g["model"].b0).action_name == "Wait"
    # 10 % is in the charge_low bin: the tracker observes charge_low, the policy docks.
    assert _feed(g, "battery", BatteryState(percentage=0.1), "charge_low") == "Dock"
    assert _feed(g, "arrived", cv.text_to_msg("at_desk"), "at_desk") == "Wait"
    _feed(g, "person", cv.text_to_msg("person_seen"), "person_seen")


def test_the_launch_stops_cleanly(launched):
    code = launched["launch"].stop(timeout=15.0)
    err = launched["launch"].stderr()
    assert code == 0, err[-3000:]
    assert "Traceback" not in err
    assert "tracking reception" in err and "charge (number) on /battery_state" in err
