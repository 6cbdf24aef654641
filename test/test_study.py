"""The study grid: paired statistics, jobs-independence and the acceptance check."""
import pytest

from pearl_sim import study
from pearl_sim.experiment import EpisodeResult, build_agents
from pearl_sim.residents import paper_residents, resident_scenarios, study_template
from pearl_sim.scenario import default_domain

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


def test_acceptance_is_evaluated_not_assumed():
    eps = []
    for noise in (0.0, 0.3, 0.6):
        for seed in range(6):
            eps.append(study.StudyEpisode("behaviour_tree", "A", "walk", noise, noise, seed,
                                          _result("behaviour_tree", True, 2 if noise else 0, 50.0 + seed)))
            eps.append(study.StudyEpisode("hierarchical", "A", "walk", noise, noise, seed,
                                          _result("hierarchical", True, 1 if noise else 0, 50.0 + seed)))
    goal = study.acceptance(study.per_policy(eps), study.paired(eps))
    assert goal["met"] is True and set(goal["noisiest_levels"]) == {"0.3", "0.6"}
    worse = [e for e in eps if not (e.policy == "hierarchical" and e.noise == 0.6)]
    worse += [study.StudyEpisode("hierarchical", "A", "walk", 0.6, 0.6, s, _result("hierarchical", False, 0, 0.0))
              for s in range(6)]
    goal = study.acceptance(study.per_policy(worse), study.paired(worse))
    assert goal["met"] is False and goal["noisiest_levels"]["0.6"]["at_least_equal_success"] is False


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
    assert report["acceptance"] is None or report["acceptance"]["quietest_level"] == "30"
    assert main(["experiment", "--snr", "99", "--out", str(tmp_path / "x")]) == 2
    assert "--snr: 99.0 dB is outside [-20, 60]" in capsys.readouterr().err
