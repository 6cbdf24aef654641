"""Our solvers side by side with the peer solvers' recorded results (``--peer-results RESULTS.md``).

For every model in ``test/data/pomdp/`` (or those picked with ``--problems``):

* **incprune** (exact) for every horizon at which pomdp-solve finished in the peer results
  (without ``--peer-results``: ``--horizons``, default 10)
  (10, 15 for tiger.95, and ``inf`` = run to the epsilon stop), capped at
  ``--incprune-time-limit`` seconds (default 300, pomdp-solve's cap). Compared: α-vector
  count, V(b0), epochs, wall time (ratio ours / pomdp-solve). Problems where pomdp-solve
  did not finish 10 epochs are skipped for incprune (and say so).
* **pointbased**, target gap 1e-3 at b0 (SARSOP's ``--precision``), time limit
  ``--time-limit`` (default 60 s, SARSOP's timeout). Compared: lower bound at b0 against
  SARSOP's (shortfall in %, "within 2 %"), upper bound, gap, time (ratio ours / SARSOP's
  wall time; only a target where SARSOP stopped on precision).
* **qmdp** as a baseline (its value at b0 is an upper bound of the optimum).

With a peer on PATH, ``time_ratio_vs_peer_here`` compares against the peer's wall time in
this same run (same machine load); ``time_ratio_vs_pomdp_solve`` / ``time_ratio_vs_sarsop``
compare against the recorded peer times. On a loaded machine compare CPU seconds
(``cpu_ratio_vs_peer_here``): our ``--time-limit`` is wall-clock, while ``pomdpsol
--timeout`` counts its own solving time, so under load SARSOP gets more CPU in "60 s".

The reference tables are parsed from the peer-results file (not retyped): the markdown the
peers' runs wrote (pomdp-solve and SARSOP are built and run outside this repository). Without it
the peer columns are empty and the script says so. If ``pomdpsol`` or
``pomdp-solve`` is on PATH they are run in the same run, with the same caps, for time
ratios on equal terms (``peers`` in the output).

    .venv/bin/python bench/solvers.py [--problems tiger.95,cheese.95] [--time-limit 60]
        [--incprune-time-limit 300] [--methods incprune,pointbased,qmdp] [--no-peers] [--peer-results FILE]

Prints one JSON object on stdout; progress (tqdm) on stderr.
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import re
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Dict, List, Optional

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "bench"))
from models import model_files, peer_results  # noqa: E402  (bench/models.py: test/data/pomdp)

# ------------------------------------------------------------ peer results


def markdown_tables(text: str) -> List[List[Dict[str, str]]]:
    """Every pipe table in ``text`` as a list of row dicts keyed by the header cells."""
    tables, block = [], []
    for line in text.splitlines() + [""]:
        if line.strip().startswith("|"):
            block.append(line.strip())
            continue
        if len(block) >= 2:
            split = [[c.strip() for c in row.strip("|").split("|")] for row in block]
            header, rows = split[0], [r for r in split[1:] if not all(re.fullmatch(r":?-+:?", c) for c in r)]
            tables.append([dict(zip(header, r)) for r in rows])
        block = []
    return tables


_NUM = r"[-−]?\d+(?:\.\d+)?(?:[eE][-+]?\d+)?"


def first_number(cell: str) -> Optional[float]:
    """The first number in a cell (``"0.994222 (0.994217–0.994222)"`` → 0.994222); None for "—"."""
    m = re.search(_NUM, cell.replace("**", ""))
    return None if m is None else float(m.group(0).replace("−", "-"))


def parse_results(path: Path) -> dict:
    """``{"sarsop": {file: row}, "pomdp_solve": {file: {horizon: row}}}`` with numbers parsed."""
    sarsop, psolve = {}, {}
    for table in markdown_tables(path.read_text()):
        if not table:
            continue
        keys = table[0].keys()
        if "LB at b0" in keys:
            for row in table:
                sarsop[row["problem"]] = {
                    "stop": row["stop"],
                    "wall_seconds": first_number(row["wall s, median (min–max)"]),
                    "lower_bound": first_number(row["LB at b0"]),
                    "upper_bound": first_number(row["UB at b0"]),
                    "gap": first_number(row["gap"]),
                    "alpha_vectors": int(first_number(row["#α"])),
                    "load_seconds": first_number(row["load s"]),
                }
        elif "horizon" in keys and "epochs" in keys:
            for row in table:
                finished = row["result"].strip() == "finished"
                peak = re.search(r"\((\d+)\)", row["#α final (peak)"])
                psolve.setdefault(row["problem"], {})[row["horizon"]] = {
                    "finished": finished,
                    "result": row["result"].replace("**", ""),
                    "epochs": None if first_number(row["epochs"]) is None else int(first_number(row["epochs"])),
                    "alpha_vectors": int(first_number(row["#α final (peak)"])) if finished else None,
                    "peak_vectors": int(peak.group(1)) if (finished and peak) else None,
                    "wall_seconds": first_number(row["wall s"]),
                    # The notes carry V(uniform) with more digits where the file's b0 is uniform.
                    "value_at_start": _precise_value(row),
                }
    return {"sarsop": sarsop, "pomdp_solve": psolve}


def _precise_value(row: dict) -> Optional[float]:
    value = first_number(row["V(b0) = max α·b0"])
    m = re.search(r"V\(uniform\) = (" + _NUM + ")", row.get("notes", ""))
    if m and value is not None and abs(float(m.group(1)) - value) < 1e-6:
        return float(m.group(1))
    return value


# ----------------------------------------------------------------- our runs


def _ratio(a, b):
    return None if (a is None or b is None or b == 0) else round(a / b, 3)


def _round(x, n=6):
    return None if x is None else float(round(x, n))


def run_incprune(model, horizon, time_limit, ref):
    from pearl_pomdp.solvers.incremental_pruning import solve_incremental_pruning

    c0, t0 = time.process_time(), time.perf_counter()
    r = solve_incremental_pruning(model, horizon=horizon, time_limit=time_limit)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    ours = {"alpha_vectors": r.policy.num_vectors, "value_at_start": r.value_at_start, "epochs": r.iterations,
            "peak_vectors": max(r.vectors_per_epoch) if r.vectors_per_epoch else None,
            "seconds": round(wall, 4), "cpu_seconds": round(cpu, 4), "converged": bool(r.converged)}
    out = {"horizon": "inf" if horizon is None else horizon, "ours": ours, "reference": ref}
    complete = r.converged or (horizon is not None and r.iterations == horizon)
    out["complete"] = bool(complete)
    if ref.get("value_at_start") is not None:
        out["value_diff"] = float(r.value_at_start - ref["value_at_start"])
    out["vectors_match"] = (None if ref.get("alpha_vectors") is None
                            else bool(complete and ref["alpha_vectors"] == r.policy.num_vectors))
    out["time_ratio_vs_pomdp_solve"] = _ratio(wall, ref.get("wall_seconds")) if complete else None
    return out


def run_pointbased(model, time_limit, ref):
    from pearl_pomdp.solvers.point_based import solve_point_based

    c0, t0 = time.process_time(), time.perf_counter()
    r = solve_point_based(model, time_limit=time_limit, epsilon=1e-3, seed=0)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    ours = {"lower_bound": r.value_at_start, "upper_bound": r.upper_bound, "gap": r.gap,
            "alpha_vectors": r.policy.num_vectors, "iterations": r.iterations, "seconds": round(wall, 3),
            "cpu_seconds": round(cpu, 3), "converged": bool(r.converged)}
    out = {"ours": ours, "reference": ref}
    lb = ref.get("lower_bound")
    if lb is not None:
        shortfall = (lb - r.value_at_start) / abs(lb) * 100 if lb != 0 else None
        out["lower_bound_shortfall_pct"] = _round(shortfall, 4)
        out["within_2pct_of_sarsop_lb"] = bool(shortfall is not None and shortfall <= 2.0)
    out["time_ratio_vs_sarsop"] = _ratio(wall, ref.get("wall_seconds"))
    out["sarsop_time_is_target"] = ref.get("stop") == "precision"
    return out


def run_qmdp(model):
    from pearl_pomdp.solvers.mdp import solve_qmdp

    t0 = time.perf_counter()
    r = solve_qmdp(model)
    return {"value_at_start": r.value_at_start, "upper_bound": r.upper_bound,
            "seconds": round(time.perf_counter() - t0, 4)}


# ------------------------------------------------------------------- peers


def _children_cpu() -> float:
    """User + system CPU seconds of finished child processes (to time a peer by CPU, not wall)."""
    ru = resource.getrusage(resource.RUSAGE_CHILDREN)
    return ru.ru_utime + ru.ru_stime


def run_pomdpsol(path: Path, timeout: float) -> dict:
    """Run SARSOP's ``pomdpsol`` as for the recorded peer results; parse the last summary row for the bounds."""
    with tempfile.TemporaryDirectory() as tmp:
        cmd = ["pomdpsol", "--timeout", f"{timeout:g}", "--precision", "1e-3", "-o", str(Path(tmp) / "out.policy"),
               str(path)]
        t0, c0 = time.perf_counter(), _children_cpu()
        try:
            proc = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout * 3 + 60)
        except subprocess.TimeoutExpired:
            return {"error": "did not exit", "wall_seconds": time.perf_counter() - t0}
        wall, cpu = time.perf_counter() - t0, _children_cpu() - c0
    # Summary rows: "time  #Trial  #Backup  LBound  UBound  Precision  #Alphas  #Beliefs"
    rows = [ln.split() for ln in proc.stdout.splitlines() if re.match(r"^\s*\d+(\.\d+)?\s+\d+\s+\d+\s+" + _NUM, ln)]
    out = {"wall_seconds": round(wall, 3), "cpu_seconds": round(cpu, 3), "returncode": proc.returncode}
    if rows:
        last = rows[-1]
        out.update({"solve_seconds": float(last[0]), "lower_bound": float(last[3]), "upper_bound": float(last[4]),
                    "alpha_vectors": int(last[6]) if len(last) > 6 else None})
    return out


def run_pomdp_solve(path: Path, horizon, timeout: float, b0: np.ndarray) -> dict:
    """Run pomdp-solve's incprune; count vectors in the .alpha file and take max α·b0."""
    with tempfile.TemporaryDirectory() as tmp:
        prefix = str(Path(tmp) / "out")
        cmd = ["pomdp-solve", "-pomdp", str(path), "-method", "incprune", "-o", prefix]
        if horizon is not None:
            cmd[5:5] = ["-horizon", str(horizon)]
        t0, c0 = time.perf_counter(), _children_cpu()
        try:
            subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, cwd=tmp)
        except subprocess.TimeoutExpired:
            return {"finished": False, "wall_seconds": round(time.perf_counter() - t0, 3)}
        wall, cpu = time.perf_counter() - t0, _children_cpu() - c0
        alpha = Path(prefix + ".alpha")
        if not alpha.is_file():
            return {"finished": False, "wall_seconds": round(wall, 3), "error": "no .alpha file"}
        nums = alpha.read_text().split()
    S = b0.shape[0]
    vecs = np.array([float(x) for x in nums]).reshape(-1, S + 1)[:, 1:]
    return {"finished": True, "wall_seconds": round(wall, 3), "cpu_seconds": round(cpu, 3),
            "alpha_vectors": int(vecs.shape[0]),
            "value_at_start": float((vecs @ b0).max())}


# -------------------------------------------------------------------- main


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--problems", default=None, help="comma-separated names (file name with or without extension)")
    ap.add_argument("--methods", default="incprune,pointbased,qmdp")
    ap.add_argument("--time-limit", type=float, default=60.0, help="pointbased time limit, s (default 60)")
    ap.add_argument("--incprune-time-limit", type=float, default=300.0, help="cap per incprune run, s (default 300)")
    ap.add_argument("--peer-results", metavar="FILE", default=None,
                    help="markdown tables of the peers' recorded runs (pomdp-solve, SARSOP); without it no peer columns")
    ap.add_argument("--horizons", default="10", help="incprune horizons without --peer-results (default 10)")
    ap.add_argument("--no-peers", action="store_true", help="do not run pomdpsol/pomdp-solve even if on PATH")
    args = ap.parse_args()

    from tqdm import tqdm

    from pearl_pomdp.jsonable import numpy_to_json
    from pearl_pomdp.model import load_model

    results = peer_results(args.peer_results)
    refs = parse_results(results) if results is not None else {"sarsop": {}, "pomdp_solve": {}}
    own_horizons = {h.strip(): {"finished": True} for h in args.horizons.split(",") if h.strip()}
    files = sorted(model_files())
    if args.problems:
        wanted = [w.strip().lower() for w in args.problems.split(",") if w.strip()]
        names = {p: {p.name.lower(), p.stem.lower()} for p in files}
        unknown = [w for w in wanted if not any(w in n for n in names.values())]
        if unknown:
            sys.exit(f"bench/solvers.py: unknown problem(s) {', '.join(unknown)}; "
                     f"known: {', '.join(p.stem for p in files)}")
        files = [p for p in files if names[p] & set(wanted)]
    methods = [m.strip() for m in args.methods.split(",") if m.strip()]
    peers = {} if args.no_peers else {n: shutil.which(n) for n in ("pomdpsol", "pomdp-solve")}
    peers = {k: v for k, v in peers.items() if v}

    problems = {}
    bar = tqdm(files, desc="solvers", unit="model", file=sys.stderr)
    for path in bar:
        bar.set_postfix_str(path.name)
        t0 = time.perf_counter()
        entry: dict = {}
        try:
            model = load_model(path)
        except Exception as err:  # noqa: BLE001 - the benchmark reports, then goes on
            problems[path.name] = {"error": f"load: {type(err).__name__}: {err}"}
            continue
        entry["load_seconds"] = round(time.perf_counter() - t0, 3)
        entry["S/A/O"] = f"{model.num_states}/{model.num_actions}/{model.num_observations}"
        ps_rows = refs["pomdp_solve"].get(path.name, {}) if results is not None else own_horizons
        sarsop_row = refs["sarsop"].get(path.name) if results is not None else {}

        if "incprune" in methods:
            runs = []
            for horizon_text, ref in ps_rows.items():
                if not ref["finished"]:
                    continue
                horizon = None if horizon_text == "inf" else int(horizon_text)
                bar.set_postfix_str(f"{path.name} incprune h={horizon_text}")
                try:
                    run = run_incprune(model, horizon, args.incprune_time_limit, ref)
                except Exception as err:  # noqa: BLE001
                    run = {"horizon": horizon_text, "error": f"{type(err).__name__}: {err}"}
                if "pomdp-solve" in peers:
                    peer = run_pomdp_solve(path, horizon, args.incprune_time_limit, model.b0)
                    run["peer_pomdp_solve"] = peer
                    if run.get("complete") and peer.get("finished"):
                        run["time_ratio_vs_peer_here"] = _ratio(run["ours"]["seconds"], peer["wall_seconds"])
                        run["cpu_ratio_vs_peer_here"] = _ratio(run["ours"]["cpu_seconds"], peer["cpu_seconds"])
                        run["value_diff_vs_peer_here"] = float(run["ours"]["value_at_start"] - peer["value_at_start"])
                runs.append(run)
            if runs:
                entry["incprune"] = runs
            else:
                entry["incprune"] = {"skipped": "pomdp-solve did not finish 10 epochs within 300 s in the peer results"}

        if "pointbased" in methods and sarsop_row is not None:
            bar.set_postfix_str(f"{path.name} pointbased")
            try:
                entry["pointbased"] = run_pointbased(model, args.time_limit, sarsop_row)
            except Exception as err:  # noqa: BLE001
                entry["pointbased"] = {"error": f"{type(err).__name__}: {err}"}
            if "pomdpsol" in peers:
                peer = run_pomdpsol(path, args.time_limit)
                entry["pointbased"]["peer_pomdpsol"] = peer
                if "ours" in entry["pointbased"] and peer.get("lower_bound") is not None:
                    ours = entry["pointbased"]["ours"]
                    entry["pointbased"]["time_ratio_vs_peer_here"] = _ratio(ours["seconds"], peer["wall_seconds"])
                    entry["pointbased"]["cpu_ratio_vs_peer_here"] = _ratio(ours["cpu_seconds"], peer["cpu_seconds"])
                    lb = peer["lower_bound"]
                    entry["pointbased"]["lower_bound_shortfall_pct_vs_peer_here"] = (
                        _round((lb - ours["lower_bound"]) / abs(lb) * 100, 4) if lb else None)

        if "qmdp" in methods:
            try:
                entry["qmdp"] = run_qmdp(model)
            except Exception as err:  # noqa: BLE001
                entry["qmdp"] = {"error": f"{type(err).__name__}: {err}"}
        problems[path.name] = entry
        del model

    def collect(key, pred):
        return [name for name, e in problems.items() if pred(e.get(key))]

    summary = {
        "incprune_runs": sum(len(e["incprune"]) for e in problems.values() if isinstance(e.get("incprune"), list)),
        "incprune_vector_counts_matching": sum(
            bool(r.get("vectors_match")) for e in problems.values() if isinstance(e.get("incprune"), list)
            for r in e["incprune"]),
        "incprune_max_abs_value_diff": max(
            [abs(r["value_diff"]) for e in problems.values() if isinstance(e.get("incprune"), list)
             for r in e["incprune"] if r.get("complete") and "value_diff" in r] or [None], key=lambda x: x or 0),
        "pointbased_within_2pct_of_sarsop_lb": collect("pointbased", lambda p: bool(p and p.get("within_2pct_of_sarsop_lb"))),
        "pointbased_not_within_2pct": collect("pointbased", lambda p: bool(p and p.get("within_2pct_of_sarsop_lb") is False)),
    }
    print(json.dumps({
        "benchmark": "solvers",
        "load_average_1min_at_end": round(os.getloadavg()[0], 2),
        "reference": None if results is None else str(results),
        "machine": {"cpus": os.cpu_count(), "python": platform.python_version(), "platform": platform.platform()},
        "options": {"problems": [p.name for p in files], "methods": methods, "pointbased_time_limit": args.time_limit,
                    "incprune_time_limit": args.incprune_time_limit, "peers_on_path": sorted(peers)},
        "problems": problems,
        "summary": summary,
    }, default=numpy_to_json))


if __name__ == "__main__":
    main()
