"""The reception robot end to end: ``pearl demo`` and ``pearl experiment`` with
``--domain config/reception.domain.yaml`` run and report; the demo through the ROS graph takes the
same actions as the study's fast path (one loop); and nothing of the nursing-home robot is needed:
the run opens none of its files, imports none of its world's modules, and neither the reception
sources, its config nor anything the run writes holds a name of config/pearl.domain.yaml."""
from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
from ros_helpers import allocate_domain_id, ros_env  # noqa: E402

from pearl_pomdp.model.domain_yaml import load_domain  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
DOMAIN = REPO / "config" / "reception.domain.yaml"
PARAMS = REPO / "config" / "reception_nodes.yaml"
SCENARIO = REPO / "config" / "scenarios" / "reception" / "one_visitor.yaml"
#: Words of Pearl's domain that are ordinary English, or the reception domain's own as well.
GENERIC = {"home", "room", "time", "weather", "go", "unknown", "yes", "no", "none", "ok", "low", "Battery"}
#: The nursing home's modules: a reception run must not need them.
PEARL_MODULES = ("pearl_sim.nursing_home.world", "pearl_sim.nursing_home.scenario", "pearl_sim.nursing_home.residents", "pearl_sim.nursing_home.behaviour_tree",
                 "pearl_sim.nursing_home.agents", "pearl_sim.nursing_home.experiment", "pearl_sim.nursing_home.study", "pearl_sim.nursing_home.demo")
PEARL_FILES = ("pearl.domain.yaml", "pearl.hierarchy.yaml", "pearl_nodes.yaml", "scenarios/study.yaml",
               "scenarios/figure4.yaml")

_RUN = r'''
import os, sys, json
opened = set()
def hook(event, args):
    if event == "open" and isinstance(args[0], (str, os.PathLike)):
        opened.add(os.path.abspath(os.fspath(args[0])))
sys.addaudithook(hook)
from pearl_pomdp.cli import main
domain, policy, out, domain_id, report = sys.argv[1:6]
codes = [main(["demo", "--domain", domain, "--policy", policy, "--out", out + "/demo", "--json",
               "--domain-id", domain_id]),
         main(["experiment", "--domain", domain, "--episodes", "1", "--noise", "0.2",
               "--policies", "qmdp,behaviour_tree", "--out", out + "/study", "--json"])]
json.dump({"codes": codes, "opened": sorted(opened), "modules": sorted(sys.modules)}, open(report, "w"))
'''


def pearl_vocabulary() -> set:
    """Every name of config/pearl.domain.yaml (features, values, actions, modalities, symbols) that is
    neither ordinary English nor a name of the reception domain (its keywords are English phrases:
    "clock", "walk")."""
    pearl, reception = load_domain(REPO / "config/pearl.domain.yaml"), load_domain(DOMAIN)

    def names(d) -> set:
        out = {f.name for f in d.features} | {v for f in d.features for v in f.values} | set(d.actions)
        return out | {z for syms in d.modalities.values() for z in syms} | set(d.modalities)

    return names(pearl) - names(reception) - GENERIC


@pytest.fixture(scope="module")
def policy(tmp_path_factory):
    from pearl_pomdp.hierarchy import load_hierarchy, plan

    domain = load_domain(DOMAIN)
    return plan(domain, load_hierarchy(REPO / "config/reception.hierarchy.yaml", domain)).save(
        tmp_path_factory.mktemp("reception") / "policy")


@pytest.fixture(scope="module")
def run(tmp_path_factory, policy):
    """``pearl demo`` and ``pearl experiment`` on the reception domain, in a fresh interpreter that
    records every file it opens and every module it imports."""
    out = tmp_path_factory.mktemp("run")
    report = out / "report.json"
    domain_id = allocate_domain_id()
    proc = subprocess.run([sys.executable, "-c", _RUN, str(DOMAIN), str(policy), str(out), str(domain_id),
                           str(report)], env=ros_env(domain_id, out), cwd=str(out), capture_output=True, text=True,
                          timeout=240)
    assert proc.returncode == 0, proc.stderr[-3000:]
    lines = [json.loads(line) for line in proc.stdout.splitlines() if line.startswith("{")]
    return {"out": out, "demo": lines[0], "study": lines[1], **json.loads(report.read_text())}


def test_the_vocabulary_is_pearls_own():
    words = pearl_vocabulary()
    assert {"RobotLocation", "GuideToPhysio", "physio", "navFailed", "userLost", "RemindPhysioAppt",
            "toPhysioWithRobot", "g_physio", "t_go", "DoNothing"} <= words
    assert not words & {"Wait", "Greet", "gallery", "Visitor", "unheard"}


def test_the_demo_runs_through_the_graph_and_reports(run):
    demo = run["demo"]
    assert run["codes"] == [0, 0]
    assert demo["world"] == "reception" and demo["steps"] == 16 and demo["bag_messages"] > 100
    assert demo["served_all"] and demo["visitors_served"] == 1 and demo["outcome"].startswith(
        "outcome: 1/1 visitor(s) handed over where they wanted to go")
    assert (run["out"] / "demo" / "bag").is_dir() and (run["out"] / "demo" / "transcript.txt").is_file()


def test_the_demo_takes_the_study_loops_actions(run, policy):
    """One loop: the graph over DDS and the core executive give the same actions for the same seed."""
    from pearl_pomdp.hierarchy import load_hierarchical_policy
    from pearl_sim.planning import Controller
    from pearl_sim.reception.scenario import load_reception_scenarios
    from pearl_sim.reception.study import run_reception_episode

    domain = load_domain(DOMAIN)
    scenario = load_reception_scenarios(SCENARIO)[0]
    fast = run_reception_episode(scenario, Controller("hierarchical", load_hierarchical_policy(policy, domain)), domain,
                                 PARAMS)
    assert fast.actions == run["demo"]["actions"]
    assert fast.visitors_served == run["demo"]["visitors_served"]


def test_the_experiment_reports_paired_differences_that_recompute(run):
    from pearl_sim.reception.study import BASELINE

    study = json.loads((run["out"] / "study" / "study.json").read_text())
    assert study["protocol"]["episodes"] == 6 * 2 and study["protocol"]["baseline"] == BASELINE
    rows = {(e["policy"], e["scenario"]): e for e in study["episodes"]}
    diffs = [rows[("qmdp", s)]["discounted_return"] - rows[(BASELINE, s)]["discounted_return"]
             for (p, s) in rows if p == "qmdp"]
    paired = run["study"]["paired_vs_baseline"]["qmdp"]["0.2"]["discounted_return"]
    assert paired["n"] == 6 and paired["mean"] == pytest.approx(sum(diffs) / 6, abs=1e-12)
    tree = run["study"]["per_policy"][BASELINE]["0.2"]
    assert tree["success_rate"]["successes"] == sum(rows[(BASELINE, s)]["success"] for (p, s) in rows if p == BASELINE)


def test_the_run_needs_nothing_of_the_nursing_home(run):
    assert not [m for m in run["modules"] if m in PEARL_MODULES]
    repo_files = [f for f in run["opened"] if f.startswith(str(REPO))]
    assert not [f for f in repo_files if f.endswith(PEARL_FILES)]
    assert str(PARAMS) in repo_files and str(SCENARIO) in repo_files


def test_no_pearl_name_in_the_reception_sources_config_or_output(run):
    words = pearl_vocabulary()
    pattern = re.compile(r"(?<![A-Za-z0-9_])(" + "|".join(sorted(map(re.escape, words), key=len, reverse=True))
                         + r")(?![A-Za-z0-9_])")
    checked = [*sorted((REPO / "pearl_sim" / "reception").glob("*.py")), REPO / "pearl_sim" / "loop.py",
               REPO / "pearl_sim" / "messages.py", REPO / "pearl_sim" / "planning.py",
               REPO / "pearl_sim" / "world_study.py", REPO / "pearl_sim" / "world_scenario.py",
               REPO / "pearl_sim" / "world_base.py", REPO / "pearl_sim" / "world_tree.py", DOMAIN, PARAMS,
               REPO / "config" / "reception.hierarchy.yaml", *sorted((REPO / "config/scenarios/reception").glob("*"))]
    checked += [p for p in run["out"].rglob("*") if p.is_file() and p.name != "report.json"]
    assert len(checked) > 15
    found = {}
    for path in checked:
        text = path.read_bytes().decode("utf-8", errors="replace")
        hits = sorted(set(pattern.findall(text)))
        if hits:
            found[str(path)] = hits
    assert found == {}


def test_a_domain_without_a_world_is_one_clear_error(tmp_path, capsys):
    from pearl_pomdp.cli import main

    other = tmp_path / "kiosk.domain.yaml"
    other.write_text(DOMAIN.read_text().replace("name: reception", "name: kiosk"))
    for command in ("experiment", "demo"):
        assert main([command, "--domain", str(other)]) == 2
        assert capsys.readouterr().err.startswith(
            f"pearl {command}: error: {other}: name: no simulated world for domain 'kiosk' (worlds: pearl: ")


@pytest.mark.parametrize("args, message", [
    (["--snr", "20"], "--snr: the reception world has the word-error recogniser only; use --noise"),
    (["--residents", "paper"], "--residents: the reception world's visitors are in its study file (--study)"),
    (["--noise", "0.2,1.5"], "--noise: '0.2,1.5': word error rates in [0, 1] are needed"),
    (["--policies", "qmdp,scripted"], "--policies: 'scripted': the reception world compares behaviour_tree, "
                                      "flat_pointbased, hierarchical, most_likely_state, qmdp"),
])
def test_the_nursing_home_only_options_are_refused_by_name(args, message, capsys):
    from pearl_pomdp.cli import main

    assert main(["experiment", "--domain", str(DOMAIN), *args]) == 2
    assert capsys.readouterr().err.strip() == f"pearl experiment: error: <command line>: {message}"


def test_the_demos_bag_replays_by_the_reception_robots_rules(run):
    """The bag keeps the domain, the policy and the node params beside it: `pearl replay` runs the
    tracker by config/reception_nodes.yaml's rules and takes the recorded actions again."""
    proc = subprocess.run([str(Path(sys.executable).parent / "pearl"), "replay", str(run["out"] / "demo" / "bag"),
                           "--json"], env=ros_env(allocate_domain_id(), run["out"]), capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode == 0, proc.stderr[-2000:]
    report = json.loads(proc.stdout)
    # The recorded actions include the policy's answer to the last belief (one more than the world carried out).
    assert report["match"] is True and report["beliefs_match"] is True and report["actions"] == report["expected_actions"]
    assert report["actions"][:len(run["demo"]["actions"])] == run["demo"]["actions"]
    # The bag holds b0 itself (latched with depth 1: the demo waits until the recorder has it).
    from pearl_pomdp.bags.reader import BagReader
    from pearl_pomdp.model.domain_yaml import load_domain
    from pearl_pomdp.nodes.bag_replay import recorded_beliefs

    first = recorded_beliefs(BagReader(run["out"] / "demo" / "bag"))[0]
    assert max(abs(x - y) for x, y in zip(first, load_domain(DOMAIN).compile().b0)) < 1e-12
