"""Pace adaptation in the manager, used by the simulator (issue 14 item 4): the world's guided
drive takes its speed from the core GuidePace fed by the simulated people tracker."""
from __future__ import annotations

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
from ros_helpers import DOMAIN  # noqa: E402

from pearl_pomdp.guide_pace import GuidePaceConfig  # noqa: E402
from pearl_pomdp.model.domain_yaml import load_domain  # noqa: E402
from pearl_sim.nursing_home.scenario import load_scenarios, parse_scenarios  # noqa: E402
from pearl_sim.nursing_home.world import World, default_guide_pace  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
GUIDE = ["GotoPatientRoom", "RingDoorBell", "RemindPhysioAppt", "GuideToPhysio"]


def scenario(walking_speed: float, rest_probability: float = 0.0, rest_seconds: float = 10.0, adapt: bool = True):
    return parse_scenarios(
        "name: t\nappointments: [{at: 1, kind: physio}]\n"
        f"robot: {{speed: 0.6, pace_adaptation: {'true' if adapt else 'false'}}}\n"
        f"resident: {{walking_speed: {walking_speed}, rest_probability: {rest_probability}, "
        f"rest_seconds: {rest_seconds}, willingness: 1.0, answers_door: 1.0, touchscreen: 0.0}}\n"
        "speech: {word_error_rate: 0.0}\n")[0]


def guide(world: World):
    for action in GUIDE[:-1]:
        world.act(action)
        world.wait(world.time + 1.0)
    return world.act("GuideToPhysio")


def test_the_world_uses_the_guide_pace_nodes_settings():
    config, symbol = default_guide_pace()
    assert symbol == "userLost"
    assert (config.follow_gap, config.resume_gap, config.stop_gap, config.lost_timeout) == (1.0, 1.5, 2.5, 60.0)


def test_a_slow_resident_sets_the_pace_and_arrives():
    world = World(scenario(0.05), seed=1)
    result = guide(world)
    assert world.metrics.guidances_completed == 1 and world.metrics.residents_lost == 0
    (speed,) = world.metrics.guide_speeds
    assert speed == pytest.approx(0.05, rel=0.1)          # the robot went at her pace, not at 0.6 m/s
    assert [m.text for m in result.messages] == ["atPhysio"]


def test_at_fixed_pace_the_same_resident_is_lost():
    world = World(scenario(0.05, adapt=False), seed=1)
    guide(world)
    assert world.metrics.guidances_completed == 0 and world.metrics.residents_lost == 1
    assert world.metrics.guide_speeds == [pytest.approx(0.6)]


def test_a_fast_resident_keeps_the_robot_at_cruise_speed():
    world = World(scenario(1.0), seed=1)
    guide(world)
    (speed,) = world.metrics.guide_speeds
    assert speed / 0.6 >= 0.98                             # the stated margin: 2 %


def test_the_pace_comes_from_the_given_guide_pace_config_not_the_world():
    """A GuidePace that never waits (stop_gap far beyond her give-up distance) loses her:
    the outcome follows the manager's settings, so no pace rule hides in the world."""
    lax = GuidePaceConfig(follow_gap=20.0, resume_gap=25.0, stop_gap=30.0, gain=0.5)
    world = World(scenario(0.05), seed=1, guide_pace=(lax, "userLost"))
    guide(world)
    assert world.metrics.residents_lost == 1 and world.metrics.guidances_completed == 0


def test_a_resident_who_stops_following_is_reported_userLost_and_the_belief_says_she_is_not_there():
    """She gives up 2 m behind (a guide holding her 3 m back loses her) and walks back: the
    people tracker no longer sees her, GuidePace waits lost_timeout and declares her lost, the
    world reports Laser userLost before the landmark, and the tracker's step closes with it."""
    from pearl_pomdp.params import step_settings
    from pearl_pomdp.tracking import BeliefTracker

    far = GuidePaceConfig(follow_gap=3.0, resume_gap=3.5, stop_gap=5.0, lost_timeout=5.0)
    sc = scenario(0.05)
    sc.resident.lose_distance = 2.0
    world = World(sc, seed=2, guide_pace=(far, "userLost"))
    result = guide(world)
    assert [m.text for m in result.messages] == ["userLost", "atPhysio"]
    assert world.metrics.lost_reports == 1
    domain = load_domain(DOMAIN)
    tracker = BeliefTracker(domain.compile(), domain, step_settings(drive_speed=0.0))
    for action, obs in (("GotoPatientRoom", "atRoom"), ("RingDoorBell", "t_yes")):
        tracker.on_action(action, 0.0)
        tracker.on_input("laser" if obs.startswith("at") else "touchscreen", obs, 0.0)
    before = tracker.marginals()["UserPresent"]["yes"]
    tracker.on_action("GuideToPhysio", 0.0)
    closed = tracker.on_input("laser", "userLost", 1.0).closed
    assert closed.observation == "userLost"
    assert before > 0.7 and tracker.marginals()["UserPresent"]["yes"] < 0.2


def test_in_the_full_loop_guide_pace_completes_the_slow_residents_guidances(pearl_policy):
    """The study's slow residents (5–35 cm/s, with rests) through the whole episode loop:
    ≥ 95 % of the guidances complete with guide_pace; at fixed pace the three slowest never do."""
    from pearl_pomdp.hierarchy import load_hierarchical_policy
    from pearl_sim.nursing_home.agents import Controller
    from pearl_sim.nursing_home.experiment import run_episode

    domain = load_domain(DOMAIN)
    agent = Controller("hierarchical", load_hierarchical_policy(pearl_policy, domain))
    slow = {}
    for sc in load_scenarios(REPO / "config" / "scenarios" / "study.yaml"):
        if sc.resident.walking_speed <= 0.35:
            slow.setdefault(sc.resident.name, sc)
    assert len(slow) == 4
    counts = {True: [0, 0], False: [0, 0]}
    for sc in slow.values():
        for adapt in (True, False):
            for k in range(2):
                r = run_episode(sc, agent, domain, seed=sc.seed + 1000 * k, pace_adaptation=adapt)
                counts[adapt][0] += r.guidance_completed
                counts[adapt][1] += 1
    done, total = counts[True]
    assert done / total >= 0.95, f"guide_pace: {done}/{total}"
    assert counts[False][0] <= 2, f"fixed pace completed {counts[False][0]}/{counts[False][1]}"
