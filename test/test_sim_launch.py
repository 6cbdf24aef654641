"""launch/pearl_sim.launch.xml under `pearl launch`: the simulated world and the manager as
separate processes run a scenario to its end and the launch exits (issue 14 item 6)."""
from __future__ import annotations

import json
import re
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
from ros_helpers import Proc, allocate_domain_id, ros_env  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
PEARL = Path(sys.executable).with_name("pearl")
pytestmark = pytest.mark.ros


@pytest.mark.slow
def test_the_sim_launch_runs_nav_blocked_to_the_end_and_exits(tmp_path, pearl_policy):
    cmd = [str(PEARL), "launch", str(REPO / "launch" / "pearl_sim.launch.xml"),
           f"scenario:={REPO / 'config' / 'scenarios' / 'nav_blocked.yaml'}", "rate:=50.0", f"policy:={pearl_policy}"]
    proc = Proc(cmd, ros_env(allocate_domain_id(), tmp_path), tmp_path, "sim_launch")
    try:
        code = proc.wait(240)
        out = proc.stdout() + proc.stderr()
        assert code == 0, out[-4000:]
    finally:
        proc.stop()
    m = re.search(r"pearl_sim_world: finished nav_blocked: (\{.*\})", out)
    assert m, out[-4000:]
    summary = json.loads(m.group(1))
    assert summary["actions"] == 20                       # the scenario's max_steps: it ran to the end
    # The corridor was blocked: the world reported nothing, only the tracker's drive deadline
    # (its own timer under /clock, in another process) closed those steps, and the policy retried.
    assert summary["blocked_drives"] >= 3
    first = summary["first_actions"]
    start = first.index("GotoPatientRoom")                # after waiting at home for the reminder
    assert first[start:start + 3] == ["GotoPatientRoom"] * 3
    assert "GotoPatientRoom did not arrive within its deadline" in out
    assert "closing the step with 'navFailed'" in out
    assert "pearl_sim_world exited with code 0" in out


def test_the_sim_world_node_rejects_a_bad_scenario_in_one_line(tmp_path):
    proc = Proc([str(Path(sys.executable).with_name("pearl_sim_world")), "--ros-args", "-p", "scenario:=/no/such.yaml"],
                ros_env(allocate_domain_id(), tmp_path), tmp_path, "bad_world")
    try:
        assert proc.wait(60) == 2
        assert "pearl_sim_world: error:" in proc.stderr() and "/no/such.yaml" in proc.stderr()
    finally:
        proc.stop()


@pytest.mark.slow
def test_a_day_through_separate_processes_survives_its_simulator_killed_and_reports_memory_and_answers_per_hour(
        tmp_path):
    """bench/day_processes.py: `pearl launch launch/pearl_sim.launch.xml day:=true` runs the day world against
    the nodes in their own processes; the bench reads each process's memory per hour and bins the policy's
    decision times by the hour of the day. Here the day's first 65 minutes (two hours' bins), with the
    simulator SIGKILLed at 25 minutes: the launch respawns it, it resumes its world from its journal and
    the day runs to its end."""
    cmd = [sys.executable, str(REPO / "bench" / "day_processes.py"), "--until", "3900", "--rate", "400",
           "--kill-simulator-at", "1500",
           "--domain-id", str(allocate_domain_id()), "--run-dir", str(tmp_path / "run"), "--wall-timeout", "240"]
    proc = Proc(cmd, ros_env(allocate_domain_id(), tmp_path), tmp_path, "day_processes")
    try:
        code = proc.wait(300)
        assert code == 0, (proc.stdout() + proc.stderr())[-4000:]
    finally:
        proc.stop()
    report = json.loads(proc.stdout())
    assert report["exit_code"] == 0 and report["day"] == "G01-day0"
    # Every node journals as on a robot, the simulator too (its calls appended to the journal's log).
    assert report["journals"] == {"nodes": True, "simulator": True}
    log = Path(report["log"]).read_text()
    assert "pearl_sim_world: no journal" in log
    killed = report["simulator_killed"]
    assert 1500.0 <= killed["at_s"] < 3900.0 and "pearl_sim_world exited with code -9; respawning" in log
    # It resumed where its journal was (at most a few ticks before the kill) and ran the day to its end.
    assert 1400.0 <= killed["resumed_at_s"] <= killed["at_s"] + 60.0 and killed["actions_before"] >= 100
    assert report["checklist"]["wrong_actions"] == 0
    assert report["checklist"]["hours"] == pytest.approx(3900 / 3600, abs=0.01)   # the world ran to `until`
    assert set(report["nodes"]) == {"belief_tracker", "hierarchical_policy", "action_executor",
                                    "lifecycle_supervisor", "pearl_sim_world"}
    for name, node in report["nodes"].items():
        assert len(node["per_hour_mb"]) == 2 and all(20.0 < mb < 4000.0 for mb in node["per_hour_mb"]), (name, node)
        assert node["growth"] == pytest.approx(node["last_hour_mb"] / node["first_hour_mb"] - 1.0, abs=0.01)
    hours = report["decisions_per_hour"]
    assert set(hours) == {"08", "09"}
    # Steps of ~8 s: about 450 decisions in the first hour, a few in the 5 minutes after it.
    assert 300 <= hours["08"]["decisions"] <= 600 and 5 <= hours["09"]["decisions"] <= 100
    # Each decision paired with the belief it answered; before her first trip the belief holds mass on at
    # most 24 states (docs/day.md), so the first hour's decisions all fall in the lowest support band.
    total = sum(h["decisions"] for h in hours.values())
    bands = report["decisions_by_support"]
    assert report["decisions_paired_with_belief"] >= 0.95 * total
    assert sum(c["decisions"] for band in bands.values() for c in band.values()) == report["decisions_paired_with_belief"]
    assert bands["1-24"]["08"]["decisions"] >= 0.95 * hours["08"]["decisions"]
    assert 0.0 < hours["08"]["p50_ms"] <= hours["08"]["p99_ms"] < 1000.0
    assert report["actions"] >= hours["08"]["decisions"]


def test_the_day_bench_follows_a_respawned_node_to_its_new_process(load_bench, tmp_path):
    bench = load_bench("day_processes")
    log = tmp_path / "launch.log"
    log.write_text("[launch] started belief_tracker (pid 11)\n[launch] started pearl_sim_world (pid 12)\n"
                   "[launch] pearl_sim_world exited with code -9; respawning in 1 s (restart 1 of at most 3 within 60 s)\n"
                   "[launch] respawned pearl_sim_world (pid 13)\n")
    assert bench.node_pids(log) == {"belief_tracker": 11, "pearl_sim_world": 13}


def test_support_bands_of_the_day_bench_cover_every_size_once(load_bench):
    bench = load_bench("day_processes")
    assert [bench.support_band(n) for n in (1, 24, 25, 64, 65, 128, 129, 256, 257, 10_000)] == \
        ["1-24", "1-24", "25-64", "25-64", "65-128", "65-128", "129-256", "129-256", "257+", "257+"]
    table = bench.by_support([(0, 24, 0.001), (0, 24, 0.003), (2, 150, 0.002)])
    assert table == {"1-24": {"08": {"decisions": 2, "p50_ms": 2.0, "p99_ms": 2.98}},
                     "129-256": {"10": {"decisions": 1, "p50_ms": 2.0, "p99_ms": 2.0}}}


@pytest.mark.parametrize("param, words", [("resident:=0", "parameter resident: 0 is outside [1, 200]"),
                                           ("until:=50000.0", "parameter until: 50000.0 is outside (0, 43200] s"),
                                           ("day_domain:=/no/day.yaml", "/no/day.yaml")])
def test_the_sim_world_node_rejects_a_bad_day_parameter_in_one_line(tmp_path, param, words):
    proc = Proc([str(Path(sys.executable).with_name("pearl_sim_world")), "--ros-args", "-p", "day:=true", "-p", param],
                ros_env(allocate_domain_id(), tmp_path), tmp_path, "bad_day")
    try:
        assert proc.wait(60) == 2
        err = proc.stderr()
        assert "pearl_sim_world: error:" in err and words in err, err
        assert len([line for line in err.splitlines() if line.startswith("pearl_sim_world: error:")]) == 1
    finally:
        proc.stop()
