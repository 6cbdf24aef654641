"""Load/write times of every benchmark model (.pomdp reader and writer, PomdpX).

For each file in test/data/pomdp (bench/models.py): read time (min and median of --repeat runs, wall
and process CPU — CPU is less disturbed by the other jobs on this shared machine), the size,
the .pomdp write and re-read times, whether the re-read model is identical (fingerprint and
exact arrays), and the same for PomdpX. Prints one JSON object; progress on stderr.

    .venv/bin/python bench/load_models.py                # 3 repeats
    .venv/bin/python bench/load_models.py --repeat 5 --only RockSample_7_8.pomdp
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import scipy.sparse as sp

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from pearl_pomdp.model.pomdp_format import read_pomdp  # noqa: E402
from pearl_pomdp.model.pomdp_writer import write_pomdp  # noqa: E402
from pearl_pomdp.model.pomdpx import read_pomdpx, write_pomdpx  # noqa: E402

sys.path.insert(0, str(REPO / "bench"))
from models import model_dir  # noqa: E402  (bench/models.py: test/data/pomdp)

BENCHMARKS = model_dir()


def timed(fn, *args):
    w, c = time.perf_counter(), time.process_time()
    out = fn(*args)
    return out, time.perf_counter() - w, time.process_time() - c


def identical(m, m2) -> bool:
    return (m.fingerprint() == m2.fingerprint() and (m.states, m.actions, m.observations)
            == (m2.states, m2.actions, m2.observations) and m.discount == m2.discount
            and np.array_equal(m.O, m2.O) and np.array_equal(m.R, m2.R) and np.array_equal(m.b0, m2.b0)
            and all((sp.csr_matrix(x) != sp.csr_matrix(y)).nnz == 0 for x, y in zip(m.T, m2.T)))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--only", nargs="*", default=None, help="file names to run")
    ap.add_argument("--no-pomdpx", action="store_true")
    args = ap.parse_args()
    files = sorted((p for p in BENCHMARKS.iterdir() if p.suffix.lower() == ".pomdp"), key=lambda p: p.stat().st_size)
    if args.only:
        files = [p for p in files if p.name in args.only]
    out = {"benchmarks": str(BENCHMARKS), "repeat": args.repeat, "loadavg_start": os.getloadavg()[0], "files": {}}
    with tempfile.TemporaryDirectory() as tmp:
        for p in files:
            print(f"{p.name} ...", file=sys.stderr, flush=True)
            walls, cpus = [], []
            for _ in range(args.repeat):
                m, w, c = timed(read_pomdp, p)
                walls.append(w)
                cpus.append(c)
            row = {
                "bytes": p.stat().st_size, "S": m.num_states, "A": m.num_actions, "Z": m.num_observations,
                "sparse": m.is_sparse,
                "read_s_min": round(min(walls), 4), "read_s_median": round(statistics.median(walls), 4),
                "read_cpu_s_min": round(min(cpus), 4),
            }
            path = Path(tmp) / ("copy_" + p.name)
            _, w, _ = timed(write_pomdp, m, path)
            m2, w2, _ = timed(read_pomdp, path)
            row.update({"write_s": round(w, 4), "written_bytes": path.stat().st_size, "reread_s": round(w2, 4),
                        "round_trip_identical": identical(m, m2)})
            if not args.no_pomdpx:
                xpath = Path(tmp) / (p.stem + ".pomdpx")
                _, w, _ = timed(write_pomdpx, m, xpath)
                m3, w3, _ = timed(read_pomdpx, xpath)
                row.update({"pomdpx_write_s": round(w, 4), "pomdpx_bytes": xpath.stat().st_size,
                            "pomdpx_read_s": round(w3, 4), "pomdpx_round_trip_identical": identical(m, m3)})
            out["files"][p.name] = row
    out["loadavg_end"] = os.getloadavg()[0]
    json.dump(out, sys.stdout, indent=1)
    sys.stdout.write("\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
