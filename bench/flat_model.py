"""Point-based solver on Pearl's flat model: bounds at b0 per trial budget and per second (one JSON object).

The study plans the flat policy with a trial budget (``pearl solve --trials N``), so the
figures that decide its quality are the bounds after N trials and the trials per second.
For each ``--trials`` budget (deterministic: FIB runs to convergence, no clock limit) it
reports setup (FIB) seconds, search seconds, trials per second, LB/UB at b0, gap and the
gap as a fraction of LB; ``--time-limit`` adds a clock-limited run (as ``pearl solve
--time-limit``). ``--repo DIR`` runs another checkout's solver with this interpreter, so
two versions can be compared in one run under the same load.

    OMP_NUM_THREADS=1 .venv/bin/python bench/flat_model.py [--model config/pearl.domain.yaml]
        [--trials 50,100] [--time-limit 0] [--repo DIR]
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]

_WORKER = r"""
import json, sys, time
sys.path.insert(0, sys.argv[1])
from pearl_pomdp.model import load_model
from pearl_pomdp.solvers.point_based import solve_point_based
model = load_model(sys.argv[2])
trials = int(sys.argv[3]) or None
limit = float(sys.argv[4]) or None
t0 = time.perf_counter()
r = solve_point_based(model, time_limit=limit, max_trials=trials)
wall = time.perf_counter() - t0
setup = r.extra["setup_seconds"]
lb, ub = r.value_at_start, r.upper_bound
print(json.dumps({
    "states": model.num_states, "actions": model.num_actions, "observations": model.num_observations,
    "trials": r.iterations, "seconds": round(wall, 3), "setup_seconds": round(setup, 3),
    "search_seconds": round(wall - setup, 3), "trials_per_second": round(r.iterations / max(wall - setup, 1e-9), 2),
    "lb": round(lb, 5), "ub": round(ub, 5), "gap": round(ub - lb, 5),
    "gap_fraction": round((ub - lb) / max(abs(lb), 1e-9), 4),
    "backups": r.extra["backups"], "perseus_backups": r.extra["perseus_backups"],
    "vectors": r.extra["vectors"], "ub_points": r.extra["ub_points"], "nodes": r.extra["nodes"],
    "fib_iterations": r.extra["fib_iterations"]}))
"""


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--model", type=Path, default=REPO / "config" / "pearl.domain.yaml")
    ap.add_argument("--trials", default="50", help="comma-separated trial budgets (default 50; 0: none, e.g. with --time-limit)")
    ap.add_argument("--time-limit", type=float, default=0.0, help="also one clock-limited run of this many seconds")
    ap.add_argument("--repo", type=Path, default=REPO, help="checkout whose solver to run (default: this one)")
    args = ap.parse_args()
    if not (args.repo / "pearl_pomdp" / "solvers" / "point_based.py").is_file():
        raise SystemExit(f"bench/flat_model.py: --repo {args.repo}: no pearl_pomdp/solvers/point_based.py there")
    runs = [(int(t), 0.0) for t in args.trials.split(",") if t.strip() and int(t) > 0]  # 0: none
    if args.time_limit > 0:
        runs.append((0, args.time_limit))
    out = {"bench": "flat_model", "repo": str(args.repo.resolve()), "model": str(args.model),
           "omp_num_threads": os.environ.get("OMP_NUM_THREADS"), "runs": []}
    for trials, limit in runs:
        load = os.getloadavg()[0]
        proc = subprocess.run([sys.executable, "-c", _WORKER, str(args.repo.resolve()), str(args.model),
                               str(trials), str(limit)], capture_output=True, text=True)
        if proc.returncode != 0:
            raise SystemExit(f"bench/flat_model.py: the worker failed:\n{proc.stderr[-2000:]}")
        row = json.loads(proc.stdout.strip().splitlines()[-1])
        row.update({"budget_trials": trials or None, "time_limit": limit or None, "load": round(load, 2)})
        out["runs"].append(row)
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
