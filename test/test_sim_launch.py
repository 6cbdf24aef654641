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
