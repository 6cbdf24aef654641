"""The action executor: configuration from the params file, drives on Nav2's ``/goal_pose``.

* With no parameters at all, the executor does what ``config/pearl_nodes.yaml`` says, for
  every action in the file (say, display, goal pose on ``/goal_pose`` in the map frame).
* ``-p`` overrides a file default; ``defaults_file:=''`` configures nothing.
* A defaults file with a wrong type or an unknown field stops the node with one line.
* The module names no action of the Pearl domain.
"""
from __future__ import annotations

import math
import re
from pathlib import Path

import pytest

from ros_helpers import DOMAIN, REPO, Probe, wait_for

pytestmark = [pytest.mark.ros]
import rclpy

from rclpy.executors import SingleThreadedExecutor  # noqa: E402

from pearl_pomdp.nodes import conversions as cv  # noqa: E402
from pearl_pomdp.nodes.action_executor import ActionExecutorNode  # noqa: E402
from pearl_pomdp.nodes.common import EVENT_QOS, LATCHED_QOS, NodeSetupError  # noqa: E402
from pearl_pomdp.params import node_parameters  # noqa: E402

PARAMS = REPO / "config" / "pearl_nodes.yaml"


class Rig:
    """An executor node and a probe on one executor."""

    def __init__(self, context, overrides=None):
        self.node = ActionExecutorNode(context=context, parameter_overrides=overrides or {})
        self.probe = Probe(rclpy.create_node("executor_probe", context=context))
        self.say = self.probe.listen("/pearl/say", cv.TextMsg, EVENT_QOS)
        self.display = self.probe.listen("/pearl/display", cv.TextMsg, EVENT_QOS)
        self.goals = self.probe.listen("/goal_pose", cv.PoseMsg, LATCHED_QOS)
        self.action = self.probe.publisher("/pearl/action", cv.ActionMsg, LATCHED_QOS)
        self.executor = SingleThreadedExecutor(context=context)
        self.executor.add_node(self.node)
        self.executor.add_node(self.probe.node)
        assert wait_for(lambda: not self.probe.unmatched([self.node]), 10.0, self.executor)

    def run(self, action: str, says: int = 0, displays: int = 0, goals: int = 0) -> None:
        """Publish ``action``; wait until the node has executed it and the probe has heard at least the
        given numbers of new outputs (they cross DDS after the node's counter moves: under load that
        takes longer than any fixed sleep), then a short settle so that an unexpected extra is heard."""
        counts = (len(self.say), len(self.display), len(self.goals), sum(self.node.executed.values()),
                  self.node.unknown)
        self.action.publish(cv.action_to_msg(action))
        assert wait_for(lambda: (sum(self.node.executed.values()), self.node.unknown) != counts[3:], 5.0,
                        self.executor)
        wanted = (counts[0] + says, counts[1] + displays, counts[2] + goals)
        assert wait_for(lambda: len(self.say) >= wanted[0] and len(self.display) >= wanted[1]
                        and len(self.goals) >= wanted[2], 5.0, self.executor), action
        wait_for(lambda: False, 0.05, self.executor)

    def close(self):
        self.executor.shutdown()
        self.node.destroy_node()
        self.probe.node.destroy_node()


@pytest.fixture
def rig_factory(ros_context):
    context, _ = ros_context
    rigs = []

    def make(overrides=None):
        rigs.append(Rig(context, overrides))
        return rigs[-1]

    yield make
    for r in rigs:
        r.close()


def test_with_no_parameters_every_action_does_what_the_params_file_says(rig_factory):
    expected = node_parameters("action_executor", PARAMS)
    rig = rig_factory()
    assert sorted(rig.node.behaviour) == sorted(expected["action_names"])
    assert rig.node.locations == {name: expected[f"locations.{name}"] for name in expected["location_names"]}
    for action in expected["action_names"]:
        before = (len(rig.say), len(rig.display), len(rig.goals))
        say, display, goal = (expected.get(f"actions.{action}.{k}", "") for k in ("say", "display", "goal"))
        rig.run(action, says=int(bool(say)), displays=int(bool(display)), goals=int(bool(goal)))
        assert len(rig.say) - before[0] == (1 if say else 0), action
        assert len(rig.display) - before[1] == (1 if display else 0), action
        assert len(rig.goals) - before[2] == (1 if goal else 0), action
        if say and "{" not in say:
            assert rig.say[-1].data == say
        if goal:
            pose = cv.msg_to_pose(rig.goals[-1])
            x, y, yaw = expected[f"locations.{goal}"]
            assert (pose["x"], pose["y"], pose["frame_id"]) == (x, y, "map")
            assert pose["yaw"] == pytest.approx(math.atan2(math.sin(yaw), math.cos(yaw)))
    assert rig.node.unknown == 0
    assert rig.node.executed == {a: 1 for a in expected["action_names"]}


def test_a_guidance_drives_to_physio_on_goal_pose(rig_factory):
    rig = rig_factory()
    rig.run("GuideToPhysio", says=1, goals=1)
    assert rig.say[-1].data == "Please follow me."
    pose = cv.msg_to_pose(rig.goals[-1])
    assert (pose["x"], pose["y"], pose["frame_id"]) == (21.0, -4.0, "map")
    assert pose["yaw"] == pytest.approx(3.1416 - 2 * math.pi if 3.1416 > math.pi else 3.1416)


def test_overrides_beat_the_file_and_an_empty_defaults_file_configures_nothing(rig_factory):
    rig = rig_factory({"actions.GuideToPhysio.say": "This way, please.", "locations.physio": [20.0, -3.0, 0.0]})
    rig.run("GuideToPhysio", says=1, goals=1)
    assert rig.say[-1].data == "This way, please."
    assert cv.msg_to_pose(rig.goals[-1])["x"] == 20.0
    bare = rig_factory({"defaults_file": ""})
    assert bare.node.behaviour == {} and bare.node.locations == {}
    bare.run("GuideToPhysio")
    assert bare.node.unknown == 1 and bare.node.executed == {}


@pytest.mark.parametrize("body, message", [
    ("action_executor:\n  ros__parameters:\n    location_names: home\n",
     "{f}: action_executor.location_names: expected a list of strings, got 'home'"),
    ("action_executor:\n  ros__parameters:\n    action_names: [Go]\n    actions:\n      Go: {sya: hello}\n",
     "{f}: action_executor.actions.Go.sya: unknown field 'sya' (expected one of say, display, goal)"),
    ("/**:\n  ros__parameters:\n    locations:\n      home: [0, 0, zero]\n    location_names: [home]\n",
     "{f}: action_executor.locations.home: expected a list of numbers, got [0, 0, 'zero']"),
    ("action_executor: [1, 2]\n", "parameter defaults_file: {f}:1: action_executor: expected {{ros__parameters: "
                                  "{{name: value, ...}}}}"),
])
def test_a_bad_defaults_file_is_one_clear_error(ros_context, tmp_path, body, message):
    context, _ = ros_context
    path = tmp_path / "bad.yaml"
    path.write_text(body)
    with pytest.raises(NodeSetupError) as err:
        ActionExecutorNode(context=context, parameter_overrides={"defaults_file": str(path)})
    assert str(err.value) == message.format(f=path)


def test_no_action_of_the_domain_is_named_in_the_executor():
    import yaml

    actions = yaml.safe_load(DOMAIN.read_text())["actions"]
    names = list(actions) if isinstance(actions, dict) else [a["name"] for a in actions]
    assert len(names) >= 19
    source = Path(ActionExecutorNode.__module__.replace(".", "/") + ".py")
    text = (REPO / source).read_text()
    assert [n for n in names if re.search(rf"\b{re.escape(n)}\b", text)] == []
