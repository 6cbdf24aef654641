"""The study on days (pearl_sim/nursing_home/day_study.py): cases, paired statistics, the acceptance
rows, `pearl experiment --day` end to end and the day's picture."""
import json
import time

import pytest

from pearl_sim.nursing_home.day_study import (BASELINE, acceptance, day_cases, run_day, summarize)
from pearl_sim.nursing_home.residents import generate_residents


def _checklist(**over):
    base = {"reminders_due": 3, "reminders_on_time": 3, "walks_wanted": 1, "walks_completed": 1,
            "questions_raised": 2, "questions_answered": 2, "unprompted": 0, "unprompted_per_hour": 0.0,
            "wrong_actions": 0, "battery_empty": False, "battery_low_s": 0.0, "docked_at_end": True,
            "station_share": 0.9, "metres_driven": 100.0, "hours": 12.0}
    base.update(over)
    return base


def _day(policy, seed, score, noise=0.25, **over):
    return {"policy": policy, "resident": f"G{seed % 2}", "day": seed, "seed": seed, "noise": noise,
            "score": score, "checklist": _checklist(**over)}


def test_day_cases_follow_the_protocols_seed_rule():
    cases = day_cases(generate_residents(3, seed=11), 2)
    assert [(c.resident, c.day, c.seed) for c in cases] == [
        ("G01", 0, 0), ("G01", 1, 1), ("G02", 0, 1000), ("G02", 1, 1001), ("G03", 0, 2000), ("G03", 1, 2001)]


def test_summarize_pairs_each_day_with_the_trees_same_day():
    days = ([_day("hierarchical", s, 90.0 + s) for s in range(4)]
            + [_day(BASELINE, s, 85.0 + 2 * s) for s in range(4)])
    summary = summarize(days)
    diff = summary["paired_vs_baseline"]["hierarchical"]["0.25"]["score"]
    # differences 5, 4, 3, 2: mean 3.5, sd 1.29, t(3) 3.182 → half width 2.054
    assert diff["mean"] == pytest.approx(3.5) and diff["n"] == 4
    assert diff["ci95"] == pytest.approx(3.182446 * 1.290994 / 2, rel=1e-5)
    table = summary["per_policy"]["hierarchical"]["0.25"]
    assert table["days"] == 4 and table["score"]["mean"] == pytest.approx(91.5)
    assert table["pooled"]["reminders_on_time_share"] == 1.0 and table["pooled"]["reminders_due"] == 12


def test_acceptance_reads_each_row_as_measured():
    good = [_day("hierarchical", s, 95.0 + s % 2) for s in range(6)]
    tree = [_day(BASELINE, s, 90.0, reminders_on_time=2) for s in range(6)]
    result = acceptance(summarize(good + tree))["0.25"]
    assert result["met"] and all(result["checks"].values())
    late = [_day("hierarchical", s, 95.0, reminders_on_time=2, battery_empty=(s == 0)) for s in range(6)]
    checks = acceptance(summarize(late + tree))["0.25"]["checks"]
    assert checks["reminders_on_time_95"] is False and checks["battery_never_empty"] is False
    assert checks["paired_score_vs_tree_ci_above_0"] is True        # 95 vs 90 every day


def test_no_walk_wanted_is_no_miss():
    days = [_day("hierarchical", s, 95.0, walks_wanted=0, walks_completed=0) for s in range(3)]
    table = summarize(days + [_day(BASELINE, s, 90.0) for s in range(3)])
    assert table["per_policy"]["hierarchical"]["0.25"]["pooled"]["walks_completed_share"] is None
    assert acceptance(table)["0.25"]["checks"]["walks_completed_95"] is True


def test_pearl_experiment_day_runs_the_study_and_matches_run_day(tmp_path, capsys):
    from pearl_pomdp.cli import main
    from pearl_pomdp.model.domain_yaml import load_domain
    from pearl_sim.nursing_home.day_study import day_agents

    assert main(["experiment", "--day", "--domain", "config/pearl.domain.yaml", "--policies", "qmdp,day_tree",
                 "--residents", "generated:1", "--days", "1", "--seed", "11", "--noise", "0.5",
                 "--out", str(tmp_path), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["protocol"]["resident_seed"] == 11 and report["protocol"]["days"] == 2
    assert set(report["per_policy"]) == {"qmdp", BASELINE}
    assert (tmp_path / "day-study.json").exists() and (tmp_path / "day-study.png").stat().st_size > 10_000
    # Each day was kept as it came in (a study stopped half way keeps what it did).
    kept = [json.loads(line) for line in (tmp_path / "days.jsonl").read_text().splitlines()]
    assert kept == report["days"]
    tree_day = next(d for d in report["days"] if d["policy"] == BASELINE)
    # The same day run directly gives the same checklist: the study adds nothing of its own.
    domain = load_domain("config/pearl.domain.yaml")
    case = day_cases(generate_residents(1, seed=11), 1)[0]
    direct = run_day(day_agents(domain, None, [BASELINE])[BASELINE], domain, case, 0.5)
    assert direct["checklist"] == tree_day["checklist"] and direct["score"] == tree_day["score"]


def test_pearl_experiment_day_refuses_what_it_cannot_run(capsys):
    from pearl_pomdp.cli import main

    assert main(["experiment", "--day", "--domain", "config/pearl.domain.yaml", "--policies", "behaviour_tree"]) == 2
    assert "--policies" in capsys.readouterr().err
    assert main(["experiment", "--day", "--domain", "config/pearl.domain.yaml", "--residents", "paper"]) == 2
    assert "--residents" in capsys.readouterr().err
    assert main(["experiment", "--day", "--domain", "config/pearl.domain.yaml", "--days", "0"]) == 2
    assert "--days" in capsys.readouterr().err
    assert main(["experiment", "--day", "--snr", "20", "--noise", "0.5"]) == 2
    assert "--snr: give --snr or --noise, not both" in capsys.readouterr().err
    assert main(["experiment", "--day", "--snr", "20", "--noise-kind", "white,babble"]) == 2
    err = capsys.readouterr().err
    assert "--noise-kind" in err and "one kind per run" in err
    assert main(["experiment", "--day", "--snr", "90"]) == 2
    assert "SNRs in dB within [-20, 60]" in capsys.readouterr().err
    assert main(["experiment", "--day", "--noise-kind", "babble"]) == 2
    assert "--noise-kind: needs --snr" in capsys.readouterr().err


@pytest.mark.slow
def test_the_day_study_hears_her_through_the_measured_channel_at_each_snr(tmp_path, capsys):
    """`pearl experiment --day --snr`: the SNR axis of the paper's conjecture on days. The same two days of
    the tree at 60 dB and at -5 dB of white noise through the measured recogniser channel: the noisy ones
    take more clarification questions (deterministic for these seeds), so her speech really went through
    the channel at each level."""
    from pearl_pomdp.cli import main

    assert main(["experiment", "--day", "--policies", "day_tree", "--residents", "generated:1", "--seed", "11",
                 "--days", "2", "--snr", "60,-5", "--noise-kind", "white", "--out", str(tmp_path), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    protocol = report["protocol"]
    assert (protocol["noise_axis"], protocol["noise_kind"], protocol["noise_levels"]) == ("snr_db", "white", [-5.0, 60.0])
    assert protocol["channel"].endswith("config/speech/pearl_channel.json")
    by_level = {level: [d for d in report["days"] if d["noise"] == level] for level in (-5.0, 60.0)}
    assert [len(v) for v in by_level.values()] == [2, 2]
    asked = {level: sum(d["checklist"]["clarifications"] for d in days) for level, days in by_level.items()}
    assert asked[-5.0] > asked[60.0]
    assert set(report["per_policy"][BASELINE]) == {"-5.0", "60.0"}


def test_the_days_picture_is_drawn(tmp_path):
    from pearl_pomdp.model.domain_yaml import load_domain
    from pearl_sim.nursing_home.day_plot import plot_day
    from pearl_sim.nursing_home.day_study import day_agents

    domain = load_domain("config/pearl.domain.yaml")
    case = day_cases(generate_residents(1, seed=11), 1)[0]
    day = run_day(day_agents(domain, None, [BASELINE])[BASELINE], domain, case, 0.25, timeline=True)
    rows = day["timeline"]
    assert rows[0]["t"] == 0.0 and rows[-1]["t"] < 12 * 3600 and len(rows) == day["checklist"]["steps"]
    assert {r["robot"] for r in rows} <= {"home", "room", "physio"}
    png = plot_day(rows, day["checklist"], tmp_path / "day.png", "G01 day 0")
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 20_000


def _row(domain, action: str, parents: str) -> dict:
    """The observation row of ``action`` at its parents' values ``"v1,v2"``, as {symbol: probability}."""
    cpt = domain._observations[domain.actions.index(action)]
    index = tuple(domain.features[p].values.index(v) for p, v in zip(cpt.parents, parents.split(",")))
    return {z: float(p) for z, p in zip(domain.observations, cpt.table[index]) if p > 0}


def test_the_twins_speech_rows_move_as_the_measured_channel_says(tmp_path):
    """The conjecture arm's twins (docs/day.md) are the day domain with its speech rows refitted to the
    babble channel at each SNR: the doorbell's 'yes' is heard as 'yes' less at 5 dB than at 30 dB (the
    channel's Ĉ(yes|yes) 0.97 → 0.53), the touchscreen part is untouched; only the twin with insertions
    (chatter share 0.2) hears keywords in a silent row, in the channel's measured proportion."""
    import numpy as np

    from pearl_pomdp.asr.channel import ChannelTable, fitted_confusion
    from pearl_pomdp.model.domain_yaml import load_domain
    from pearl_sim.nursing_home.day_study import fit_channel_twins, twin_name

    channel = "config/speech/pearl_channel_babble.json"
    records = fit_channel_twins("config/pearl_day.domain.yaml", channel, "babble", [30.0, 5.0], [0.0, 0.2],
                                tmp_path)
    assert [(r["name"], r["snr_db"]) for r in records] == [
        (twin_name(0.0), 30.0), (twin_name(0.2), 30.0), (twin_name(0.0), 5.0), (twin_name(0.2), 5.0)]
    assert [r["name"] for r in records[:2]] == ["hierarchical@channel-chatter0", "hierarchical@channel-chatter0.2"]
    twins = {(r["snr_db"], r["chatter_share"]): load_domain(r["domain"]) for r in records}
    designer = load_domain("config/pearl_day.domain.yaml")
    bell = {key: _row(d, "RingDoorBell", "yes") for key, d in twins.items()}
    before = _row(designer, "RingDoorBell", "yes")
    assert bell[(5.0, 0.0)]["yes"] < bell[(30.0, 0.0)]["yes"] < before["yes"]
    assert bell[(5.0, 0.0)]["yes"] < 0.6 * before["yes"]
    assert bell[(5.0, 0.0)]["t_yes"] == pytest.approx(before["t_yes"])        # the touchscreen is not speech
    table = ChannelTable.load(channel)
    for snr in (30.0, 5.0):
        heard = fitted_confusion(table, snr, 10.0)["unknown"]                # chatter heard as keywords
        silent = {share: _row(twins[(snr, share)], "TellTime", "no,none") for share in (0.0, 0.2)}
        assert _row(designer, "TellTime", "no,none") == {"unknown": 1.0} == silent[0.0]
        assert silent[0.2]["no"] == pytest.approx(0.2 * heard["no"]) and silent[0.2]["no"] > 0
        assert silent[0.2]["unknown"] == pytest.approx(1 - 0.2 * (1 - heard["unknown"]))
    # Everything but the speech rows is the day domain's: its 864 states and its fitted transitions.
    for domain in twins.values():
        assert len(domain.compile().states) == 864
        assert all(np.array_equal(a, b) for a, b in zip(domain.compile().T, designer.compile().T))
    assert records[1]["speech_rows_changed"] > records[0]["speech_rows_changed"] > 50


def test_the_snr_contrast_is_the_paired_advantage_at_the_quietest_minus_at_the_noisiest():
    """c = (P − tree)[30 dB] − (P − tree)[5 dB] per day, by hand on three days: −2, −4, −3."""
    days = []
    for seed, (tree30, pol30, tree5, pol5) in enumerate([(90, 85, 80, 77), (90, 86, 70, 70), (95, 90, 85, 83)]):
        days += [_day(BASELINE, seed, tree30, noise=30.0), _day("hierarchical", seed, pol30, noise=30.0),
                 _day(BASELINE, seed, tree5, noise=5.0), _day("hierarchical", seed, pol5, noise=5.0)]
    from pearl_sim.nursing_home.day_study import snr_contrasts

    c = snr_contrasts(days)["hierarchical"]
    assert (c["quiet_db"], c["noisy_db"]) == (30.0, 5.0)
    assert c["contrast"]["mean"] == pytest.approx(-3.0) and c["contrast"]["n"] == 3
    assert c["contrast"]["high"] == pytest.approx(-3.0 + 4.302653 * 1.0 / 3 ** 0.5, rel=1e-5)
    assert snr_contrasts([d for d in days if d["noise"] == 5.0]) == {}


def test_the_speech_twins_option_says_what_it_needs(capsys):
    from pearl_pomdp.cli import main

    assert main(["experiment", "--day", "--policies", "day_tree", "--speech-twins", "0,0.2"]) == 2
    assert "--speech-twins: needs --snr" in capsys.readouterr().err
    assert main(["experiment", "--day", "--policies", "day_tree", "--snr", "5", "--speech-twins", "0,1.5"]) == 2
    assert "--speech-twins: '0,1.5': chatter shares are fractions in [0, 1]" in capsys.readouterr().err
    assert main(["experiment", "--day", "--policies", "day_tree", "--snr", "15", "--speech-twins", "0"]) == 2
    err = capsys.readouterr().err
    assert "pearl_channel.json" in err and "snr_db" in err and "15 dB was not measured" in err
    assert main(["experiment", "--snr", "5", "--speech-twins", "0"]) == 2
    assert "--speech-twins: is the day study's" in capsys.readouterr().err


@pytest.mark.slow
def test_pearl_experiment_day_runs_the_channel_twins_beside_the_others(tmp_path, capsys, monkeypatch):
    """`pearl experiment --day --snr 5 --speech-twins 0,0.2`: both twins planned on their refitted domains
    (written with their plans into the run's folder), each with its own results and paired difference at
    the level it was fitted for; a twin tracks its belief in its own domain, the world in the run's."""
    from pearl_pomdp.cli import main
    from pearl_pomdp.hierarchy.execute import load_hierarchical_policy
    from pearl_pomdp.model.domain_yaml import load_domain
    from pearl_sim.nursing_home import experiment
    from pearl_sim.planning import Controller

    assert main(["experiment", "--day", "--domain", "config/pearl.domain.yaml", "--policies", "day_tree",
                 "--speech-twins", "0,0.2", "--snr", "5", "--noise-kind", "babble", "--residents", "generated:1",
                 "--seed", "11", "--days", "1", "--jobs", "2", "--out", str(tmp_path), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    twins = ["hierarchical@channel-chatter0", "hierarchical@channel-chatter0.2"]
    assert set(report["per_policy"]) == {BASELINE, *twins} and set(report["paired_vs_baseline"]) == set(twins)
    for name in twins:
        assert report["per_policy"][name]["5.0"]["days"] == 1
        mine = [d for d in report["days"] if d["policy"] == name]
        assert len(mine) == 1 and mine[0]["checklist"]["steps"] > 1000
        tree = next(d for d in report["days"] if d["policy"] == BASELINE)
        assert report["paired_vs_baseline"][name]["5.0"]["score"]["mean"] == pytest.approx(
            mine[0]["score"] - tree["score"])
    records = report["protocol"]["speech_twins"]["twins"]
    assert [(r["name"], r["chatter_share"], r["snr_db"]) for r in records] == [(twins[0], 0.0, 5.0),
                                                                              (twins[1], 0.2, 5.0)]
    assert report["protocol"]["speech_twins"]["prior_strength"] == 10.0
    record = records[1]
    assert record["domain"] == str(tmp_path / "twins" / "babble-5dB-chatter0.2.domain.yaml")
    fitted = load_domain(record["domain"])
    policy = load_hierarchical_policy(record["policy"], fitted)     # the plan saved is the fitted domain's
    seen = []
    real = experiment.episode_executive
    monkeypatch.setattr(experiment, "episode_executive",
                        lambda controller, domain, scenario, model=None: seen.append((domain, model))
                        or real(controller, domain, scenario, model))
    world = load_domain("config/pearl.domain.yaml")
    case = day_cases(generate_residents(1, seed=11), 1)[0]
    day = run_day(Controller(twins[1], policy, domain=fitted), world, case, 5.0, until=120.0,
                  channel="config/speech/pearl_channel_babble.json")
    assert seen[0][0] is fitted and seen[0][1].O is not world.compile().O and day["checklist"]["steps"] > 5
    # The run's folder resumes: the twins' saved plans are loaded for their domains, not planned again.
    from pearl_sim.nursing_home.day_study import plan_channel_twins

    started = time.perf_counter()
    by_level, again, _ = plan_channel_twins("config/pearl.domain.yaml", "config/pearl.hierarchy.yaml",
                                            "config/speech/pearl_channel_babble.json", "babble", [5.0], [0.0, 0.2],
                                            tmp_path / "twins")
    assert [(r["plan_reused"], r["plan_seconds"]) for r in again] == [(True, None), (True, None)]
    assert set(by_level[5.0]) == set(twins) and time.perf_counter() - started < 20.0


def test_day_questions_follows_every_question_the_checklist_counts(load_bench):
    """bench/day_questions.py reads each question's fate from the world's events; on whole training days
    of the tree its counts are the checklist's (raised, answered), and the study's run_day gives the
    same checklist for the same day."""
    from pearl_pomdp.model.domain_yaml import load_domain
    from pearl_sim.nursing_home.day_study import day_agents, day_cases, run_day
    from pearl_sim.nursing_home.residents import generate_residents

    bench = load_bench("day_questions")
    domain = load_domain("config/pearl_day.domain.yaml")
    model = domain.compile()
    tree = day_agents(domain, "config/pearl.hierarchy.yaml", [BASELINE])[BASELINE]
    fates = []
    for k, case in enumerate(day_cases(generate_residents(2, seed=11), 2)):
        questions, checklist = bench.follow_day(tree, domain, model, case, 0.5)
        assert len(questions) == checklist["questions_raised"]
        assert sum(q["fate"] == "answered" for q in questions) == checklist["questions_answered"]
        if k == 1:   # the day with both kinds: the study's own run of it counts the same
            assert run_day(tree, domain, case, 0.5, model=model)["checklist"] == checklist
        fates += [q["fate"] for q in questions]
    assert set(fates) <= {"answered", "forgotten beside the robot", "forgotten after the robot left her",
                          "lapsed: her session began", "replaced by a new question", "open when the day ended"}
    # measured: G01 day 1 holds one of each kind, G02 day 0 two answered
    assert sorted(fates) == ["answered", "answered", "answered", "forgotten after the robot left her"]
