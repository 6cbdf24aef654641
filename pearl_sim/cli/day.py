"""One working day of Pearl, 08:00-20:00, with the nurse's checklist and a picture of the day.

A resident from the study's generator (`--resident-seed`, `--resident`) lives one day (`--seed`):
meals, a nap, the lounge, a visitor, her physiotherapy appointment and session, three reminders,
questions, and the robot's battery over hours (docs/day.md). The controller is the hierarchical
POMDP planned on the day domain (config/pearl_day.domain.yaml, fitted on training days; its plan
ships in config/plans/pearl_day, so the day starts at once), or
`--policy day_tree|qmdp|flat_pointbased`. The day runs on the core executive, the step loop the
nodes run (about a second of CPU a day for the tree, several for the hierarchy); with --nodes it
runs through the real ROS 2 nodes over DDS under /clock (the hierarchical policy; minutes for a
whole day) and records a rosbag2 bag split by the hour that `pearl replay` and `pearl bag-info`
read, with the answer time per hour and the process's memory. Prints the checklist (or, with
--json, one JSON object holding every row) and writes day.png (where she is, where the robot is,
its battery, every action), checklist.json and timeline.json into --out.

Examples:
  pearl day --seed 3 --until 12:00            # the hierarchy (the shipped plan), the morning
  pearl day --policy day_tree --seed 3 --out out/day-tree
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import Optional

COMMAND = "day"
HELP = "run one working day (08:00-20:00) and print the nurse's checklist and a picture of the day"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from pearl_sim.worlds import share_path

    parser.add_argument("--seed", type=int, default=0, help="the day's seed: her routine, the appointment, every draw")
    parser.add_argument("--resident-seed", type=int, default=29,
                        help="the resident generator's seed (default 29, the day protocol's reported population)")
    parser.add_argument("--resident", type=int, default=1, help="which generated resident (1-based, default 1)")
    parser.add_argument("--noise", type=float, default=0.25, help="recogniser word error rate (default 0.25)")
    parser.add_argument("--policy", default="hierarchical",
                        help="hierarchical (default), flat_pointbased, qmdp or day_tree")
    parser.add_argument("--domain", default=share_path("config/pearl_day.domain.yaml"),
                        help="the domain the POMDPs are planned on (default: Pearl's domain fitted on training days)")
    parser.add_argument("--hierarchy", default=share_path("config/pearl.hierarchy.yaml"),
                        help="the action hierarchy of the hierarchical policy (default: Pearl's)")
    parser.add_argument("--nodes", action="store_true",
                        help="run through the ROS 2 nodes over DDS (hierarchical policy), recording a bag split by "
                             "the hour into OUT/bag")
    parser.add_argument("--until", default="20:00", metavar="HH:MM",
                        help="end the day early at this clock time (default 20:00)")
    parser.add_argument("--policy-dir", default="", metavar="DIR",
                        help="a hierarchical policy `pearl plan` saved for the domain (default: the shipped plan "
                             "config/plans/pearl_day when the domain and hierarchy are the shipped ones, else plan "
                             "now, 1-2 minutes)")
    parser.add_argument("--domain-id", type=int, default=None, help="with --nodes: ROS_DOMAIN_ID of the graph")
    parser.add_argument("--out", default=None, help="folder for day.png, checklist.json, timeline.json "
                                                    "(default out/day-<time>)")
    parser.add_argument("--json", action="store_true", help="print one JSON object with every checklist row")


def run(args: argparse.Namespace) -> int:
    from pearl_pomdp.cli import print_json
    from pearl_pomdp.cli._inputs import require_dir, require_file
    from pearl_pomdp.errors import SpecError
    from pearl_pomdp.model.domain_yaml import load_domain
    from pearl_sim.nursing_home.day import clock
    from pearl_sim.nursing_home.day_plot import plot_day
    from pearl_sim.nursing_home.day_study import DAY_POLICY_NAMES, day_agents, generated_case, run_day
    from pearl_sim.nursing_home.residents import MAX_GENERATED

    started = time.perf_counter()
    if args.policy not in DAY_POLICY_NAMES:
        raise SpecError("<command line>", "--policy", f"{args.policy!r} is not one of {', '.join(DAY_POLICY_NAMES)}")
    if not 1 <= args.resident <= MAX_GENERATED:
        raise SpecError("<command line>", "--resident", f"{args.resident}: a resident number in [1, {MAX_GENERATED}]")
    if not 0.0 <= args.noise <= 1.0:
        raise SpecError("<command line>", "--noise", f"{args.noise} is not a word error rate in [0, 1]")
    until = _clock_seconds(args.until)
    if args.nodes and args.policy != "hierarchical":
        raise SpecError("<command line>", "--nodes", f"runs the hierarchical policy node, not {args.policy!r}")
    require_file(args.domain, "domain file (--domain)")
    require_file(args.hierarchy, "hierarchy file (--hierarchy)")
    domain = load_domain(args.domain)
    case = generated_case(args.resident_seed, args.resident, args.seed)
    out = Path(args.out) if args.out else Path("out") / f"day-{time.strftime('%Y%m%d-%H%M%S')}"
    out.mkdir(parents=True, exist_ok=True)
    if args.policy_dir:
        require_dir(args.policy_dir, "policy directory (--policy-dir, from `pearl plan`)")
    if args.nodes:
        day = _run_nodes(args, domain, case, until, out)
    else:
        planned = _planned_policy_dir(args, domain) if args.policy == "hierarchical" else None
        if planned is not None:
            from pearl_pomdp.hierarchy import load_hierarchical_policy
            from pearl_sim.planning import Controller

            controller = Controller(args.policy, load_hierarchical_policy(planned, domain))
        else:
            controller = day_agents(domain, args.hierarchy, [args.policy])[args.policy]
        day = run_day(controller, domain, case, args.noise, timeline=True, until=until)
    title = (f"{args.policy} · resident {case.resident} (generator seed {args.resident_seed}) · day seed {args.seed} · "
             f"noise {args.noise}")
    png = plot_day(day["timeline"], day["checklist"], out / "day.png", title)
    (out / "checklist.json").write_text(json.dumps({**{k: v for k, v in day.items() if k != "timeline"}},
                                                   indent=1), encoding="utf-8")
    (out / "timeline.json").write_text(json.dumps(day["timeline"]), encoding="utf-8")
    report = {"policy": args.policy, "resident": case.resident, "resident_seed": args.resident_seed, "seed": args.seed,
              "noise": args.noise, "score": day["score"], "checklist": day["checklist"],
              "files": {"png": str(png), "checklist": str(out / "checklist.json"), "timeline": str(out / "timeline.json")},
              "day_seconds": day.get("seconds", day.get("wall_seconds")),
              "seconds": round(time.perf_counter() - started, 1)}
    if args.nodes:
        report["nodes"] = {k: day[k] for k in ("bag", "bag_files", "bag_messages", "answer_ms_per_hour", "rss_mb",
                                               "tracker_counters", "final_belief_valid", "wall_seconds")}
    if args.json:
        print_json(report)
        return 0
    c = day["checklist"]
    print(f"{title}: day score {day['score']:.1f} / 100")
    print(f"  reminders: {c['reminders_on_time']} of {c['reminders_due']} on time (≤ 10 min), "
          f"{c['reminders_delivered']} delivered; delays {c['reminder_delay_s']} s")
    print(f"  walks: {c['walks_completed']} of {c['walks_wanted']} wanted completed ({c['staff_walks']} by the staff); "
          f"durations {c['walk_s']} s")
    print(f"  questions: {c['questions_answered']} of {c['questions_raised']} answered; delays {c['answer_delay_s']} s")
    print(f"  unprompted acts: {c['unprompted']} ({c['unprompted_per_hour']:.2f} an hour); wrong actions "
          f"{c['wrong_actions']}; clarification questions {c['clarifications']}")
    print(f"  battery: {c['battery_low_s'] / 60:.0f} min below 20 %, {'ran EMPTY' if c['battery_empty'] else 'never empty'}, "
          f"{c['battery_at_end']:.0%} at {clock(12 * 3600)}; {'docked' if c['docked_at_end'] else 'NOT docked'} at the end")
    print(f"  at the station {c['station_share']:.0%} of the time nothing was wanted; {c['metres_driven']:.0f} m driven; "
          f"{c['steps']} steps")
    if args.nodes:
        n = report["nodes"]
        hours = [h for h in n["answer_ms_per_hour"] if h["steps"]]
        print(f"  through the nodes: {n['wall_seconds']} s wall; bag {n['bag']} ({len(n['bag_files'])} file(s), "
              f"{n['bag_messages']} messages); answer p99 per hour (ms): "
              + ", ".join(f"{h['p99_ms']:.0f}" for h in hours)
              + "; memory (MB): " + ", ".join(f"{m['rss_mb']:.0f}" for m in n["rss_mb"]))
    print(f"wrote {png}, {out / 'checklist.json'}, {out / 'timeline.json'} ({report['seconds']} s)")
    return 0


def _clock_seconds(text: str) -> float:
    """``HH:MM`` of the day as world seconds after 08:00 (08:00 < time ≤ 20:00)."""
    from pearl_pomdp.errors import SpecError
    from pearl_sim.nursing_home.day import DAY_SECONDS, DAY_START

    try:
        hours, minutes = (int(x) for x in text.split(":"))
    except ValueError:
        raise SpecError("<command line>", "--until", f"{text!r}: expected HH:MM") from None
    t = hours * 3600.0 + minutes * 60.0 - DAY_START
    if not 0 < t <= DAY_SECONDS or not 0 <= minutes < 60:
        raise SpecError("<command line>", "--until", f"{text!r}: a time after 08:00, at most 20:00")
    return t


#: The shipped plan of the shipped day domain and Pearl's hierarchy (`pearl plan
#: config/pearl_day.domain.yaml --out config/plans/pearl_day`, 1-2 minutes of CPU), so a day starts at once.
SHIPPED_DAY_PLAN = "config/plans/pearl_day"


def shipped_day_plan(domain_path, hierarchy_path, domain) -> Optional[Path]:
    """The shipped day plan when ``domain_path`` and ``hierarchy_path`` are the shipped day domain and
    Pearl's hierarchy and the plan was planned for ``domain`` (its model fingerprint), else ``None``
    (``pearl day`` and ``pearl demo`` then plan)."""
    from pearl_pomdp.errors import PolicyError
    from pearl_pomdp.hierarchy import load_hierarchical_policy
    from pearl_sim.worlds import share_path

    shipped = Path(share_path(SHIPPED_DAY_PLAN))
    defaults = (share_path("config/pearl_day.domain.yaml"), share_path("config/pearl.hierarchy.yaml"))
    if (Path(domain_path).resolve(), Path(hierarchy_path).resolve()) != tuple(Path(p).resolve() for p in defaults):
        return None
    try:
        load_hierarchical_policy(shipped, domain)
    except (PolicyError, OSError):
        return None   # a refitted domain the shipped plan is not for: plan it now
    return shipped


def _planned_policy_dir(args, domain) -> Optional[Path]:
    """``--policy-dir``, else the shipped day plan (:func:`shipped_day_plan`), else ``None`` (plan now)."""
    if args.policy_dir:
        return Path(args.policy_dir)
    return shipped_day_plan(args.domain, args.hierarchy, domain)


def _run_nodes(args, domain, case, until: float, out: Path) -> dict:
    """The day through the ROS 2 graph: a policy planned before (--policy-dir, or the shipped plan of
    the shipped domain) or planned now, then run_day_graph."""
    from pearl_pomdp.hierarchy import load_hierarchy, plan
    from pearl_sim.nursing_home.day_graph import run_day_graph

    planned = _planned_policy_dir(args, domain)
    if planned is not None:
        policy_dir = planned
    else:
        if not args.json:
            print("pearl day: planning the hierarchical policy…", flush=True)
        policy_dir = plan(domain, load_hierarchy(args.hierarchy, domain)).save(out / "policy")
    return run_day_graph(args.domain, policy_dir, case.fields, case.articulation_wer, args.noise, case.seed, out,
                         until=until, domain_id=args.domain_id, name=f"{case.resident}-day{case.seed}")
