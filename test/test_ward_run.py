"""``pearl experiment`` and ``pearl demo`` on the ward domain (docs/ward.md): the tree's study runs end
to end and reports paired statistics; the demo runs an episode through the graph; the
nursing-home-only options are one-line errors."""
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
from ros_helpers import allocate_domain_id  # noqa: E402

from pearl_pomdp.model.domain_yaml import load_domain  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
PEARL = str(Path(sys.executable).parent / "pearl")
DOMAIN = str(REPO / "config" / "ward.domain.yaml")


def _pearl(*args, cwd):
    return subprocess.run([PEARL, *args], capture_output=True, text=True, cwd=cwd, timeout=300,
                          env={**os.environ, "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"})


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


@pytest.mark.ros
@pytest.mark.slow
def test_the_ward_demo_runs_an_episode_through_the_graph_and_writes_a_readable_bag(tmp_path):
    import yaml

    from pearl_pomdp.bags.reader import open_bag

    study = yaml.safe_load((REPO / "config" / "scenarios" / "ward" / "study.yaml").read_text())
    study["episodes"] = [dict(study["episodes"][0], max_steps=6)]
    scenario = tmp_path / "short.yaml"
    scenario.write_text(yaml.safe_dump(study))
    demo = _pearl("demo", "--domain", DOMAIN, "--scenario", str(scenario), "--policy", "online:3", "--json",
                  "--out", str(tmp_path / "demo"), "--domain-id", str(allocate_domain_id()), cwd=tmp_path)
    assert demo.returncode == 0, demo.stderr[-3000:]
    summary = json.loads(demo.stdout)
    assert summary["world"] == "ward" and summary["scenario"] == study["episodes"][0]["name"]
    assert summary["steps"] == len(summary["actions"]) == 6
    assert set(summary["actions"]) <= set(load_domain(DOMAIN).actions)
    assert summary["outcome"].startswith(f"outcome: {summary['requests_met']}/{summary['requests']} request(s) met")
    topics = {m.topic for m in open_bag(tmp_path / "demo" / "bag").read_messages()}
    assert {"/pearl/action", "/pearl/belief", "/pearl/decision", "/ward/sim/truth"} <= topics
    # The ward's truth is typed (issue 40) and the fit counts from it: a true ward state per action.
    from pearl_pomdp.fit import episodes_from_bag

    assert open_bag(tmp_path / "demo" / "bag").topics["/ward/sim/truth"].type == "pearl_interfaces/msg/WorldTruth"
    episode = episodes_from_bag(tmp_path / "demo" / "bag")
    assert episode.actions[:6] == summary["actions"] and episode.states is not None
    assert len(episode.states) == len(episode.actions) + 1 and episode.states[0]["RobotAt"] == "station"
    ward = load_domain(DOMAIN)
    assert all(0 <= ward.state_index(state) < ward.compile().num_states for state in episode.states)


def test_the_flat_options_and_a_bad_online_spec_are_one_line_errors(tmp_path):
    flat = _pearl("experiment", "--domain", DOMAIN, "--flat-trials", "10", cwd=tmp_path)
    assert flat.returncode != 0 and "--flat-trials: is not for the ward study" in flat.stderr
    bad = _pearl("experiment", "--domain", DOMAIN, "--policies", "online:x", cwd=tmp_path)
    assert bad.returncode != 0 and "online:x" in bad.stderr
