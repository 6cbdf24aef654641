#!/usr/bin/env python3
"""Regenerate the recorded scenarios in bags/ from the simulated world through the Pearl nodes.

For each scenario this script runs ``pearl demo`` (pearl_sim/nursing_home/demo.py): the belief tracker,
hierarchical policy and action executor as real rclpy nodes over DDS with the simulated
hardware nodes, in one process under sim time, the world of ``pearl_sim`` answering every
action. The demo's bag carries every input, action, decision and belief, and the world's
true state on ``/pearl/sim/truth`` (what ``pearl fit`` counts from). The bag is then
rewritten into ``bags/<name>/`` with its replay configuration pointing at ``bags/pearl/``
(a snapshot of the domain, hierarchy and planned policy, so the bags stay replayable when
``config/`` evolves), and ``bags/<name>.expected.json`` lists the actions seen live.

``bags/README.md`` states, per bag, what it shows in a form ``test/test_bag_claims.py``
checks against the bag's replay (actions in order, the true state at each RingDoorBell).

Scenarios:

* ``figure4_guidance`` — ``config/scenarios/figure4.yaml``: the paper's Figure 4, from the
  reminder to the answered weather question.
* ``table4_clarification`` — ``config/scenarios/table4_dialog.yaml``: the checklist, then
  mumbled information requests (45 % word errors) that call for clarification.

Run from the repository root:
    .venv/bin/python bags/record_scenarios.py [--only NAME] [--replan]
"""
from __future__ import annotations

import argparse
import json
import shutil
import sys
import tempfile
from pathlib import Path
from typing import Dict, List, Optional

REPO = Path(__file__).resolve().parents[1]
BAGS = REPO / "bags"
PEARL = BAGS / "pearl"

#: bag name → (scenario file, one-line description).
SCENARIOS: Dict[str, tuple] = {
    "figure4_guidance": ("config/scenarios/figure4.yaml",
                         "Figure 4: reminder, contact, guidance of a slow resident, weather question"),
    "table4_clarification": ("config/scenarios/table4_dialog.yaml",
                             "Table 4-style dialog: checklist, then mumbled information requests and clarifications"),
}


def ensure_policy(replan: bool) -> None:
    """Plan bags/pearl/policy from a snapshot of config/'s domain + hierarchy unless it exists."""
    if (PEARL / "policy").is_dir() and not replan:
        return
    from pearl_pomdp.hierarchy import load_hierarchy, plan
    from pearl_pomdp.model.domain_yaml import load_domain

    PEARL.mkdir(parents=True, exist_ok=True)
    shutil.copy(REPO / "config" / "pearl.domain.yaml", PEARL / "domain.yaml")
    shutil.copy(REPO / "config" / "pearl.hierarchy.yaml", PEARL / "hierarchy.yaml")
    domain = load_domain(PEARL / "domain.yaml")
    print("planning bags/pearl/policy ...", file=sys.stderr)
    policy = plan(domain, load_hierarchy(PEARL / "hierarchy.yaml", domain))
    if (PEARL / "policy").exists():
        shutil.rmtree(PEARL / "policy")
    policy.save(PEARL / "policy")


def rewrite_bag(src: Path, dst: Path, name: str) -> None:
    """Copy bag ``src`` to ``dst`` (every topic, QoS and message as recorded) with its replay
    configuration pointing at ``bags/pearl/``."""
    from pearl_pomdp.bags.reader import BagReader
    from pearl_pomdp.bags.writer import BagWriter

    reader = BagReader(src, salvage=False)
    custom = dict((reader.metadata or {}).get("custom_data") or {})
    custom.update({"pearl.domain": "../pearl/domain.yaml", "pearl.policy": "../pearl/policy",
                   "pearl.scenario": name,
                   "scenario": str(Path(custom.get("scenario", "")).resolve().relative_to(REPO))})
    if dst.exists():
        shutil.rmtree(dst)
    with BagWriter(dst, custom_data=custom) as out:
        for topic, info in reader.topics.items():
            out.add_topic(topic, info.type, qos=info.offered_qos_profiles)
        for m in reader.messages:
            out.write(m.topic, m.data, m.log_time, m.publish_time, m.sequence)


def record(name: str, scenario: str, domain_id: Optional[int]) -> List[str]:
    """Run the demo of ``scenario`` with bags/pearl's policy; write bags/<name>; return its actions."""
    from pearl_sim.nursing_home.demo import run_demo

    with tempfile.TemporaryDirectory(prefix=f"pearl_{name}_") as tmp:
        result = run_demo(REPO / scenario, Path(tmp) / "out", domain_path=PEARL / "domain.yaml",
                          hierarchy_path=PEARL / "hierarchy.yaml", policy=str(PEARL / "policy"),
                          domain_id=domain_id)
        rewrite_bag(result.bag, BAGS / name, name)
        print(f"  {name}: {result.outcome()}", file=sys.stderr)
        return [s.action for s in result.steps]


def main(argv: Optional[List[str]] = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--only", choices=sorted(SCENARIOS), help="record one scenario")
    ap.add_argument("--replan", action="store_true", help="snapshot config/ into bags/pearl and plan again")
    ap.add_argument("--domain-id", type=int, help="ROS domain of the in-process graph (default: ROS_DOMAIN_ID)")
    args = ap.parse_args(argv)
    ensure_policy(args.replan)
    from pearl_pomdp.bags.reader import BagReader
    from pearl_pomdp.nodes.bag_replay import expected_actions

    for name, (scenario, doc) in SCENARIOS.items():
        if args.only and name != args.only:
            continue
        actions = record(name, scenario, args.domain_id)
        recorded = expected_actions(BagReader(BAGS / name, salvage=False))
        # The bag also holds the policy's answer to the last step's observation.
        if recorded[:len(actions)] != actions or len(recorded) > len(actions) + 1:
            print(f"{name}: the bag's /pearl/action ({len(recorded)}) differs from the demo's steps "
                  f"({len(actions)}): {recorded} vs {actions}", file=sys.stderr)
            return 1
        (BAGS / f"{name}.expected.json").write_text(json.dumps(
            {"scenario": name, "source": scenario, "description": doc, "expected_actions": recorded}, indent=1) + "\n")
        print(f"{name}: {len(recorded)} actions recorded in bags/{name}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
