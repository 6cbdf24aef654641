"""`pearl experiment` end to end on a small configuration (cheap policies, two sweep points)."""
import json
from pathlib import Path

from pearl_pomdp.cli import main

REPO = Path(__file__).resolve().parents[1]


def test_experiment_json_reports_policies_pace_and_sweep(tmp_path, capsys):
    code = main(["experiment", "--policies", "qmdp,most_likely_state,scripted", "--episodes", "1",
                 "--sweep-episodes", "1", "--wer", "0,0.6", "--out", str(tmp_path), "--json"])
    assert code == 0
    report = json.loads(capsys.readouterr().out)
    assert len(report["scenarios"]) == 12
    policies = report["policies"]
    assert set(policies) == {"qmdp", "most_likely_state", "scripted"}
    for name, s in policies.items():
        g = s["guidance_success"]
        assert g["n"] == 12 and 0 <= g["low"] <= g["rate"] <= g["high"] <= 1
    # The most-likely-state controller acts on a guessed state: it issues wrong actions, QMDP does not.
    assert policies["most_likely_state"]["wrong_actions_per_episode"]["mean"] > \
        policies["qmdp"]["wrong_actions_per_episode"]["mean"]
    sweep = report["wer_sweep"]
    assert sweep["word_error_rates"] == [0.0, 0.6]
    assert set(sweep["per_policy"]) == set(policies)
    assert Path(sweep["png"]).stat().st_size > 10_000
    assert json.loads((tmp_path / "experiment.json").read_text())["policies"] == policies


def test_experiment_rejects_unknown_policy(tmp_path, capsys):
    code = main(["experiment", "--policies", "qmdp,telepathy", "--episodes", "1", "--wer", "", "--out", str(tmp_path)])
    assert code == 2
    assert "--policies: unknown policy 'telepathy'" in capsys.readouterr().err
