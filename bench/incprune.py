"""Incremental pruning vs pomdp-solve 5.5.2 on the benchmark files (test/data/pomdp).

Prints one JSON object: for each run (file, horizon) our vector count and
V(b0) next to pomdp-solve's (its measured runs, in ``REFERENCE`` below), our
seconds (wall and CPU) and the ratio to pomdp-solve's seconds. If a
``pomdp-solve`` binary is on PATH (or given with ``--pomdp-solve``), it is run
on the same file in the same session, so the time ratio is measured under the
same machine load (``ps_seconds_here``, ``ratio_here``); the ratio against
those recorded runs is kept too (``ratio_results``).

    .venv/bin/python bench/incprune.py                 # the slow runs (minutes)
    .venv/bin/python bench/incprune.py --set fast      # the small files (seconds)
    .venv/bin/python bench/incprune.py --set all --time-limit 600

Progress goes to stderr; the JSON to stdout.
"""
from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from pearl_pomdp.model import load_model  # noqa: E402
from pearl_pomdp.solvers.incremental_pruning import solve_incremental_pruning  # noqa: E402

from models import model_path  # noqa: E402  (bench/models.py: test/data/pomdp)

# (file, horizon or None, pomdp-solve vectors, pomdp-solve V(b0), pomdp-solve wall s, epochs): pomdp-solve 5.5.2
# built outside the repository, `-method incprune`, run on this 2-core machine on 2026-11-23
REFERENCE = [
    ("tiger.95.POMDP", 10, 27, 6.693368432, 0.023, 10),
    ("tiger.95.POMDP", 15, 47, 9.728424745, 0.085, 15),
    ("tiger.95.POMDP", None, 9, 19.37136837, 1.22, 477),
    ("tiger.aaai.POMDP", 10, 29, 1.66156005, 0.025, 10),
    ("tiger.aaai.POMDP", None, 9, 1.933438985, 0.26, 80),
    ("1d.POMDP", 10, 4, 1.185142583, 0.007, 10),
    ("1d.POMDP", None, 4, 1.260343623, 0.02, 76),
    ("network.POMDP", 10, 197, 121.2702633, 0.106, 10),
    ("network.POMDP", None, 487, 293.1852873, 298.0, 528),
    ("parr95.95.POMDP", 10, 5, 2.889511319, 0.008, 10),
    ("parr95.95.POMDP", None, 5, 7.201039921, 0.17, 475),
    ("shuttle.95.POMDP", 10, 1529, 11.28048794, 25.2, 10),
    ("shuttle.95.POMDP", None, 193, 32.88972469, 128.0, 488),
    ("4x3.95.POMDP", 10, 3373, 0.5397587649, 69.8, 10),
    ("cheese.95.POMDP", 10, 14, 1.233496312, 0.016, 10),
    ("cheese.95.POMDP", None, 14, 3.486206824, 0.772, 444),
]
SLOW = {("shuttle.95.POMDP", 10), ("network.POMDP", None), ("4x3.95.POMDP", 10), ("shuttle.95.POMDP", None)}


def run_pomdp_solve(binary: str, path: Path, horizon, limit: float):
    """Run pomdp-solve as for REFERENCE; return (seconds, vectors, V(b0) or None) or None on timeout."""
    with tempfile.TemporaryDirectory() as tmp:
        prefix = os.path.join(tmp, "out")
        cmd = [binary, "-pomdp", str(path), "-method", "incprune", "-o", prefix]
        if horizon is not None:
            cmd += ["-horizon", str(horizon)]
        t0 = time.perf_counter()
        try:
            subprocess.run(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, timeout=limit, check=True)
        except (subprocess.TimeoutExpired, subprocess.CalledProcessError):
            return None
        seconds = time.perf_counter() - t0
        text = open(prefix + ".alpha").read().split()
        return seconds, text


def alpha_file_stats(tokens, model):
    S = model.num_states
    arr = np.array(tokens, dtype=float).reshape(-1, S + 1)[:, 1:]
    return int(arr.shape[0]), float(np.max(arr @ model.b0))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--set", choices=["slow", "fast", "all"], default="slow")
    ap.add_argument("--time-limit", type=float, default=900.0, help="seconds per run of ours (and of pomdp-solve)")
    ap.add_argument("--pomdp-solve", default=shutil.which("pomdp-solve"), help="pomdp-solve binary (default: from PATH)")
    ap.add_argument("--only", default=None, help="regex on 'file:horizon' to select runs")
    args = ap.parse_args(argv)

    runs = []
    for name, horizon, ref_n, ref_v, ref_s, ref_epochs in REFERENCE:
        slow = (name, horizon) in SLOW
        if args.set == "slow" and not slow or args.set == "fast" and slow:
            continue
        tag = f"{name}:{horizon if horizon is not None else 'inf'}"
        if args.only and not re.search(args.only, tag):
            continue
        model = load_model(model_path(name))
        print(f"[incprune bench] {tag} …", file=sys.stderr, flush=True)
        c0 = time.process_time()
        res = solve_incremental_pruning(model, horizon=horizon, time_limit=args.time_limit, progress=True)
        cpu = time.process_time() - c0
        row = {
            "problem": name, "horizon": horizon if horizon is not None else "inf",
            "S_A_Z": [model.num_states, model.num_actions, model.num_observations],
            "vectors": res.policy.num_vectors, "ref_vectors": ref_n,
            "value_at_start": res.value_at_start, "ref_value": ref_v,
            "value_diff": res.value_at_start - ref_v,
            "epochs": res.iterations, "ref_epochs": ref_epochs, "peak_vectors": max(res.vectors_per_epoch or [0]),
            "converged": res.converged,
            "seconds": round(res.seconds, 3), "cpu_seconds": round(cpu, 3),
            "ref_seconds": ref_s, "ratio_results": round(res.seconds / ref_s, 3),
            "lps": res.extra["prune"]["lps"],
        }
        if args.pomdp_solve:
            out = run_pomdp_solve(args.pomdp_solve, model_path(name), horizon, args.time_limit)
            if out is None:
                row["ps_seconds_here"] = None
            else:
                secs, tokens = out
                n, v = alpha_file_stats(tokens, model)
                row.update(ps_seconds_here=round(secs, 3), ps_vectors_here=n, ps_value_here=v,
                           ratio_here=round(res.seconds / secs, 3))
        runs.append(row)
        print(f"[incprune bench] {tag}: {row['vectors']} vectors (ref {ref_n}), V {row['value_at_start']:.10g} "
              f"(ref {ref_v}), {row['seconds']} s (ref {ref_s} s)", file=sys.stderr, flush=True)
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else None
    print(json.dumps({"bench": "incprune", "load_average_1min": load,
                      "pomdp_solve": args.pomdp_solve, "runs": runs}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
