"""`pearl experiment` end to end on a small configuration, and its input errors."""
import json
from pathlib import Path

import pytest

from pearl_pomdp.cli import main


@pytest.mark.slow
def test_experiment_json_reports_policies_pairs_and_files(tmp_path, capsys):
    code = main(["experiment", "--policies", "qmdp,most_likely_state,behaviour_tree", "--residents", "generated:1",
                 "--episodes", "1", "--noise", "0,0.6", "--out", str(tmp_path), "--json"])
    assert code == 0
    report = json.loads(capsys.readouterr().out)
    assert report["protocol"]["episodes"] == 3 * 3 * 2          # policies × tasks × noise levels
    table = report["per_policy"]
    assert set(table) == {"qmdp", "most_likely_state", "behaviour_tree"}
    for by_noise in table.values():
        assert set(by_noise) == {"0", "0.6"}
        for s in by_noise.values():
            g = s["guidance_success"]
            assert g["n"] == 3 and 0 <= g["low"] <= g["rate"] <= g["high"] <= 1
            assert "unprompted_questions_per_episode" in s
            w = s["wanted_guidance_success"]
            assert w["n"] <= g["n"] and (w["n"] == 0 or 0 <= w["low"] <= w["rate"] <= w["high"] <= 1)
    assert set(report["paired_vs_baseline"]) == {"qmdp", "most_likely_state"}
    assert report["paired_vs_baseline"]["qmdp"]["0.6"]["wrong_actions"]["n"] == 3
    assert report["acceptance"] is None                         # no hierarchical policy in this run
    assert Path(report["files"]["png"]).stat().st_size > 10_000
    rows = Path(report["files"]["csv"]).read_text().splitlines()
    assert len(rows) == 1 + 18 and rows[0].startswith("policy,resident,task,noise")
    assert json.loads((tmp_path / "study.json").read_text())["per_policy"] == table
    # Per scenario (resident-task) and policy, and every episode's action sequence.
    scenarios = report["per_scenario"]
    assert sorted(scenarios) == ["G01-walk", "G01-walk+time", "G01-walk+weather"]
    for by_policy in scenarios.values():
        assert set(by_policy) == {"qmdp", "most_likely_state", "behaviour_tree"}
        assert all(s["episodes"] == 2 and s["unprompted_questions_per_episode"] >= 0 for s in by_policy.values())
    assert len(report["episodes"]) == 18
    for e in report["episodes"]:
        assert e["steps"] == len(e["actions"]) > 0 and set(e["actions"]) <= set(_pearl_actions())
        assert e["unprompted_questions"] <= sum(a.startswith(("Confirm", "Verify")) for a in e["actions"])


def _pearl_actions():
    from pearl_pomdp.model.domain_yaml import load_domain

    return load_domain(Path(__file__).resolve().parents[1] / "config" / "pearl.domain.yaml").actions


@pytest.mark.slow
def test_flat_policy_budget_gives_the_same_study_beside_a_cpu_burner(tmp_path, capsys):
    """The flat point-based policy is planned with a trial budget, not the clock: the same seed
    gives the same episodes on a quiet machine and beside a busy process (one of the two cores)."""
    import subprocess
    import sys

    def study(out):
        code = main(["experiment", "--policies", "flat_pointbased", "--residents", "generated:1", "--episodes", "1",
                     "--noise", "0.25", "--flat-trials", "3", "--out", str(out), "--json", "--quiet"])
        assert code == 0
        report = json.loads(capsys.readouterr().out)
        return report["per_policy"], [(e["task"], e["actions"]) for e in report["episodes"]]

    quiet = study(tmp_path / "quiet")
    burners = [subprocess.Popen([sys.executable, "-c", "while True: pass"])]
    try:
        busy = study(tmp_path / "busy")
    finally:
        for p in burners:
            p.kill()
            p.wait(timeout=10)
    assert busy == quiet
    assert len(quiet[1]) == 3 and all(actions for _task, actions in quiet[1])


@pytest.mark.parametrize("argv, message", [
    (["--policies", "qmdp,telepathy"], "--policies: unknown policy 'telepathy'"),
    (["--episodes", "0"], "--episodes: 0: at least 1 seed"),
    (["--residents", "generated:0"], "--residents: generated:0: the count must be in [1, 200]"),
    (["--residents", "nobody"], "--residents: 'nobody' is not"),
    (["--noise", "0,1.5"], "--noise: 1.5 is not a word error rate"),
    (["--jobs", "0"], "--jobs: 0"),
    (["--flat-trials", "0"], "--flat-trials: must be at least 1"),
    (["--flat-trials", "5", "--flat-time-limit", "3"], "--flat-trials: give --flat-trials or --flat-time-limit"),
    (["--noise-kind", "babble"], "--noise-kind: needs --snr"),
    (["--snr", "10", "--noise-kind", "white,pink"], "--noise-kind: 'pink' is not one of white, babble"),
    (["--snr", "10", "--noise-kind", "babble", "--babble-channel", "none.json"], "none.json"),
    (["--measured-policies", "qmdp"], "--measured-policies: needs --speech-rows"),
    (["--speech-rows", "config/pearl.domain.yaml", "--measured-policies", "behaviour_tree"],
     "--measured-policies: 'behaviour_tree' is not a POMDP policy"),
    (["--snr", "10", "--cluster", "tcp://127.0.0.1:9", "--cluster-timeout", "1"],
     "--cluster tcp://127.0.0.1:9: no Dask scheduler answered within 1 s"),
])
def test_bad_input_is_one_clear_error_before_any_work(tmp_path, capsys, argv, message):
    out = tmp_path / "out"
    code = main(["experiment", *argv, "--out", str(out)])
    assert code == 2
    err = capsys.readouterr().err
    assert message in err and "planned" not in err
    assert not out.exists()                                     # nothing was started
