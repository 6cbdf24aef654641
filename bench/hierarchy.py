"""Hierarchical vs flat planning on the Pearl domain (issue 4, item 9).

Plans ``config/pearl.domain.yaml`` with ``config/pearl.hierarchy.yaml`` (PLAN/SOLVE with
exact abstraction), and flat with the point-based solver (lower and upper bound), QMDP
and the most-likely-state policy; then simulates every policy over the same seeded
episodes (:func:`pearl_pomdp.simulate.simulate`: same seed → the same random stream for
every policy) and prints one JSON object: plan times, subtask sizes, mean discounted
return ± 95 % CI per policy, the paired per-episode differences hierarchical − other
(mean ± 95 % CI), the same hierarchical plan executed without lookahead (ablation, when
the hierarchy uses it), and the acceptance ratios (hierarchical ≥ 95 % of flat
point-based; better than QMDP and MLS).

    .venv/bin/python bench/hierarchy.py [--episodes 500] [--flat-time 60] [--seed 0]

Timings are wall-clock on a shared machine: compare within one run.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))


def summary(result: dict) -> dict:
    return {"mean": round(result["mean"], 4), "ci95": round(result["ci95"], 4), "std": round(result["std"], 4)}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--domain", default=str(REPO / "config" / "pearl.domain.yaml"))
    ap.add_argument("--hierarchy", default=str(REPO / "config" / "pearl.hierarchy.yaml"))
    ap.add_argument("--episodes", type=int, default=500)
    ap.add_argument("--steps", type=int, default=None, help="steps per episode (default: γ^T < 1e-3)")
    ap.add_argument("--flat-time", type=float, default=60.0, help="seconds for the flat point-based solver")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()

    from pearl_pomdp.hierarchy import load_hierarchy, plan
    from pearl_pomdp.model.domain_yaml import load_domain
    from pearl_pomdp.simulate import simulate
    from pearl_pomdp.solvers.mdp import most_likely_state_policy, solve_qmdp
    from pearl_pomdp.solvers.point_based import solve_point_based

    domain = load_domain(args.domain)
    model = domain.compile()
    hierarchy = load_hierarchy(args.hierarchy, domain)

    t0 = time.perf_counter()
    hp = plan(domain, hierarchy)
    hier_seconds = time.perf_counter() - t0
    # Ablation: the same plan executed without any subtask's forward search (EXECUTE by the
    # bare horizon-h vectors), to show what the lookahead contributes.
    bare = None
    if any(spec.lookahead for spec in hierarchy.subtasks.values()):
        bare = plan(domain, dataclasses.replace(hierarchy, subtasks={
            name: dataclasses.replace(spec, lookahead=0) for name, spec in hierarchy.subtasks.items()}))
    flat = solve_point_based(model, time_limit=args.flat_time, seed=args.seed)
    t1 = time.perf_counter()
    qmdp = solve_qmdp(model)
    qmdp_seconds = time.perf_counter() - t1
    mls = most_likely_state_policy(model)

    runs, returns = {}, {}
    policies = [("hierarchical", hp), ("flat_pointbased", flat.policy), ("qmdp", qmdp.policy),
                ("most_likely_state", mls)]
    if bare is not None:
        policies.append(("hierarchical_without_lookahead", bare))
    for name, policy in policies:
        result = simulate(model, policy, episodes=args.episodes, steps=args.steps, seed=args.seed)
        runs[name] = summary(result)
        returns[name] = result["returns"]
    # Episode i of every policy starts from the same seed stream, so the per-episode
    # differences are paired: their CI is the fair test of "better than".
    paired = {}
    for other in ("flat_pointbased", "qmdp", "most_likely_state"):
        diff = returns["hierarchical"] - returns[other]
        paired[f"hierarchical_minus_{other}"] = {
            "mean": round(float(diff.mean()), 4),
            "ci95": round(float(1.96 * diff.std(ddof=1) / np.sqrt(diff.size)), 4) if diff.size > 1 else None}
    h, f = runs["hierarchical"]["mean"], runs["flat_pointbased"]["mean"]
    out = {
        "domain": model.name, "states": model.num_states, "actions": model.num_actions,
        "observations": model.num_observations,
        "episodes": args.episodes, "seed": args.seed,
        "plan_seconds": {"hierarchical": round(hier_seconds, 3), "flat_pointbased": round(flat.seconds, 3),
                         "qmdp": round(qmdp_seconds, 3)},
        "subtasks": [{k: r[k] for k in ("name", "states_full", "states_abstract", "observations_full", "horizon", "lookahead",
                                        "observations_abstract", "actions", "solver", "exact", "alpha_vectors",
                                        "seconds", "relevant_features")} for r in hp.report["subtasks"]],
        "all_subtasks_exact": all(r["exact"] for r in hp.report["subtasks"]),
        "flat_bounds": {"lower": round(flat.value_at_start, 4),
                        "upper": None if flat.upper_bound is None else round(flat.upper_bound, 4)},
        "returns": runs,
        "paired_differences": paired,
        "hierarchical_over_flat": round(h / f, 4) if f > 0 else None,
        "acceptance": {
            "plan_under_2s": hier_seconds < 2.0,
            "hierarchical_ge_95pct_flat": (h >= 0.95 * f) if f > 0 else h >= f,
            "better_than_qmdp": h > runs["qmdp"]["mean"],
            "better_than_mls": h > runs["most_likely_state"]["mean"],
        },
        "load_average_1min": round(os.getloadavg()[0], 2),
    }
    json.dump(out, sys.stdout)
    sys.stdout.write("\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
