"""Start-up errors and shutdown of the node processes, as a user meets them.

A bad parameter or a missing file: the process exits 2 and prints exactly one line naming the
node, the parameter and the problem (no traceback). SIGINT and SIGTERM: exit 0.
"""
from __future__ import annotations

import signal
import sys
from pathlib import Path

import pytest

from ros_helpers import DISCOVERY_TIMEOUT, REPO, Proc, allocate_domain_id, ros_env, wait_for

pytestmark = pytest.mark.ros

import rclpy  # noqa: F401  (a missing install fails, it is not skipped)

BIN = Path(sys.executable).parent


def _run(tmp_path, argv, name="node"):
    proc = Proc(argv, ros_env(allocate_domain_id(), tmp_path), tmp_path, name)
    code = proc.wait(60.0)
    if code is None:
        proc.stop(5.0)
        pytest.fail(f"{argv} did not exit: {proc.stderr()}")
    proc.stop(1.0)
    return code, [line for line in proc.stderr().splitlines() if line.strip()]


BAD = [
    (["belief_tracker", "--ros-args", "-p", "domain:=/no/such/domain.yaml"],
     "belief_tracker: error: parameter domain: no such file: /no/such/domain.yaml"),
    (["belief_tracker", "--ros-args", "-p", "step_timeout:=-1.0"],
     "belief_tracker: error: Invalid parameter value (-1.0) for parameter. Reason: Parameter step_timeout out of "
     "range Min: 0.0, Max: 3600.0, value: -1.0: step_timeout"),
    (["belief_tracker", "--ros-args", "-p", "step_timeout:=soon"],
     "belief_tracker: error: Trying to set parameter 'step_timeout' to 'soon' of type 'STRING', expecting type "
     "'DOUBLE': step_timeout"),
    (["belief_tracker", "--ros-args", "-p", "step_timeout:=8"],
     "belief_tracker: error: Trying to set parameter 'step_timeout' to '8' of type 'INTEGER', expecting type "
     "'DOUBLE': step_timeout (a whole number where a decimal is declared: write it with a decimal point, e.g. 8.0)"),
    (["pearl_sim_world", "--ros-args", "-p", "rate:=40"],
     "pearl_sim_world: error: Trying to set parameter 'rate' to '40' of type 'INTEGER', expecting type "
     "'DOUBLE': rate (a whole number where a decimal is declared: write it with a decimal point, e.g. 8.0)"),
    (["belief_tracker", "--ros-args", "-p", "timeout_observation:=silence"],
     "belief_tracker: error: parameter timeout_observation 'silence' is not an observation of pearl (valid: yes, "
     "no, time, weather, go, unknown, t_yes, t_no, t_time, t_weather, t_go, atRoom, atPhysio, atHome, navFailed, "
     "userLost, g_none, g_physio, g_vitamin, g_checklist; or step_timeout 0)"),
    (["hierarchical_policy", "--ros-args", "-p", "policy:=/no/such/plan"],
     "hierarchical_policy: error: parameter policy: no such policy file or directory: /no/such/plan"),
    (["action_executor", "--ros-args", "-p", "actions.TellTime.goal:=moon"],
     "action_executor: error: parameter actions.TellTime.goal: unknown location 'moon' (location_names: home, "
     "room, physio)"),
    (["action_executor", "--ros-args", "-p", "locations.home:=[1.0, 2.0]"],
     "action_executor: error: parameter locations.home: expected [x, y, yaw] (finite numbers), got [1.0, 2.0]"),
]


@pytest.fixture(scope="module")
def bad_runs(tmp_path_factory):
    """All the bad-parameter processes, started at once (each is mostly Python start-up)."""
    tmp = tmp_path_factory.mktemp("bad")
    procs = [Proc([str(BIN / argv[0]), *argv[1:]], ros_env(allocate_domain_id(), tmp), tmp, f"bad{i}")
             for i, (argv, _) in enumerate(BAD)]
    results = []
    for proc in procs:
        code = proc.wait(60.0)
        proc.stop(1.0)
        results.append((code, [line for line in proc.stderr().splitlines() if line.strip()]))
    return results


@pytest.mark.parametrize("index", range(len(BAD)), ids=[f"{a[0]}:{a[-1]}" for a, _ in BAD])
def test_bad_parameter_exits_2_with_one_line(bad_runs, index):
    code, lines = bad_runs[index]
    assert code == 2, lines
    assert lines == [BAD[index][1]]


def test_pearl_run_reports_the_same_way(tmp_path):
    code, lines = _run(tmp_path, [str(BIN / "pearl"), "run", "belief_tracker", "--ros-args", "-p",
                                  "domain:=missing.yaml"])
    assert code == 2
    assert lines == [f"belief_tracker: error: parameter domain: no such file: {REPO / 'missing.yaml'} "
                     f"(nor {REPO / 'missing.yaml'})"] or lines == [
        f"belief_tracker: error: parameter domain: no such file: {REPO / 'missing.yaml'}"]


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_node_exits_0_on_signal(tmp_path, sig):
    proc = Proc([str(BIN / "belief_tracker"), "--ros-args", "--params-file", "config/pearl_nodes.yaml"],
                ros_env(allocate_domain_id(), tmp_path), tmp_path, "tracker")
    try:
        assert wait_for(lambda: "tracking pearl" in proc.stderr() or proc.returncode is not None, DISCOVERY_TIMEOUT)
        assert proc.returncode is None, proc.stderr()
        proc.popen.send_signal(sig)
        assert proc.wait(DISCOVERY_TIMEOUT) == 0, proc.stderr()
    finally:
        proc.stop(5.0)
    assert "Traceback" not in proc.stderr()


def test_launch_stops_everything_when_a_node_fails(tmp_path, pearl_policy):
    """A node failing at start-up ends the launch with its exit code and its one line."""
    proc = Proc([str(BIN / "pearl"), "launch", "launch/pearl.launch.xml", f"policy:={pearl_policy}",
                 "step_timeout:=-1.0"], ros_env(allocate_domain_id(), tmp_path), tmp_path, "launch")
    code = proc.wait(3 * DISCOVERY_TIMEOUT)
    if code is None:
        proc.stop(5.0)
        pytest.fail(f"launch did not stop: {proc.stderr()}")
    proc.stop(1.0)
    err = proc.stderr()
    assert code == 2, err
    assert ("[launch] belief_tracker exited with code 2: belief_tracker: error: Invalid parameter value (-1.0) "
            "for parameter. Reason: Parameter step_timeout out of range") in err
    assert "Traceback" not in err
