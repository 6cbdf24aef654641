"""Requests raised while the robot is away: answered / raised, visits per hour, ends at home (one JSON object).

A resident who wants the time or the weather while the robot waits at its station cannot be
heard from her room (the world's earshot). This runs every controller of the study on
scenarios where she raises questions in her room with no reminder to bring the robot to her
— ``test/data/scenarios/fresh/evening_questions.yaml`` (a vitamin round, then a question
soon after and one much later) and ``test/data/scenarios/away/afternoon_questions.yaml``
(no appointment at all; written before any policy ran on it) — and reports, per scenario and
controller over ``--seeds`` seeds:

* ``answered`` / ``raised``: questions answered out of those she came to have;
* ``visits_per_hour``: ``GotoPatientRoom`` actions per hour of simulated time (what the
  rounding costs; each is a −5 drive in the domain's reward);
* ``ended_home``: the share of episodes whose last drive was ``GoHome`` (or that never left);
* ``return``: the domain's discounted return on the world's true state, mean ± 95 % CI.

    .venv/bin/python bench/away_requests.py [--seeds 20] [--domain config/pearl.domain.yaml]
        [--hierarchy config/pearl.hierarchy.yaml] [--policies hierarchical,flat_pointbased,qmdp,behaviour_tree]
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

SCENARIOS = ("test/data/scenarios/fresh/evening_questions.yaml", "test/data/scenarios/away/afternoon_questions.yaml")


def mean_ci(xs):
    """The mean and its 95 % t half-width (the studies' one implementation), rounded for the report."""
    from pearl_sim.stats import t_ci

    ci = t_ci(xs)
    return {"mean": round(ci["mean"], 4), "ci95": round(ci["ci95"], 4)}


def main() -> int:
    from pearl_pomdp.model.domain_yaml import load_domain
    from pearl_sim.nursing_home.experiment import build_agents, run_episode
    from pearl_sim.nursing_home.scenario import load_scenarios

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--domain", default=str(REPO / "config/pearl.domain.yaml"))
    ap.add_argument("--hierarchy", default=str(REPO / "config/pearl.hierarchy.yaml"))
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--policies", default="hierarchical,flat_pointbased,qmdp,behaviour_tree")
    ap.add_argument("--scenarios", default=",".join(SCENARIOS))
    args = ap.parse_args()

    domain = load_domain(args.domain)
    agents = build_agents(domain, args.hierarchy, policies=[p for p in args.policies.split(",") if p])
    out = {"bench": "away_requests", "domain": args.domain, "hierarchy": args.hierarchy, "seeds": args.seeds,
           "load_average_1min": round(os.getloadavg()[0], 2), "scenarios": {}}
    t0 = time.perf_counter()
    for path in args.scenarios.split(","):
        for scenario in load_scenarios(REPO / path):
            rows = {}
            for name, agent in agents.items():
                raised = answered = visits = home = 0
                hours = 0.0
                returns = []
                for seed in range(args.seeds):
                    r = run_episode(scenario, agent, domain, seed=seed)
                    raised += r.questions_raised
                    answered += r.questions_answered
                    visits += sum(a == "GotoPatientRoom" for a in r.actions)
                    drives = [a for a in r.actions if a in ("GotoPatientRoom", "GuideToPhysio", "GoHome")]
                    home += (not drives) or drives[-1] == "GoHome"
                    hours += r.seconds / 3600.0
                    returns.append(r.discounted_return)
                rows[name] = {"raised": raised, "answered": answered,
                              "answered_share": round(answered / raised, 4) if raised else None,
                              "visits_per_hour": round(visits / hours, 3) if hours else None,
                              "ended_home": round(home / args.seeds, 4), "return": mean_ci(returns)}
            out["scenarios"][scenario.name] = rows
    out["seconds"] = round(time.perf_counter() - t0, 1)
    json.dump(out, sys.stdout)
    sys.stdout.write("\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
