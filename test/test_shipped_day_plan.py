"""The shipped plan of the working day's domain (config/plans/pearl_day) is the plan of the shipped day
domain, and `pearl day` uses it only where it applies."""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

from pearl_pomdp.hierarchy import load_hierarchical_policy
from pearl_pomdp.model.domain_yaml import load_domain
from pearl_sim.cli import day as day_cli

REPO = Path(__file__).resolve().parents[1]
DAY_DOMAIN = REPO / "config" / "pearl_day.domain.yaml"
HIERARCHY = REPO / "config" / "pearl.hierarchy.yaml"
SHIPPED = REPO / day_cli.SHIPPED_DAY_PLAN


def test_the_shipped_plan_was_planned_for_the_shipped_day_domain():
    # Fails after the day domain is refitted or edited without planning again; the fix:
    #   pearl plan config/pearl_day.domain.yaml --out config/plans/pearl_day
    domain = load_domain(DAY_DOMAIN)
    policy = load_hierarchical_policy(SHIPPED, domain)
    assert policy.root == "Act" and set(policy.subtasks) == {"Act", "Remind", "Contact", "Move", "Inform", "Assist", "Rest"}


def _args(**changes):
    base = dict(policy_dir="", domain=str(DAY_DOMAIN), hierarchy=str(HIERARCHY))
    return argparse.Namespace(**{**base, **changes})


def test_pearl_day_takes_the_shipped_plan_only_for_the_shipped_domain_and_hierarchy(tmp_path):
    domain = load_domain(DAY_DOMAIN)
    assert day_cli._planned_policy_dir(_args(), domain) == SHIPPED
    other = tmp_path / "my.hierarchy.yaml"
    other.write_text(HIERARCHY.read_text())
    assert day_cli._planned_policy_dir(_args(hierarchy=str(other)), domain) is None
    # A domain the plan is not for (Pearl's episode domain given as the day's): planned now.
    assert day_cli._planned_policy_dir(_args(), load_domain(REPO / "config" / "pearl.domain.yaml")) is None
    assert day_cli._planned_policy_dir(_args(policy_dir=str(tmp_path)), domain) == tmp_path


def test_pearl_day_runs_the_hierarchy_without_planning(tmp_path):
    done = subprocess.run([sys.executable, "-c", "import sys; from pearl_pomdp.cli import main; sys.exit(main())", "day", "--seed", "3", "--until", "09:00",
                           "--json", "--out", str(tmp_path / "day")], capture_output=True, text=True, timeout=300,
                          cwd=tmp_path)
    assert done.returncode == 0, done.stderr[-3000:]
    report = json.loads(done.stdout)
    assert report["policy"] == "hierarchical" and report["checklist"]["steps"] > 0
    # Planning the 864-state day hierarchy takes 50+ s of CPU; loading the shipped plan under a second.
    assert report["seconds"] < 40, report["seconds"]
