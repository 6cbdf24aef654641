"""Seeds per cell a study claim needs, from a pilot study's variance (docs/study.md § power).

For each policy against the behaviour tree, the pilot's ``study.json`` (every episode) gives
the standard deviation ``s`` of the per-cell quantity a claim tests:

* ``paired``: the paired difference (policy − tree) of the return / wrong actions at a level;
* ``growth``: the difference of those differences between two levels
  (:func:`pearl_sim.nursing_home.study.growth`, e.g. ``white:10`` against ``white:30``).

A two-sided test at α = 0.05 with power 1 − β = 0.8 needs ``n = ((z_.975 + z_.8) · s / δ)²``
matched cells to detect a true mean ``δ``; with ``cases`` resident-task cases per seed that is
``ceil(n / cases)`` seeds per cell. ``δ`` is given per metric (``--delta-return``,
``--delta-wrong``), chosen before the pilot was read (docs/study.md).

    .venv/bin/python bench/study_power.py out/pilot/study.json [--worse white:10 --better white:30]
    .venv/bin/python bench/study_power.py out/day-pilot/day-study.json --days [--delta-score 5]

Prints one JSON object.
"""
from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))


def main(argv=None) -> int:
    from scipy import stats

    from pearl_sim.nursing_home.experiment import EpisodeResult
    from pearl_sim.nursing_home.study import BASELINE, StudyEpisode, growth, paired

    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("study", help="a pilot's study.json (pearl experiment --out)")
    parser.add_argument("--worse", default="white:10")
    parser.add_argument("--better", default="white:30")
    parser.add_argument("--delta-return", type=float, default=5.0)
    parser.add_argument("--delta-wrong", type=float, default=0.1)
    parser.add_argument("--power", type=float, default=0.8)
    parser.add_argument("--days", action="store_true",
                        help="the pilot is a day study (pearl experiment --day --out): days per resident to resolve "
                             "--delta-score points of the paired day score (docs/day.md, Part 2)")
    parser.add_argument("--delta-score", type=float, default=5.0, help="with --days: the paired difference to resolve "
                                                                       "(5 points: 5 %% of the day score's scale)")
    args = parser.parse_args(argv)

    report = json.loads(Path(args.study).read_text(encoding="utf-8"))
    if args.days:
        print(json.dumps(day_power(report, args.study, args.delta_score, args.power)))
        return 0
    episodes = []
    for row in report["episodes"]:
        r = EpisodeResult(scenario="", agent=row["policy"], seed=row["seed"], discounted_return=row["discounted_return"],
                          steps=row["steps"], guidance_needed=True, guidance_completed=bool(row["guidance_completed"]),
                          time_to_goal=row["time_to_goal_s"], clarifications=row["clarifications"],
                          unprompted_questions=row["unprompted_questions"], goals_achieved=row["goals_achieved"],
                          wrong_actions=row["wrong_actions"], residents_lost=row["residents_lost"], walking_speed=0.0)
        episodes.append(StudyEpisode(row["policy"], row["resident"], row["task"], row["noise"], float("nan"),
                                     row["seed"], r, row.get("noise_kind", "")))
    cases = len({(e.resident, e.task) for e in episodes})
    z = stats.norm.ppf(0.975) + stats.norm.ppf(args.power)
    deltas = {"discounted_return": args.delta_return, "wrong_actions": args.delta_wrong}

    def need(sd: float, delta: float) -> dict:
        n = (z * sd / delta) ** 2
        return {"sd": round(sd, 4), "delta": delta, "cells": math.ceil(n), "seeds_per_cell": max(1, math.ceil(n / cases))}

    diffs = paired(episodes)
    out = {"bench": "study_power", "pilot": args.study, "cases_per_seed": cases,
           "seeds_in_pilot": len({e.seed for e in episodes}), "alpha": 0.05, "power": args.power,
           "paired": {}, "growth": {}}
    for policy in sorted(diffs):
        out["paired"][policy] = {}
        for level, d in diffs[policy].items():
            out["paired"][policy][level] = {}
            for metric, delta in deltas.items():
                ci = d[metric]
                sd = ci["ci95"] * math.sqrt(ci["n"]) / stats.t.ppf(0.975, ci["n"] - 1) if ci["n"] > 1 else 0.0
                out["paired"][policy][level][metric] = need(sd, delta)
        out["growth"][policy] = {}
        for metric, delta in deltas.items():
            g = growth(episodes, policy, args.worse, args.better, metric, BASELINE)
            sd = g["ci95"] * math.sqrt(g["n"]) / stats.t.ppf(0.975, g["n"] - 1) if g["n"] > 1 else 0.0
            out["growth"][policy][metric] = dict(need(sd, delta), mean=round(g["mean"], 4) if g["n"] else None,
                                                 contrast=f"{args.worse} vs {args.better}")
    print(json.dumps(out))
    return 0


def day_power(report: dict, pilot: str, delta: float, power: float) -> dict:
    """Days per resident each controller's paired day score against the day tree needs, per noise
    level, from the pilot's per-day differences: ``n = ((z.975 + z_power)·s/δ)²`` days, over the
    pilot's residents. The study's number is the largest over every controller and level."""
    import numpy as np
    from scipy import stats

    days = report["days"]
    baseline = report["protocol"]["baseline"]
    residents = len({d["resident"] for d in days})
    z = stats.norm.ppf(0.975) + stats.norm.ppf(power)
    base = {(d["resident"], d["seed"], d["noise"]): d["score"] for d in days if d["policy"] == baseline}
    out: dict = {"bench": "study_power", "pilot": pilot, "kind": "days", "residents": residents,
                 "pilot_days_per_resident": report["protocol"]["days_per_resident"], "alpha": 0.05,
                 "power": power, "delta_score": delta, "paired": {}}
    worst = 1
    for policy in sorted({d["policy"] for d in days} - {baseline}):
        out["paired"][policy] = {}
        for level in sorted({d["noise"] for d in days}):
            diffs = [d["score"] - base[(d["resident"], d["seed"], d["noise"])] for d in days
                     if d["policy"] == policy and d["noise"] == level and (d["resident"], d["seed"], d["noise"]) in base]
            sd = float(np.std(diffs, ddof=1)) if len(diffs) > 1 else 0.0
            n = math.ceil((z * sd / delta) ** 2)
            per_resident = max(1, math.ceil(n / residents))
            worst = max(worst, per_resident)
            out["paired"][policy][str(level)] = {"sd": round(sd, 3), "mean": round(float(np.mean(diffs)), 3),
                                                 "pilot_days": len(diffs), "days": n, "days_per_resident": per_resident}
    out["days_per_resident"] = worst
    return out


if __name__ == "__main__":
    sys.exit(main())
