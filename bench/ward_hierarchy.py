"""The ward's hierarchy — per-resident subtasks planned offline under a root that plans online —
planned and run for one episode; one JSON object (docs/ward.md, "The hierarchy").

Plans ``config/ward.hierarchy.yaml`` (each subtask's states, features, seconds; the root's bounds and
its decision at b0), then runs the hierarchical policy through the core executive in the simulated
ward for one episode of the study file and reports every decision's wall time (p50/p99/max), the
root search's size (trials, nodes, expansions, root gap) and the episode's scores. Seconds are wall
and this process's CPU (a shared machine slows the wall clock, not the CPU work).

    python bench/ward_hierarchy.py [--episode quiet_morning] [--noise 0.1] [--seed-index 0] [--seed 0]
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "bench"))


def main() -> int:
    from ward_belief_support import add_ward_files

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_ward_files(ap)
    ap.add_argument("--episode", default="quiet_morning", help="an episode of the study file")
    ap.add_argument("--noise", type=float, default=0.1, help="recogniser word error rate")
    ap.add_argument("--seed-index", type=int, default=0, help="k: the world's seed is the episode's + 1000 k")
    ap.add_argument("--seed", type=int, default=0, help="the planner's seed")
    ap.add_argument("--compare-flat", type=int, default=20, metavar="N",
                    help="also time the flat online decider (DESPOT over all 15 actions, the root's trials and "
                         "bounds) at the episode's first N beliefs (0: not)")
    args = ap.parse_args()

    import numpy as np

    from pearl_pomdp.hierarchy import load_hierarchy, plan
    from pearl_pomdp.model.domain_yaml import load_domain
    from pearl_sim.planning import Controller
    from pearl_sim.ward.scenario import load_ward_scenarios
    from pearl_sim.ward.study import run_ward_episode

    def clocks():
        return time.perf_counter(), time.process_time()

    w0, c0 = clocks()
    domain = load_domain(args.domain)
    model = domain.compile()
    w1, c1 = clocks()
    policy = plan(domain, load_hierarchy(args.hierarchy, domain), seed=args.seed)
    w2, c2 = clocks()
    subtasks = [{k: s.get(k) for k in ("name", "solver", "states_abstract", "relevant_features", "seconds",
                                       "solve_seconds", "iterations", "stop_reason", "bounds_seconds", "b0_decision")}
                for s in policy.report["subtasks"]]

    searches = []
    beliefs: list = []

    class Recorded:
        """The policy, each decision's wall time and search record kept."""

        def __init__(self, inner):
            self.inner = inner

        def execute(self, belief):
            t, c = time.perf_counter(), time.process_time()
            d = self.inner.execute(belief)
            s = d.search or {}
            if len(beliefs) < args.compare_flat:
                beliefs.append(np.array(belief, dtype=float))
            searches.append({"seconds": time.perf_counter() - t, "cpu": time.process_time() - c,
                             "trace": [x.choice for x in d.trace],
                             **{k: s.get(k) for k in ("trials", "nodes", "expansions", "gap")}})
            return d

        def __getattr__(self, name):
            return getattr(self.inner, name)

    scenario = next((s for s in load_ward_scenarios(args.study) if s.name == args.episode), None)
    if scenario is None:
        ap.error(f"--episode {args.episode!r} is not in {args.study}")
    w3, c3 = clocks()
    episode = run_ward_episode(scenario, Controller("hierarchical", Recorded(policy)), domain, args.params,
                               seed=scenario.seed + 1000 * args.seed_index, word_error_rate=args.noise, model=model)
    w4, c4 = clocks()
    secs = np.array([s["seconds"] for s in searches])
    cpus = np.array([s["cpu"] for s in searches])

    def ms(q, values=None):
        v = secs if values is None else values
        return round(1000 * float(np.percentile(v, q)), 1) if v.size else None

    flat = None
    if beliefs:
        from pearl_pomdp.online.decider import OnlineDecider
        from pearl_pomdp.online.despot import DespotSettings

        root = policy.online_root
        online = OnlineDecider(model, bounds=root.bounds, settings=DespotSettings(trials=root.settings.trials),
                               seed=args.seed)
        own = np.array([s["cpu"] for s in searches[:len(beliefs)]])
        wall, cpu = [], []
        for b in beliefs:
            t, c = time.perf_counter(), time.process_time()
            online.execute(b)
            wall.append(time.perf_counter() - t)
            cpu.append(time.process_time() - c)
        flat = {"beliefs": len(beliefs), "trials": root.settings.trials,
                "flat_cpu_ms_p50": ms(50, np.array(cpu)), "flat_wall_ms_p50": ms(50, np.array(wall)),
                "hierarchy_cpu_ms_p50_same_beliefs": ms(50, own)}

    child = sum(1 for s in searches if len(s["trace"]) > 1)
    print(json.dumps({
        "domain": args.domain, "hierarchy": args.hierarchy, "states": model.num_states,
        "compile": {"wall_s": round(w1 - w0, 1), "cpu_s": round(c1 - c0, 1)},
        "plan": {"wall_s": round(w2 - w1, 1), "cpu_s": round(c2 - c1, 1), "subtasks": subtasks},
        "episode": {"name": scenario.name, "noise": args.noise, "seed": episode.seed, "steps": episode.steps,
                    "discounted_return": round(episode.discounted_return, 3), "success": episode.success,
                    "requests_met": f"{episode.requests_met}/{episode.requests}",
                    "pills_taken": f"{episode.pills_taken}/{episode.pills}", "wrong_actions": episode.wrong_actions,
                    "wall_s": round(w4 - w3, 1), "cpu_s": round(c4 - c3, 1), "actions": episode.actions},
        "decisions": {"n": int(secs.size), "p50_ms": ms(50), "p99_ms": ms(99), "max_ms": ms(100),
                      "cpu_p50_ms": ms(50, cpus), "cpu_p99_ms": ms(99, cpus),
                      "through_a_child": child,
                      "nodes_p50": float(np.median([s["nodes"] for s in searches])) if searches else None,
                      "expansions_p50": float(np.median([s["expansions"] for s in searches])) if searches else None,
                      "root_gap_p50": round(float(np.median([s["gap"] for s in searches])), 2) if searches else None},
        "flat_online_same_beliefs": flat,
    }, default=float))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
