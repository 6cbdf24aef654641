"""Point-based solver vs SARSOP on every benchmark file (one JSON object on stdout).

For each model in ``test/data/pomdp/`` (or ``--problems``) it runs
:func:`pearl_pomdp.solvers.point_based.solve_point_based` with target gap
``--epsilon`` (1e-3, SARSOP's ``--precision``) and ``--time-limit`` seconds (60, SARSOP's
``--timeout``), and reports our lower/upper bound at b0, gap, seconds, α-vectors,
trials, and the time at which our lower bound first came within 2 % of SARSOP's,
next to SARSOP's LB/UB/wall time/stop parsed from ``--peer-results FILE`` (the markdown of
SARSOP's recorded runs; SARSOP is built and run outside this repository; without it no SARSOP columns).
"within_2pct" is ``LB_ours ≥ LB_sarsop − 0.02·|LB_sarsop|``. ``load_seconds`` (reading
the file) is reported apart from the solve.

    .venv/bin/python bench/pointbased.py [--problems hallway,tiger.95] [--time-limit 60]
        [--epsilon 1e-3] [--progress] [--peer-results FILE]

Timings on the shared machine are noisy; the ``load`` field records the load
average at the start of each problem.
"""
from __future__ import annotations

import argparse
import json
import os
import re
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "bench"))
from models import model_files, peer_results  # noqa: E402  (bench/models.py: test/data/pomdp)

from pearl_pomdp.model import load_model  # noqa: E402
from pearl_pomdp.solvers.point_based import solve_point_based  # noqa: E402


def sarsop_rows(results_md: Path) -> dict:
    """SARSOP's table in the peer-results markdown: problem file → {lb, ub, wall_s, stop, vectors}."""
    rows = {}
    in_table = False
    header = None
    num = lambda c: float(re.match(r"-?[\d.]+(?:e-?\d+)?", c.replace("−", "-")).group(0))
    for line in results_md.read_text().splitlines():
        if line.startswith("### SARSOP"):
            in_table = True
            continue
        if in_table and line.startswith("### "):
            break
        if not (in_table and line.startswith("|")):
            continue
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if header is None:
            header = cells
            continue
        if set(cells[0]) <= set("-: "):
            continue
        c = dict(zip(header, cells))
        rows[c["problem"]] = {"lb": num(c["LB at b0"]), "ub": num(c["UB at b0"]),
                              "wall_s": num(c["wall s, median (min–max)"]), "stop": c["stop"],
                              "vectors": int(num(c["#α"]))}
    return rows


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--problems", default="", help="comma-separated file-name prefixes (default: all)")
    ap.add_argument("--time-limit", type=float, default=60.0)
    ap.add_argument("--epsilon", type=float, default=1e-3)
    ap.add_argument("--progress", action="store_true", help="tqdm line per problem on stderr")
    ap.add_argument("--peer-results", metavar="FILE", default=None,
                    help="markdown of SARSOP's recorded runs (a '### SARSOP' table); without it no SARSOP columns")
    args = ap.parse_args()

    results = peer_results(args.peer_results)
    ref = sarsop_rows(results) if results is not None else {}
    files = sorted(model_files())
    if args.problems:
        wanted = [w.strip() for w in args.problems.split(",") if w.strip()]
        files = [f for f in files if any(f.name.startswith(w) for w in wanted)]
    out = {"time_limit": args.time_limit, "epsilon": args.epsilon, "cpus": os.cpu_count(), "problems": {}}
    n_ok = n_ref = 0
    for path in files:
        load = os.getloadavg()[0]
        t0 = time.perf_counter()
        model = load_model(path)
        load_s = time.perf_counter() - t0
        res = solve_point_based(model, time_limit=args.time_limit, epsilon=args.epsilon, progress=args.progress)
        r = ref.get(path.name)
        row = {
            "states": model.num_states, "actions": model.num_actions, "observations": model.num_observations,
            "load": round(load, 2), "load_seconds": round(load_s, 3),
            "lb": res.value_at_start, "ub": res.upper_bound, "gap": res.gap, "seconds": round(res.seconds, 3),
            "converged": res.converged, "vectors": res.policy.num_vectors, "trials": res.iterations,
            "backups": res.extra.get("backups"), "ub_points": res.extra.get("ub_points"),
        }
        if r is not None:
            target = r["lb"] - 0.02 * abs(r["lb"])
            hit = next((t for t, lb, _ in res.extra.get("history", []) if lb >= target), None)
            row.update({
                "sarsop": r,
                "lb_target_2pct": target,
                "within_2pct": bool(res.value_at_start >= target),
                "lb_shortfall_pct": 100.0 * (r["lb"] - res.value_at_start) / abs(r["lb"]) if r["lb"] else None,
                "seconds_to_2pct": hit,
                "time_ratio_vs_sarsop": (res.seconds / r["wall_s"]) if r["stop"] == "precision" and res.converged else None,
            })
            n_ref += 1
            n_ok += row["within_2pct"]
        out["problems"][path.name] = row
        print(f"{path.name}: LB {res.value_at_start:.6g} UB {res.upper_bound:.6g} gap {res.gap:.3g} "
              f"{res.seconds:.1f}s" + (f" (SARSOP LB {r['lb']:.6g}, within 2%: {row['within_2pct']})" if r else ""),
              file=sys.stderr, flush=True)
    out["within_2pct"] = f"{n_ok}/{n_ref}"
    print(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
