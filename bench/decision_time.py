"""Time per decision of the hierarchical policy (EXECUTE alone), at Pearl's size (one JSON object).

The policy decides along its own episodes in the flat model compiled from the domain
(:func:`pearl_pomdp.simulate.simulate` calls ``action(belief)`` once per step and episode, so
the beliefs are the ones a robot running this policy meets, in the order it meets them, and
the per-marginal cache works as it does on the robot). Each call's ``HierarchicalPolicy.execute``
is timed with ``time.perf_counter``. With ``--beliefs FILE.npy`` the beliefs are those of the file
instead (``bench/latency.py --mode inprocess --save-beliefs FILE.npy`` saves the ones its simulated
resident leads the policy node to, wide ones the per-marginal cache rarely serves), each decided
once at the policy's own root depth. Otherwise reported per root search depth (``--lookahead 0,1``: the
root's ``lookahead``, the children's offers searched that many more steps within
``--expansions`` expanded beliefs): p50/p90/p99/max/mean in ms and the expansions per decision
(``Decision.expansions``). Start-up (loading or planning the policy, compiling the model) is
reported apart and is not in the per-decision figures. Issue 21's target: p99 ≤ 2 ms.

    OMP_NUM_THREADS=1 .venv/bin/python bench/decision_time.py [--policy DIR] [--episodes 10]
        [--steps 100] [--lookahead 0,1] [--expansions 256] [--beliefs FILE.npy]
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))


class _TimedPolicy:
    """``action(belief)`` through ``execute``, recording each call's wall time and expansions."""

    def __init__(self, policy):
        self.policy = policy
        self.seconds: list[float] = []
        self.expansions: list[int] = []

    def action(self, belief) -> int:
        t0 = time.perf_counter()
        decision = self.policy.execute(belief)
        self.seconds.append(time.perf_counter() - t0)
        self.expansions.append(int(decision.expansions))
        return int(decision.action)


def main() -> int:
    import numpy as np

    from pearl_pomdp.hierarchy import load_hierarchical_policy, load_hierarchy, plan
    from pearl_pomdp.model.domain_yaml import load_domain
    from pearl_pomdp.simulate import simulate

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--domain", default=str(REPO / "config" / "pearl.domain.yaml"))
    ap.add_argument("--hierarchy", default=str(REPO / "config" / "pearl.hierarchy.yaml"))
    ap.add_argument("--policy", help="a saved plan (pearl plan --out DIR); planned here when omitted")
    ap.add_argument("--episodes", type=int, default=10)
    ap.add_argument("--steps", type=int, default=100)
    ap.add_argument("--lookahead", default="0,1", help="root search depths to time, comma-separated")
    ap.add_argument("--expansions", type=int, default=256, help="expanded beliefs per decision at depth > 0")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--beliefs", metavar="FILE.npy",
                    help="time EXECUTE on these beliefs ([N, S], e.g. bench/latency.py --mode inprocess "
                         "--save-beliefs: the resident's, wide ones the per-marginal cache rarely serves) "
                         "instead of the policy's own episodes; each once, in order, from a cold cache")
    args = ap.parse_args()

    t0 = time.perf_counter()
    domain = load_domain(args.domain)
    model = domain.compile()
    if args.policy:
        policy = load_hierarchical_policy(args.policy, domain)
        how = f"loaded {args.policy}"
    else:
        policy = plan(domain, load_hierarchy(args.hierarchy, domain))
        how = f"planned from {args.hierarchy}"
    startup = time.perf_counter() - t0
    root = policy.subtasks[policy.root]
    rows = []
    if args.beliefs:
        beliefs = np.load(args.beliefs)
        if beliefs.ndim != 2 or beliefs.shape[1] != model.num_states:
            ap.error(f"--beliefs {args.beliefs}: shape {beliefs.shape}, expected [N, {model.num_states}]")
        policy._pick_cache.clear()
        seconds = []
        for b in beliefs:
            t1 = time.perf_counter()
            policy.execute(b)
            seconds.append(time.perf_counter() - t1)
        ms = np.array(seconds) * 1000.0
        rows.append({"beliefs": args.beliefs, "decisions": int(ms.size),
                     "support_mean": round(float((beliefs > 0).sum(axis=1).mean()), 1),
                     "p50_ms": round(float(np.percentile(ms, 50)), 3), "p90_ms": round(float(np.percentile(ms, 90)), 3),
                     "p99_ms": round(float(np.percentile(ms, 99)), 3), "max_ms": round(float(ms.max()), 3),
                     "mean_ms": round(float(ms.mean()), 3)})
    for depth in ([] if args.beliefs else [int(d) for d in args.lookahead.split(",") if d]):
        root.search_depth, root.expansions = 1 + depth, args.expansions
        policy._pick_cache.clear()   # each depth starts cold, as a freshly started node does
        timed = _TimedPolicy(policy)
        sim = simulate(model, timed, episodes=args.episodes, steps=args.steps, seed=args.seed)
        ms = np.array(timed.seconds) * 1000.0
        ex = np.array(timed.expansions)
        rows.append({"lookahead": depth, "decisions": int(ms.size),
                     "p50_ms": round(float(np.percentile(ms, 50)), 3), "p90_ms": round(float(np.percentile(ms, 90)), 3),
                     "p99_ms": round(float(np.percentile(ms, 99)), 3), "max_ms": round(float(ms.max()), 3),
                     "mean_ms": round(float(ms.mean()), 3),
                     "expansions_mean": round(float(ex.mean()), 1), "expansions_max": int(ex.max()),
                     "return_mean": round(float(sim["mean"]), 3), "return_ci95": round(float(sim["ci95"]), 3)})
    out = {"bench": "decision_time", "domain": model.name, "states": model.num_states,
           "policy": how, "startup_seconds": round(startup, 2), "seed": args.seed,
           "episodes": args.episodes, "steps": args.steps, "expansions_budget": args.expansions,
           "depths": rows, "target_p99_ms": 2.0,
           "load_average_1min": round(os.getloadavg()[0], 2)}
    json.dump(out, sys.stdout)
    sys.stdout.write("\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
