"""Save (or compare) the exact solver's policies on the benchmark files (test/data/pomdp): the before/after check of a pruning change.

    .venv/bin/python bench/exact_snapshot.py save DIR [FILE:H ...]     # one .npz per run into DIR
    .venv/bin/python bench/exact_snapshot.py compare DIR_A DIR_B        # ONE JSON object on stdout

``compare`` reports, per run, whether vectors, labels and their order are identical, and
else the max abs difference of the lexicographically sorted rows, whether the sorted
labels agree, and |ΔV(b0)|. The import path is whatever ``PYTHONPATH`` / the venv gives.
"""
from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from models import model_path  # noqa: E402  (bench/models.py: test/data/pomdp)

DEFAULT_RUNS = ["tiger.95.POMDP:15", "tiger.95.POMDP:inf", "tiger.aaai.POMDP:10", "tiger.aaai.POMDP:inf",
                "1d.POMDP:10", "1d.POMDP:inf", "parr95.95.POMDP:10", "parr95.95.POMDP:inf",
                "cheese.95.POMDP:10", "cheese.95.POMDP:inf", "network.POMDP:10"]


def save(out_dir: Path, runs) -> None:
    from pearl_pomdp.model import load_model
    from pearl_pomdp.solvers.incremental_pruning import solve_incremental_pruning

    out_dir.mkdir(parents=True, exist_ok=True)
    for spec in runs:
        name, h = spec.rsplit(":", 1)
        path = model_path(name)
        model = load_model(str(path))
        name = path.name
        t0 = time.perf_counter()
        res = solve_incremental_pruning(model, horizon=None if h == "inf" else int(h))
        np.savez(out_dir / f"{name}_{h}.npz", alphas=res.policy.alphas, actions=res.policy.actions,
                 b0=np.asarray(model.b0), seconds=res.seconds, epochs=res.iterations)
        print(f"{spec}: {res.policy.num_vectors} vectors, {time.perf_counter() - t0:.2f} s", file=sys.stderr, flush=True)


def compare(a_dir: Path, b_dir: Path) -> dict:
    out = {}
    for fa in sorted(a_dir.glob("*.npz")):
        fb = b_dir / fa.name
        if not fb.exists():
            continue
        a, b = np.load(fa), np.load(fb)
        row = {"vectors": [int(len(a["alphas"])), int(len(b["alphas"]))],
               "epochs": [int(a["epochs"]), int(b["epochs"])]}
        same_shape = a["alphas"].shape == b["alphas"].shape
        row["identical"] = bool(same_shape and np.array_equal(a["alphas"], b["alphas"])
                                and np.array_equal(a["actions"], b["actions"]))
        va, vb = (a["alphas"] @ a["b0"]).max(), (b["alphas"] @ b["b0"]).max()
        row["dV_b0"] = float(abs(va - vb))
        if same_shape:
            oa, ob = np.lexsort(a["alphas"].T[::-1]), np.lexsort(b["alphas"].T[::-1])
            row["sorted_max_abs_diff"] = float(np.abs(a["alphas"][oa] - b["alphas"][ob]).max()) if len(oa) else 0.0
            row["sorted_labels_equal"] = bool(np.array_equal(a["actions"][oa], b["actions"][ob]))
            row["same_order_max_abs_diff"] = float(np.abs(a["alphas"] - b["alphas"]).max()) if len(oa) else 0.0
        out[fa.stem] = row
    return out


if __name__ == "__main__":
    if sys.argv[1] == "save":
        save(Path(sys.argv[2]), sys.argv[3:] or DEFAULT_RUNS)
    else:
        print(json.dumps(compare(Path(sys.argv[2]), Path(sys.argv[3])), indent=1))
