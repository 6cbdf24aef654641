"""A working day through the real nodes (pearl_sim/nursing_home/day_graph.py, `pearl day --nodes`):
the same day as the core executive's, a bag split by the hour that replays, the measurements."""
from pathlib import Path

import pytest

from ros_helpers import allocate_domain_id, configure_test_process

REPO = Path(__file__).resolve().parents[1]
pytestmark = [pytest.mark.ros, pytest.mark.slow]   # a whole morning through the nodes (the shipped day plan)
#: A morning that starts with a vitamin reminder at 08:05 (the rest of the day far away), to 08:15.
UNTIL = 15 * 60.0
SPLIT = 5 * 60.0
RESIDENT = {"name": "Mrs D", "walking_speed": 0.4, "answers_door": 1.0, "touchscreen": 0.3}


def _plan():
    from pearl_sim.nursing_home.day import DayPlan

    return DayPlan(seed=5, activities=(), appointment=8.5 * 3600, vitamin_due=300.0, checklist_due=10 * 3600.0,
                   arrival_question=None)


@pytest.fixture(scope="module")
def day(tmp_path_factory, day_policy):
    from pearl_sim.nursing_home.day_graph import run_day_graph

    tmp = tmp_path_factory.mktemp("day")
    configure_test_process(tmp)
    return run_day_graph(REPO / "config/pearl_day.domain.yaml", day_policy, RESIDENT, 0.0, 0.25, 5, tmp / "out",
                         until=UNTIL, split_s=SPLIT, domain_id=allocate_domain_id(), name="test-day", plan=_plan())


def test_the_nodes_live_the_same_morning_as_the_core(day, day_policy):
    """The graph over DDS and the core executive take the same actions and leave the same checklist."""
    from pearl_pomdp.hierarchy import load_hierarchical_policy
    from pearl_pomdp.model.domain_yaml import load_domain
    from pearl_sim.nursing_home.day_study import DayCase, run_day
    from pearl_sim.planning import Controller

    domain = load_domain(REPO / "config/pearl_day.domain.yaml")
    controller = Controller("hierarchical", load_hierarchical_policy(day_policy, domain))
    core = run_day(controller, domain, DayCase("Mrs D", RESIDENT, 0.0, 5, 5), 0.25, timeline=True, until=UNTIL,
                   plan=_plan())
    assert [r["action"] for r in day["timeline"]] == [r["action"] for r in core["timeline"]]
    assert day["checklist"] == core["checklist"]
    assert day["checklist"]["reminders_delivered"] == 1 and day["checklist"]["reminders_on_time"] == 1


def test_the_bag_is_split_every_five_minutes_and_replays(day):
    from pearl_pomdp.bags.reader import BagReader
    from pearl_pomdp.nodes.bag_replay import replay_bag

    # A file holds at most five minutes of log time from its first message: the 15-minute morning (and
    # the second of /clock the run adds after it, as the demo's) in three or four files, in order.
    files = day["bag_files"]
    assert files == [f"bag_{k}.mcap" for k in range(len(files))] and len(files) in (3, 4)
    spans = []
    for name in files:
        times = [m.log_time for m in BagReader(Path(day["bag"]) / name).messages]
        spans.append((min(times), max(times)))
    assert all(last - first < SPLIT * 1e9 for first, last in spans)
    assert all(spans[k][1] < spans[k + 1][0] for k in range(len(spans) - 1))   # split in time order
    assert spans[-1][1] - spans[0][0] >= (UNTIL - 10.0) * 1e9                   # the whole morning is there
    reader = BagReader(day["bag"])
    assert not reader.salvaged and reader.message_count == day["bag_messages"]
    replay = replay_bag(day["bag"], domain_id=allocate_domain_id())
    assert replay.match, f"first mismatch at {replay.to_dict().get('first_mismatch')}"
    assert replay.expected_actions[:len(day["timeline"])] == [r["action"] for r in day["timeline"]]


def test_the_measurements_are_taken(day):
    assert day["final_belief_valid"]
    hour = day["answer_ms_per_hour"][0]
    # Every action after the first answered a step; the one decided at the end is answered, not taken.
    assert hour["steps"] == len(day["timeline"]) and 0 < hour["p50_ms"] <= hour["p99_ms"]
    assert day["rss_mb"][0]["hour"] == 0 and day["rss_mb"][-1]["hour"] == "end"
    assert all(m["rss_mb"] > 50 for m in day["rss_mb"])


def test_the_demo_ends_when_pearl_has_left_for_its_station(tmp_path, day_policy):
    """Figure 4(f), "Pearl leaves": with a policy that goes home after its work (the day domain's), the
    episode ends once the robot is back at its station with nothing wanted, before the scenario's
    max_steps; the outcome line says so."""
    from pearl_sim.nursing_home.demo import run_demo

    configure_test_process(tmp_path)
    # Figure 4 with twice its step budget: the episode must end by Pearl leaving, not by the budget.
    scenario = tmp_path / "figure4_long.yaml"
    text = (REPO / "config/scenarios/figure4.yaml").read_text()
    assert "max_steps: 30 " in text
    scenario.write_text(text.replace("max_steps: 30 ", "max_steps: 60 "))
    result = run_demo(scenario, tmp_path / "out",
                      domain_path=REPO / "config/pearl_day.domain.yaml",
                      hierarchy_path=REPO / "config/pearl.hierarchy.yaml", policy=str(day_policy), seed=4,
                      domain_id=allocate_domain_id())
    actions = [s.action for s in result.steps]
    assert actions[-1] == "GoHome" and len(actions) < 60
    assert result.metrics["guidances_completed"] == 1
    assert result.transcript.read_text().splitlines()[-1].startswith("outcome: guidance completed")
    assert "ended at home" in result.outcome()
