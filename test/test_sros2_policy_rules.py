"""pearl_pomdp.sros2_policy without ROS: building, reading back, the schema's rules, actions, the notice."""
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from pearl_pomdp.errors import SpecError
from pearl_pomdp.sros2_policy import (OPERATOR_NODE, NodeEndpoints, build_policy, fold_actions, operator_endpoints,
                                      policy_problems, read_policy, renamed, security_notice)


def _node(name, ns="/", **grants):
    return NodeEndpoints(name, ns, **{k: frozenset(v) for k, v in grants.items()})


TRACKER = _node("belief_tracker", publishes={"/pearl/belief", "/rosout", "/belief_tracker/transition_event"},
                subscribes={"/pearl/speech", "/pearl/action"},
                serves={"/pearl/reset", "/belief_tracker/get_state", "/belief_tracker/get_parameters"})
POLICY = _node("hierarchical_policy", publishes={"/pearl/action", "/rosout"},
               subscribes={"/pearl/belief", "/pearl/operator/veto", "/pearl/operator/command"},
               serves={"/pearl/operator/confirm", "/hierarchical_policy/get_parameters"})
SUPERVISOR = _node("lifecycle_supervisor", ns="/robot", publishes={"/rosout", "/robot/lifecycle_supervisor/x"},
                   calls={"/belief_tracker/get_state"})
OPERATOR_PARAMS = {"veto_topic": "/pearl/operator/veto", "command_topic": "/pearl/operator/command",
                   "proposal_topic": "/pearl/proposal", "operator_events_topic": "/pearl/operator/events",
                   "confirm_service": "/pearl/operator/confirm", "set_autonomy_service": "/pearl/operator/set_autonomy",
                   "veto_service": "/pearl/operator/veto_action", "command_service": "/pearl/operator/command_action"}


def test_a_built_policy_reads_back_to_the_same_grants_and_writes_private_names_with_a_tilde():
    text = build_policy([POLICY, TRACKER, SUPERVISOR])
    assert "<service>~/get_state</service>" in text and "<topic>/pearl/belief</topic>" in text
    assert "<topic>~/x</topic>" in text     # private to a node in a namespace
    assert policy_problems(ET.fromstring(text)) == []
    back = read_policy(text)
    assert [path for path, _ in back] == ["/pearl/belief_tracker", "/pearl/hierarchical_policy",
                                          "/pearl/lifecycle_supervisor"]
    assert {n.fully_qualified_name: n for _, n in back} == {n.fully_qualified_name: n
                                                            for n in (TRACKER, POLICY, SUPERVISOR)}


def test_nodes_started_in_one_enclave_share_it_and_the_others_get_their_own():
    text = build_policy([TRACKER, POLICY, SUPERVISOR], enclaves={"/belief_tracker": "/robot/manager",
                                                                  "/hierarchical_policy": "/robot/manager",
                                                                  "/robot/lifecycle_supervisor": "/"})
    back = read_policy(text)
    assert [(path, n.name) for path, n in back] == [("/pearl/lifecycle_supervisor", "lifecycle_supervisor"),
                                                    ("/robot/manager", "belief_tracker"),
                                                    ("/robot/manager", "hierarchical_policy")]
    assert text.count("<enclave ") == 2


def test_the_same_graph_gives_the_same_bytes_whatever_the_order():
    text = build_policy([TRACKER, POLICY], comment="made by\na test")
    assert text == build_policy([POLICY, TRACKER], comment="made by\na test")
    assert ET.fromstring(text).tag == "policy" and "  a test\n-->" in text
    with pytest.raises(ValueError, match="cannot hold '--'"):
        build_policy([TRACKER], comment="started with --enclave")


def test_relative_and_private_names_resolve_as_sros2_resolves_them():
    text = """<policy version="0.2.0"><enclaves><enclave path="/e"><profiles>
      <profile ns="/robot" node="talker">
        <topics publish="ALLOW"><topic>chatter</topic><topic>~/private</topic><topic>/abs</topic></topics>
        <services request="ALLOW"><service>add</service></services>
        <actions call="ALLOW"><action>/navigate_to_pose</action></actions>
      </profile></profiles></enclave></enclaves></policy>"""
    (path, node), = read_policy(text)
    assert path == "/e" and node.fully_qualified_name == "/robot/talker"
    assert node.publishes == {"/robot/chatter", "/robot/talker/private", "/abs"}
    assert node.calls == {"/robot/add"} and node.invokes == {"/navigate_to_pose"}


@pytest.mark.parametrize("text, problem", [
    ('<policy><enclaves><enclave path="/e"><profiles><profile ns="/" node="n"/></profiles></enclave></enclaves></policy>',
     "version None"),
    ('<policy version="0.1.0"><enclaves/></policy>', "the schema fixes '0.2.0'"),
    ('<policy version="0.2.0"><enclaves/></policy>', "<enclaves>: no <enclave>"),
    ('<policy version="0.2.0"><enclaves><enclave><profiles><profile ns="/" node="n"/></profiles></enclave>'
     '</enclaves></policy>', "no path attribute"),
    ('<policy version="0.2.0"><enclaves><enclave path="/e"><profiles/></enclave></enclaves></policy>',
     "holds no <profile>"),
    ('<policy version="0.2.0"><enclaves><enclave path="/e"><profiles><profile node="n"/></profiles></enclave>'
     '</enclaves></policy>', "no ns attribute"),
    ('<policy version="0.2.0"><enclaves><enclave path="/e"><profiles><profile ns="/" node="n">'
     '<topics publish="YES"><topic>t</topic></topics></profile></profiles></enclave></enclaves></policy>',
     "publish='YES', expected ALLOW or DENY"),
    ('<policy version="0.2.0"><enclaves><enclave path="/e"><profiles><profile ns="/" node="n">'
     '<topics reply="ALLOW"><topic>t</topic></topics></profile></profiles></enclave></enclaves></policy>',
     "unexpected attribute reply"),
    ('<policy version="0.2.0"><enclaves><enclave path="/e"><profiles><profile ns="/" node="n">'
     '<topics publish="ALLOW"><service>t</service></topics></profile></profiles></enclave></enclaves></policy>',
     "unexpected element <service>"),
    ('<policy version="0.2.0"><enclaves><enclave path="/e"><profiles><profile ns="/" node="n">'
     '<topics publish="ALLOW"/></profile></profiles></enclave></enclaves></policy>', "no <topic>"),
    ('<policy version="0.2.0"><enclaves><enclave path="/e"><profiles><profile ns="/" node="n">'
     '<topics publish="ALLOW"><topic> </topic></topics></profile></profiles></enclave></enclaves></policy>',
     "must hold a name"),
    ('<policy version="0.2.0"><enclaves><enclave path="/e"><profiles><metadata/><profile ns="/" node="n"/>'
     '</profiles></enclave></enclaves></policy>', "<metadata> must come once, after the profiles"),
    ('<policy version="0.2.0"><enclaves><enclave path="/e"><profiles><profile ns="/" node="n">'
     '<params/></profile></profiles></enclave></enclaves></policy>', "unexpected element <params>"),
])
def test_each_rule_of_the_schema_is_checked(text, problem):
    problems = policy_problems(ET.fromstring(text))
    assert any(problem in p for p in problems), problems
    with pytest.raises(SpecError, match="my.policy.xml: "):
        read_policy(text, "my.policy.xml")


def test_a_deny_rule_is_refused_by_the_reader_not_silently_dropped():
    text = ('<policy version="0.2.0"><enclaves><enclave path="/e"><profiles><profile ns="/" node="n">'
            '<topics publish="DENY"><topic>t</topic></topics></profile></profiles></enclave></enclaves></policy>')
    assert policy_problems(ET.fromstring(text)) == []
    with pytest.raises(SpecError, match="publish=\"DENY\""):
        read_policy(text)


def test_an_action_s_hidden_topics_and_services_fold_into_one_action():
    hidden = "/navigate_to_pose/_action/"
    client = _node("action_executor", publishes={"/rosout"},
                   subscribes={hidden + "feedback", hidden + "status", "/pearl/action"},
                   calls={hidden + "send_goal", hidden + "cancel_goal", hidden + "get_result", "/other"})
    folded = fold_actions(client)
    assert folded.invokes == {"/navigate_to_pose"} and folded.executes == frozenset()
    assert folded.subscribes == {"/pearl/action"} and folded.calls == {"/other"}
    server = _node("bt_navigator", publishes={hidden + "feedback", hidden + "status"},
                   serves={hidden + "send_goal", hidden + "cancel_goal", hidden + "get_result"})
    assert fold_actions(server) == _node("bt_navigator", executes={"/navigate_to_pose"})
    partial = _node("x", calls={hidden + "send_goal"})
    assert fold_actions(partial) == partial   # not a whole action: left as it is
    assert "<actions call=\"ALLOW\">" in build_policy([folded])


def test_the_operator_gets_the_operator_endpoints_and_what_a_bare_node_has():
    bare = _node("_probe", publishes={"/rosout", "/parameter_events"},
                 serves={"/_probe/get_parameters", "/_probe/list_parameters"})
    assert renamed(bare, OPERATOR_NODE).serves == {"/pearl_operator/get_parameters", "/pearl_operator/list_parameters"}
    operator = operator_endpoints(OPERATOR_PARAMS, bare)
    assert operator.publishes == {"/rosout", "/parameter_events", "/pearl/operator/veto", "/pearl/operator/command"}
    assert operator.subscribes == {"/pearl/proposal", "/pearl/operator/events"}
    assert operator.calls == {"/pearl/operator/confirm", "/pearl/operator/set_autonomy",
                              "/pearl/operator/veto_action", "/pearl/operator/command_action"}
    assert operator.serves == {"/pearl_operator/get_parameters", "/pearl_operator/list_parameters"}
    text = build_policy([TRACKER, POLICY], operator)
    assert read_policy(text)[-1] == ("/pearl/operator", operator)
    with pytest.raises(SpecError, match="veto_topic"):
        operator_endpoints({k: v for k, v in OPERATOR_PARAMS.items() if k != "veto_topic"}, bare)


def test_the_security_notice_is_said_only_when_security_is_off():
    line = security_notice({}, 7, ["/pearl/operator/veto"])
    assert "ROS domain 7" in line and "/pearl/operator/veto" in line and "docs/reliability.md" in line
    assert security_notice({"ROS_SECURITY_ENABLE": "false"}, 7, ["/v"]) is not None
    assert security_notice({"ROS_SECURITY_ENABLE": "true"}, 7, ["/v"]) is None


@pytest.mark.parametrize("argv, message", [
    (["security", "policy", "nope.launch.xml"], "nope.launch.xml: no such launch file"),
    (["security", "policy", "launch/pearl.launch.xml", "--ros-domain-id", "999"], "--ros-domain-id must be 0..232"),
    (["security", "policy", "launch/pearl.launch.xml", "--timeout", "0"], "--timeout must be > 0 s"),
])
def test_pearl_security_policy_refuses_with_one_line(argv, message, capsys, monkeypatch):
    from pearl_pomdp.cli import main

    monkeypatch.chdir(Path(__file__).resolve().parents[1])
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("pearl security: error: ") and message in err[0], err
