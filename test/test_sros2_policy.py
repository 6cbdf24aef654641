"""Who may command the robot (docs/reliability.md): the shipped SROS2 policy
``config/sros2/pearl.policy.xml`` against the graph ``launch/pearl.launch.xml`` really starts.

* ``pearl security policy`` regenerates it byte for byte (it starts the graph on its own domain);
* a graph started separately with ``pearl launch`` and read by this test's own graph queries
  (rclpy's ``get_*_names_and_types_by_node``) uses every topic and service the policy grants each
  node, and nothing the policy does not grant: compared both ways, per node and kind;
* only the operator's enclave may publish the veto and command or call the operator services;
* the file keeps SROS2's policy schema (its rules checked by hand: the schema file ships with the
  ``sros2`` package, which PyPI does not carry);
* the operator-facing node (the policy) says once at start that DDS security is off.
"""
from __future__ import annotations

import subprocess
import sys
import time
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from ros_helpers import DISCOVERY_TIMEOUT, REPO, allocate_domain_id, ros_env
from test_nodes_multiprocess import LaunchedGraph

pytestmark = [pytest.mark.ros, pytest.mark.slow]

from pearl_pomdp.sros2_policy import OPERATOR_NODE, policy_problems, read_policy  # noqa: E402

SHIPPED = REPO / "config" / "sros2" / "pearl.policy.xml"
PEARL = str(Path(sys.executable).parent / "pearl")
KINDS = {"publishes": "get_publisher_names_and_types_by_node",
         "subscribes": "get_subscriber_names_and_types_by_node",
         "serves": "get_service_names_and_types_by_node",
         "calls": "get_client_names_and_types_by_node"}
OPERATOR_ONLY = {"publishes": {"/pearl/operator/veto", "/pearl/operator/command"},
                 "calls": {"/pearl/operator/confirm", "/pearl/operator/set_autonomy", "/pearl/operator/veto_action",
                           "/pearl/operator/command_action"}}


def _used(graph: LaunchedGraph) -> dict:
    """{node fqn: {kind: names, "enclave": its enclave}} for every node in the graph but this test's probe."""
    node = graph.node
    found = {}
    for name, ns, enclave in node.get_node_names_and_namespaces_with_enclaves():
        fqn = f"{ns.rstrip('/')}/{name}"
        if fqn == f"/{node.get_name()}":
            continue
        found[fqn] = {kind: {t for t, _ in getattr(node, method)(name, ns)} for kind, method in KINDS.items()}
        found[fqn]["enclave"] = enclave
    return found


@pytest.fixture(scope="module")
def launched(tmp_path_factory, pearl_policy):
    """The graph of launch/pearl.launch.xml, up (the policy answered b0) and its endpoints settled."""
    g = LaunchedGraph(tmp_path_factory.mktemp("launch"), pearl_policy)
    try:
        ready = g.wait(lambda: len(g.actions) >= 1 and len(g.beliefs) >= 1
                       and g.node.count_publishers("/pearl/say") >= 1, 3 * DISCOVERY_TIMEOUT)
        assert ready, f"graph not ready: {g.launch.stderr()[-3000:]}"
        used, since = _used(g), time.monotonic()
        deadline = since + DISCOVERY_TIMEOUT
        while time.monotonic() - since < 2.0 and time.monotonic() < deadline:
            g.wait(lambda: False, 0.5)
            now = _used(g)
            if now != used:
                used, since = now, time.monotonic()
        yield g, used
    finally:
        g.stop()


def test_the_shipped_policy_is_what_the_command_generates(tmp_path, pearl_policy):
    domain_id = allocate_domain_id()
    out = tmp_path / "pearl.policy.xml"
    done = subprocess.run([PEARL, "security", "policy", "launch/pearl.launch.xml", f"policy:={pearl_policy}",
                           "--ros-domain-id", str(domain_id), "--out", str(out)],
                          cwd=REPO, env=ros_env(domain_id, tmp_path), capture_output=True, text=True, timeout=240)
    assert done.returncode == 0, done.stderr[-3000:]
    assert out.read_text() == SHIPPED.read_text(), \
        "config/sros2/pearl.policy.xml is out of date: pearl security policy launch/pearl.launch.xml --out it"


def test_the_policy_grants_exactly_what_each_launched_node_uses(launched):
    graph, used = launched
    policy = [(path, node) for path, node in read_policy(SHIPPED.read_text(), str(SHIPPED)) if path != "/pearl/operator"]
    granted = {node.fully_qualified_name: node for _, node in policy}
    assert set(granted) == set(used), "nodes of the graph without a profile, or profiles of no node"
    # Each node runs in the enclave whose profile grants it (the launch file's --enclave).
    assert {node.fully_qualified_name: path for path, node in policy} == {fqn: k["enclave"] for fqn, k in used.items()}
    assert {"/belief_tracker", "/hierarchical_policy", "/action_executor", "/lifecycle_supervisor",
            "/landmark_detector", "/guide_pace"} == set(used)
    wrong = []
    for fqn, kinds in used.items():
        for kind, names in kinds.items():
            if kind == "enclave":
                continue
            allowed = getattr(granted[fqn], kind)
            wrong += [f"{fqn} {kind} {n}: used, not granted" for n in sorted(names - allowed)]
            wrong += [f"{fqn} {kind} {n}: granted, not used" for n in sorted(allowed - names)]
        assert not granted[fqn].executes and not granted[fqn].invokes   # no action on this install (no Nav2)
    assert wrong == []
    # The tracker's inputs are the domain's declared modalities.
    assert {"/pearl/speech", "/pearl/laser", "/pearl/touchscreen", "/pearl/reminder"} <= granted["/belief_tracker"].subscribes


def test_only_the_operator_may_command(launched):
    _, used = launched
    policy = read_policy(SHIPPED.read_text(), str(SHIPPED))
    operator = dict(policy)["/pearl/operator"]
    assert operator.name == OPERATOR_NODE
    for kind, names in OPERATOR_ONLY.items():
        assert names <= getattr(operator, kind)
        others = [(path, sorted(getattr(node, kind) & names)) for path, node in policy if path != "/pearl/operator"]
        assert [o for o in others if o[1]] == []
    # ... and the graph agrees: only the policy node listens to the veto and command and serves the operator.
    assert [fqn for fqn, k in used.items() if k["publishes"] & OPERATOR_ONLY["publishes"]] == []
    assert [fqn for fqn, k in used.items() if k["subscribes"] & OPERATOR_ONLY["publishes"]] == ["/hierarchical_policy"]
    assert [fqn for fqn, k in used.items() if k["serves"] & OPERATOR_ONLY["calls"]] == ["/hierarchical_policy"]
    assert operator.subscribes == {"/pearl/proposal", "/pearl/operator/events"}


def test_the_policy_keeps_the_sros2_schema():
    assert policy_problems(ET.parse(SHIPPED).getroot()) == []


def test_the_operator_facing_node_says_once_that_security_is_off(launched):
    graph, _ = launched
    text = graph.launch.stdout() + graph.launch.stderr()
    lines = [line for line in text.splitlines() if "DDS security is off" in line]
    assert len(lines) == 1 and "hierarchical_policy" in lines[0], lines
    assert f"ROS domain {graph.domain_id}" in lines[0] and "/pearl/operator/veto" in lines[0]
