"""What became of each question she voiced on working days (docs/day.md): one JSON object.

The day checklist counts questions raised and answered; this follows each one from the world's
events: *answered*; *forgotten* (her own memory, ``forgets``) — split by whether the robot had
driven away from her before she forgot, and whether it ever heard a question word while it was
open; *lapsed* when her session began; *replaced* when the world gave her a new question while
one was open (the question she asks on arriving at the department takes the place of one she had
voiced before the walk); *open* when the day ended. It runs the study's step loop
(the same worlds, residents and days as ``pearl experiment --day``) on the **training** residents
by default (generator seed 11, which no reported study uses), so what it shows may guide a change
without touching the reported days.

    python bench/day_questions.py [--policies hierarchical,day_tree] [--days 10] [--noise 0.5]
                                  [--resident-seed 11] [--residents 6] [--examples 3]
"""
from __future__ import annotations

import argparse
import collections
import json
import sys
import time
from pathlib import Path
from typing import Any, Dict, List, Optional, Tuple

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
#: The actions that take the robot away from her (a drive from where she is).
DRIVES = ("GoHome", "GotoPatientRoom", "GuideToPhysio", "RechargeBattery")


def follow_day(controller, domain, model, case, noise: float) -> Tuple[List[Dict[str, Any]], Dict[str, Any]]:
    """Every question she voiced on one day, with its fate and the robot's steps while it was open, and
    the day's checklist (whose questions raised and answered these must match: raises if not)."""
    from pearl_sim.loop import ExecutiveBackend, run_episode
    from pearl_sim.nursing_home.day import DAY_SECONDS
    from pearl_sim.nursing_home.day_study import day_world
    from pearl_sim.nursing_home.experiment import episode_executive

    world = day_world(case, domain, noise)
    scenario = world.scenario
    executive = episode_executive(controller, domain, scenario, model)
    questions: List[Dict[str, Any]] = []
    current: Optional[Dict[str, Any]] = None

    def close(fate: str) -> None:
        nonlocal current
        assert current is not None
        current["fate"] = fate
        questions.append(current)
        current = None

    def on_action(result, waits) -> None:
        nonlocal current
        if current is not None and result.action:
            heard = executive.steps[-1].observation if executive.steps else None
            current["steps"].append(f"{result.action}/{heard}")
            current["left_her"] |= result.action in DRIVES
            current["heard_a_question_word"] |= heard in ("time", "weather", "t_time", "t_weather")
        for step in [result, *waits]:
            for event in step.events:
                if "wants to know the" in event:
                    if current is not None:   # the world put a new question in place of hers (her arrival's)
                        close("replaced by a new question")
                    current = {"resident": case.resident, "day": case.day, "at": world.resident_at,
                               "steps": [], "left_her": False, "heard_a_question_word": False}
                elif current is not None and "question answered" in event:
                    close("answered")
                elif current is not None and "forgets she wanted" in event:
                    close("forgotten after the robot left her" if current["left_her"] else "forgotten beside the robot")
                elif current is not None and "goes unanswered" in event:
                    close("lapsed: her session began")

    run_episode(world, ExecutiveBackend(executive), on_action=on_action, stop_when=lambda: world.time >= DAY_SECONDS)
    if current is not None:
        close("open when the day ended")
    checklist = world.checklist()
    found = (len(questions), sum(q["fate"] == "answered" for q in questions))
    if found != (checklist["questions_raised"], checklist["questions_answered"]):
        raise AssertionError(f"{case.resident} day {case.day}: the checklist raised and answered "
                             f"{checklist['questions_raised']} and {checklist['questions_answered']} questions, "
                             f"the events {found[0]} and {found[1]}")
    return questions, checklist


def main() -> int:
    from pearl_pomdp.model.domain_yaml import load_domain
    from pearl_sim.nursing_home.day_study import day_agents, day_cases
    from pearl_sim.nursing_home.residents import generate_residents

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--domain", default=str(REPO / "config/pearl_day.domain.yaml"))
    ap.add_argument("--hierarchy", default=str(REPO / "config/pearl.hierarchy.yaml"))
    ap.add_argument("--policies", default="hierarchical,day_tree")
    ap.add_argument("--resident-seed", type=int, default=11, help="the generator's seed (11: the training residents)")
    ap.add_argument("--residents", type=int, default=6)
    ap.add_argument("--days", type=int, default=10)
    ap.add_argument("--noise", type=float, default=0.5, help="recogniser word error rate")
    ap.add_argument("--examples", type=int, default=3, help="unanswered questions shown per policy (their steps)")
    args = ap.parse_args()

    started = time.perf_counter()
    domain = load_domain(args.domain)
    model = domain.compile()
    policies = [p.strip() for p in args.policies.split(",") if p.strip()]
    agents = day_agents(domain, args.hierarchy, policies)
    cases = day_cases(generate_residents(args.residents, seed=args.resident_seed), args.days)
    report: Dict[str, Any] = {"bench": "day_questions", "domain": args.domain, "resident_seed": args.resident_seed,
                              "residents": args.residents, "days": args.days, "noise": args.noise, "policies": {}}
    for name in policies:
        questions = [q for case in cases for q in follow_day(agents[name], domain, model, case, args.noise)[0]]
        fates = collections.Counter(q["fate"] for q in questions)
        unanswered = [q for q in questions if q["fate"] != "answered"]
        report["policies"][name] = {
            "raised": len(questions), "answered": fates["answered"],
            "answered_share": round(fates["answered"] / len(questions), 3) if questions else None,
            "fates": dict(fates.most_common()),
            "unanswered_never_heard_a_question_word": sum(not q["heard_a_question_word"] for q in unanswered),
            "unanswered_left_her_first": sum(q["left_her"] for q in unanswered),
            "examples": [{**q, "steps": q["steps"][:8]} for q in unanswered[:args.examples]],
        }
    report["seconds"] = round(time.perf_counter() - started, 1)
    print(json.dumps(report))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
