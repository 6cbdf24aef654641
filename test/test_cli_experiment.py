"""`pearl experiment` end to end on a small configuration, and its input errors."""
import json
from pathlib import Path

import pytest

from pearl_pomdp.cli import main


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
    assert set(report["paired_vs_baseline"]) == {"qmdp", "most_likely_state"}
    assert report["paired_vs_baseline"]["qmdp"]["0.6"]["wrong_actions"]["n"] == 3
    assert report["acceptance"] is None                         # no hierarchical policy in this run
    assert Path(report["files"]["png"]).stat().st_size > 10_000
    rows = Path(report["files"]["csv"]).read_text().splitlines()
    assert len(rows) == 1 + 18 and rows[0].startswith("policy,resident,task,noise")
    assert json.loads((tmp_path / "study.json").read_text())["per_policy"] == table


@pytest.mark.parametrize("argv, message", [
    (["--policies", "qmdp,telepathy"], "--policies: unknown policy 'telepathy'"),
    (["--episodes", "0"], "--episodes: 0: at least 1 seed"),
    (["--residents", "generated:0"], "--residents: generated:0: the count must be in [1, 200]"),
    (["--residents", "nobody"], "--residents: 'nobody' is not"),
    (["--noise", "0,1.5"], "--noise: 1.5 is not a word error rate"),
    (["--jobs", "0"], "--jobs: 0"),
])
def test_bad_input_is_one_clear_error_before_any_work(tmp_path, capsys, argv, message):
    out = tmp_path / "out"
    code = main(["experiment", *argv, "--out", str(out)])
    assert code == 2
    err = capsys.readouterr().err
    assert message in err and "planned" not in err
    assert not out.exists()                                     # nothing was started
