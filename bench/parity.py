"""Behaviour parity of two source trees (a refactor's check): the study's fast path on every
scenario file, a few seeds each, with the hierarchical policy, QMDP and the behaviour tree —
same actions, beliefs within 1e-12? — and on every scenario of the reception's and the ward's
study files with their trees and one POMDP controller (QMDP; DESPOT at 3 trials), the ward's
233,280-state beliefs compared by their digest at 12 decimals. Prints one JSON object; exit 1 on
any difference.

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
try:
    from pearl_sim.nursing_home.agents import Controller
    from pearl_sim.nursing_home.experiment import episode_executive
except ImportError:  # a tree from before the nursing home's study moved into its package
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

# The worlds of the frame: every scenario of their study files, the tree and one POMDP controller each
# (QMDP for the reception; DESPOT online at 3 trials for the ward, whose hierarchy takes ~16 s to plan).
import hashlib
import numpy as np
from pearl_pomdp.executive import Executive
from pearl_pomdp.online.decider import OnlineDecider
from pearl_pomdp.online.despot import DespotSettings
from pearl_sim.reception.behaviour_tree import ReceptionBehaviourTree
from pearl_sim.reception.scenario import load_reception_scenarios
from pearl_sim.reception.world import ReceptionWorld
from pearl_sim.ward.behaviour_tree import WardBehaviourTree
from pearl_sim.ward.scenario import load_ward_scenarios
from pearl_sim.ward.world import WardWorld
from pearl_sim.world_study import episode_settings

for name, load, make, tree_cls, pomdp in (
        ("reception", load_reception_scenarios, ReceptionWorld, ReceptionBehaviourTree,
         lambda m: Controller("qmdp", FlatPolicyDecider(solve(m, "qmdp").policy, m))),
        ("ward", load_ward_scenarios, WardWorld, WardBehaviourTree,
         lambda m: Controller("online:3", OnlineDecider(m, settings=DespotSettings(trials=3), seed=0)))):
    d = load_domain(tree / f"config/{name}.domain.yaml")
    m = d.compile()
    params = tree / f"config/{name}_nodes.yaml"
    for f in sorted(glob.glob(str(tree / f"config/scenarios/{name}/*.yaml"))):
        for sc in load(f):
            for seed in range(min(seeds, 2)):
                for agent in (tree_cls("behaviour_tree", list(m.actions)), pomdp(m)):
                    if hasattr(agent.decider, "reset"):
                        agent.decider.reset()
                    backend = ExecutiveBackend(Executive(m, agent.decider, domain=d, settings=episode_settings(sc, params)))
                    trace = run_episode(make(sc, seed=sc.seed + 1000 * seed), backend)
                    beliefs = backend.beliefs()
                    # A ward belief has 233,280 states: its digest at 12 decimals stands in for the vector.
                    res[f"{name}/{Path(f).name}:{sc.name}:{seed}:{agent.name}"] = {
                        "actions": trace.actions,
                        "beliefs": [b.tolist() for b in beliefs] if m.num_states <= 4096 else [],
                        "digests": [hashlib.sha256(np.round(b, 12).tobytes()).hexdigest() for b in beliefs]
                        if m.num_states > 4096 else []}
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
                       or len(a[k]["beliefs"]) != len(b[k]["beliefs"])
                       or a[k].get("digests", []) != b[k].get("digests", []))
    worst, beliefs = 0.0, 0
    for k in a:
        if k in b and k not in differing:
            for x, y in zip(a[k]["beliefs"], b[k]["beliefs"]):
                worst = max(worst, max(abs(u - v) for u, v in zip(x, y)))
                beliefs += 1
    digests = sum(len(a[k].get("digests", [])) for k in a if k not in differing)
    out = {"benchmark": "parity", "episodes": len(a), "beliefs_compared": beliefs, "max_belief_difference": worst,
           "belief_digests_compared": digests,
           "differing_episodes": differing[:20], "only_in_new": sorted(set(b) - set(a))[:20],
           "seconds": round(time.perf_counter() - t0, 1)}
    print(json.dumps(out))
    return 0 if not differing and worst <= 1e-12 and not out["only_in_new"] else 1


if __name__ == "__main__":
    sys.exit(main())
