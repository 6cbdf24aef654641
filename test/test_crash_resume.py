"""A belief that survives a crash and a graph that heals (docs/reliability.md, "Crashes"):
``pearl launch launch/pearl.launch.xml`` runs the tracker, the policy node, the executor and the
lifecycle supervisor as processes over Fast DDS; each managed node is SIGKILLed in the middle of
guiding the resident to physiotherapy. The launcher respawns it, the supervisor brings it up
again, the tracker resumes from its journal with the belief it journaled (to 1e-12, in fact bit
for bit), nothing is done or said twice, and the guidance completes without a new reminder.
What is lost without a journal: bench/fault_injection.py.
"""
from __future__ import annotations

import json
import os
import re
import signal
import time
from pathlib import Path

import numpy as np
import pytest

from ros_helpers import DISCOVERY_TIMEOUT, DOMAIN
from test_nodes_multiprocess import LaunchedGraph

pytestmark = [pytest.mark.ros, pytest.mark.slow]

from pearl_pomdp.journal import Journal, decode_array, domain_hash  # noqa: E402
from pearl_pomdp.nodes import conversions as cv  # noqa: E402
from pearl_pomdp.nodes.common import EVENT_QOS  # noqa: E402

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


class HealingGraph(LaunchedGraph):
    """``pearl launch launch/pearl.launch.xml`` (tracker, policy, executor, lifecycle_supervisor), and a
    probe in this process (test_nodes_multiprocess.LaunchedGraph, with the reminder input and
    /diagnostics; silence closes no step, and drives keep their deadlines: GuideToPhysio's is
    ~25 min at her pace)."""

    def __init__(self, tmp: Path, policy_dir: Path):
        super().__init__(tmp, policy_dir, extra_args=(f"domain:={DOMAIN}", "navigation:=false"),
                         inputs=("speech", "laser", "reminder"))
        self.diagnostics = self.probe.listen("/diagnostics", cv.DiagnosticsMsg, EVENT_QOS)
        #: The journal the tracker writes (journal:=auto under this test's ROS_HOME).
        self.journal_path = tmp / "pearl" / "journal" / f"domain{self.domain_id}" / "belief_tracker.json"

    def log(self) -> str:
        return self.launch.stderr() + self.launch.stdout()

    def pid(self, name: str) -> int:
        """The pid of ``name``'s latest process (started or respawned), from the launcher's lines."""
        found = re.findall(rf"\[launch\] (?:started|respawned) {name} \(pid (\d+)\)", self.launch.stderr())
        assert found, self.launch.stderr()[-2000:]
        return int(found[-1])

    def kill(self, name: str) -> float:
        """SIGKILL ``name`` and wait until the launcher respawned it; when it was killed (monotonic)."""
        pid = self.pid(name)
        respawned = self.launch.stderr().count(f"respawned {name} ")
        os.kill(pid, signal.SIGKILL)
        killed = time.monotonic()
        assert self.wait(lambda: self.launch.stderr().count(f"respawned {name} ") > respawned, DISCOVERY_TIMEOUT), \
            self.launch.stderr()[-3000:]
        return killed

    def ready(self) -> bool:
        """The tracker listens to every input and the policy's answer to its first belief is out."""
        return (all(p.get_subscription_count() >= 1 for p in self.inputs.values()) and len(self.actions) >= 1
                and len(self.beliefs) >= 1 and self.node.count_publishers("/pearl/say") >= 1)

    def answer(self, topic: str, text: str) -> str:
        """Publish an input; the policy's next action (after the tracker's next belief)."""
        return self.say(text, "", topic)

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

    def supervisor_states(self) -> dict:
        """The lifecycle supervisor's latest state of each managed node (its /diagnostics)."""
        out = {}
        for msg in self.diagnostics:
            for name, status in cv.msg_to_diagnostics(msg).items():
                if name.startswith("pearl: supervisor: "):
                    out[name.rsplit(": ", 1)[1]] = status["values"]["state"]
        return out


@pytest.fixture
def launched(tmp_path, pearl_policy):
    g = HealingGraph(tmp_path, pearl_policy)
    try:
        assert g.wait(g.ready, 3 * DISCOVERY_TIMEOUT), f"graph not ready: {g.log()[-3000:]}"
        assert cv.msg_to_action(g.actions[-1]) == "DoNothing"   # b0: nothing to do yet
        yield g
    finally:
        g.stop()


def test_a_launched_graph_heals_mid_guidance_and_the_tracker_resumes_its_journaled_belief(launched):
    """The tracker, then the policy, then the executor SIGKILLed while the robot guides the resident:
    the launcher respawns each, the supervisor configures and activates it again, the tracker resumes
    with its journaled belief (to 1e-12: bit for bit), nothing is done or said twice, and the
    guidance completes without a new reminder."""
    g = launched
    taken = g.guide_until("GuideToPhysio")
    assert "RemindPhysioAppt" in taken, taken
    before = g.beliefs[-1]
    key = cv.msg_to_belief_key(before)
    assert key is not None and key[1] == len(taken) - 1     # b0 is step 0, one step per answered action
    assert g.wait(lambda: g.says and g.says[-1].data == "Please follow me.", 10.0)   # the executor did it
    actions_before, says_before = len(g.actions), len(g.says)
    # The tracker has GuideToPhysio open (the policy's answer to the last belief) when it dies.
    # (Read through Journal.load: the step's opening is in the journal's small update file.)
    journal = Journal(g.journal_path, "belief_tracker", str(DOMAIN), domain_hash(DOMAIN))
    assert g.wait(lambda: (journal.load().state or {}).get("open_action") == "GuideToPhysio", 10.0)
    journaled = journal.load()
    assert journaled.state is not None, journaled.reason
    journaled_belief = decode_array(journaled.state["belief"])

    seen = len(g.beliefs)
    g.kill("belief_tracker")
    assert g.wait(lambda: len(g.beliefs) > seen, 3 * DISCOVERY_TIMEOUT), f"no belief after the restart: {g.log()[-3000:]}"
    resumed = g.beliefs[seen]
    assert cv.msg_to_belief_key(resumed) == key
    assert np.max(np.abs(cv.msg_to_belief(resumed) - journaled_belief)) <= 1e-12
    assert np.array_equal(cv.msg_to_belief(resumed), cv.msg_to_belief(before))
    log = g.log()
    assert "belief_tracker exited with code -9; respawning in 1 s" in log
    assert "belief_tracker is back (unconfigured): bringing it up again" in log
    assert "resuming from journal" in log and "open step GuideToPhysio" in log
    # The policy saw that belief's step answered already: no action again.
    assert g.wait(lambda: "was answered already" in g.log(), 10.0), g.log()[-2000:]

    # The policy dies: respawned, it knows from its journal that it acted on this step.
    answered = g.log().count("was answered already")
    g.kill("hierarchical_policy")
    assert g.wait(lambda: g.log().count("was answered already") > answered, 3 * DISCOVERY_TIMEOUT), g.log()[-3000:]
    # The executor dies: respawned (its action subscription is volatile: nothing old comes back).
    activated = g.log().count("action_executor is active")
    g.kill("action_executor")
    assert g.wait(lambda: g.log().count("action_executor is active") > activated, 3 * DISCOVERY_TIMEOUT), \
        g.log()[-3000:]
    assert g.wait(lambda: set(g.supervisor_states().values()) == {"active"}, 10.0), g.supervisor_states()
    assert not g.wait(lambda: len(g.actions) > actions_before or len(g.says) > says_before, 1.0), \
        ([cv.msg_to_action(a) for a in g.actions[actions_before:]], [m.data for m in g.says[says_before:]])
    # The guidance completes from where it was: no new reminder, no new question.
    assert g.answer("laser", "atPhysio") == "TerminateGuidance"
    after = [cv.msg_to_action(a) for a in g.actions[actions_before:]]
    assert after == ["TerminateGuidance"], after
    assert g.wait(lambda: any(m.data == "We have arrived. Have a good session." for m in g.says[says_before:]), 10.0)
    assert [m.data for m in g.says[says_before:]] == ["We have arrived. Have a good session."]
    assert "replaces" not in g.log()   # the policy's latched GuideToPhysio did not reopen the step


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


def test_a_policy_whose_record_cannot_go_out_still_journals_the_step_it_acted_on(ros_context, pearl_policy,
                                                                                  tmp_path):
    """A stop signal shuts the context down under a running callback: the action went out, then
    publishing the decision record raises. The journal must still say the step was acted on, or
    a restarted policy acts on the tracker's latched belief again (the race .ci/run once hit)."""
    from pearl_pomdp.nodes.hierarchical_policy import HierarchicalPolicyNode

    context, _ = ros_context
    params = {"domain": str(DOMAIN), "policy": str(pearl_policy), "journal": str(tmp_path / "policy.json")}
    node = HierarchicalPolicyNode(context=context, parameter_overrides=params)
    try:
        published = []
        node.action_pub.publish = published.append          # the action goes out

        def context_gone(_msg):
            raise RuntimeError("publisher's context is invalid")

        node.decision_pub.publish = context_gone              # the record does not
        belief = cv.belief_to_msg(node.model.b0, step=3, run=77)
        with pytest.raises(RuntimeError, match="context is invalid"):
            node._on_belief(belief)
        assert len(published) == 1
        assert json.loads((tmp_path / "policy.json").read_text())["state"]["acted"] == [77, 3]
    finally:
        node.destroy_node()


def test_a_journal_sync_mode_the_node_does_not_know_is_refused_naming_the_parameter(ros_context, pearl_policy,
                                                                                   tmp_path):
    from pearl_pomdp.nodes.common import NodeSetupError
    from pearl_pomdp.nodes.hierarchical_policy import HierarchicalPolicyNode

    context, _ = ros_context
    params = {"domain": str(DOMAIN), "policy": str(pearl_policy), "journal": str(tmp_path / "policy.json"),
              "journal_sync": "sometimes"}
    with pytest.raises(NodeSetupError, match="journal_sync: 'sometimes' is not one of fsync, background, none"):
        HierarchicalPolicyNode(context=context, parameter_overrides=params).destroy_node()
