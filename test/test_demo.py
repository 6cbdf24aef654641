"""`pearl demo`: Figure 4 through the full graph under sim time, transcript + bag + replay."""
import json
from pathlib import Path

import pytest

from ros_helpers import allocate_domain_id, configure_test_process

REPO = Path(__file__).resolve().parents[1]
pytestmark = pytest.mark.ros


@pytest.fixture(scope="module")
def demo(tmp_path_factory, pearl_policy):
    from pearl_sim.demo import run_demo

    tmp = tmp_path_factory.mktemp("demo")
    configure_test_process(tmp)
    lines = []
    result = run_demo(REPO / "config/scenarios/figure4.yaml", tmp / "out", domain_path=REPO / "config/pearl.domain.yaml",
                      hierarchy_path=REPO / "config/pearl.hierarchy.yaml", policy=str(pearl_policy), seed=4,
                      domain_id=allocate_domain_id(), echo=lines.append)
    return result, lines


def test_demo_transcript_shows_clarification_and_completed_guidance(demo):
    result, lines = demo
    text = result.transcript.read_text()
    assert text.splitlines()[-1].startswith("outcome: guidance completed")
    assert result.metrics["guidances_completed"] == 1 and result.metrics["residents_lost"] == 0
    assert result.clarifications >= 1
    actions = [s.action for s in result.steps]
    # Figure 4's order: contact before the reminder, the reminder before the guidance.
    assert actions.index("RemindPhysioAppt") < actions.index("GuideToPhysio")
    assert any(a in ("RingDoorBell", "GotoPatientRoom") for a in actions[:actions.index("RemindPhysioAppt")])
    # Each step's trace runs root → … → the primitive that was published.
    for step in result.steps:
        assert step.trace and step.trace[-1]["choice"] == step.action
    # What was echoed live is what was written.
    assert "\n".join(lines) in text
    summary = json.loads((result.out_dir / "summary.json").read_text())
    assert summary["actions"] == actions and summary["bag_messages"] == result.bag_messages > 0
    assert result.plot.stat().st_size > 10_000


def test_demo_bag_replays_to_the_same_actions(demo):
    from pearl_pomdp.nodes.bag_replay import replay_bag

    result, _ = demo
    replay = replay_bag(result.bag, domain_id=allocate_domain_id())
    assert replay.expected_actions[:len(result.steps)] == [s.action for s in result.steps]
    assert replay.match, f"first mismatch at {replay.to_dict().get('first_mismatch')}"
