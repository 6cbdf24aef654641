"""A belief that survives a crash (docs/reliability.md, "Crashes"): the tracker, the policy
node and the executor run as separate processes over Fast DDS; the tracker is SIGKILLed in
the middle of guiding the resident to physiotherapy and started again. It resumes from its
journal with the belief it journaled (to 1e-12, in fact bit for bit), the policy does not
answer that step again, the executor says nothing twice, and the guidance completes without
a new reminder. Without a journal the same crash starts the tracker again at b0.
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest

from ros_helpers import (DISCOVERY_TIMEOUT, DOMAIN, Probe, Proc, allocate_domain_id, configure_test_process,
                         ros_env, wait_for)

pytestmark = [pytest.mark.ros, pytest.mark.slow]

import rclpy  # noqa: E402

from pearl_pomdp.journal import Journal, decode_array, domain_hash  # noqa: E402
from pearl_pomdp.model.factored import load_domain  # noqa: E402
from pearl_pomdp.nodes import conversions as cv  # noqa: E402
from pearl_pomdp.nodes.common import EVENT_QOS, INPUT_QOS, LATCHED_QOS  # noqa: E402

BIN = Path(sys.executable).parent
#: The resident of the guidance: what she (or the robot's laser) answers each action with.
#: The reminder comes from the scheduler first; the policy then fetches her, reminds and guides.
RESIDENT = {
    "DoNothing": ("speech", "let's go"),
    "GotoPatientRoom": ("laser", "atRoom"),
    "RingDoorBell": ("speech", "yes, come in"),
    "CheckUserPresent": ("speech", "yes I am here"),
    "RemindPhysioAppt": ("speech", "let's go"),
    "ConfirmGuideToPhysio": ("speech", "yes please"),
    "GuideToPhysio": ("laser", "atPhysio"),
}
#: Drives keep no deadline and silence closes no step: the test's inputs alone close steps.
STEP_RULES = ["-p", "step_timeout:=0.0", "-p", "drive_speed:=0.0"]


class Graph:
    """The three nodes as processes, and a probe in this process."""

    def __init__(self, tmp: Path, policy_dir: Path, journal: bool):
        from rclpy.context import Context
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.signals import SignalHandlerOptions

        configure_test_process(tmp)
        self.tmp, self.policy_dir = tmp, policy_dir
        self.journal_path = tmp / "tracker.journal.json" if journal else None
        self.domain_id = allocate_domain_id()
        self.env = ros_env(self.domain_id, tmp)
        self.context = Context()
        rclpy.init(context=self.context, domain_id=self.domain_id, signal_handler_options=SignalHandlerOptions.NO)
        self.node = rclpy.create_node("crash_probe", context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        probe = Probe(self.node)
        self.probe = probe
        self.actions = probe.listen("/pearl/action", cv.TextMsg, LATCHED_QOS)
        self.beliefs = probe.listen("/pearl/belief", cv.BeliefMsg, LATCHED_QOS)
        self.says = probe.listen("/pearl/say", cv.TextMsg, EVENT_QOS)
        self.diagnostics = probe.listen("/diagnostics", cv.DiagnosticsMsg, EVENT_QOS)
        self.inputs = {t: probe.publisher(f"/pearl/{t}", cv.TextMsg, INPUT_QOS) for t in ("speech", "laser", "reminder")}
        self.procs = []
        self.trackers = 0
        self.tracker = self.start_tracker()
        self.policy = self.start(BIN / "hierarchical_policy", "policy", "-p", f"policy:={policy_dir}",
                                 "-p", f"journal:={tmp / 'policy.journal.json'}")
        self.executor_proc = self.start(BIN / "action_executor", "executor")

    def start(self, exe: Path, name: str, *params: str) -> Proc:
        proc = Proc([str(exe), "--ros-args", "-p", f"domain:={DOMAIN}", *params], self.env, self.tmp, name)
        self.procs.append(proc)
        return proc

    def start_tracker(self) -> Proc:
        self.trackers += 1
        journal = str(self.journal_path) if self.journal_path is not None else "''"
        return self.start(BIN / "belief_tracker", f"tracker{self.trackers}", *STEP_RULES, "-p", f"journal:={journal}")

    def wait(self, predicate, timeout=DISCOVERY_TIMEOUT) -> bool:
        return wait_for(predicate, timeout, self.executor)

    def ready(self) -> bool:
        """The tracker listens to every input and the policy's answer to its latest belief is out."""
        return (all(p.get_subscription_count() >= 1 for p in self.inputs.values()) and len(self.actions) >= 1
                and len(self.beliefs) >= 1 and self.node.count_publishers("/pearl/say") >= 1)

    def answer(self, topic: str, text: str) -> str:
        """Publish an input; the policy's next action (after the tracker's next belief)."""
        n_actions, n_beliefs = len(self.actions), len(self.beliefs)
        self.inputs[topic].publish(cv.text_to_msg(text))
        assert self.wait(lambda: len(self.actions) > n_actions and len(self.beliefs) > n_beliefs), \
            f"no answer to {text!r}: {self.tracker.stderr()[-2000:]}"
        return cv.msg_to_action(self.actions[-1])

    def guide_until(self, last: str, first_input=("reminder", "g_physio"), max_steps: int = 10) -> list:
        """Answer the robot as the resident does until it takes ``last``; the actions taken."""
        taken = [cv.msg_to_action(self.actions[-1])]
        topic, text = first_input
        for _ in range(max_steps):
            taken.append(self.answer(topic, text))
            if taken[-1] == last:
                return taken
            topic, text = RESIDENT.get(taken[-1], ("speech", "let's go"))
        raise AssertionError(f"the robot never took {last}: {taken}")

    def tracker_diagnostics(self) -> list:
        out = []
        for msg in self.diagnostics:
            for name, status in cv.msg_to_diagnostics(msg).items():
                if name.endswith("belief_tracker"):
                    out.append(status["values"])
        return out

    def stop(self) -> None:
        for proc in self.procs:
            proc.stop(timeout=10.0)
        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)


@pytest.fixture
def graph_factory(tmp_path, pearl_policy):
    made = []

    def make(journal: bool) -> Graph:
        g = Graph(tmp_path / f"journal_{journal}", pearl_policy, journal)
        made.append(g)
        assert g.wait(g.ready, 3 * DISCOVERY_TIMEOUT), f"graph not ready: {g.tracker.stderr()[-3000:]}"
        assert cv.msg_to_action(g.actions[-1]) == "DoNothing"   # b0: nothing to do yet
        return g

    yield make
    for g in made:
        g.stop()


def kill_and_restart_tracker(g: Graph) -> int:
    """SIGKILL the tracker and start it again at once (DDS forgets the dead one only after its
    lease); how many beliefs were seen before: the later ones are the new tracker's."""
    g.tracker.popen.kill()
    assert g.tracker.wait(10.0) == -9
    g.wait(lambda: False, 0.2)   # anything the dead tracker sent is in
    seen = len(g.beliefs)
    g.tracker = g.start_tracker()
    assert g.wait(lambda: len(g.beliefs) > seen, 3 * DISCOVERY_TIMEOUT), \
        f"the restarted tracker published no belief: {g.tracker.stderr()[-3000:]}"
    return seen


def test_a_tracker_killed_mid_guidance_resumes_with_its_journaled_belief(graph_factory):
    g = graph_factory(journal=True)
    taken = g.guide_until("GuideToPhysio")
    assert "RemindPhysioAppt" in taken, taken
    before = g.beliefs[-1]
    key = cv.msg_to_belief_key(before)
    assert key is not None and key[1] == len(taken) - 1     # b0 is step 0, one step per answered action
    assert g.wait(lambda: g.says and g.says[-1].data == "Please follow me.", 10.0)   # the executor did it
    actions_before, says_before = len(g.actions), len(g.says)
    # The tracker has GuideToPhysio open (the policy's answer to the last belief) when it dies.
    assert g.wait(lambda: json.loads(g.journal_path.read_text())["state"]["open_action"] == "GuideToPhysio", 10.0)
    journaled = Journal(g.journal_path, "belief_tracker", str(DOMAIN), domain_hash(DOMAIN)).load()
    assert journaled.state is not None, journaled.reason
    journaled_belief = decode_array(journaled.state["belief"])

    seen = kill_and_restart_tracker(g)
    resumed = g.beliefs[seen]
    assert cv.msg_to_belief_key(resumed) == key
    assert np.max(np.abs(cv.msg_to_belief(resumed) - journaled_belief)) <= 1e-12
    assert np.array_equal(cv.msg_to_belief(resumed), cv.msg_to_belief(before))
    assert "resuming from journal" in g.tracker.stderr() and "open step GuideToPhysio" in g.tracker.stderr()
    assert g.wait(lambda: any(str(v.get("journal_status", "")).startswith(f"resuming from journal {g.journal_path}")
                              for v in g.tracker_diagnostics()), 10.0)
    # The policy saw that belief's step answered already: no action again, nothing said again.
    assert g.wait(lambda: "was answered already" in g.policy.stderr(), 10.0), g.policy.stderr()[-2000:]
    assert not g.wait(lambda: len(g.actions) > actions_before or len(g.says) > says_before, 1.5), \
        ([cv.msg_to_action(a) for a in g.actions[actions_before:]], [m.data for m in g.says[says_before:]])
    # The guidance completes from where it was: no new reminder, no new question.
    assert g.answer("laser", "atPhysio") == "TerminateGuidance"
    after = [cv.msg_to_action(a) for a in g.actions[actions_before:]]
    assert after == ["TerminateGuidance"], after
    assert g.wait(lambda: any(m.data == "We have arrived. Have a good session." for m in g.says[says_before:]), 10.0)
    assert [m.data for m in g.says[says_before:]] == ["We have arrived. Have a good session."]
    assert "replaces" not in g.tracker.stderr()   # the policy's latched GuideToPhysio did not reopen the step


def test_without_a_journal_the_killed_tracker_starts_again_at_b0(graph_factory):
    """What the journal is for: the same crash with journal:='' forgets the reminder and the walk."""
    g = graph_factory(journal=False)
    g.guide_until("GuideToPhysio")
    seen = kill_and_restart_tracker(g)
    model = load_domain(DOMAIN).compile()
    np.testing.assert_allclose(cv.msg_to_belief(g.beliefs[seen]), model.b0, atol=1e-12)
    assert cv.msg_to_belief_key(g.beliefs[seen])[1] == 0
    # A new run: the policy answers b0 again (DoNothing), as at the start of the day.
    assert g.wait(lambda: cv.msg_to_action(g.actions[-1]) == "DoNothing", 10.0)


def test_a_restarted_policy_keeps_the_operators_level_from_its_journal(ros_context, pearl_policy, tmp_path):
    """The operator set autonomy off at run time; the policy node dies and comes back with the
    launch file's full: its journal restores off (the parameter reads off too)."""
    from rclpy.parameter import Parameter

    from pearl_pomdp.nodes.hierarchical_policy import HierarchicalPolicyNode

    context, _ = ros_context
    params = {"domain": str(DOMAIN), "policy": str(pearl_policy), "journal": str(tmp_path / "policy.json"),
              "autonomy": "full"}
    first = HierarchicalPolicyNode(context=context, parameter_overrides=params)
    try:
        assert first.set_parameters([Parameter("autonomy", value="off")])[0].successful
        assert json.loads((tmp_path / "policy.json").read_text())["state"]["autonomy"] == "off"
    finally:
        first.destroy_node()
    second = HierarchicalPolicyNode(context=context, parameter_overrides=params)
    try:
        assert second.gate is not None and second.gate.autonomy == "off"
        assert second.get_parameter("autonomy").value == "off"
        assert second.journal is not None and second.journal.status.startswith("resuming from journal")
    finally:
        second.destroy_node()
    third = HierarchicalPolicyNode(context=context, parameter_overrides={**params, "journal_max_age": 0.001})
    try:
        assert third.gate is not None and third.gate.autonomy == "full"    # too old: the parameter's level
        assert third.journal is not None and "more than journal_max_age" in third.journal.status
    finally:
        third.destroy_node()
