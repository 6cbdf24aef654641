"""The behaviour-tree node in the ROS graph in place of the POMDP policy: the real
belief_tracker process and the pearl_bt process over DDS on a test-unique domain; the test
plays the resident and the hardware on the input topics and checks every action against the
same tree run in the core (tick for tick)."""
from __future__ import annotations

import sys
from pathlib import Path

import pytest

from ros_helpers import (DISCOVERY_TIMEOUT, DOMAIN, Probe, Proc, allocate_domain_id, configure_test_process,
                         ros_env, wait_for)

pytestmark = [pytest.mark.ros]
import rclpy

from pearl_pomdp.model.domain_yaml import load_domain  # noqa: E402
from pearl_pomdp.nodes import conversions as cv  # noqa: E402
from pearl_pomdp.nodes.common import INPUT_QOS, LATCHED_QOS  # noqa: E402
from pearl_sim.nursing_home.behaviour_tree import PearlBehaviourTree  # noqa: E402

BIN = Path(sys.executable).parent
#: What the resident / hardware answer to each action: (topic, text, symbol the tracker makes of it).
INPUTS = [
    ("reminder", "g_physio", "g_physio"),          # closes DoNothing
    ("laser", "atRoom", "atRoom"),                 # closes GotoPatientRoom
    ("speech", "yes come in", "yes"),              # closes RingDoorBell
    ("touchscreen", "t_go", "t_go"),               # closes RemindPhysioAppt: the button, no confirmation
    ("laser", "atPhysio", "atPhysio"),             # closes GuideToPhysio
]


def test_bt_node_drives_the_tracker_over_dds(tmp_path):
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.signals import SignalHandlerOptions

    configure_test_process(tmp_path)
    domain_id = allocate_domain_id()
    env = ros_env(domain_id, tmp_path)
    context = Context()
    rclpy.init(context=context, domain_id=domain_id, signal_handler_options=SignalHandlerOptions.NO)
    procs = []
    try:
        node = rclpy.create_node("bt_test_probe", context=context)
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(node)
        probe = Probe(node)
        actions = probe.listen("/pearl/action", cv.ActionMsg, LATCHED_QOS)
        marginals = probe.listen("/pearl/belief", cv.BeliefMsg, LATCHED_QOS)
        pubs = {t: probe.publisher(f"/pearl/{t}", cv.RecognisedSpeechMsg if t == "speech" else cv.TextMsg, INPUT_QOS)
                for t, _, _ in INPUTS}
        procs.append(Proc([str(BIN / "belief_tracker"), "--ros-args", "-p", f"domain:={DOMAIN}",
                           "-p", "step_timeout:=0.0"], env, tmp_path, "tracker"))
        procs.append(Proc([str(BIN / "pearl_bt"), "--ros-args", "-p", f"domain:={DOMAIN}"], env, tmp_path, "bt"))
        # The tracker's latched b0 marginals (no action, no observation yet) must be in before the
        # steps are counted: arriving after the first input, it was once taken for that step's.
        assert wait_for(lambda: not probe.unmatched() and len(actions) >= 1 and len(marginals) >= 1,
                        DISCOVERY_TIMEOUT, executor), \
            f"no first action; bt stderr: {procs[1].stderr()[-400:]} tracker: {procs[0].stderr()[-400:]}"

        reference = PearlBehaviourTree(actions=list(load_domain(DOMAIN).actions))
        expected = [reference.execute(None).action_name]
        assert actions[0].name == expected[0] == "DoNothing"
        first = cv.msg_to_marginals(marginals[0])
        assert (first["action"], first["observation"]) == (None, None)
        for topic, text, symbol in INPUTS:
            # The tracker has opened the step with the last action when its step count moved on.
            seen, seen_steps = len(actions), len(marginals)
            pubs[topic].publish(cv.speech_to_msg(text) if topic == "speech" else cv.text_to_msg(text))
            assert wait_for(lambda: len(actions) > seen and len(marginals) > seen_steps, DISCOVERY_TIMEOUT, executor), \
                f"no action after {text!r}; tracker: {procs[0].stderr()[-400:]}"
            reference.observe(expected[-1], symbol)
            expected.append(reference.execute(None).action_name)
            last = cv.msg_to_marginals(marginals[-1])
            assert (last["action"], last["observation"]) == (expected[-2], symbol)
        assert [m.name for m in actions] == expected
        assert expected == ["DoNothing", "GotoPatientRoom", "RingDoorBell", "RemindPhysioAppt", "GuideToPhysio",
                            "TerminateGuidance"]
        # A closed step without its action or observation is logged and counted; the node carries on.
        junk = probe.publisher("/pearl/belief", cv.BeliefMsg, LATCHED_QOS)
        assert wait_for(lambda: junk.get_subscription_count() >= 2, DISCOVERY_TIMEOUT, executor)   # bt + probe
        junk.publish(cv.belief_to_msg([1.0], step=99))
        assert wait_for(lambda: "rejected message on /pearl/belief" in procs[1].stderr(),
                        DISCOVERY_TIMEOUT, executor), procs[1].stderr()[-400:]
        for p in procs:
            assert p.returncode is None, f"{p.name} exited: {p.stderr()[-400:]}"
    finally:
        for p in procs:
            p.stop()
        rclpy.try_shutdown(context=context)
