"""docs/new-robot.md's worked example, exactly as written: the reception domain loads with its
three inputs and no Pearl name, its battery readings give the symbols the page says, its error
example is the loader's message, `pearl plan` plans it and `pearl launch` starts the nodes with
its files only."""
from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from pearl_pomdp.errors import SpecError
from pearl_pomdp.model.domain_yaml import load_domain
from pearl_pomdp.tracking import BeliefTracker, StepSettings

REPO = Path(__file__).resolve().parents[1]
DOC = (REPO / "docs" / "new-robot.md").read_text()
BIN = Path(sys.executable).parent
BLOCKS = re.findall(r"```yaml\n(.*?)```", DOC, flags=re.S)
DOMAIN, PARAMS, REMAP = BLOCKS
#: Names of Pearl's domain and robot that a second robot's files must not need.
PEARL_NAMES = ("navFailed", "RobotLocation", "UserLocation", "physio", "Physio", "userLost", "atHome", "t_yes",
               "g_none", "pearl", "GuideTo", "Remind")


@pytest.fixture
def files(tmp_path):
    (tmp_path / "reception.domain.yaml").write_text(DOMAIN)
    (tmp_path / "reception_nodes.yaml").write_text(PARAMS)
    return tmp_path


def test_the_domain_loads_with_its_inputs_and_no_pearl_name(files):
    d = load_domain(files / "reception.domain.yaml")
    assert [(c.name, c.kind, c.topic) for c in d.inputs] == [
        ("presence", "symbol", "/reception/person"), ("voice", "speech", "/reception/speech"),
        ("charge", "number", "/battery_state")]
    assert d.compile().num_states == 6 and d.silence_symbol == "unheard"
    for name in PEARL_NAMES:
        assert name not in DOMAIN and name not in PARAMS, name
    params = yaml.safe_load(PARAMS)
    assert params["action_executor"]["ros__parameters"]["action_names"] == d.actions
    assert yaml.safe_load(REMAP)["belief_tracker"]["ros__parameters"]["inputs"]["charge"]["topic"] == \
        "/base/battery_state"


def test_the_battery_readings_give_what_the_page_says(files):
    d = load_domain(files / "reception.domain.yaml")
    t = BeliefTracker(d.compile(), d, StepSettings(step_timeout=0.0))
    said = []
    for reading in (0.60, 0.24, 0.21, 0.19, 0.28, 0.31):
        t.on_action("Wait", 0.0)
        out = t.on_input("charge", reading, 0.0)
        said.append(out.closed.observation if out.closed is not None else None)
        if out.closed is None:
            t.abandon_step()
    assert said == ["charge_ok", None, None, "charge_low", None, "charge_ok"]
    assert "0.60, 0.24, 0.21, 0.19, 0.28, 0.31 give `charge_ok`" in DOC


def test_the_error_example_is_the_loaders_message(files):
    broken = files / "reception.domain.yaml"
    broken.write_text(DOMAIN.replace("charge_ok: [0.25, 1.0]", "charge_ok: [0.3, 1.0]"))
    with pytest.raises(SpecError) as err:
        load_domain(broken)
    shown = next(line for line in DOC.splitlines() if line.startswith("reception.domain.yaml:"))
    assert str(err.value).replace(str(files) + "/", "") == shown


def test_pearl_plan_and_pearl_launch_take_the_files_as_written(files):
    plan = subprocess.run([str(BIN / "pearl"), "plan", "reception.domain.yaml", "--flat", "--out",
                           "out/policies/reception", "--json"], cwd=files, capture_output=True, text=True, timeout=120)
    assert plan.returncode == 0, plan.stderr
    report = json.loads(plan.stdout)
    assert report["hierarchy_file"] is None and (files / "out" / "policies" / "reception").is_dir()
    command = next(line for line in DOC.splitlines() if line.startswith("$ pearl launch"))
    args = command.split("launch/pearl.launch.xml")[1].replace("\\", "").split() + \
        next(line for line in DOC.splitlines() if "params_file:=reception_nodes.yaml" in line).split()
    args = [a for a in args if ":=" in a]
    launch = subprocess.run([str(BIN / "pearl"), "launch", str(REPO / "launch" / "pearl.launch.xml"), *args,
                             "--print"], cwd=files, capture_output=True, text=True, timeout=60)
    assert launch.returncode == 0, launch.stderr
    nodes = json.loads(launch.stdout)["nodes"]
    assert [n["name"] for n in nodes] == ["belief_tracker", "hierarchical_policy", "action_executor",
                                          "lifecycle_supervisor"]
    for node in nodes[:3]:   # the supervisor takes no robot's values: only the node names it brings up
        files_given = [node["command"][i + 1] for i, a in enumerate(node["command"]) if a == "--params-file"]
        params = str(files / "reception_nodes.yaml")
        assert files_given[0] == params
        written = yaml.safe_load(Path(files_given[1]).read_text())[f"/{node['name']}"]["ros__parameters"]
        # No Pearl params file behind it: the node reads the same file for its defaults.
        assert (files / written["defaults_file"]).resolve() == Path(params).resolve()
