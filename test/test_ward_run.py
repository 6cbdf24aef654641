"""``pearl experiment`` and ``pearl demo`` on the ward domain (docs/ward.md): the tree's study runs end
to end and reports paired statistics; the demo and the nursing-home-only options are one-line errors."""
import json
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
PEARL = str(Path(sys.executable).parent / "pearl")
DOMAIN = str(REPO / "config" / "ward.domain.yaml")


def _pearl(*args, cwd):
    return subprocess.run([PEARL, *args], capture_output=True, text=True, cwd=cwd, timeout=300)


@pytest.mark.slow
def test_the_ward_study_runs_the_tree_in_every_cell_and_writes_study_json(tmp_path):
    out = tmp_path / "study"
    run = _pearl("experiment", "--domain", DOMAIN, "--policies", "behaviour_tree", "--episodes", "1", "--noise", "0.1",
                 "--json", "--out", str(out), cwd=tmp_path)
    assert run.returncode == 0, run.stderr
    report = json.loads(run.stdout)
    assert report["world"] == "ward" and report["protocol"]["episodes"] == 4
    assert report["protocol"]["episodes_per_cell"] == ["quiet_morning", "busy_ward", "moving_residents", "quiet_residents"]
    row = report["per_policy"]["behaviour_tree"]["0.1"]
    assert row["episodes"] == 4 and row["discounted_return"]["n"] == 4 and row["success_rate"]["n"] == 4
    episodes = json.loads((out / "study.json").read_text())["episodes"]
    assert len(episodes) == 4 and all(len(e["actions"]) == 60 for e in episodes)
    assert all(e["requests"] >= 1 for e in episodes)


def test_the_demo_and_the_flat_options_are_one_line_errors(tmp_path):
    demo = _pearl("demo", "--domain", DOMAIN, cwd=tmp_path)
    assert demo.returncode != 0
    lines = [x for x in demo.stderr.splitlines() if x.strip()]
    assert len(lines) == 1 and "ward.domain.yaml: name: 'ward' has no `pearl demo`" in lines[0]
    flat = _pearl("experiment", "--domain", DOMAIN, "--flat-trials", "10", cwd=tmp_path)
    assert flat.returncode != 0 and "--flat-trials: is not for the ward study" in flat.stderr
    bad = _pearl("experiment", "--domain", DOMAIN, "--policies", "online:x", cwd=tmp_path)
    assert bad.returncode != 0 and "online:x" in bad.stderr
