"""The MDP bounds' set-up time (QMDP's value and the blind policies) against plain value iteration; one JSON object.

The online planner and the hierarchy's online root compute, at every start, the fully observed
MDP's values (QMDP, the upper bound) and the blind policies' values (the lower bound).
``pearl_pomdp.solvers.mdp`` solves them by policy iteration with certified results; this script
times it, in one run and on the same loaded model, beside plain value iteration written out here
(the method the project used before: Bellman sweeps from ``R_max/(1-γ)`` until successive
iterates differ by ``ε(1-γ)/(2γ)``, ε = 1e-6; blind sweeps from ``R_min/(1-γ)``), and reports
how far apart the answers are and whether each bound holds on the other's values. Loading and
compiling are start-up and are reported apart. Per model: ``seconds`` (wall) of both methods,
``ratio`` (plain / ours), policy evaluations, ``max_abs_difference`` of V and of the blind vectors.

    python bench/mdp_bounds.py                              # the ward, Pearl, RockSample(7,8), Tag
    python bench/mdp_bounds.py --only config/pearl.domain.yaml
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
sys.path.insert(0, str(REPO / "bench"))

from models import model_dir  # noqa: E402  (bench/models.py: test/data/pomdp)

MODELS = ["config/ward.domain.yaml", "config/pearl.domain.yaml", "RockSample_7_8.pomdp", "TagAvoid.pomdp"]


def load(name: str):
    from pearl_pomdp.model.domain_yaml import load_domain
    from pearl_pomdp.model.pomdp_format import read_pomdp

    if name.endswith(".yaml"):
        return load_domain(REPO / name).compile()
    return read_pomdp(model_dir() / name)


def plain_value_iteration(mats, R, g, epsilon=1e-6):
    """Bellman sweeps from the optimistic constant (each iterate an upper bound)."""
    tol = epsilon * (1.0 - g) / (2.0 * g)
    V = np.full(R.shape[0], R.max() / (1.0 - g))
    sweeps = 0
    while True:
        sweeps += 1
        Vn = np.max(np.stack([R[:, a] + g * (Ta @ V) for a, Ta in enumerate(mats)], axis=1), axis=1)
        done = float(np.max(np.abs(Vn - V))) <= tol
        V = Vn
        if done:
            return V, sweeps


def plain_blind(mats, R, g, epsilon=1e-6):
    """Each action's fixed-point sweeps from its worst constant (each iterate a lower bound)."""
    tol = epsilon * (1.0 - g) / (2.0 * g)
    out = np.empty((R.shape[1], R.shape[0]))
    for a, Ta in enumerate(mats):
        v = np.full(R.shape[0], R[:, a].min() / (1.0 - g))
        while True:
            vn = np.maximum(R[:, a] + g * (Ta @ v), v)
            done = float(np.max(vn - v)) <= tol
            v = vn
            if done:
                break
        out[a] = v
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", nargs="*", default=None, help="models to run (names as in the default list)")
    ap.add_argument("--json", action="store_true", help="accepted for symmetry: the output is always one JSON object")
    args = ap.parse_args()
    from pearl_pomdp.solvers import mdp

    evaluations = [0]
    policy_matrix = mdp._policy_matrix

    def counting(mats, actions):
        evaluations[0] += 1
        return policy_matrix(mats, actions)

    mdp._policy_matrix = counting  # count policy iteration's evaluations (same function underneath)
    out = {"loadavg_start": round(os.getloadavg()[0], 2), "epsilon": 1e-6, "models": {}}
    for name in args.only or MODELS:
        if sys.stderr.isatty():
            print(f"[mdp_bounds] {name} ...", file=sys.stderr, flush=True)
        t = time.perf_counter()
        model = load(name)
        startup = time.perf_counter() - t
        mats = mdp._transition_mats(model)
        R = np.asarray(model.R, dtype=float)
        g = float(model.discount)
        evaluations[0] = 0
        t = time.perf_counter()
        V, _ = mdp.mdp_value_iteration(model)
        ours_v = time.perf_counter() - t
        policy_evaluations = evaluations[0]
        t = time.perf_counter()
        blind = mdp.blind_lower_bound(model)
        ours_b = time.perf_counter() - t
        t = time.perf_counter()
        V_plain, sweeps = plain_value_iteration(mats, R, g)
        plain_v = time.perf_counter() - t
        t = time.perf_counter()
        blind_plain = plain_blind(mats, R, g)
        plain_b = time.perf_counter() - t
        out["models"][name] = {
            "states": model.num_states, "actions": model.num_actions, "load_and_compile_s": round(startup, 3),
            "qmdp_values": {"ours_s": round(ours_v, 3), "plain_value_iteration_s": round(plain_v, 3),
                            "ratio": round(plain_v / ours_v, 1), "policy_evaluations": policy_evaluations,
                            "plain_sweeps": sweeps, "max_abs_difference": float(np.abs(V - V_plain).max())},
            "blind_policies": {"ours_s": round(ours_b, 3), "plain_sweeps_s": round(plain_b, 3),
                               "ratio": round(plain_b / ours_b, 1),
                               "max_abs_difference": float(np.abs(blind - blind_plain).max())},
        }
    out["loadavg_end"] = round(os.getloadavg()[0], 2)
    print(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
