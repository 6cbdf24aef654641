"""`pearl demo`: Figure 4 through the full graph under sim time, transcript + bag + replay."""
import json
from pathlib import Path

import pytest

from ros_helpers import allocate_domain_id, configure_test_process

REPO = Path(__file__).resolve().parents[1]
pytestmark = pytest.mark.ros


@pytest.fixture(scope="module")
def demo(tmp_path_factory):
    """What `pearl demo` runs: Figure 4 with the day domain and its shipped plan."""
    from pearl_sim.nursing_home.demo import run_demo

    tmp = tmp_path_factory.mktemp("demo")
    configure_test_process(tmp)
    lines = []
    result = run_demo(REPO / "config/scenarios/figure4.yaml", tmp / "out",
                      domain_path=REPO / "config/pearl_day.domain.yaml",
                      hierarchy_path=REPO / "config/pearl.hierarchy.yaml", policy=str(REPO / "config/plans/pearl_day"),
                      seed=4, domain_id=allocate_domain_id(), echo=lines.append)
    return result, lines


def test_demo_transcript_shows_the_completed_guidance(demo):
    result, lines = demo
    text = result.transcript.read_text()
    assert text.splitlines()[-1].startswith("outcome: guidance completed")
    # Figure 4(f), "Pearl leaves": it answers her weather question, then drives back to its station.
    assert "1/1 question(s) answered" in text.splitlines()[-1] and "ended at home" in text.splitlines()[-1]
    assert result.metrics["guidances_completed"] == 1 and result.metrics["residents_lost"] == 0
    # No clarification here since issue 21: after the reminder and her 'sure' (and a 'yes' on the
    # screen) the converged plan is confident enough to guide, and on arrival it listens for her
    # question instead of asking "What would you like to know?". The eq. 15-17 plan asked both.
    assert result.metrics["clarifications"] == 0 and result.metrics.get("unprompted_questions", 0) == 0
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


def test_every_pearl_message_of_the_demo_bag_decodes_with_mcap_ros2_support_alone(demo):
    """Issue 39: a reader that imports nothing of this project reads the whole /pearl/* loop of a
    recorded bag from the bag's own schemas — typed fields, not JSON inside strings."""
    from pearl_pomdp.bags.reader import BagReader
    from ros_helpers import decode_with_mcap_ros2_alone

    result, _ = demo
    topics = decode_with_mcap_ros2_alone(result.bag)
    recorded = BagReader(result.bag).topics
    pearl = {t for t in recorded if t.startswith("/pearl/")}
    assert set(topics) == pearl and len(pearl) >= 10
    assert {t: e["count"] for t, e in topics.items()} == {t: recorded[t].message_count for t in pearl}
    types = {t: e["type"] for t, e in topics.items()}
    assert {t: types[t] for t in ("/pearl/action", "/pearl/belief", "/pearl/decision", "/pearl/speech")} == {
        "/pearl/action": "pearl_interfaces/msg/Action", "/pearl/belief": "pearl_interfaces/msg/Belief",
        "/pearl/decision": "pearl_interfaces/msg/Decision", "/pearl/speech": "pearl_interfaces/msg/RecognisedSpeech"}
    assert topics["/pearl/action"]["first"]["name"] == result.steps[0].action
    b0 = topics["/pearl/belief"]["first"]
    assert b0["step"] == 0 and [m["feature"] for m in b0["marginals"]][:2] == ["RobotLocation", "UserLocation"]
    assert abs(sum(m for m in b0["marginals"][0]["probabilities"]) - 1.0) < 1e-9
    decision = topics["/pearl/decision"]["first"]
    assert decision["action"] == result.steps[0].action and decision["trace"][-1]["choice"] == decision["action"]
    speech = topics["/pearl/speech"]["first"]
    assert isinstance(speech["text"], str) and 0.0 <= speech["confidence"] <= 1.0 and not speech["text"].startswith("{")
    truth = topics["/pearl/sim/truth"]["first"]    # issue 40: the world's truth typed too
    assert types["/pearl/sim/truth"] == "pearl_interfaces/msg/WorldTruth"
    assert (truth["phase"], truth["action"], truth["has_outcome"]) == ("start", result.steps[0].action, False)
    assert dict(zip(truth["feature_names"], truth["feature_values"]))["RobotLocation"] == "home"


def test_the_demo_bag_holds_the_worlds_truth_and_the_fit_counts_from_it(demo):
    """Issue 40: the truth of every action's start and end, as the world saw it, and the fit's true states."""
    from pearl_pomdp.bags.reader import BagReader
    from pearl_pomdp.fit import episodes_from_bag
    from pearl_pomdp.world_truth import truth_records

    result, _ = demo
    records = truth_records(BagReader(result.bag), "/pearl/sim/truth")
    starts = [r for r in records if r["phase"] == "start"]
    ends = [r for r in records if r["phase"] == "end"]
    actions = [s.action for s in result.steps]
    assert [r["action"] for r in starts] == actions + [""] and [r["action"] for r in ends] == actions
    assert [r["wrong"] for r in ends] == [s.wrong for s in result.steps]
    answered = sum(e.endswith("question answered") for r in ends for e in r["events"])
    assert answered == result.metrics["questions_answered"] >= 1
    guided = actions.index("GuideToPhysio")
    assert ends[guided]["state"]["UserLocation"] == "physio" and starts[guided]["state"]["UserLocation"] == "room"
    episode = episodes_from_bag(result.bag)
    assert episode.states == [r["state"] for r in starts][:len(episode.actions) + 1]


def test_demo_bag_replays_to_the_same_actions(demo):
    from pearl_pomdp.nodes.bag_replay import replay_bag

    result, _ = demo
    replay = replay_bag(result.bag, domain_id=allocate_domain_id())
    assert replay.expected_actions[:len(result.steps)] == [s.action for s in result.steps]
    assert replay.match, f"first mismatch at {replay.to_dict().get('first_mismatch')}"
    # Every belief is in the bag from b0 on (b0 is latched with depth 1: a recorder that joined
    # late lost it, one demo in three under load), and the replay computes each of them again.
    from pearl_pomdp.bags.reader import BagReader
    from pearl_pomdp.model.domain_yaml import load_domain
    from pearl_pomdp.nodes.bag_replay import recorded_beliefs

    b0 = load_domain(REPO / "config" / "pearl_day.domain.yaml").compile().b0
    first = recorded_beliefs(BagReader(result.bag))[0]
    assert max(abs(x - y) for x, y in zip(first, b0)) < 1e-12
    assert replay.beliefs_match and replay.beliefs == replay.expected_beliefs


def test_plotted_features_follow_the_scenario():
    """The belief plot draws what the scenario involves (issue 16): table4's checklist reminder and
    both questions, no walk; figure4's physio reminder, the walk and arrival, the weather."""
    from pearl_sim.nursing_home.demo import plotted_features
    from pearl_sim.nursing_home.scenario import load_scenarios

    (table4,) = load_scenarios(REPO / "config/scenarios/table4_dialog.yaml")
    (figure4,) = load_scenarios(REPO / "config/scenarios/figure4.yaml")
    t4 = plotted_features(table4)
    assert ("ReminderGoal", "checklist") in t4 and ("UserMotionGoal", "toPhysioWithRobot") not in t4
    assert {("UserInfoGoal", "wantTime"), ("UserInfoGoal", "wantWeather")} <= set(t4)
    f4 = plotted_features(figure4)
    assert {("ReminderGoal", "physio"), ("UserMotionGoal", "toPhysioWithRobot"), ("UserLocation", "physio"),
            ("UserInfoGoal", "wantWeather")} <= set(f4) and ("UserInfoGoal", "wantTime") not in f4


def test_outcome_scores_only_what_the_scenario_asked_for():
    from pearl_sim.nursing_home.demo import outcome_line

    metrics = {"guidances_completed": 0, "guidances_started": 0, "time_to_goal": [], "reminders_delivered": 1,
               "reminders_due": 1, "questions_answered": 1, "questions_raised": 2, "clarifications": 3,
               "unprompted_questions": 1, "wrong_actions": 0, "robot_at_end": "room"}
    assert outcome_line(dict(metrics, guidance_wanted=False)) == (
        "outcome: no guidance wanted; 1/1 reminder(s) delivered, 1/2 question(s) answered, 3 clarification "
        "question(s), 1 unprompted, 0 wrong action(s), ended away from home")
    assert outcome_line(dict(metrics, guidance_wanted=True)).startswith(
        "outcome: guidance NOT completed; 1/1 reminder(s)")
    # No question was raised and no reminder fell due: the line says nothing about them.
    idle = dict(metrics, reminders_due=0, questions_raised=0, robot_at_end="home", guidance_wanted=False)
    assert outcome_line(idle) == ("outcome: no guidance wanted; 3 clarification question(s), 1 unprompted, "
                                  "0 wrong action(s), ended at home")
