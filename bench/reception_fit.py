"""Fit the reception domain to its simulated world with ``pearl fit``; one JSON object
(docs/reception.md, "Arm 2").

Training data: the study's six episodes (config/scenarios/reception/study.yaml) at the noise
levels 0, 0.2, 0.4 with seeds k = 100…104 (the evaluation uses k = 0…19), each run by the
reception behaviour tree and by the hierarchical policy planned on the domain being fitted; the
episodes, with the true state at the start of every action, go to ``pearl fit`` (counting,
prior strength 10). The JSON lists the rows fitted and the largest changes.

    python bench/reception_fit.py [--seeds 100,101,102,103,104] [--prior-strength 10]
                                  [--keep-designer Wish] [--out out/reception-fit]
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))


def main() -> int:
    from pearl_pomdp.fit import fit_domain, load_episodes, write_fitted
    from pearl_pomdp.model.domain_yaml import load_domain
    from pearl_sim.reception.scenario import load_reception_scenarios
    from pearl_sim.reception.study import reception_agents, run_reception_episode

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--domain", default=str(REPO / "config/reception.domain.yaml"))
    ap.add_argument("--hierarchy", default=str(REPO / "config/reception.hierarchy.yaml"))
    ap.add_argument("--study", default=str(REPO / "config/scenarios/reception/study.yaml"))
    ap.add_argument("--seeds", default="100,101,102,103,104", help="seed indices k (seed = episode seed + 1000 k)")
    ap.add_argument("--noise", default="0,0.2,0.4")
    ap.add_argument("--prior-strength", type=float, default=10.0)
    ap.add_argument("--top", type=int, default=10, help="largest row changes to list")
    ap.add_argument("--keep-designer", default="", metavar="FEATURE,…",
                    help="keep the designer's transition rows of these features (their fitted rows are dropped)")
    ap.add_argument("--out", default=str(REPO / "out/reception-fit"))
    args = ap.parse_args()

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    domain = load_domain(args.domain)
    model = domain.compile()
    params = REPO / "config/reception_nodes.yaml"
    scenarios = load_reception_scenarios(args.study)
    seeds = [int(k) for k in args.seeds.split(",")]
    noise = [float(x) for x in args.noise.split(",")]
    t0 = time.perf_counter()
    agents = reception_agents(domain, args.hierarchy, policies=("hierarchical", "behaviour_tree"))
    path = out / "episodes.jsonl"
    with path.open("w", encoding="utf-8") as fh:
        for name, agent in agents.items():
            for x in noise:
                for sc in scenarios:
                    for k in seeds:
                        e = run_reception_episode(sc, agent, domain, params, seed=sc.seed + 1000 * k,
                                                  word_error_rate=x, model=model)
                        fh.write(json.dumps(dict(e.record, controller=name, noise=x)) + "\n")
    record_s = time.perf_counter() - t0
    episodes = load_episodes([path])
    result = fit_domain(domain, episodes, prior_strength=args.prior_strength)
    kept = [f.strip() for f in args.keep_designer.split(",") if f.strip()]
    if kept:
        # e.g. Wish: the world's truth of the next visitor's wish would teach the model the
        # study's episodes (docs/reception.md, "Arm 3").
        from dataclasses import replace

        result = replace(result, rows=[r for r in result.rows
                                       if not any(r.table.startswith("transition ") and r.table.endswith(f"/{f}")
                                                  for f in kept)])
    fitted = out / "reception.fitted.domain.yaml"
    write_fitted(args.domain, result, fitted, prior_strength=args.prior_strength)
    print(json.dumps({
        "episodes": len(episodes), "steps": sum(len(e.actions) for e in episodes), "seeds": seeds, "noise": noise,
        "record_seconds": round(record_s, 1), "prior_strength": args.prior_strength,
        "rows_fitted": len(result.rows), "rows_kept": len(result.kept), "designer_kept_for": kept, "out": str(fitted),
        "largest_changes": result.largest_changes(args.top),
    }))
    return 0


if __name__ == "__main__":
    sys.exit(main())
