"""The study grid: paired statistics, jobs-independence and the acceptance check."""
import pytest

from pearl_sim.nursing_home import study
from pearl_sim.nursing_home.experiment import EpisodeResult, build_agents
from pearl_sim.nursing_home.residents import paper_residents, resident_scenarios, study_template
from pearl_sim.nursing_home.scenario import default_domain

STUDY = "config/scenarios/study.yaml"


def _result(agent, completed, wrong, ret):
    return EpisodeResult(scenario="s", agent=agent, seed=0, discounted_return=ret, steps=1, guidance_needed=True,
                         guidance_completed=completed, time_to_goal=10.0 if completed else None, clarifications=0,
                         unprompted_questions=0, goals_achieved=int(completed), wrong_actions=wrong, residents_lost=0,
                         walking_speed=0.5)


def test_paired_differences_match_cells_and_use_student_t():
    episodes = []
    for seed, (bt_wrong, h_wrong) in enumerate([(2, 0), (1, 0), (3, 1), (0, 0)]):
        episodes.append(study.StudyEpisode("behaviour_tree", "A", "walk", 0.5, 0.5, seed,
                                           _result("behaviour_tree", True, bt_wrong, 10.0)))
        episodes.append(study.StudyEpisode("hierarchical", "A", "walk", 0.5, 0.5, seed,
                                           _result("hierarchical", True, h_wrong, 12.0)))
    d = study.paired(episodes)["hierarchical"]["0.5"]
    # differences -2, -1, -2, 0: mean -1.25, sd 0.957, t(0.975, 3) = 3.182
    assert d["wrong_actions"]["mean"] == pytest.approx(-1.25)
    assert d["wrong_actions"]["ci95"] == pytest.approx(3.1824 * 0.9574 / 2, rel=1e-3)
    assert d["discounted_return"]["mean"] == pytest.approx(2.0) and d["discounted_return"]["ci95"] == 0.0
    assert d["success"]["n"] == 4 and d["time_to_goal"]["mean"] == 0.0


def _acceptance_episodes(levels, quiet_success=True, quiet_return=50.0, noisy_wrong=1, noisy_success=True):
    """Six seeds per level; the baseline: success, 2 wrong actions at noisy levels, return 50+seed.
    The hierarchical policy: what the arguments say (defaults: every check of the goal holds)."""
    eps = []
    quiet = levels[0]
    for noise in levels:
        for seed in range(6):
            eps.append(study.StudyEpisode("behaviour_tree", "A", "walk", noise, noise, seed,
                                          _result("behaviour_tree", True, 0 if noise == quiet else 2, 50.0 + seed)))
            if noise == quiet:
                done, wrong, ret = quiet_success, 0, quiet_return + seed
            else:
                done, wrong, ret = noisy_success, noisy_wrong, 50.0 + seed
            eps.append(study.StudyEpisode("hierarchical", "A", "walk", noise, noise, seed,
                                          _result("hierarchical", done, wrong, ret)))
    return eps


def _goal(eps, snr=False):
    return study.acceptance(study.per_policy(eps), study.paired(eps), snr=snr)


def test_acceptance_is_evaluated_not_assumed():
    """Met when every check holds; each check made false on its own makes it not met, and says which."""
    levels = (0.0, 0.3, 0.6)
    goal = _goal(_acceptance_episodes(levels))
    assert goal["met"] is True and goal["quietest_level"] == "0" and set(goal["noisiest_levels"]) == {"0.3", "0.6"}
    assert goal["success_within_baseline_ci"] and goal["return_within_baseline_ci"]
    # Quietest level, success: none completed against the baseline's 6/6 (Wilson CI [0.61, 1]).
    goal = _goal(_acceptance_episodes(levels, quiet_success=False))
    assert goal["met"] is False and goal["success_within_baseline_ci"] is False
    assert goal["return_within_baseline_ci"] is True
    # Quietest level, return: 20 below the baseline's mean (its CI is ±1.9).
    goal = _goal(_acceptance_episodes(levels, quiet_return=30.0))
    assert goal["met"] is False and goal["return_within_baseline_ci"] is False
    assert goal["success_within_baseline_ci"] is True
    # Noisiest levels, wrong actions: as many as the baseline (paired CI not below 0).
    goal = _goal(_acceptance_episodes(levels, noisy_wrong=2))
    assert goal["met"] is False
    assert [v["fewer_wrong_actions"] for v in goal["noisiest_levels"].values()] == [False, False]
    assert all(v["at_least_equal_success"] for v in goal["noisiest_levels"].values())
    # Noisiest levels, success: none completed.
    goal = _goal(_acceptance_episodes(levels, noisy_success=False))
    assert goal["met"] is False
    assert [v["at_least_equal_success"] for v in goal["noisiest_levels"].values()] == [False, False]
    assert all(v["fewer_wrong_actions"] for v in goal["noisiest_levels"].values())


def test_acceptance_on_the_snr_axis_takes_the_highest_snr_as_quietest():
    """--snr: the quietest level is the highest SNR (30 dB), the noisiest the two lowest."""
    eps = _acceptance_episodes((30.0, 10.0, 5.0))
    goal = _goal(eps, snr=True)
    assert goal["quietest_level"] == "30" and set(goal["noisiest_levels"]) == {"10", "5"} and goal["met"] is True
    # Read as word error rates, the same levels would put 5 first.
    assert _goal(eps, snr=False)["quietest_level"] == "5"


def test_jobs_2_gives_the_numbers_of_jobs_1(tmp_path):
    domain = default_domain()
    agents = build_agents(domain, None, policies=["behaviour_tree", "qmdp"])
    cases = resident_scenarios(study_template(STUDY), paper_residents(STUDY)[4:6])[:2]
    grid = study.cells(len(cases), [0.0, 0.5], 1)
    one = study.run_cells(domain, agents, cases, grid, jobs=1)
    two = study.run_cells(domain, agents, cases, grid, jobs=2)
    assert len(one) == len(two) == 8
    assert [e.row() for e in one] == [e.row() for e in two]
    study.write_csv(one, tmp_path / "e.csv")
    assert (tmp_path / "e.csv").read_text().count("\n") == 9


def test_snr_axis_runs_through_the_measured_recogniser_channel(tmp_path, capsys):
    """--snr: the noise axis is the room's SNR through the shipped calibrated channel
    (config/speech/pearl_channel.json, from `pearl calibrate-speech`); quietest = highest SNR."""
    import json

    from pearl_pomdp.cli import main

    assert main(["experiment", "--policies", "qmdp,behaviour_tree", "--residents", "generated:1", "--episodes", "1",
                 "--snr", "30,5", "--out", str(tmp_path), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["protocol"]["noise_axis"] == "snr_db" and report["protocol"]["channel"].endswith("pearl_channel.json")
    assert set(report["per_policy"]["qmdp"]) == {"30", "5"}
    assert report["acceptance"] is None   # no hierarchical policy in this run (its SNR ordering: above)
    assert main(["experiment", "--snr", "99", "--out", str(tmp_path / "x")]) == 2
    assert "--snr: 99.0 dB is outside [-20, 60]" in capsys.readouterr().err


@pytest.mark.slow
def test_a_policy_planned_with_measured_speech_rows_tracks_its_belief_in_them(tmp_path):
    """`--speech-rows`: the @measured twin's executive runs on the fitted domain (its O), the
    world and the score on the designer's; the study's CLI adds the twin beside its policy."""
    import json

    from pearl_pomdp.asr.channel import ChannelTable
    from pearl_pomdp.cli import main
    from pearl_pomdp.fit_speech import write_speech_fitted
    from pearl_pomdp.model.domain_yaml import load_domain
    from pearl_sim.nursing_home.agents import Controller
    from pearl_sim.nursing_home.experiment import run_episode

    table = ChannelTable.load("config/speech/pearl_channel_babble.json")
    path, _ = write_speech_fitted("config/pearl.domain.yaml", table, 10, tmp_path / "b10.yaml")
    fitted, designer = load_domain(path), default_domain()
    assert not (fitted.compile().O == designer.compile().O).all()
    twin = Controller("qmdp@measured", build_agents(fitted, None, policies=["qmdp"])["qmdp"].decider, domain=fitted)
    case = resident_scenarios(study_template(STUDY), paper_residents(STUDY)[:1])[0]
    seen = []
    run_episode(case.scenario, twin, designer, seed=3, on_step=lambda world, result, waits, ex: seen.append(ex))
    assert seen and seen[0].domain is fitted and seen[0].tracker.model.O is fitted.compile().O
    out = tmp_path / "study"
    assert main(["experiment", "--policies", "qmdp,behaviour_tree", "--residents", "generated:1", "--episodes", "1",
                 "--snr", "10", "--noise-kind", "babble", "--speech-rows", str(path), "--out", str(out), "--json"]) == 0
    report = json.loads((out / "study.json").read_text())
    assert set(report["per_policy"]) == {"qmdp", "qmdp@measured", "behaviour_tree"}
    assert set(report["paired_vs_baseline"]) == {"qmdp", "qmdp@measured"}


def test_growth_of_the_advantage_is_a_paired_difference_of_differences():
    """g = (P − tree)[worse] − (P − tree)[better] per matched cell: by hand on three seeds."""
    eps = []
    # returns (tree, policy): at babble:30 the policy is +1, +2, +3 ahead; at babble:10 +5, +5, +9.
    for seed, (q_tree, q_pol, n_tree, n_pol) in enumerate([(50, 51, 40, 45), (50, 52, 40, 45), (50, 53, 30, 39)]):
        for level, tree, pol in ((30.0, q_tree, q_pol), (10.0, n_tree, n_pol)):
            eps.append(study.StudyEpisode("behaviour_tree", "A", "walk", level, float("nan"), seed,
                                          _result("behaviour_tree", True, 0, tree), "babble"))
            eps.append(study.StudyEpisode("hierarchical", "A", "walk", level, float("nan"), seed,
                                          _result("hierarchical", True, 0, pol), "babble"))
    g = study.growth(eps, "hierarchical", "babble:10", "babble:30")
    # g = 4, 3, 6: mean 4.333, sd 1.528, t(0.975, 2) = 4.303 → half-width 3.795
    assert g["n"] == 3 and g["mean"] == pytest.approx(13 / 3)
    assert g["ci95"] == pytest.approx(4.3027 * 1.5275 / 3 ** 0.5, rel=1e-3)
    contrasts = study.growth_contrasts(eps)
    assert set(contrasts) == {"babble:10 vs babble:30"}
    assert contrasts["babble:10 vs babble:30"]["hierarchical"]["discounted_return"]["mean"] == pytest.approx(13 / 3)
    assert contrasts["babble:10 vs babble:30"]["hierarchical"]["wrong_actions"]["mean"] == 0.0
