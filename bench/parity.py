"""Behaviour parity of two source trees (a refactor's check): the study's fast path on every
scenario file, a few seeds each, with the hierarchical policy, QMDP and the behaviour tree —
same actions, beliefs within 1e-12? Prints one JSON object; exit 1 on any difference.

    .venv/bin/python bench/parity.py OLD_TREE NEW_TREE [--seeds 3]

Each tree runs in its own interpreter with the tree first on ``PYTHONPATH`` (build its C
kernels in place first: ``python setup.py build_ext --inplace`` in a plain clone). Both use
the hierarchical policy saved in ``bags/pearl`` of the first tree, so planning is not compared.
Recogniser-channel scenarios (pocketsphinx) are left out. The issue-22 tracker refactor:
189 episodes, 9,378 beliefs, max |difference| 0 against the tree before it.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

#: Runs inside each tree's interpreter: argv = tree, policy dir, seeds, output file.
_RUN = r'''
import glob, json, sys
from pathlib import Path
tree, policy_dir, seeds, out = Path(sys.argv[1]), Path(sys.argv[2]), int(sys.argv[3]), sys.argv[4]
import pearl_pomdp
assert Path(pearl_pomdp.__file__).resolve().is_relative_to(tree.resolve()), pearl_pomdp.__file__
try:
    from pearl_pomdp.policies import FlatPolicyDecider
except ImportError:  # a tree from before the policies package
    from pearl_pomdp.executive import FlatPolicyDecider
from pearl_pomdp.hierarchy import load_hierarchical_policy
try:
    from pearl_pomdp.model.domain_yaml import load_domain
except ImportError:  # a tree from before the domain YAML reader had its own module
    from pearl_pomdp.model.factored import load_domain
from pearl_pomdp.solvers.registry import solve
from pearl_sim.agents import Controller
from pearl_sim.experiment import episode_executive
from pearl_sim.loop import ExecutiveBackend, run_episode
try:
    from pearl_sim.nursing_home.behaviour_tree import PearlBehaviourTree
    from pearl_sim.nursing_home.scenario import load_scenarios
    from pearl_sim.nursing_home.world import World
except ImportError:  # a tree from before the nursing home had its own package
    from pearl_sim.behaviour_tree import PearlBehaviourTree
    from pearl_sim.scenario import load_scenarios
    from pearl_sim.world import World
domain = load_domain(policy_dir.parent / "domain.yaml")
model = domain.compile()
agents = [Controller("hierarchical", load_hierarchical_policy(policy_dir, domain)),
          Controller("qmdp", FlatPolicyDecider(solve(model, "qmdp").policy, model)),
          PearlBehaviourTree("behaviour_tree", list(model.actions))]
files = sorted(glob.glob(str(tree / "config/scenarios/*.yaml")) + glob.glob(str(tree / "test/data/scenarios/*.yaml"))
               + glob.glob(str(tree / "test/data/scenarios/fresh/*.yaml")))
res = {}
for f in files:
    for sc in load_scenarios(f):
        if sc.speech.get("channel") == "recogniser":
            continue
        for seed in range(seeds):
            for agent in agents:
                backend = ExecutiveBackend(episode_executive(agent, domain, sc))
                trace = run_episode(World(sc, seed=seed, domain=domain), backend)
                res[f"{Path(f).name}:{sc.name}:{seed}:{agent.name}"] = {
                    "actions": trace.actions, "beliefs": [b.tolist() for b in backend.beliefs()]}
json.dump(res, open(out, "w"))
'''


def run(tree: Path, policy: Path, seeds: int, out: Path) -> dict:
    env = {**os.environ, "PYTHONPATH": str(tree) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    subprocess.run([sys.executable, "-c", _RUN, str(tree), str(policy), str(seeds), str(out)], env=env, check=True,
                   cwd=tree)
    return json.loads(out.read_text())


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("old", type=Path)
    ap.add_argument("new", type=Path)
    ap.add_argument("--seeds", type=int, default=3)
    args = ap.parse_args()
    policy = (args.old / "bags" / "pearl" / "policy").resolve()
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        a = run(args.old.resolve(), policy, args.seeds, Path(tmp) / "old.json")
        b = run(args.new.resolve(), policy, args.seeds, Path(tmp) / "new.json")
    differing = sorted(k for k in a if k not in b or a[k]["actions"] != b[k]["actions"]
                       or len(a[k]["beliefs"]) != len(b[k]["beliefs"]))
    worst, beliefs = 0.0, 0
    for k in a:
        if k in b and k not in differing:
            for x, y in zip(a[k]["beliefs"], b[k]["beliefs"]):
                worst = max(worst, max(abs(u - v) for u, v in zip(x, y)))
                beliefs += 1
    out = {"benchmark": "parity", "episodes": len(a), "beliefs_compared": beliefs, "max_belief_difference": worst,
           "differing_episodes": differing[:20], "only_in_new": sorted(set(b) - set(a))[:20],
           "seconds": round(time.perf_counter() - t0, 1)}
    print(json.dumps(out))
    return 0 if not differing and worst <= 1e-12 and not out["only_in_new"] else 1


if __name__ == "__main__":
    sys.exit(main())
