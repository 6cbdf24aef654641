"""The online planner's memory over a long ward episode; one JSON object (docs/ward.md, issue 24 part 2).

Compiles ``config/ward.domain.yaml`` (233,280 states), builds the online decider (DESPOT, QMDP and
blind bounds) and runs it through the core executive in the simulated ward for ``--steps``
actions (default 1000: a long shift — every resident's medication every 15 minutes, a request
every 5–7 minutes, moves between room and lounge). Reports the process's peak resident set size
(``ru_maxrss``: compile and bounds included), the largest RSS sampled after each step, the RSS
after setup, the largest arrays held, and the decisions' wall times (p50/p99/max).

    python bench/ward_memory.py [--steps 1000] [--trials 5] [--noise 0.2] [--seed 0]
"""
from __future__ import annotations

import argparse
import json
import resource
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))


def rss_mb() -> float:
    """The resident set size now (MB), from /proc/self/statm."""
    import os

    with open("/proc/self/statm") as f:
        pages = int(f.read().split()[1])
    return pages * os.sysconf("SC_PAGE_SIZE") / 2 ** 20


_NO_BELIEF = None  # set in main (an empty array)


def peak_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def long_shift(steps: int, seed: int):
    """A ward scenario long enough for ``steps`` actions: the study's ward, with recurring events."""
    from pearl_sim.ward.scenario import Resident, WardScenario

    hours = 4 * 3600.0
    residents = []
    for i, name in enumerate(("Ann", "Bob", "Cleo")):
        pills = [600.0 + 300 * i + 900 * k for k in range(int(hours // 900))]
        period = 300.0 + 60 * i
        needs = ("water", "help", "talk") if i != 1 else ("water", "talk", "help")
        requests = [(120.0 + 97 * i + period * k, needs[k % 3]) for k in range(int(hours // period))]
        moves = [(400.0 + 1800 * k + 200 * i, "lounge" if k % 2 == 0 else "room") for k in range(int(hours // 1800))]
        residents.append(Resident(name=name, pills=pills, requests=requests, moves=moves))
    return WardScenario(name="long_shift", seed=seed, max_steps=steps, residents=residents)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--domain", default=str(REPO / "config/ward.domain.yaml"))
    ap.add_argument("--params", default=str(REPO / "config/ward_nodes.yaml"))
    ap.add_argument("--steps", type=int, default=1000)
    ap.add_argument("--trials", type=int, default=5, help="DESPOT trials a decision (online:TRIALS)")
    ap.add_argument("--noise", type=float, default=0.2, help="recogniser word error rate")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()

    import numpy as np

    from pearl_pomdp.model.domain_yaml import load_domain
    from pearl_sim.ward.study import run_ward_episode, ward_agents

    global _NO_BELIEF
    _NO_BELIEF = np.zeros(0)
    start = rss_mb()
    t0 = time.perf_counter()
    domain = load_domain(args.domain)
    model = domain.compile()
    compiled = {"seconds": round(time.perf_counter() - t0, 1), "rss_mb": round(rss_mb(), 1), "peak_mb": round(peak_mb(), 1)}
    t0 = time.perf_counter()
    agents = ward_agents(domain, None, policies=[f"online:{args.trials}"], seed=args.seed)
    agent = agents[f"online:{args.trials}"]
    setup = {"seconds": round(time.perf_counter() - t0, 1), "rss_mb": round(rss_mb(), 1), "peak_mb": round(peak_mb(), 1)}
    samples = []

    def on_step(world, result, waits, executive) -> None:
        # The core Executive records every closed step with its [S] belief (1.8 MB here: 1.8 GB over
        # 1000 steps) for the study's scoring; the robot's tracker node keeps no history. Keep the
        # last step's belief only, so the figure is the planner's and the tracker's memory.
        for closed in executive.steps[:-1]:
            closed.belief = _NO_BELIEF
        samples.append(rss_mb())
        if sys.stderr.isatty() and len(samples) % 50 == 0:
            print(f"step {len(samples)}: rss {samples[-1]:.0f} MB", file=sys.stderr, flush=True)

    t0 = time.perf_counter()
    episode = run_ward_episode(long_shift(args.steps, args.seed), agent, domain, args.params, seed=args.seed,
                               word_error_rate=args.noise, model=model, on_step=on_step)
    secs = np.array(episode.decision_seconds)
    arrays = {"O [A,S,Z] float64": model.O.nbytes,
              "T (CSR data + indices + indptr, all actions)": sum(t.data.nbytes + t.indices.nbytes + t.indptr.nbytes
                                                                 for t in model.T),
              "R [S,A]": model.R.nbytes,
              "bounds: upper Q [S,A]": agent.decider.bounds.upper_q.nbytes,
              "bounds: lower α [S,K]": agent.decider.bounds.lower_alphas_t.nbytes}
    report = {
        "bench": "ward_memory", "domain": args.domain, "states": model.num_states, "actions": model.num_actions,
        "observations": model.num_observations, "policy": f"online:{args.trials}", "bounds": agent.decider.bounds.description,
        "steps": episode.steps, "episode_seconds": round(time.perf_counter() - t0, 1),
        "rss_mb": {"start": round(start, 1), "after_compile": compiled["rss_mb"], "after_setup": setup["rss_mb"],
                   "episode_max": round(max(samples), 1) if samples else None, "peak_ru_maxrss": round(peak_mb(), 1)},
        "peak_under_1_gib": peak_mb() < 1024.0,
        "seconds": {"compile": compiled["seconds"], "bounds": setup["seconds"]},
        "arrays_mb": {k: round(v / 2 ** 20, 1) for k, v in sorted(arrays.items(), key=lambda kv: -kv[1])},
        "decision_ms": {"p50": round(1000 * float(np.percentile(secs, 50)), 1),
                        "p99": round(1000 * float(np.percentile(secs, 99)), 1),
                        "max": round(1000 * float(secs.max()), 1), "n": int(secs.size)},
        "episode": {"requests": episode.requests, "requests_met": episode.requests_met, "pills": episode.pills,
                    "pills_taken": episode.pills_taken, "wrong_actions": episode.wrong_actions,
                    "discounted_return": round(episode.discounted_return, 2)},
    }
    print(json.dumps(report, indent=1 if sys.stdout.isatty() else None))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
