"""In-process decision times of the flat online planner on the ward (issue 24); one JSON object.

Compiles ``config/ward.domain.yaml`` (233,280 states), computes the online decider's default
bounds once (QMDP above, blind policies below; not timed) and walks ``--decisions``
beliefs: ``b0``, then each next belief from the decision's action, a true state drawn from the
belief, its step and the tracker's update (``BeliefFilter``). The same beliefs are then decided
by ``OnlineDecider(model, bounds, DespotSettings(trials=T)).execute(belief)`` for every ``T`` of
``--trials`` and every step engine of ``--engines``:

* ``model``: ``ExplicitModel.step`` as shipped (the C kernel ``_step_kernel.step``);
* ``numpy``: the same draws by the numpy reference of the kernel's definition
  (``test/test_step_kernel.py``: ``reference_step``), the numpy cost the kernel replaced.

Per configuration: wall ms per decision p50/p99/max (``time.perf_counter``) and CPU ms
(``time.process_time``), the actions and tree sizes (so two engines can be seen to build the same
trees), and the machine's load before and after. ``--profile`` adds the top functions
(cProfile, by own time) of the first configuration's decisions.

    OMP_NUM_THREADS=1 .venv/bin/python bench/ward_decision.py [--trials 5,20] [--engines model,numpy]
        [--decisions 11] [--seed 0] [--profile]
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


def _stats(ms):
    import numpy as np

    v = np.asarray(ms, dtype=float)
    return {"p50": round(float(np.percentile(v, 50)), 1), "p99": round(float(np.percentile(v, 99)), 1),
            "max": round(float(v.max()), 1), "n": int(v.size)}


def _decider(model, bounds, trials: int, engine: str):
    from pearl_pomdp.online.decider import OnlineDecider
    from pearl_pomdp.online.despot import DespotSettings

    decider = OnlineDecider(model, bounds=bounds, settings=DespotSettings(trials=trials))
    if engine == "numpy":
        sys.path.insert(0, str(REPO / "test"))
        from test_step_kernel import reference_step

        g = decider.generative
        g.step = lambda states, action, uniforms: reference_step(g, states, action, uniforms)  # type: ignore[method-assign]
        g.step_many = None                      # (the search then steps one action at a time)
    elif engine != "model":
        raise SystemExit(f"--engines: {engine!r} is not one of model, numpy")
    return decider


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--domain", default=str(REPO / "config/ward.domain.yaml"))
    ap.add_argument("--trials", default="5,20", help="trials per decision, comma-separated")
    ap.add_argument("--engines", default="model", help="step engines, comma-separated: model, numpy")
    ap.add_argument("--decisions", type=int, default=11)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--profile", action="store_true", help="cProfile the first configuration's decisions")
    args = ap.parse_args()
    trials = [int(t) for t in args.trials.split(",")]
    engines = args.engines.split(",")

    import numpy as np

    from pearl_pomdp.belief import BeliefFilter
    from pearl_pomdp.model.domain_yaml import load_domain
    from pearl_pomdp.online.decider import default_bounds
    from pearl_pomdp.online.generative import sample_step

    load_start = os.getloadavg()
    t0 = time.perf_counter()
    model = load_domain(args.domain).compile()
    compile_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    bounds = default_bounds(model)
    bounds_s = time.perf_counter() - t0

    # The beliefs: b0 and the tracker's beliefs along one seeded walk of the first configuration.
    walker = _decider(model, bounds, trials[0], engines[0])
    tracker = BeliefFilter(model)
    rng = np.random.default_rng(args.seed)
    b = tracker.initial()
    state = int(rng.choice(model.num_states, p=b))
    beliefs = [b]
    while len(beliefs) < args.decisions:
        a = walker.execute(b).action
        state, o, _ = sample_step(walker.generative, state, a, rng)
        b = tracker.update(b, a, o)
        beliefs.append(b)

    runs = []
    for engine in engines:
        for t in trials:
            decider = _decider(model, bounds, t, engine)
            wall, cpu, actions, nodes = [], [], [], []
            for belief in beliefs:
                w0, c0 = time.perf_counter(), time.process_time()
                d = decider.execute(belief)
                wall.append(1000 * (time.perf_counter() - w0))
                cpu.append(1000 * (time.process_time() - c0))
                actions.append(d.action_name)
                nodes.append(int(d.search["nodes"]))
            runs.append({"engine": engine, "trials": t, "wall_ms": _stats(wall), "cpu_ms": _stats(cpu),
                         "wall_ms_each": [round(x, 1) for x in wall], "actions": actions, "nodes": nodes})
    profile = None
    if args.profile:
        # Apart from the timed runs (cProfile slows every Python call down).
        import cProfile
        import pstats

        decider = _decider(model, bounds, trials[0], engines[0])
        prof = cProfile.Profile(time.process_time)   # (CPU seconds: a loaded machine shifts wall time)
        prof.enable()
        for belief in beliefs:
            decider.execute(belief)
        prof.disable()
        st = pstats.Stats(prof)
        entries = st.stats.items()  # type: ignore[attr-defined]
        total = sum(v[2] for _, v in entries)
        top = sorted(entries, key=lambda kv: -kv[1][2])[:12]
        profile = {"engine": engines[0], "trials": trials[0], "total_s": round(total, 3),
                   "top_by_own_time": [{"function": f"{Path(k[0]).name}:{k[1]}:{k[2]}", "calls": v[1],
                                        "own_s": round(v[2], 3), "cumulative_s": round(v[3], 3)} for k, v in top]}

    same = {}
    for t in trials:
        by_engine = [r for r in runs if r["trials"] == t]
        if len(by_engine) > 1:
            same[str(t)] = all(r["actions"] == by_engine[0]["actions"] and r["nodes"] == by_engine[0]["nodes"]
                               for r in by_engine)
    report = {"bench": "ward_decision", "domain": args.domain, "states": model.num_states,
              "actions": model.num_actions, "observations": model.num_observations, "decisions": len(beliefs),
              "seed": args.seed, "bounds": bounds.description, "omp_num_threads": os.environ.get("OMP_NUM_THREADS"),
              "seconds": {"compile": round(compile_s, 1), "bounds": round(bounds_s, 1)},
              "load": {"start": [round(x, 2) for x in load_start], "end": [round(x, 2) for x in os.getloadavg()]},
              "runs": runs, "same_actions_and_nodes_across_engines": same}
    if profile is not None:
        report["profile"] = profile
    print(json.dumps(report, indent=1 if sys.stdout.isatty() else None))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
