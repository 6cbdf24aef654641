"""Behaviour habits of a planned Pearl policy in the simulated world (issue 11), one JSON object.

Per scenario file and seed, runs the hierarchical policy through the study's step loop
(:func:`pearl_sim.nursing_home.experiment.run_episode`) and counts the habits a nurse would object to:
unprompted questions (offers/confirmations about a goal the resident does not have),
ConfirmGuideToPhysio offers when no guidance is wanted, RingDoorBell away from the
resident, whether the robot ends the episode at home, wrong actions, guidance success.

    python bench/behaviour.py config/scenarios/figure4.yaml SCENARIO.yaml … [--seeds 50] [--policy DIR]
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
    from pearl_pomdp.hierarchy import load_hierarchical_policy, load_hierarchy, plan
    from pearl_pomdp.model.domain_yaml import load_domain
    from pearl_sim.nursing_home.agents import Controller
    from pearl_sim.nursing_home.experiment import run_episode
    from pearl_sim.nursing_home.scenario import load_scenarios

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scenarios", nargs="+")
    ap.add_argument("--seeds", type=int, default=50)
    ap.add_argument("--domain", default=str(REPO / "config/pearl.domain.yaml"))
    ap.add_argument("--hierarchy", default=str(REPO / "config/pearl.hierarchy.yaml"))
    ap.add_argument("--policy", default="", help="a planned policy directory (default: plan now)")
    ap.add_argument("--until-left", action="store_true",
                    help="run each episode until Pearl leaves for its station (or LEAVE_LIMIT s), as pearl demo")
    args = ap.parse_args()
    domain = load_domain(args.domain)
    t0 = time.perf_counter()
    decider = (load_hierarchical_policy(args.policy, domain) if args.policy
               else plan(domain, load_hierarchy(args.hierarchy, domain)))
    plan_s = time.perf_counter() - t0
    controller = Controller("hierarchical", decider)
    out = {"plan_seconds": round(plan_s, 2), "seeds": args.seeds, "until_left": args.until_left, "scenarios": {}}
    for path in args.scenarios:
        for sc in load_scenarios(path):
            rows = []
            for seed in range(args.seeds):
                habits = {"doorbell_away": 0}

                def on_step(world, result, waits, executive, habits=habits):
                    if result.action == "RingDoorBell" and world.robot_at != world.resident_at:
                        habits["doorbell_away"] += 1

                r = run_episode(sc, controller, domain, seed=sc.seed + 1000 * seed, on_step=on_step,
                                until_left=args.until_left)
                rows.append({"unprompted": r.unprompted_questions,
                             "offers": r.actions.count("ConfirmGuideToPhysio"),
                             "doorbell_away": habits["doorbell_away"], "wrong": r.wrong_actions,
                             "raised": r.questions_raised, "answered": r.questions_answered,
                             "guided": r.guidance_completed, "needed": r.guidance_needed,
                             "wanted": r.guidance_wanted,
                             "ends_home": _ends_home(r.actions), "seconds": r.seconds,
                             "left": any(a in ("GotoPatientRoom", "GuideToPhysio") for a in r.actions)})
            n = len(rows)
            needed = [x for x in rows if x["needed"]]
            out["scenarios"][sc.name] = {
                "episodes": n,
                "unprompted_per_episode": sum(x["unprompted"] for x in rows) / n,
                "guide_offers_per_episode": sum(x["offers"] for x in rows) / n,
                "doorbell_away_per_episode": sum(x["doorbell_away"] for x in rows) / n,
                "wrong_per_episode": sum(x["wrong"] for x in rows) / n,
                "ends_at_home": sum(x["ends_home"] for x in rows) / n,
                # The acceptance's share: of the episodes in which the robot left its station at all.
                "ends_at_home_where_it_left": (sum(x["ends_home"] for x in rows if x["left"])
                                               / max(1, sum(x["left"] for x in rows))),
                "seconds_per_episode": sum(x["seconds"] for x in rows) / n,
                "questions_raised_per_episode": sum(x["raised"] for x in rows) / n,
                "questions_answered_per_episode": sum(x["answered"] for x in rows) / n,
                "guidance_success": (sum(x["guided"] for x in needed) / len(needed)) if needed else None,
                "wanted_guidance_success": (sum(x["guided"] for x in rows if x["wanted"])
                                            / sum(x["wanted"] for x in rows)) if any(x["wanted"] for x in rows) else None,
            }
    json.dump(out, sys.stdout)
    sys.stdout.write("\n")
    return 0


def _ends_home(actions) -> bool:
    """True when the last drive of the episode was GoHome (the robot went back to its station)."""
    drives = [a for a in actions if a in ("GoHome", "GotoPatientRoom", "GuideToPhysio")]
    return bool(drives) and drives[-1] == "GoHome"


if __name__ == "__main__":
    sys.exit(main())
