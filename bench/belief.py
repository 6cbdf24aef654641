"""Belief-update throughput on a 576-state model (issue 3, item 3: target ≥ 50,000 updates/s).

Times :meth:`pearl_pomdp.belief.BeliefFilter.update` (the public, validating call) over a
chain of updates, against a naive per-state Python loop of eq. 5 in the same run.

The model is the Pearl domain ``config/pearl.domain.yaml`` (via ``load_model``) when it
exists, else a seeded random sparse model of the same size (576 states, 19 actions,
18 observations) whose transition rows have 1, 2, 4 or 8 successors — a factored domain
where each action changes a few features stochastically has rows of that kind.
The output says which model was used.

    .venv/bin/python bench/belief.py [--updates 20000] [--naive-updates 20] [--model PATH]

Prints one JSON object. ``updates_per_second`` is wall-clock; on the shared 2-core machine
also look at ``updates_per_cpu_second`` and ``load_average_1min``.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np
import scipy.sparse as sp

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from pearl_pomdp.belief import BeliefFilter  # noqa: E402
from pearl_pomdp.model.pomdp import Pomdp  # noqa: E402

TARGET = 50_000


def random_pearl_sized(seed: int = 0) -> Pomdp:
    """576 states / 19 actions / 18 observations, sparse T (1–8 successors per row)."""
    S, A, Z = 576, 19, 18
    rng = np.random.default_rng(seed)
    T = []
    for _ in range(A):
        rows, cols, vals = [], [], []
        for s in range(S):
            k = int(rng.choice([1, 2, 4, 8]))
            succ = rng.choice(S, size=k, replace=False)
            p = rng.dirichlet(np.ones(k))
            rows += [s] * k
            cols += list(succ)
            vals += list(p)
        T.append(sp.csr_matrix((vals, (rows, cols)), shape=(S, S)))
    O = rng.dirichlet(np.full(Z, 0.3), size=(A, S))
    R = rng.normal(size=(S, A))
    return Pomdp.create([f"s{i}" for i in range(S)], [f"a{i}" for i in range(A)], [f"o{i}" for i in range(Z)],
                        T, O, R, sparse=True, name="random-576")


def naive_update(T_lists, O, b, a, o):
    """Eq. 5 as a per-state Python loop over dense lists (the baseline)."""
    S = len(b)
    Ta = T_lists[a]
    out = [0.0] * S
    for s2 in range(S):
        acc = 0.0
        for s in range(S):
            acc += Ta[s][s2] * b[s]
        out[s2] = O[a][s2][o] * acc
    total = sum(out)
    return [x / total for x in out]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--updates", type=int, default=20000)
    ap.add_argument("--naive-updates", type=int, default=20)
    ap.add_argument("--model", default=str(REPO / "config" / "pearl.domain.yaml"))
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()

    model_path = Path(args.model)
    if model_path.is_file():
        from pearl_pomdp.model import load_model

        model = load_model(model_path)
        source = str(model_path.relative_to(REPO) if model_path.is_relative_to(REPO) else model_path)
    else:
        model = random_pearl_sized(args.seed)
        source = "random sparse 576/19/18 (rows with 1, 2, 4 or 8 successors; config/pearl.domain.yaml absent)"

    rng = np.random.default_rng(args.seed)
    f = BeliefFilter(model)
    # A plausible (action, observation) chain: observations drawn from P(o | b, a).
    b = f.initial()
    seq = []
    for _ in range(args.updates):
        a = int(rng.integers(model.num_actions))
        lik = f.observation_likelihood(b, a)
        o = int(rng.choice(model.num_observations, p=lik / lik.sum()))
        seq.append((a, o))
        b = f.update(b, a, o)

    f = BeliefFilter(model)
    b = f.initial()
    c0, t0 = time.process_time(), time.perf_counter()
    for a, o in seq:
        b = f.update(b, a, o)
    fast_s = time.perf_counter() - t0
    fast_cpu = time.process_time() - c0
    fast_rate = args.updates / fast_s

    chain_recoveries = f.zero_likelihood_count

    # Batch path (used by simulation): 1000 copies of b0, each with a random action and an
    # observation drawn from P(o | b0, a).
    fb = BeliefFilter(model)
    B = np.tile(fb.initial(), (1000, 1))
    acts = rng.integers(model.num_actions, size=1000)
    obs = np.array([rng.choice(model.num_observations, p=fb.observation_likelihood(fb.initial(), a)) for a in acts])
    t0 = time.perf_counter()
    reps = 5
    for _ in range(reps):
        fb.update_batch(B, acts, obs)
    batch_rate = reps * 1000 / (time.perf_counter() - t0)

    T_lists = [(Ta.toarray() if sp.issparse(Ta) else np.asarray(Ta)).tolist() for Ta in model.T]
    O_lists = model.O.tolist()
    bn = model.b0.tolist()
    n_naive = min(args.naive_updates, len(seq))
    t0 = time.perf_counter()
    for a, o in seq[:n_naive]:
        bn = naive_update(T_lists, O_lists, bn, a, o)
    naive_rate = n_naive / (time.perf_counter() - t0)
    # Same chain, same answer.
    check = f.initial()
    g = BeliefFilter(model)
    for a, o in seq[:n_naive]:
        check = g.update(check, a, o)
    max_diff = float(np.max(np.abs(check - np.array(bn))))

    nnz = [Ta.nnz if sp.issparse(Ta) else int(np.count_nonzero(Ta)) for Ta in model.T]
    print(json.dumps({
        "benchmark": "belief_update",
        "model": source,
        "states": model.num_states, "actions": model.num_actions, "observations": model.num_observations,
        "mean_successors_per_row": round(float(np.mean(nnz)) / model.num_states, 2),
        "updates": args.updates,
        "updates_per_second": round(fast_rate),
        "microseconds_per_update": round(1e6 / fast_rate, 2),
        # The machine is shared: CPU time counts only the cycles this process got.
        "updates_per_cpu_second": round(args.updates / fast_cpu),
        "batch_updates_per_second": round(batch_rate),
        "naive_updates": n_naive,
        "naive_updates_per_second": round(naive_rate, 1),
        "speedup_vs_naive": round(fast_rate / naive_rate, 1),
        "naive_vs_filter_max_abs_diff": max_diff,
        "zero_likelihood_recoveries": chain_recoveries + fb.zero_likelihood_count,
        "load_average_1min": round(os.getloadavg()[0], 2),
        "cpus": os.cpu_count(),
        "target_updates_per_second": TARGET,
        "target_met": bool(fast_rate >= TARGET),
        "target_met_per_cpu_second": bool(args.updates / fast_cpu >= TARGET),
    }))


if __name__ == "__main__":
    main()
