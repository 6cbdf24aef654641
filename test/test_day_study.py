"""The study on days (pearl_sim/nursing_home/day_study.py): cases, paired statistics, the acceptance
rows, `pearl experiment --day` end to end and the day's picture."""
import json

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
