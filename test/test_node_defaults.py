"""One source for every default: a node started alone (``ros2 run``) declares what the launch
file gives it, the tracker's parameters are StepSettings' fields, and the shipped params file holds
only values that differ from the code's defaults, each with its reason.

Each node is built in this process three ways on one context: as ``ros2 run pearl_pomdp NODE``
starts it (no parameters), as the launch file starts it (``--params-file config/pearl_nodes.yaml``),
and the code's defaults are each class's parameter table. Managed nodes get ``autostart:=false``
in every case (the comparison is of declared parameters; planning a policy is not needed for it).
"""
from __future__ import annotations

import re
from pathlib import Path
from typing import Any, Dict, List, Optional

import pytest
import rclpy

from pearl_pomdp.params import flatten
from pearl_pomdp.tracking import StepSettings
from pearl_pomdp.yaml_lines import parse_yaml

pytestmark = pytest.mark.ros

REPO = Path(__file__).resolve().parents[1]
PARAMS = REPO / "config" / "pearl_nodes.yaml"


def _node_classes():
    from pearl_pomdp.nodes.action_executor import ActionExecutorNode
    from pearl_pomdp.nodes.belief_tracker import BeliefTrackerNode
    from pearl_pomdp.nodes.guide_pace import GuidePaceNode
    from pearl_pomdp.nodes.hierarchical_policy import HierarchicalPolicyNode
    from pearl_pomdp.nodes.landmark_detector import LandmarkDetectorNode
    from pearl_pomdp.nodes.speech_recognizer import SpeechRecognizerNode
    from pearl_pomdp.nodes.speech_synthesizer import SpeechSynthesizerNode
    from pearl_pomdp.nodes.supervisor import LifecycleSupervisorNode
    from pearl_sim.nursing_home.bt_node import BehaviourTreeNode
    from pearl_sim.nursing_home.world_node import _make_node_class

    return {"belief_tracker": BeliefTrackerNode, "hierarchical_policy": HierarchicalPolicyNode,
            "action_executor": ActionExecutorNode, "landmark_detector": LandmarkDetectorNode,
            "guide_pace": GuidePaceNode, "speech_recognizer": SpeechRecognizerNode,
            "speech_synthesizer": SpeechSynthesizerNode, "lifecycle_supervisor": LifecycleSupervisorNode,
            "pearl_bt": BehaviourTreeNode,
            "pearl_sim_world": _make_node_class()}


def test_every_console_script_node_is_covered():
    """setup.py's node scripts are the nodes checked here (a new node joins the check)."""
    text = (REPO / "setup.py").read_text(encoding="utf-8")
    scripts = set(re.findall(r'"(\w+)": "pearl_pomdp\.nodes\.\w+:main"', text))
    scripts |= set(re.findall(r'"(pearl_\w+) = pearl_sim\.[\w.]+:main"', text))
    assert scripts == set(_node_classes())


def _declared(context, cls, overrides: Dict[str, Any], cli_args: Optional[List[str]] = None) -> Dict[str, Any]:
    from pearl_pomdp.nodes.managed import ManagedPearlNode

    kwargs: Dict[str, Any] = {"context": context, "cli_args": cli_args}
    if issubclass(cls, ManagedPearlNode):
        overrides = {**overrides, "autostart": False}
    if overrides:
        kwargs["parameter_overrides"] = overrides
    if not hasattr(cls, "PARAMETERS"):          # the sim world: an rclpy Node with its own name
        kwargs.pop("parameter_overrides", None)
        from rclpy.parameter import Parameter

        kwargs["parameter_overrides"] = [Parameter(k, value=v) for k, v in overrides.items()]
    node = cls(**kwargs)
    try:
        # node._parameters: also the statically typed ones no value was given (get_parameter raises there).
        return {name: param.value for name, param in sorted(node._parameters.items())}
    finally:
        node.destroy_node()


@pytest.fixture(scope="module")
def context(tmp_path_factory):
    """One rclpy context on its own domain for the module's nodes."""
    from rclpy.context import Context
    from rclpy.signals import SignalHandlerOptions

    from ros_helpers import allocate_domain_id, configure_test_process

    configure_test_process(tmp_path_factory.mktemp("ros"))
    ctx = Context()
    rclpy.init(context=ctx, domain_id=allocate_domain_id(), signal_handler_options=SignalHandlerOptions.NO)
    yield ctx
    rclpy.try_shutdown(context=ctx)


@pytest.fixture(scope="module")
def declared(context):
    """``{node: (alone, launched, code defaults)}`` of every node's declared parameter values."""
    out = {}
    for name, cls in _node_classes().items():
        alone = _declared(context, cls, {})
        launched = _declared(context, cls, {}, ["--ros-args", "--params-file", str(PARAMS)])
        # The code's defaults: each class's table (some nodes cannot start without the file's tables).
        code = {p.name: p.default for p in getattr(cls, "PARAMETERS", ())} if hasattr(cls, "PARAMETERS") else alone
        out[name] = (alone, launched, code)
    return out


@pytest.mark.parametrize("node", sorted(_node_classes()))
def test_a_node_started_alone_declares_what_the_launch_file_gives_it(declared, node):
    alone, launched, _ = declared[node]
    assert alone == launched


def test_the_params_file_changes_what_it_says(declared):
    """The file is not inert: its values reach the nodes (otherwise the check above proves nothing)."""
    tracker_alone, _, tracker_code = declared["belief_tracker"]
    assert (tracker_alone["stale_after"], tracker_alone["drive_speed"], tracker_alone["guide_actions"]) == \
        (30.0, 0.6, ["GuideToPhysio"])
    assert (tracker_code["stale_after"], tracker_code["drive_speed"]) == (0.0, 0.0)
    assert tracker_alone["location_names"] == ["home", "room", "physio"]
    assert [n for n in tracker_code["location_names"] if n] == []
    assert declared["action_executor"][0]["actions.TellTime.say"] == "It is {time}."
    assert declared["landmark_detector"][0]["landmarks.physio"] == "atPhysio"


def test_no_value_in_the_params_file_is_a_default(declared):
    """Each value differs from the code's default of a node that declares it (``/**``: of at least one)."""
    data = parse_yaml(PARAMS.read_text(encoding="utf-8"), str(PARAMS))
    same = []
    for section, body in data.items():
        values = flatten(body["ros__parameters"])
        nodes = list(declared) if section == "/**" else [section]
        for key, value in values.items():
            defaults = [declared[n][2][key] for n in nodes if key in declared[n][2]]
            # A place's pose or an action's table entry is declared only once its name is given:
            # the code has none of them, so they differ from the code by being there at all.
            if defaults and all(d == value for d in defaults):
                same.append(f"{section}.{key} = {value!r}")
    assert same == []


def test_every_value_in_the_params_file_carries_its_reason():
    lines = PARAMS.read_text(encoding="utf-8").splitlines()
    missing = []
    for i, line in enumerate(lines):
        m = re.match(r"^    (\w+):", line)       # a parameter of a section (nested tables are its data)
        if m is None:
            continue
        before = lines[i - 1].strip() if i else ""
        if "#" not in line and not before.startswith("#"):
            missing.append(m.group(1))
    assert missing == []


def test_the_tracker_parameters_are_step_settings_fields(declared):
    """Names, defaults, ranges, descriptions and read-only flags come from StepSettings' metadata."""
    from pearl_pomdp.nodes.belief_tracker import BeliefTrackerNode

    params = {p.name: p for p in BeliefTrackerNode.PARAMETERS}
    specs = StepSettings.parameters()
    assert [s.name for s in specs] == [f for f in StepSettings.__dataclass_fields__ if f != "places"]
    code = declared["belief_tracker"][2]
    defaults = StepSettings()
    for spec in specs:
        p = params[spec.name]
        assert (p.default, p.range, p.read_only) == (spec.default if spec.default != [] else [""], spec.range,
                                                    not spec.live), spec.name
        assert p.description.startswith(spec.description), spec.name
        value = getattr(defaults, spec.name)
        expected = (list(value or ()) or [""]) if (value is None or isinstance(value, tuple)) else value
        assert code[spec.name] == expected, spec.name
    assert {s.name for s in specs if s.live} == {"step_timeout", "stale_after", "confidence_floor"}


def test_the_study_and_the_node_run_the_same_step_settings(declared):
    """The fast path (params.step_settings) reads what the node declares."""
    from pearl_pomdp.params import step_settings

    alone = declared["belief_tracker"][0]
    assert step_settings() == StepSettings.from_params(alone)


def test_a_live_parameter_goes_through_the_core_and_is_checked(context):
    from rcl_interfaces.msg import SetParametersResult  # noqa: F401  (rclpy's reply type)
    from rclpy.parameter import Parameter

    from pearl_pomdp.nodes.belief_tracker import BeliefTrackerNode

    node = BeliefTrackerNode(context=context)
    try:
        assert node.core is not None and node.core.settings.confidence_floor == 0.0
        ok = node.set_parameters([Parameter("confidence_floor", value=0.4), Parameter("stale_after", value=5.0)])
        assert all(r.successful for r in ok)
        assert (node.core.settings.confidence_floor, node.core.settings.stale_after) == (0.4, 5.0)
        bad = node.set_parameters([Parameter("step_timeout", value=-2.0)])[0]
        assert not bad.successful and node.core.settings.step_timeout == 10.0
        read_only = node.set_parameters([Parameter("drive_speed", value=1.0)])[0]
        assert not read_only.successful and node.core.settings.drive_speed == 0.6
    finally:
        node.destroy_node()


def _courier(tmp_path, nodes_yaml: Optional[str] = None) -> Path:
    """A robot that is not Pearl (the battery domain of test_channels, named courier) in ``tmp_path``,
    with ``courier_nodes.yaml`` beside it when ``nodes_yaml`` is given."""
    from test_channels import BATTERY

    path = tmp_path / "courier.domain.yaml"
    path.write_text(BATTERY.replace("name: battery-robot", "name: courier"))
    if nodes_yaml is not None:
        (tmp_path / "courier_nodes.yaml").write_text(nodes_yaml)
    return path


def test_a_tracker_given_only_another_robots_domain_runs_on_the_code_defaults_and_its_topics(context, tmp_path):
    """Pearl's params (place_feature RobotLocation, its guidance, its places) never reach another
    robot: with only ``domain:=`` the tracker starts and subscribes to that domain's own inputs."""
    from pearl_pomdp.nodes.belief_tracker import BeliefTrackerNode

    path = _courier(tmp_path)
    node = BeliefTrackerNode(context=context, parameter_overrides={"domain": str(path)})
    try:
        assert node.core is not None
        values = {name: param.value for name, param in node._parameters.items()}
        assert (values["place_feature"], values["guide_actions"], values["stale_after"]) == ("", [""], 0.0)
        assert values["defaults_file"] == "config/pearl_nodes.yaml"   # declared, but not read: the domain has no params
        topics = {sub.topic_name for sub in node.subscriptions}
        assert {"/robot/battery_state", "/robot/speech"} <= topics
    finally:
        node.destroy_node()


def test_a_domains_own_params_file_beside_it_gives_its_nodes_their_defaults(context, tmp_path):
    from pearl_pomdp.nodes.belief_tracker import BeliefTrackerNode

    path = _courier(tmp_path, "belief_tracker:\n  ros__parameters:\n    stale_after: 12.5   # the courier's own\n")
    node = BeliefTrackerNode(context=context, parameter_overrides={"domain": str(path)})
    try:
        values = {name: param.value for name, param in node._parameters.items()}
        assert (values["stale_after"], values["place_feature"]) == (12.5, "")
        assert node.core is not None and node.core.settings.stale_after == 12.5
    finally:
        node.destroy_node()
    # An explicit defaults_file still wins (here: none, the code's defaults).
    node = BeliefTrackerNode(context=context, parameter_overrides={"domain": str(path), "defaults_file": ""})
    try:
        assert node.get_parameter("stale_after").value == 0.0
    finally:
        node.destroy_node()


@pytest.mark.parametrize("where", ["shipped", "copy"])
def test_pearls_domain_named_explicitly_or_copied_still_reads_pearls_params(context, tmp_path, where):
    """Pearl's own domain file, or a copy of it under another file name (``pearl demo`` runs on
    ``OUT/domain.yaml``): the domain's ``name: pearl`` is Pearl's, so Pearl's params apply."""
    import shutil

    from pearl_pomdp.nodes.belief_tracker import BeliefTrackerNode

    path = REPO / "config" / "pearl.domain.yaml"
    if where == "copy":
        path = Path(shutil.copyfile(path, tmp_path / "domain.yaml"))
    node = BeliefTrackerNode(context=context, parameter_overrides={"domain": str(path)})
    try:
        assert (node.get_parameter("place_feature").value, node.get_parameter("stale_after").value) == \
            ("RobotLocation", 30.0)
    finally:
        node.destroy_node()
