"""A world outside pearl_sim, in three files, registers by entry point and runs ``pearl demo`` and
``pearl experiment`` through the frame (the kiosk: test/data/kiosk_world); the registry's errors
name the entry point or the domain file."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
from ros_helpers import allocate_domain_id  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
KIOSK = REPO / "test" / "data" / "kiosk_world"
DOMAIN = KIOSK / "kiosk.domain.yaml"


def register(site: Path, entry: str) -> Path:
    """A distribution ``kiosk_world`` on ``site`` whose only metadata is the ``pearl.worlds`` entry
    point ``entry`` (what ``pip install`` of a world's package writes)."""
    info = site / "kiosk_world-0.1.dist-info"
    info.mkdir(parents=True, exist_ok=True)
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: kiosk_world\nVersion: 0.1\n", encoding="utf-8")
    (info / "entry_points.txt").write_text(f"[pearl.worlds]\n{entry}\n", encoding="utf-8")
    return site


def pearl(args, site: Path, timeout: float = 300.0) -> subprocess.CompletedProcess:
    """``pearl ARGS`` in a fresh process that sees the kiosk (``site``'s metadata, its module)."""
    env = dict(os.environ)
    env.update(ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    env["PYTHONPATH"] = os.pathsep.join([str(site), str(KIOSK), env.get("PYTHONPATH", "")])
    return subprocess.run([sys.executable, "-c", "import sys; from pearl_pomdp.cli import main; sys.exit(main())",
                           *args], cwd=REPO, env=env, capture_output=True, text=True, timeout=timeout)


def test_the_kiosk_world_is_three_files():
    files = sorted(p.name for p in KIOSK.iterdir() if p.name != "__pycache__")
    assert files == ["kiosk.domain.yaml", "kiosk.study.yaml", "kiosk_world.py"]


@pytest.mark.ros
@pytest.mark.slow
def test_a_world_registered_by_entry_point_runs_demo_and_experiment(tmp_path):
    site = register(tmp_path / "site", "kiosk = kiosk_world:WORLD")
    demo = pearl(["demo", "--domain", str(DOMAIN), "--out", str(tmp_path / "demo"), "--json",
                  "--domain-id", str(allocate_domain_id())], site)
    assert demo.returncode == 0, demo.stderr[-3000:]
    summary = json.loads(demo.stdout)
    assert summary["world"] == "kiosk" and summary["scenario"] == "quiet"
    # The first scenario of the study file ran: actions were taken and the world counted its customers.
    assert summary["steps"] == len(summary["actions"]) > 0
    assert set(summary["actions"]) <= {"Wait", "Greet"}
    assert summary["served"] + summary["left"] <= summary["customers"]
    assert summary["outcome"].startswith(f"outcome: {summary['served']}/{summary['customers']} customer(s) served")
    # The bag holds the loop and the world's own topics, and reads back.
    from pearl_pomdp.bags.reader import open_bag

    topics = {m.topic for m in open_bag(tmp_path / "demo" / "bag").read_messages()}
    assert {"/pearl/action", "/pearl/belief", "/kiosk/sim/truth"} <= topics
    # The kiosk's truth is typed (issue 40): the start and end of every action the world carried out.
    from pearl_pomdp.world_truth import truth_records

    truth = truth_records(open_bag(tmp_path / "demo" / "bag"), "/kiosk/sim/truth")
    assert [t["action"] for t in truth if t["phase"] == "start"] == summary["actions"] + [""]
    assert [t["action"] for t in truth if t["phase"] == "end"] == summary["actions"]
    assert truth[0]["state"] == {"Customer": "none"} and {t["state"]["Customer"] for t in truth} == {"none", "waiting"}
    assert (tmp_path / "demo" / "policy" / "hierarchy.json").is_file()   # the flat hierarchy, planned and saved
    # The bag replays on its own: the graph, rebuilt from its custom_data (the world has no params file:
    # the nodes' code defaults, recorded as such), takes the recorded actions with the same beliefs.
    replay = pearl(["replay", str(tmp_path / "demo" / "bag"), "--json", "--domain-id", str(allocate_domain_id())], site)
    assert replay.returncode == 0, replay.stderr[-3000:]
    replayed = json.loads(replay.stdout)
    assert replayed["match"] and replayed["beliefs_match"] and replayed["actions"] == replayed["expected_actions"]
    assert len(replayed["actions"]) >= summary["steps"]   # the graph also answered the last steps' beliefs

    study = pearl(["experiment", "--domain", str(DOMAIN), "--episodes", "2", "--out", str(tmp_path / "study"),
                   "--json"], site)
    assert study.returncode == 0, study.stderr[-3000:]
    report = json.loads(study.stdout)
    assert report["world"] == "kiosk" and report["protocol"]["hierarchy"] == "flat"
    assert set(report["per_policy"]) == {"hierarchical", "qmdp", "behaviour_tree"}
    # 2 scenarios x 1 noise level x 2 seeds per controller, paired with the tree cell by cell.
    row = report["per_policy"]["hierarchical"]["0"]
    assert row["episodes"] == 4 and row["served"]["n"] == 4
    paired = report["paired_vs_baseline"]["hierarchical"]["0"]["discounted_return"]
    assert paired["n"] == 4 and paired["low"] <= paired["mean"] <= paired["high"]
    episodes = json.loads((tmp_path / "study" / "study.json").read_text())["episodes"]
    assert len(episodes) == 12 and all("served" in e and "left" in e for e in episodes)


def test_a_domain_without_a_registered_world_names_the_file_and_the_worlds(tmp_path):
    empty = tmp_path / "empty-site"
    empty.mkdir()
    run = pearl(["demo", "--domain", str(DOMAIN), "--out", str(tmp_path / "demo")], empty, timeout=120)
    assert run.returncode != 0
    assert str(DOMAIN) in run.stderr and "no simulated world for domain 'kiosk'" in run.stderr
    assert "reception:" in run.stderr and "ward:" in run.stderr


@pytest.mark.parametrize("entry, problem", [
    ("kiosk = kiosk_world:NO_SUCH", "does not load: AttributeError"),
    ("kiosk = kiosk_world:DEMO", "is a WorldDemo, not a pearl_sim.worlds.SimWorld"),
    ("booth = kiosk_world:WORLD", "registers world 'kiosk' under the name 'booth'"),
])
def test_a_bad_world_entry_point_is_named(tmp_path, entry, problem):
    site = register(tmp_path / "site", entry)
    run = pearl(["experiment", "--domain", str(DOMAIN), "--out", str(tmp_path / "study")], site, timeout=120)
    assert run.returncode != 0
    assert f"entry point {entry}" in run.stderr and problem in run.stderr
