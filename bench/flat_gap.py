"""How far from optimal is the hierarchical policy on Pearl's flat model? (one JSON object)

In the flat POMDP compiled from the Pearl domain, simulated by the model's own T/O/R
(:func:`pearl_pomdp.evaluation.evaluate_policies`: common random numbers across policies,
cross-fitted state control variates, truncation bracket), it estimates the discounted value
at b0 of

* ``hierarchical``: the planned hierarchy as the robot executes it (EXECUTE, root lookahead);
* ``flat_pointbased``: the point-based solve's lower-bound vectors, greedy;
* ``flat_lookahead1``: the same vectors with one step of exact lookahead (as
  ``FlatPolicyDecider(lookahead=1)``; ``--lookahead-episodes``: ~0.8 s per episode under load);
* ``qmdp``;

and runs the point-based solver for ``--time-limit`` seconds (FIB included) for its lower
bound LB (the value of a conditional plan: deterministic) and upper bound UB at b0: its own
trials for all but ``--refine-share`` of the time, then bound updates along the beliefs
the hierarchical and the QMDP policy visit in their own episodes, and in later rounds the
flat policy's own (:func:`pearl_pomdp.solvers.refine.refine_along_paths`;
``--refine-share 0``: trials only).

Every policy value is a lower bound on V*(b0); each estimate's ``lower`` is its 95 % lower
confidence bound (truncation included). So, with 95 % confidence per estimate,

    V_H.lower / UB  ≤  V_H / V*  ≤  V_H.upper / best_lower,

where ``best_lower`` is the largest of LB and the other policies' ``lower``. ``gap_fraction``
is ``(UB − best_lower) / best_lower``: below 0.05 the statement "the hierarchical policy is
within x % of optimal" is decided to within 5 %.

    OMP_NUM_THREADS=1 .venv/bin/python bench/flat_gap.py [--episodes 600] [--time-limit 120]
        [--lookahead-episodes 60] [--seed 0]
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))


def rounded(r: dict) -> dict:
    keys = ("mean", "ci95", "lower", "upper", "variance_reduction", "episodes", "steps", "seconds")
    out = {k: (round(r[k], 4) if isinstance(r[k], float) else r[k]) for k in keys}
    out["plain"] = {k: round(v, 4) for k, v in r["plain"].items()}
    out["truncation"] = [round(x, 5) for x in r["truncation"]]
    return out


def paired(a: np.ndarray, b: np.ndarray) -> dict:
    d = a - b
    return {"mean": round(float(d.mean()), 4), "ci95": round(float(1.96 * d.std(ddof=1) / np.sqrt(d.size)), 4)}


def flat_bounds(model, path_policies, time_limit: float = 120.0, refine_share: float = 1 / 3, refine_episodes: int = 30,
                refine_depth: int = 40, refine_rounds: int = 2, seed: int = 0, note=lambda msg: None):
    """The flat point-based solve behind the bounds: trials for all but ``refine_share`` of
    ``time_limit``, then bound updates along the episodes of ``path_policies`` and (from the
    second round) of the flat policy itself. Returns ``(solver, (LB, UB) after the trials,
    refine summary or None, setup seconds, solve seconds)``; the solver is pruned."""
    import numpy as np

    from pearl_pomdp.solution import AlphaVectorPolicy
    from pearl_pomdp.solvers.point_based import PointBasedSolver
    from pearl_pomdp.solvers.refine import policy_paths, refine_along_paths

    t0 = time.perf_counter()
    solver = PointBasedSolver(model, seed=seed, fib_time=max(0.5, 0.1 * time_limit))
    setup = time.perf_counter() - t0
    solver.setup_seconds = setup
    solver.run(time_limit=max(0.0, (1.0 - refine_share) * time_limit - setup), epsilon=1e-3)
    after_trials = solver.bounds_at_start()
    note(f"flat trials: LB {after_trials[0]:.4f} UB {after_trials[1]:.4f} after {solver.trials} trials, "
         f"{time.perf_counter() - t0:.1f} s")
    refine = None
    if refine_share > 0:
        paths = np.vstack([policy_paths(model, p, refine_episodes, refine_depth, seed=seed + 1) for p in path_policies])
        rounds = max(1, refine_rounds)
        refine = {"backups": 0, "sweeps": 0, "seconds": 0.0, "rounds": []}
        for k in range(rounds):
            if k > 0:
                current = AlphaVectorPolicy(solver.GT[:, : solver.K].T.copy(), solver.gact[: solver.K].copy())
                paths = np.vstack([paths, policy_paths(model, current, refine_episodes, refine_depth,
                                                       seed=seed + 1 + k)])
            left = max(0.0, time_limit - (time.perf_counter() - t0))
            got = refine_along_paths(solver, paths, seconds=left / (rounds - k))
            for key in ("backups", "sweeps", "seconds"):
                refine[key] += got[key]
            refine["rounds"].append({"paths": int(paths.shape[0]), "lb": round(got["lb"], 4), "ub": round(got["ub"], 4)})
            note(f"updates along the policies' beliefs, round {k + 1}: LB {got['lb']:.4f} UB {got['ub']:.4f}, "
                 f"{got['backups']} backups in {got['seconds']:.1f} s")
    solver.prune()
    return solver, after_trials, refine, setup, time.perf_counter() - t0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--domain", default=str(REPO / "config" / "pearl.domain.yaml"))
    ap.add_argument("--hierarchy", default=str(REPO / "config" / "pearl.hierarchy.yaml"))
    ap.add_argument("--episodes", type=int, default=600, help="episodes per policy (the same draws for each)")
    ap.add_argument("--lookahead-episodes", type=int, default=60,
                    help="episodes for flat_lookahead1 (0: skip it; slow: ~0.8 s per episode under load)")
    ap.add_argument("--time-limit", type=float, default=120.0, help="seconds of the flat point-based solve (FIB included)")
    ap.add_argument("--refine-share", type=float, default=1 / 3,
                    help="share of --time-limit spent on updates along the policies' beliefs (0: trials only)")
    ap.add_argument("--refine-episodes", type=int, default=30, help="episodes per policy whose beliefs are updated")
    ap.add_argument("--refine-depth", type=int, default=40, help="steps per such episode")
    ap.add_argument("--refine-rounds", type=int, default=2,
                    help="rounds of updates; each round after the first adds the episodes of the flat "
                         "policy as it is then (its lower-bound vectors, greedy)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--progress", action="store_true", help="a line per stage on stderr")
    args = ap.parse_args()
    if args.episodes < 2:
        raise SystemExit("bench/flat_gap.py: --episodes must be at least 2 (a CI needs two episodes)")
    if not 0.0 <= args.refine_share < 1.0:
        raise SystemExit(f"bench/flat_gap.py: --refine-share must be in [0, 1), got {args.refine_share}")

    from pearl_pomdp.evaluation import evaluate_policies
    from pearl_pomdp.policies import LookaheadPolicy
    from pearl_pomdp.hierarchy import load_hierarchy, plan
    from pearl_pomdp.model.domain_yaml import load_domain
    from pearl_pomdp.solution import AlphaVectorPolicy
    from pearl_pomdp.solvers.mdp import solve_fib, solve_qmdp

    def note(msg: str) -> None:
        if args.progress:
            print(f"flat_gap: {msg}", file=sys.stderr, flush=True)

    load = os.getloadavg()[0]
    domain = load_domain(args.domain)
    model = domain.compile()
    t0 = time.perf_counter()
    hp = plan(domain, load_hierarchy(args.hierarchy, domain))
    plan_seconds = time.perf_counter() - t0
    note(f"planned the hierarchy in {plan_seconds:.1f} s")
    qmdp = solve_qmdp(model)
    fib = solve_fib(model)
    solver, after_trials, refine, setup, solve_seconds = flat_bounds(
        model, [hp, qmdp.policy], time_limit=args.time_limit, refine_share=args.refine_share,
        refine_episodes=args.refine_episodes, refine_depth=args.refine_depth, refine_rounds=args.refine_rounds,
        seed=args.seed, note=note)
    lb, ub = solver.bounds_at_start()
    flat_policy = AlphaVectorPolicy(solver.GT[:, : solver.K].T.copy(), solver.gact[: solver.K].copy())

    policies = {"hierarchical": hp, "flat_pointbased": flat_policy, "qmdp": qmdp.policy}
    evals = evaluate_policies(model, policies, episodes=args.episodes, seed=args.seed, progress=args.progress)
    if args.lookahead_episodes > 0:
        evals.update(evaluate_policies(model, {"flat_lookahead1": LookaheadPolicy(flat_policy, model)},
                                       episodes=args.lookahead_episodes, seed=args.seed, progress=args.progress))

    h = evals["hierarchical"]
    others = [(lb, "flat_pointbased_lower_bound")] + [(r["lower"], name) for name, r in evals.items()
                                                      if name != "hierarchical"]
    best_lower, best_source = max(others)
    lower_all, lower_all_source = max(others + [(h["lower"], "hierarchical")])
    out = {
        "bench": "flat_gap", "domain": model.name, "states": model.num_states, "actions": model.num_actions,
        "observations": model.num_observations, "discount": model.discount, "seed": args.seed,
        "plan_seconds": round(plan_seconds, 3),
        "solver": {"lb": round(lb, 4), "ub": round(ub, 4), "seconds": round(solve_seconds, 2),
                   "setup_seconds": round(setup, 2), "time_limit": args.time_limit, "trials": solver.trials,
                   "after_trials": {"lb": round(after_trials[0], 4), "ub": round(after_trials[1], 4)},
                   "refine": None if refine is None else {
                       "share": round(args.refine_share, 3), "depth": args.refine_depth,
                       "backups": refine["backups"], "sweeps": refine["sweeps"],
                       "seconds": round(refine["seconds"], 2), "rounds": refine["rounds"]},
                   "vectors": solver.K, "ub_points": solver.bound.pt_n, "nodes": len(solver.nodes),
                   "history": [[round(t, 1), round(a, 4), round(b, 4)] for t, a, b in solver.history[::10]]},
        "initial_upper_bounds": {"fib": round(float(fib.value_at_start), 4), "qmdp": round(float(qmdp.value_at_start), 4)},
        "policies": {name: rounded(r) for name, r in evals.items()},
        "paired_hierarchical_minus": {name: paired(h["values"], evals[name]["values"])
                                      for name in ("flat_pointbased", "qmdp")},
        "best_lower_bound": {"value": round(best_lower, 4), "from": best_source,
                             "including_hierarchical": round(lower_all, 4), "including_from": lower_all_source},
        "gap": round(ub - lower_all, 4),
        "gap_fraction": round((ub - lower_all) / abs(lower_all), 4) if lower_all else None,
        "gap_below_5pct": bool(ub - lower_all < 0.05 * abs(lower_all)),
        "hierarchical_fraction_of_optimal": {
            "at_least": round(h["lower"] / ub, 4) if ub > 0 else None,
            "at_most": round(min(1.0, h["upper"] / best_lower), 4) if best_lower > 0 else None},
        "load_average_1min": round(load, 2),
    }
    json.dump(out, sys.stdout)
    sys.stdout.write("\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
