"""The hierarchy's planning budget against its value in the flat model (one JSON object, a PNG).

For each root trial budget in ``--budgets`` the Pearl hierarchy is planned policy-contingent
(``config/pearl.hierarchy.yaml`` with the root's ``trials`` replaced), and its policy as
executed is valued in the flat model compiled from the domain
(:func:`pearl_pomdp.evaluation.evaluate_policies`: the same ``--episodes`` seeded episodes for
every policy, CRN and the MDP-value control variate). Beside them: the eq. 15–17 plan of the
previous hierarchy file (``--corner-hierarchy``, when given), QMDP, and the flat point-based
solve of ``bench/flat_gap.py`` (``--flat-time`` seconds, its LB and UB at b0, its vectors
valued too). Printed: per budget the plan time (whole plan; the root's solve separately), the
value ± 95 % CI and its paired difference with the flat point-based policy, the fraction of the
flat LB, and the gap to the UB. ``--png`` draws value and plan time against the budget.

    OMP_NUM_THREADS=1 .venv/bin/python bench/hierarchy_quality.py [--budgets 10,30,60,100,200,400]
        [--episodes 2000] [--flat-time 120] [--png docs/hierarchy-quality.png]
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import os
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "bench"))


def main() -> int:
    import numpy as np

    from flat_gap import flat_bounds
    from pearl_pomdp.evaluation import evaluate_policies
    from pearl_pomdp.hierarchy import load_hierarchy, plan
    from pearl_pomdp.model.domain_yaml import load_domain
    from pearl_pomdp.solution import AlphaVectorPolicy
    from pearl_pomdp.solvers.mdp import solve_qmdp

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--domain", default=str(REPO / "config" / "pearl.domain.yaml"))
    ap.add_argument("--hierarchy", default=str(REPO / "config" / "pearl.hierarchy.yaml"))
    ap.add_argument("--corner-hierarchy", help="an eq. 15-17 hierarchy file to value beside (e.g. the previous one)")
    ap.add_argument("--budgets", default="10,30,60,100,200,400", help="root trial budgets, comma-separated")
    ap.add_argument("--episodes", type=int, default=2000)
    ap.add_argument("--flat-time", type=float, default=120.0)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--png", help="draw value and plan time against the budget here")
    ap.add_argument("--progress", action="store_true")
    args = ap.parse_args()

    def note(msg):
        if args.progress:
            print(f"hierarchy_quality: {msg}", file=sys.stderr, flush=True)

    load = os.getloadavg()[0]
    domain = load_domain(args.domain)
    model = domain.compile()
    hierarchy = load_hierarchy(args.hierarchy, domain)
    budgets = [int(b) for b in args.budgets.split(",") if b]
    plans, policies = {}, {}
    for b in budgets:
        root = dataclasses.replace(hierarchy.subtasks[hierarchy.root], trials=b)
        h = dataclasses.replace(hierarchy, subtasks={**hierarchy.subtasks, hierarchy.root: root})
        t0 = time.perf_counter()
        hp = plan(domain, h, seed=args.seed)
        seconds = time.perf_counter() - t0
        info = hp.report["subtasks"][-1]
        plans[b] = {"plan_seconds": round(seconds, 2), "root_solve_seconds": round(info["solve_seconds"], 2),
                    "root_lb": round(info["value_at_start"], 4), "root_ub": round(info["upper_bound"], 4)}
        policies[f"trials_{b}"] = hp
        note(f"budget {b}: planned in {seconds:.1f} s (root LB {info['value_at_start']:.3f})")
    corner = None
    if args.corner_hierarchy:
        t0 = time.perf_counter()
        policies["corner"] = plan(domain, load_hierarchy(args.corner_hierarchy, domain), seed=args.seed)
        corner = round(time.perf_counter() - t0, 2)
    qmdp = solve_qmdp(model)
    policies["qmdp"] = qmdp.policy
    solver, after_trials, refine, _setup, flat_seconds = flat_bounds(
        model, [policies[f"trials_{budgets[-1]}"], qmdp.policy], time_limit=args.flat_time, seed=args.seed, note=note)
    lb, ub = solver.bounds_at_start()
    policies["flat_pointbased"] = AlphaVectorPolicy(solver.GT[:, : solver.K].T.copy(), solver.gact[: solver.K].copy())
    evals = evaluate_policies(model, policies, episodes=args.episodes, seed=args.seed, progress=args.progress)
    flat = evals["flat_pointbased"]["values"]

    def row(name):
        r = evals[name]
        d = r["values"] - flat
        return {"value": round(r["mean"], 4), "ci95": round(r["ci95"], 4), "lower": round(r["lower"], 4),
                "upper": round(r["upper"], 4),
                "paired_minus_flat": {"mean": round(float(d.mean()), 4),
                                      "ci95": round(float(1.96 * d.std(ddof=1) / np.sqrt(d.size)), 4)},
                "fraction_of_flat_lb": round(r["mean"] / lb, 4), "gap_to_ub": round(ub - r["mean"], 4)}

    out = {
        "bench": "hierarchy_quality", "domain": model.name, "episodes": args.episodes, "seed": args.seed,
        "flat": {"lb": round(lb, 4), "ub": round(ub, 4), "seconds": round(flat_seconds, 1),
                 "after_trials": [round(x, 4) for x in after_trials], "policy": row("flat_pointbased")},
        "budgets": [{"root_trials": b, **plans[b], **row(f"trials_{b}")} for b in budgets],
        "corner": None if corner is None else {"plan_seconds": corner, **row("corner")},
        "qmdp": row("qmdp"),
        "acceptance_95pct_of_flat_lb": {str(b): bool(evals[f"trials_{b}"]["mean"] >= 0.95 * lb) for b in budgets},
        "load_average_1min": round(load, 2),
    }
    if args.png:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, ax = plt.subplots(figsize=(7, 4.2))
        xs = budgets
        ys = [evals[f"trials_{b}"]["mean"] for b in xs]
        es = [evals[f"trials_{b}"]["ci95"] for b in xs]
        ax.errorbar(xs, ys, yerr=es, marker="o", capsize=3, label="hierarchical (policy-contingent)")
        ax.axhline(lb, color="k", ls="--", lw=1, label=f"flat LB after {args.flat_time:.0f} s ({lb:.2f})")
        ax.axhline(0.95 * lb, color="k", ls=":", lw=1, label="95 % of the flat LB")
        ax.axhline(ub, color="r", ls="--", lw=1, label=f"flat UB ({ub:.2f})")
        ax.axhline(evals["qmdp"]["mean"], color="g", ls="-.", lw=1, label="QMDP")
        if corner is not None:
            ax.axhline(evals["corner"]["mean"], color="m", ls="-.", lw=1, label="eq. 15-17 plan (previous)")
        ax.set_xscale("log")
        ax.set_xlabel("root trial budget")
        ax.set_ylabel("value at b0 in the flat model")
        ax2 = ax.twinx()
        ax2.plot(xs, [plans[b]["plan_seconds"] for b in xs], color="0.5", marker="s", ls="", label="plan seconds")
        ax2.set_ylabel("plan seconds (grey squares)")
        ax.legend(fontsize=7, loc="lower right")
        fig.tight_layout()
        fig.savefig(args.png, dpi=110)
        out["png"] = args.png
    json.dump(out, sys.stdout)
    sys.stdout.write("\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
