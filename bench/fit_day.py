"""Fit the Pearl domain to training *days* (docs/day.md, Part 2): one JSON object.

The protocol's training set: the resident generator at seed 11 (a seed no study uses), 6
residents, days 0–3 each; every day run by the day tree and by the hierarchical policy of the
domain being fitted (its designer's rows), at the paper's noise level (0.25). The days (true
state included) go to ``pearl fit`` with the designer's rows as prior (strength 10); the fitted
domain is written to ``--out`` (default ``config/pearl_day.domain.yaml``, the designer's day domain
fitted in place: its designer text is kept, its ``fitted:`` section replaced). Rewards are the
designer's, untouched.

    python bench/fit_day.py [--residents 6] [--days 4] [--seed 11] [--jobs 2] [--out FILE]
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
TRAINING_NOISE = 0.25
#: What the fitted file says of itself, above the designer's text (which write_fitted keeps as it is).
HEADER = ("# Pearl's domain fitted on WORKING DAYS (docs/day.md): written by bench/fit_day.py from the protocol's\n"
          "# training days (resident generator seed {seed}, {residents} residents x {days} days, noise {noise}, the day\n"
          "# tree and the designer's hierarchical policy). The designer's rows and rewards below are unchanged; the\n"
          "# fitted: section at the end holds what the days taught. Re-create: python bench/fit_day.py --jobs 2\n#\n")


def main() -> int:
    from pearl_pomdp.fit import fit_domain, load_episodes, write_fitted
    from pearl_pomdp.model.domain_yaml import load_domain
    from pearl_sim.nursing_home.day_study import day_agents, day_cases, run_days
    from pearl_sim.nursing_home.residents import generate_residents

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--domain", default=str(REPO / "config/pearl_day.domain.yaml"),
                    help="the designer's day domain (its fitted: section, if any, is ignored and replaced)")
    ap.add_argument("--hierarchy", default=str(REPO / "config/pearl.hierarchy.yaml"))
    ap.add_argument("--residents", type=int, default=6)
    ap.add_argument("--days", type=int, default=4)
    ap.add_argument("--seed", type=int, default=11, help="resident generator seed (training only)")
    ap.add_argument("--prior-strength", type=float, default=10.0)
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--work", default=str(REPO / "out/fit-day"), help="folder for the training days (.jsonl)")
    ap.add_argument("--out", default=str(REPO / "config/pearl_day.domain.yaml"))
    ap.add_argument("--top", type=int, default=15)
    args = ap.parse_args()

    work = Path(args.work)
    work.mkdir(parents=True, exist_ok=True)
    domain = load_domain(args.domain, fitted=False)
    t0 = time.perf_counter()
    agents = day_agents(domain, args.hierarchy, ["day_tree", "hierarchical"])
    plan_s = time.perf_counter() - t0
    cases = day_cases(generate_residents(args.residents, seed=args.seed), args.days)
    t0 = time.perf_counter()
    days = run_days(domain, agents, cases, [TRAINING_NOISE], jobs=args.jobs, record=True,
                    progress=sys.stderr.isatty())
    record_s = time.perf_counter() - t0
    path = work / "training-days.jsonl"
    with path.open("w", encoding="utf-8") as fh:
        for d in days:
            fh.write(json.dumps(d["episode"]) + "\n")
    episodes = load_episodes([path])
    result = fit_domain(domain, episodes, prior_strength=args.prior_strength)
    write_fitted(args.domain, result, args.out, prior_strength=args.prior_strength)
    out_path = Path(args.out)
    body = out_path.read_text(encoding="utf-8")
    if body.startswith(HEADER.splitlines()[0]):   # fitted in place: the old header goes with the old fit
        body = body.split("\n", HEADER.count("\n"))[-1]
    out_path.write_text(HEADER.format(seed=args.seed, residents=args.residents, days=args.days, noise=TRAINING_NOISE)
                        + body, encoding="utf-8")
    print(json.dumps({
        "training": {"resident_seed": args.seed, "residents": args.residents, "days": args.days,
                     "noise": TRAINING_NOISE, "controllers": list(agents)},
        "day_scores": {name: round(sum(d["score"] for d in days if d["policy"] == name)
                                   / max(1, sum(d["policy"] == name for d in days)), 2) for name in agents},
        "episodes": len(episodes), "steps": sum(len(e.actions) for e in episodes),
        "plan_seconds": round(plan_s, 1), "record_seconds": round(record_s, 1),
        "rows_fitted": len(result.rows), "rows_kept": len(result.kept), "out": str(args.out),
        "largest_changes": result.largest_changes(args.top),
    }))
    return 0


if __name__ == "__main__":
    sys.exit(main())
