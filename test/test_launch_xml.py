"""The ROS-free launch XML reader: what it reads, what it refuses (with file:line), and that the
arguments it builds give a node the parameter values ``ros2 launch`` would."""
from __future__ import annotations

import ast
import json
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from pearl_pomdp.errors import SpecError
from pearl_pomdp.launch_xml import package_share_dir, parse_cli_arguments, parse_launch_file, parse_launch_text

REPO = Path(__file__).resolve().parents[1]
LAUNCH = REPO / "launch" / "pearl.launch.xml"


def test_pearl_launch_file_graph():
    d = parse_launch_file(LAUNCH, {"policy": "/plans/pearl"})
    assert [(n.package, n.executable, n.name, n.output) for n in d.nodes] == [
        ("pearl_pomdp", "belief_tracker", "belief_tracker", "screen"),
        ("pearl_pomdp", "hierarchical_policy", "hierarchical_policy", "screen"),
        ("pearl_pomdp", "action_executor", "action_executor", "screen"),
        ("pearl_pomdp", "lifecycle_supervisor", "lifecycle_supervisor", "screen"),
        ("pearl_pomdp", "landmark_detector", "landmark_detector", "screen"),
        ("pearl_pomdp", "guide_pace", "guide_pace", "screen")]
    assert [n.executable for n in parse_launch_file(LAUNCH, {"navigation": "false"}).nodes] == [
        "belief_tracker", "hierarchical_policy", "action_executor", "lifecycle_supervisor"]
    # Every node is respawned when it dies; the managed ones wait for the supervisor (autostart false).
    assert all(n.respawn and n.respawn_delay == 1.0 for n in d.nodes)
    assert [n.name for n in d.nodes if ("value", "autostart", "false") in n.parameters] == [
        "belief_tracker", "hierarchical_policy", "action_executor"]
    assert package_share_dir("pearl_pomdp") == REPO  # editable install: the source tree
    params = str(REPO / "config" / "pearl_nodes.yaml")
    assert d.values["params_file"] == params and d.values["policy"] == "/plans/pearl"
    # Each node takes its defaults from params_file too (defaults_file): another robot's
    # params file is the only one its nodes read.
    assert d.nodes[1].parameters == [
        ("file", params), ("value", "defaults_file", params), ("value", "domain", str(REPO / "config" / "pearl.domain.yaml")),
        ("value", "hierarchy", str(REPO / "config" / "pearl.hierarchy.yaml")),
        ("value", "policy", "/plans/pearl"), ("value", "autonomy", "full"), ("value", "use_sim_time", "false"),
        ("value", "autostart", "false")]
    assert set(d.arguments) == {"params_file", "domain", "hierarchy", "policy", "step_timeout", "use_sim_time",
                                "autonomy", "navigation", "speech", "audio_source", "audio_output", "journal"}


def test_params_are_written_like_launch_ros(tmp_path):
    node = parse_launch_file(LAUNCH, {"step_timeout": "2.5", "use_sim_time": "true"}).nodes[0]
    args = node.ros_args(tmp_path)
    assert args[:3] == ["--ros-args", "-r", "__node:=belief_tracker"]
    files = [args[i + 1] for i, a in enumerate(args) if a == "--params-file"]
    assert files[0] == str(REPO / "config" / "pearl_nodes.yaml")
    written = yaml.safe_load(Path(files[1]).read_text())
    assert written == {"/belief_tracker": {"ros__parameters": {
        "defaults_file": files[0], "domain": str(REPO / "config" / "pearl.domain.yaml"), "step_timeout": 2.5,
        "use_sim_time": True, "autostart": False}}}


PRECEDENCE_NODE = """
import sys, rclpy
from rclpy.node import Node
rclpy.init(args=sys.argv)
n = Node("belief_tracker")
print({k: n.declare_parameter(k, d).value for k, d in
       [("step_timeout", 0.0), ("domain", "x"), ("stale_after", 0.0), ("drive_speed", 0.0), ("policy", "x")]})
"""


def test_a_later_param_beats_the_params_file_in_a_real_node(tmp_path):
    """The params file sets domain (relative) for every node and stale_after/drive_speed for
    /belief_tracker; the launch file's later <param>s (domain as an absolute path, step_timeout)
    must win (with a plain `-p` rcl would let the file win), the file's other values apply."""
    import rclpy  # noqa: F401  (a missing install fails, it is not skipped)
    node = parse_launch_file(LAUNCH, {"step_timeout": "0.5"}).nodes[0]
    node.parameters.append(("value", "policy", ""))
    script = tmp_path / "node.py"
    script.write_text(PRECEDENCE_NODE)
    out = subprocess.run([sys.executable, str(script), *node.ros_args(tmp_path)], capture_output=True, text=True,
                         timeout=60, env={"ROS_LOG_DIR": str(tmp_path), "PATH": "/usr/bin:/bin",
                                          "ROS_AUTOMATIC_DISCOVERY_RANGE": "OFF"})
    assert out.returncode == 0, out.stderr
    assert ast.literal_eval(out.stdout.strip().splitlines()[-1]) == {
        "step_timeout": 0.5, "domain": str(REPO / "config" / "pearl.domain.yaml"), "stale_after": 30.0,
        "drive_speed": 0.6, "policy": ""}


def test_groups_namespaces_let_and_conditions():
    text = """<launch>
      <arg name="sim" default="false"/>
      <let name="who" value="outer"/>
      <group>
        <push-ros-namespace namespace="robot1"/>
        <let name="who" value="inner"/>
        <node pkg="p" exec="a" name="$(var who)"/>
        <node pkg="p" exec="b" namespace="arm"/>
        <node pkg="p" exec="c" namespace="/abs"/>
      </group>
      <node pkg="p" exec="d" name="$(var who)" if="$(var sim)"/>
      <node pkg="p" exec="e" name="$(var who)" unless="$(var sim)">
        <param name="nav"><param name="speed" value="0.5"/><param name="frame" value="map"/></param>
        <remap from="/pearl/say" to="/tts"/>
      </node>
    </launch>"""
    d = parse_launch_text(text)
    assert [(n.executable, n.name, n.namespace) for n in d.nodes] == [
        ("a", "inner", "/robot1"), ("b", None, "/robot1/arm"), ("c", None, "/abs"), ("e", "outer", None)]
    assert d.nodes[3].parameters == [("value", "nav.speed", "0.5"), ("value", "nav.frame", "map")]
    assert d.nodes[3].ros_args() == ["--ros-args", "-r", "__node:=outer", "-p", "nav.speed:=0.5",
                                     "-p", "nav.frame:=map", "-r", "/pearl/say:=/tts"]
    assert [n.executable for n in parse_launch_text(text, arguments={"sim": "true"}).nodes] == ["a", "b", "c", "d"]


def test_empty_value_is_the_empty_string():
    node = parse_launch_text('<launch><node pkg="p" exec="x"><param name="policy" value=""/></node></launch>').nodes[0]
    assert node.ros_args() == ["--ros-args", "-p", "policy:=''"]


@pytest.mark.parametrize("text, arguments, message", [
    ('<launch>\n<node pkg="p" exec="x" name="$(var nope)"/>\n</launch>', {},
     r"<string>:2: <node>\.name: \$\(var nope\): no such argument or variable"),
    ('<launch>\n\n<include file="x.launch.xml"/>\n</launch>', {}, r"<string>:3: <include>: unsupported element"),
    ('<launch>\n<arg name="policy"/>\n</launch>', {}, r"<string>:2: <arg>\.name: argument 'policy' has no default"),
    ('<launch><arg name="a" default="1"/></launch>', {"b": "2"}, r"unknown launch argument\(s\) b \(declared: a\)"),
    ('<launch>\n<node pkg="p" exec="x" nmae="y"/>\n</launch>', {}, r"<string>:2: <node>\.nmae: unknown attribute"),
    ('<launch><node pkg="p"/></launch>', {}, r"<node>\.exec: missing attribute"),
    ('<launch><node pkg="p" exec="x" name="$(eval 1+1)"/></launch>', {}, r"unsupported substitution \$\(eval 1\+1\)"),
    ('<launch>\n<node pkg="p" exec="x">\n<param from="/no/such.yaml"/></node></launch>', {},
     r"<string>:3: <param>\.from: no such parameters file"),
    ('<launch>\n<node pkg="p" exec="x"\n</launch>', {}, r"<string>:3: not well-formed XML"),
    ('<node pkg="p" exec="x"/>', {}, r"root element must be <launch>"),
    ('<launch><node pkg="p" exec="x" if="maybe"/></launch>', {}, r"condition must be true/false/1/0"),
    ('<launch><node pkg="p" exec="x" on_exit="restart"/></launch>', {},
     r"<node>\.on_exit: only 'shutdown' is supported, got 'restart'"),
    ('<launch><node pkg="p" exec="x" respawn="yes"/></launch>', {}, r"<node>\.respawn: must be true/false/1/0"),
    ('<launch><node pkg="p" exec="x" respawn_delay="soon"/></launch>', {},
     r"<node>\.respawn_delay: must be seconds, got 'soon'"),
    ('<launch><node pkg="p" exec="x" respawn_delay="-1"/></launch>', {}, r"<node>\.respawn_delay: must be >= 0 s"),
])
def test_errors_name_file_line_and_problem(text, arguments, message):
    with pytest.raises(SpecError, match=message):
        parse_launch_text(text, arguments=arguments)


def test_cli_arguments():
    assert parse_cli_arguments(["policy:=/a:=b", "x:="]) == {"policy": "/a:=b", "x": ""}
    with pytest.raises(SpecError, match="'policy' is not name:=value"):
        parse_cli_arguments(["policy"])


def test_pearl_launch_print_shows_the_commands():
    out = subprocess.run([str(Path(sys.executable).parent / "pearl"), "launch", str(LAUNCH), "--print",
                          "policy:=/p"], capture_output=True, text=True, timeout=60, cwd=REPO)
    assert out.returncode == 0, out.stderr
    nodes = json.loads(out.stdout)["nodes"]
    assert [n["command"][1:3] for n in nodes] == [["-m", "pearl_pomdp.nodes.belief_tracker"],
                                                  ["-m", "pearl_pomdp.nodes.hierarchical_policy"],
                                                  ["-m", "pearl_pomdp.nodes.action_executor"],
                                                  ["-m", "pearl_pomdp.nodes.supervisor"],
                                                  ["-m", "pearl_pomdp.nodes.landmark_detector"],
                                                  ["-m", "pearl_pomdp.nodes.guide_pace"]]
    bad = subprocess.run([str(Path(sys.executable).parent / "pearl"), "launch", str(LAUNCH), "--print", "polcy:=/p"],
                         capture_output=True, text=True, timeout=60, cwd=REPO)
    assert bad.returncode == 2
    assert bad.stderr.strip().splitlines() == [
        f"pearl launch: error: {LAUNCH}: unknown launch argument(s) polcy (declared: audio_output, audio_source, "
        f"autonomy, domain, hierarchy, journal, navigation, params_file, policy, speech, step_timeout, use_sim_time)"]


def test_speech_nodes_are_off_unless_asked():
    """speech:=true adds the recogniser and the synthesiser (off by default: no audio device is assumed)."""
    default = [n.executable for n in parse_launch_file(LAUNCH).nodes]
    assert "speech_recognizer" not in default and "speech_synthesizer" not in default
    on = parse_launch_file(LAUNCH, {"speech": "true", "audio_source": "microphone"})
    rec = next(n for n in on.nodes if n.executable == "speech_recognizer")
    assert "speech_synthesizer" in [n.executable for n in on.nodes]
    assert ("value", "source", "microphone") in rec.parameters


def test_the_sim_launch_passes_answer_timeout_to_the_simulator(tmp_path):
    """`answer_timeout:=` reaches pearl_sim_world's parameters (an operator confirming actions needs more)."""
    sim = REPO / "launch" / "pearl_sim.launch.xml"
    for given, expected in ((None, 30.0), ("240.0", 240.0)):
        world = next(n for n in parse_launch_file(sim, {} if given is None else {"answer_timeout": given}).nodes
                     if n.executable == "pearl_sim_world")
        args = world.ros_args(tmp_path)
        files = [args[i + 1] for i, a in enumerate(args) if a == "--params-file"]
        written = yaml.safe_load(Path(files[-1]).read_text())
        assert written["/pearl_sim_world"]["ros__parameters"]["answer_timeout"] == expected
