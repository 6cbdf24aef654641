"""Two ways to lower the point-based upper bound on Pearl's flat model, measured (one JSON object).

After ``--time-limit`` seconds of the point-based solver (FIB included) the solver state is
copied and three continuations are compared:

* ``trials``: the solver's own trials for ``--refine-seconds`` more (the baseline);
* ``trajectory_updates``: for the same seconds,
  :func:`pearl_pomdp.solvers.refine.refine_along_paths` along the beliefs QMDP's own
  episodes reach in the model (``--episodes`` episodes of ``--depth`` steps);
* ``lp_at_b0``: no search; UB(b0) re-read with each successor of b0 bounded by the full
  convex-hull interpolation of the solver's UB points and corners (an LP per successor,
  ``min b·V_c + Σ λ_i δ_i`` s.t. ``Σ λ_i b_i ≤ b``, ``λ ≥ 0``), which is never looser than
  the sawtooth's single-point read and still ≥ V* by convexity.

The LP probe reads the solver's internals (node graph, point arrays) and changes nothing.

    OMP_NUM_THREADS=1 .venv/bin/python bench/flat_ub_probes.py [--time-limit 40] [--refine-seconds 40]
"""
from __future__ import annotations

import argparse
import copy
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))


def lp_upper_at_b0(s) -> dict:
    """UB(b0) with every successor read by the convex-hull LP over the solver's points."""
    import scipy.sparse as sp
    from scipy.optimize import linprog

    n = s.bound.pt_n
    rows = np.repeat(np.arange(n), s.bound.pt_len[:n])
    ent = s.bound.entries(np.arange(n))
    P = sp.csr_matrix((s.bound.ent_val[ent], (rows, s.bound.ent_idx[ent])), shape=(n, s.S))
    delta = s.bound.pt_delta[:n].copy()
    root = s.root
    U, C, live = s.successors(root)
    before = root.Rb + s.g * (root.p * root.ub_c).sum(axis=1)
    ub_lp = root.ub_c.copy()
    t0 = time.perf_counter()
    usable = []
    for f in live:
        b = np.zeros(s.S)
        b[U] = C[f]
        supp = b > 0
        ok = (np.asarray(P[:, ~supp].sum(axis=1)).ravel() == 0) & (delta < 0)
        idx = np.flatnonzero(ok)
        usable.append(int(idx.size))
        if idx.size == 0:
            continue
        res = linprog(delta[idx], A_ub=P[idx][:, np.flatnonzero(supp)].T.tocsc(), b_ub=b[supp],
                      bounds=(0, None), method="highs")
        if res.status == 0:
            a, o = divmod(int(f), s.Z)
            ub_lp[a, o] = min(ub_lp[a, o], float(b @ s.bound.Vc) + float(res.fun))
    after = root.Rb + s.g * (root.p * ub_lp).sum(axis=1)
    top = np.argsort(-before)[:5]
    return {"ub_sawtooth": round(float(before.max()), 5), "ub_lp": round(float(after.max()), 5),
            "lps": int(len(live)), "seconds": round(time.perf_counter() - t0, 2),
            "points": int(n), "points_usable_per_successor_median": float(np.median(usable)) if usable else 0.0,
            "top_actions": [{"action": s.model.actions[a], "q_sawtooth": round(float(before[a]), 4),
                             "q_lp": round(float(after[a]), 4)} for a in top]}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--domain", default=str(REPO / "config" / "pearl.domain.yaml"))
    ap.add_argument("--time-limit", type=float, default=40.0, help="seconds of search before the probes")
    ap.add_argument("--refine-seconds", type=float, default=40.0, help="seconds for each continuation")
    ap.add_argument("--episodes", type=int, default=30, help="QMDP episodes whose beliefs are updated")
    ap.add_argument("--depth", type=int, default=40, help="steps per episode")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()

    from pearl_pomdp.model.domain_yaml import load_domain
    from pearl_pomdp.solvers.mdp import solve_qmdp
    from pearl_pomdp.solvers.point_based import PointBasedSolver
    from pearl_pomdp.solvers.refine import policy_paths, refine_along_paths

    load = os.getloadavg()[0]
    model = load_domain(args.domain).compile()
    t0 = time.perf_counter()
    solver = PointBasedSolver(model, seed=args.seed, fib_time=None)
    setup = time.perf_counter() - t0
    solver.run(time_limit=max(0.0, args.time_limit - setup), epsilon=1e-3)
    lb0, ub0 = solver.bounds_at_start()
    out = {"bench": "flat_ub_probes", "model": model.name, "setup_seconds": round(setup, 2),
           "start": {"seconds": round(time.perf_counter() - t0, 1), "trials": solver.trials,
                     "lb": round(lb0, 5), "ub": round(ub0, 5), "ub_points": solver.bound.pt_n}}
    out["lp_at_b0"] = lp_upper_at_b0(solver)

    seqs = policy_paths(model, solve_qmdp(model).policy, args.episodes, args.depth, seed=args.seed)
    probe = copy.deepcopy(solver)
    got = refine_along_paths(probe, seqs, seconds=args.refine_seconds)
    out["trajectory_updates"] = {"seconds": round(got["seconds"], 1), "sweeps": got["sweeps"], "backups": got["backups"],
                                 "lb": round(got["lb"], 5), "ub": round(got["ub"], 5), "nodes": len(probe.nodes)}
    del probe
    t1 = time.perf_counter()
    solver.run(time_limit=args.refine_seconds, epsilon=1e-3)
    lb, ub = solver.bounds_at_start()
    out["trials"] = {"seconds": round(time.perf_counter() - t1, 1), "trials": solver.trials,
                     "lb": round(lb, 5), "ub": round(ub, 5), "nodes": len(solver.nodes)}
    out["load_average_1min"] = round(load, 2)
    json.dump(out, sys.stdout)
    sys.stdout.write("\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
