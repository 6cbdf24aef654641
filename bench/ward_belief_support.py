"""What the ward's beliefs carry: their support (states with b(s) > 0) along the study's episodes; one JSON object.

Compiles ``config/ward.domain.yaml`` (233,280 states), plans ``config/ward.hierarchy.yaml`` (the
study's hierarchical policy) and runs the episodes of the study file through the core executive in
the simulated ward (``pearl_sim.ward.study.run_ward_episode``, the study's world and noise), keeping
the support of ``b0`` and of every belief the tracker closes a step with. Reports per episode and
pooled the support as a fraction of the states (p50 / p90 / max), the states ``/pearl/belief``
lists (those that differ from ``outside_support``: 0, or the smallest value when every state is
above 0 — after a zero-likelihood recovery's uniform floor) and the belief's bytes there: the
complete vector (8 bytes a state) or the listed states (4 + 8 bytes each), whichever is smaller —
what the tracker sends (docs/ros-nodes.md, "The belief on the wire").

    OMP_NUM_THREADS=1 .venv/bin/python bench/ward_belief_support.py [--episodes quiet_morning,busy_ward]
        [--noise 0.1] [--seed-index 0]
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))


def _fractions(values, total: int) -> dict:
    import numpy as np

    v = np.asarray(values, dtype=float) / total
    return {"p50": round(float(np.percentile(v, 50)), 4), "p90": round(float(np.percentile(v, 90)), 4),
            "max": round(float(v.max()), 4), "min": round(float(v.min()), 4), "n": int(v.size)}


def add_ward_files(ap: argparse.ArgumentParser) -> None:
    """The ward's domain, hierarchy, node parameters and study file as ``ap``'s options."""
    ap.add_argument("--domain", default=str(REPO / "config/ward.domain.yaml"))
    ap.add_argument("--hierarchy", default=str(REPO / "config/ward.hierarchy.yaml"))
    ap.add_argument("--params", default=str(REPO / "config/ward_nodes.yaml"))
    ap.add_argument("--study", default=str(REPO / "config/scenarios/ward/study.yaml"))


def add_study_arguments(ap: argparse.ArgumentParser, episodes: str = "") -> None:
    """The ward study's files, episodes, noise and seeds as ``ap``'s options (``episodes``: the default)."""
    add_ward_files(ap)
    ap.add_argument("--episodes", default=episodes,
                    help=f"episodes of the study file, comma-separated (default: {episodes or 'all'})")
    ap.add_argument("--noise", type=float, default=0.1, help="recogniser word error rate")
    ap.add_argument("--seed-index", type=int, default=0, help="k: the world's seed is the episode's + 1000 k")
    ap.add_argument("--seed", type=int, default=0, help="the planner's seed")


def study_beliefs(ap: argparse.ArgumentParser, args: argparse.Namespace, on_belief) -> dict:
    """Plan the hierarchy and run the episodes ``args`` names (:func:`add_study_arguments`), calling
    ``on_belief(episode_name, belief)`` with ``b0`` and each belief the tracker closes a step with.
    Returns ``{"states", "plan_s", "steps": {episode: steps}}``."""
    from pearl_pomdp.hierarchy import load_hierarchy, plan
    from pearl_pomdp.model.domain_yaml import load_domain
    from pearl_sim.planning import Controller
    from pearl_sim.ward.scenario import load_ward_scenarios
    from pearl_sim.ward.study import run_ward_episode

    domain = load_domain(args.domain)
    model = domain.compile()
    t0 = time.perf_counter()
    policy = plan(domain, load_hierarchy(args.hierarchy, domain), seed=args.seed)
    plan_s = time.perf_counter() - t0
    scenarios = load_ward_scenarios(args.study)
    wanted = [n for n in args.episodes.split(",") if n]
    unknown = sorted(set(wanted) - {s.name for s in scenarios})
    if unknown:
        ap.error(f"--episodes: {', '.join(unknown)} not in {args.study}")
    steps = {}
    for scenario in scenarios:
        if wanted and scenario.name not in wanted:
            continue
        on_belief(scenario.name, model.b0)
        episode = run_ward_episode(scenario, Controller("hierarchical", policy), domain, args.params,
                                   seed=scenario.seed + 1000 * args.seed_index, word_error_rate=args.noise,
                                   model=model,
                                   on_step=lambda world, result, waits, ex, name=scenario.name: on_belief(name, ex.belief))
        steps[scenario.name] = episode.steps
    return {"states": model.num_states, "plan_s": plan_s, "steps": steps}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_study_arguments(ap)
    args = ap.parse_args()

    import numpy as np

    load_start = os.getloadavg()
    support: dict = {}
    listed: dict = {}

    def count(name, b):
        k = int(np.count_nonzero(b > 0))
        support.setdefault(name, []).append(k)
        listed.setdefault(name, []).append(k if k < b.size else int(np.count_nonzero(b != b.min())))

    walk = study_beliefs(ap, args, count)
    S, plan_s = walk["states"], walk["plan_s"]
    episodes, pooled, pooled_listed = [], [], []
    for name, steps in walk["steps"].items():
        pooled.extend(support[name])
        pooled_listed.extend(listed[name])
        episodes.append({"name": name, "steps": steps, "beliefs": len(support[name]),
                         "support_fraction": _fractions(support[name], S),
                         "listed_fraction": _fractions(listed[name], S),
                         "support_states_first": support[name][:6], "support_states_last": support[name][-1]})
    dense = 8 * S
    # On the wire: the listed states' indices and values, or the complete vector, whichever is smaller.
    wire = [min(4 + 12 * k, dense) for k in pooled_listed]
    print(json.dumps({
        "bench": "ward_belief_support", "domain": args.domain, "states": S, "noise": args.noise,
        "plan_s": round(plan_s, 1), "episodes": episodes,
        "pooled": {"beliefs": len(pooled), "support_fraction": _fractions(pooled, S),
                   "listed_fraction": _fractions(pooled_listed, S), "complete_bytes": dense,
                   "wire_bytes": {"p50": int(np.percentile(wire, 50)), "p90": int(np.percentile(wire, 90)),
                                  "p99": int(np.percentile(wire, 99)), "max": int(max(wire))},
                   "listed_smaller": f"{sum(w < dense for w in wire)}/{len(wire)}"},
        "load": {"start": [round(x, 2) for x in load_start], "end": [round(x, 2) for x in os.getloadavg()]},
    }, indent=1 if sys.stdout.isatty() else None))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
