"""Habits a nurse would object to, over 50 seeds per scenario in the simulated world (issue 11).

The planned hierarchical Pearl policy runs through the study's step loop (the robot's own
tracker rules, the world of ``pearl_sim``) on the paper's scenarios and on held-out ones
written before any policy ran on them (``test/data/scenarios``). Checked:

* no unprompted offers of the walk where the resident never wants to go (<= 0.1 per episode);
* no RingDoorBell where the resident is not (the robot rings only at her door);
* after the Figure 4 scenario (and the held-out walk) the robot drives home (Figure 4(f));
* the walks that are wanted are completed.

**Truly unseen** (``test/data/scenarios/fresh/``): written after the domain work and run once
then, never used to tune anything. The three in ``test/data/scenarios/`` were written before
any policy ran on them but were then run while the domain was corrected (issue 11), so they
are held out from the study, not unseen. The fresh ones get the checks every scenario gets
(no doorbell away from her, wrong actions and unprompted walk offers at most 0.1 per
episode), specified before this test first ran them: ``evening_questions`` has no walk, and
``reluctant_walker``'s resident may decline (willingness 0.6) and walks at 7 cm/s, so whether
her walk ends within 40 steps is not a habit and is not checked.
"""
from pathlib import Path

import pytest

from pearl_pomdp.hierarchy import load_hierarchical_policy
from pearl_pomdp.model.domain_yaml import load_domain
from pearl_sim.nursing_home.agents import Controller
from pearl_sim.nursing_home.experiment import run_episode
from pearl_sim.nursing_home.scenario import load_scenarios

REPO = Path(__file__).resolve().parents[1]
pytestmark = pytest.mark.slow   # 340 episodes of the planned policy (~30-45 s)
#: Seeds per scenario: the bounds below were set over 50 seeds (issue 11); fewer seeds would
#: make a different test (a walk offer in 4 of the first 20 seeds of walk_then_time), not a faster one.
SEEDS = 50
NO_WALK = ["test/data/scenarios/no_walk_questions.yaml", "test/data/scenarios/checklist_quiet.yaml",
           "config/scenarios/info_request.yaml", "config/scenarios/table4_dialog.yaml"]
WALK = ["config/scenarios/figure4.yaml", "test/data/scenarios/walk_then_time.yaml"]
#: Truly unseen scenarios (see the module doc), and their seeds (fewer: the suite's budget).
FRESH = ["test/data/scenarios/fresh/evening_questions.yaml", "test/data/scenarios/fresh/reluctant_walker.yaml"]
FRESH_SEEDS = 20


@pytest.fixture(scope="module")
def pearl(pearl_policy):
    # The session's planned Pearl policy (test/ros_helpers.py: planned once, cached by the sources).
    domain = load_domain(REPO / "config/pearl.domain.yaml")
    policy = load_hierarchical_policy(pearl_policy, domain)
    return domain, Controller("hierarchical", policy)


@pytest.fixture(scope="module")
def walk_runs(pearl):
    """The walk scenarios' episodes, run once for the two tests that judge them (~16 s each)."""
    return {path: episodes(pearl, path) for path in WALK}


def episodes(pearl, path, seeds=SEEDS):
    """Every seed of the scenario: (result, rings away from her, offers while she has no wish)."""
    domain, controller = pearl
    scenario = load_scenarios(REPO / path)[0]
    out = []
    for k in range(seeds):
        habits = {"rings_away": 0, "unwanted_offers": 0}

        def on_step(world, result, waits, executive, habits=habits):
            if result.action == "RingDoorBell" and world.robot_at != world.resident_at:
                habits["rings_away"] += 1
            if result.action == "ConfirmGuideToPhysio" and any("unprompted question" in e for e in result.events):
                habits["unwanted_offers"] += 1

        result = run_episode(scenario, controller, domain, seed=scenario.seed + 1000 * k, on_step=on_step)
        out.append((result, habits["rings_away"], habits["unwanted_offers"]))
    return out


@pytest.mark.parametrize("path", NO_WALK)
def test_no_unprompted_walk_offers_where_she_never_wants_to_go(pearl, path):
    runs = episodes(pearl, path)
    offers = sum(o for _r, _rings, o in runs) / len(runs)
    assert offers <= 0.1, f"{path}: {offers:.2f} unprompted walk offers per episode"
    assert sum(r.wrong_actions for r, _rings, _o in runs) / len(runs) <= 0.1
    assert all(rings == 0 for _r, rings, _o in runs), f"{path}: RingDoorBell away from her"


@pytest.mark.parametrize("path", WALK)
def test_wanted_walks_are_completed(walk_runs, path):
    runs = walk_runs[path]
    assert all(rings == 0 for _r, rings, _o in runs), f"{path}: RingDoorBell away from her"
    completed = sum(r.guidance_completed for r, _rings, _o in runs) / len(runs)
    assert completed >= 0.95, f"{path}: {completed:.2f} of the wanted walks completed"
    assert sum(o for _r, _rings, o in runs) / len(runs) <= 0.1


#: Missed since the hierarchy is planned to convergence (issue 21; measured 2026-12-02: 0 of 50
#: episodes end at home on both walk scenarios, with the designer's domain and with the fitted
#: one). Diagnosis: in the domain the resident never leaves the physiotherapy department and a
#: reminder or a question can arrive at any step for ever, while contact can only be made in her
#: room; so once she is there, staying with her is worth more than the station (the root's
#: one-step values at the last belief of figure4, seed 1: DoNothing 17.3, Rest's GoHome −14.8).
#: The eq. 15–17 plan went home because its Rest subtask looked one step ahead (GoHome's +5).
#: A per-step reward for being at the station (tried at +1) made the robot stop visiting her in
#: her room for questions (0 of 12 answered on afternoon_questions), so it was not adopted: the
#: domain needs the missing part (her way back from the department, the ward's other demands),
#: not a number tuned to this check. Left failing on purpose, with this diagnosis.
#: Protocol 4 (docs/day.md): with her session in the episode world and the episode run until Pearl leaves
#: (1,800 s), this domain still ends at home in 0 of 20 episodes on each of six scenarios — it waits
#: beside her, then at the empty department; the day domain, which `pearl demo` runs, goes home (below).
@pytest.mark.xfail(strict=True, reason="the converged plan stays with her at the department (see the comment above)")
@pytest.mark.parametrize("path", WALK)
def test_the_robot_goes_home_after_the_walk(walk_runs, path):
    runs = walk_runs[path]
    home = 0
    for r, _rings, _o in runs:
        drives = [a for a in r.actions if a in ("GotoPatientRoom", "GuideToPhysio", "GoHome")]
        home += bool(drives) and drives[-1] == "GoHome" and "GuideToPhysio" in drives
    assert home / len(runs) >= 0.95, f"{path}: the robot drove home after the task in {home}/{len(runs)} episodes"


@pytest.fixture(scope="module")
def fresh_runs(pearl):
    return {path: episodes(pearl, path, FRESH_SEEDS) for path in FRESH}


@pytest.mark.parametrize("path", FRESH)
def test_the_unseen_scenarios_keep_the_habits(fresh_runs, path):
    runs = fresh_runs[path]
    assert all(rings == 0 for _r, rings, _o in runs), f"{path}: RingDoorBell away from her"
    wrong = sum(r.wrong_actions for r, _rings, _o in runs) / len(runs)
    assert wrong <= 0.1, f"{path}: {wrong:.2f} wrong actions per episode"


#: The first run of the unseen scenarios missed this check for reluctant_walker (measured
#: 2026-12-02: 29 unprompted walk offers in 20 episodes, 1.45 per episode; the 10 episodes in
#: which she wanted the walk all completed it). Diagnosis: after the physiotherapy reminder the
#: robot offers the walk (ConfirmGuideToPhysio); a resident who declines (willingness 0.6: 10 of
#: 20 here) answers t_no, and the robot asks once more before it gives up — both offers count as
#: unprompted, as does an offer to a resident who has not answered the door. A nurse would accept
#: the first offer after the reminder and object to the second. Left as measured: changing the
#: domain now would tune it on the scenario meant to be unseen (reported with issue 22).
#: Since the hierarchy is planned to convergence (issue 21) the check holds there too: the
#: robot offers the walk only when her answers make it likely (the eq. 15–17 plan's repeated
#: offer came from eq. 17's child that "knows" whether she wants to go).
_MISSED: dict = {}


@pytest.mark.parametrize("path", [pytest.param(p, marks=pytest.mark.xfail(strict=True, reason=_MISSED[p]))
                                  if p in _MISSED else p for p in FRESH])
def test_the_unseen_scenarios_make_no_unprompted_walk_offers(fresh_runs, path):
    runs = fresh_runs[path]
    offers = sum(o for _r, _rings, o in runs) / len(runs)
    assert offers <= 0.1, f"{path}: {offers:.2f} unprompted walk offers per episode"


#: The six episode scenarios of docs/day.md, protocol 4 (two of them truly unseen).
EPISODES = WALK + FRESH + ["test/data/scenarios/no_walk_questions.yaml", "test/data/scenarios/checklist_quiet.yaml"]


@pytest.fixture(scope="module")
def day_domain_runs():
    """`pearl demo`'s domain (fitted on working days) with its shipped plan, each episode run until Pearl
    leaves, as the demo runs it: 20 seeds per scenario (~7 s in all)."""
    domain = load_domain(REPO / "config/pearl_day.domain.yaml")
    controller = Controller("hierarchical", load_hierarchical_policy(REPO / "config/plans/pearl_day", domain))
    runs = {}
    for path in EPISODES:
        scenario = load_scenarios(REPO / path)[0]
        runs[path] = [run_episode(scenario, controller, domain, seed=scenario.seed + 1000 * k, until_left=True)
                      for k in range(FRESH_SEEDS)]
    return runs


@pytest.mark.parametrize("path", EPISODES)
def test_the_demo_domain_goes_home_after_its_work(day_domain_runs, path):
    """Figure 4(f) on every episode scenario: ≥ 90 % of the episodes in which the robot left its station
    end with it back there (measured: 20 of 20 on each), and every walk she wanted is completed."""
    runs = day_domain_runs[path]
    drives = [[a for a in r.actions if a in ("GotoPatientRoom", "GuideToPhysio", "GoHome")] for r in runs]
    left = [d for d in drives if d]
    home = sum(d[-1] == "GoHome" for d in left)
    assert left and home >= 0.9 * len(left), f"{path}: back at the station in {home} of {len(left)} episodes"
    wanted = [r for r in runs if r.guidance_wanted]
    assert all(r.guidance_completed for r in wanted), f"{path}: a wanted walk was not completed"
    assert sum(r.wrong_actions for r in runs) / len(runs) <= 0.1
