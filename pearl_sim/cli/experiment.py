"""The guidance study on the core executive (no DDS): policies × residents × noise.

Runs the study scenarios (default: the paper's 12 guidances with 6 residents) for
each policy — hierarchical POMDP, flat point-based POMDP, QMDP, most-likely-state,
and a scripted state machine — and reports guidance success, time to goal,
clarification questions per goal, wrong actions and mean return with 95% CIs; then
sweeps the word error rate (PNG: success and wrong actions vs noise per policy) and
compares the paper's fixed-pace guidance with walking-pace adaptation.

`pearl experiment` with the defaults runs every policy on the whole study (minutes, with a
30 s flat solve); a quick look at the cheap policies:

Examples:
  pearl experiment --policies qmdp,scripted --episodes 1 --wer 0,0.5 --sweep-episodes 1
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from pearl_pomdp.cli._inputs import require_file
from pearl_pomdp.cli._progress import add_progress_arguments, show_progress

COMMAND = "experiment"
HELP = "run the guidance study (policies × residents × speech noise) on the core executive"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from pearl_sim.cli.demo import _share

    parser.add_argument("--scenarios", nargs="+", default=[_share("config/scenarios/study.yaml")],
                        help="scenario files (every episode of each is run)")
    parser.add_argument("--domain", default=_share("config/pearl.domain.yaml"),
                        help="factored domain the policies are planned for (default: the Pearl domain)")
    parser.add_argument("--hierarchy", default=_share("config/pearl.hierarchy.yaml"),
                        help="action hierarchy of the hierarchical policy (default: the Pearl hierarchy)")
    parser.add_argument("--episodes", type=int, default=5, help="seeds per scenario episode (default 5)")
    parser.add_argument("--policies", default=",".join(("hierarchical", "flat_pointbased", "qmdp",
                                                        "most_likely_state", "scripted")),
                        help="comma-separated subset of the compared policies")
    parser.add_argument("--flat-time-limit", type=float, default=30.0, help="seconds for the flat point-based solve")
    parser.add_argument("--wer", default="0,0.1,0.2,0.3,0.4,0.5,0.6", help="word error rates of the sweep ('' to skip)")
    parser.add_argument("--sweep-episodes", type=int, default=2, help="seeds per episode in each sweep point")
    parser.add_argument("--out", default=None, help="folder for the PNG and the JSON (default out/experiment-<time>)")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    add_progress_arguments(parser)


def sweep_table(sweep: dict, wers: list) -> str:
    """The word-error-rate sweep as text (the numbers of ``wer_sweep.png``): per policy, the
    guidance success rate and the wrong actions per episode at each word error rate."""
    lines = ["word error rate sweep: guidance success rate / wrong actions per episode",
             f"{'policy':<20} " + " ".join(f"{'WER ' + format(w, 'g'):>11}" for w in wers)]
    for name, s in sweep.items():
        cells = [f"{rate:.2f}/{wrong:.2f}" for rate, wrong in zip(s["success"], s["wrong"])]
        lines.append(f"{name:<20} " + " ".join(f"{c:>11}" for c in cells))
    return "\n".join(lines)


def run(args: argparse.Namespace) -> int:
    import json

    from pearl_pomdp.cli import print_json
    from pearl_pomdp.errors import SpecError
    from pearl_pomdp.model.factored import load_domain
    from pearl_pomdp.speech import KeywordFilter
    from pearl_sim.experiment import POLICY_NAMES, build_agents, plot_sweep, run_study, summarise
    from pearl_sim.scenario import load_scenarios

    # Every input is checked before the study starts (planning alone takes seconds).
    if args.episodes < 1:
        raise SpecError("<command line>", "--episodes", f"must be at least 1, got {args.episodes}")
    if args.sweep_episodes < 1:
        raise SpecError("<command line>", "--sweep-episodes", f"must be at least 1, got {args.sweep_episodes}")
    if not args.flat_time_limit > 0:
        raise SpecError("<command line>", "--flat-time-limit", f"must be > 0 seconds, got {args.flat_time_limit}")
    try:
        wers = [float(x) for x in args.wer.split(",") if x.strip()]
    except ValueError:
        raise SpecError("<command line>", "--wer", f"{args.wer!r} is not a comma-separated list of numbers") from None
    if any(not 0.0 <= w <= 1.0 for w in wers):
        raise SpecError("<command line>", "--wer", f"word error rates must be in [0, 1], got {args.wer}")
    policies = [p.strip() for p in args.policies.split(",") if p.strip()]
    unknown = sorted(set(policies) - set(POLICY_NAMES))
    if unknown or not policies:
        raise SpecError("<command line>", "--policies", f"unknown policy {unknown[0]!r}; known: {', '.join(POLICY_NAMES)}"
                        if unknown else f"no policy given; known: {', '.join(POLICY_NAMES)}")
    for path in args.scenarios:
        require_file(path, "scenario file (--scenarios)")
    require_file(args.domain, "domain file (--domain)")
    if "hierarchical" in policies:
        require_file(args.hierarchy, "hierarchy file (--hierarchy)")
    started = time.perf_counter()
    log = lambda text: print(text, file=sys.stderr, flush=True)  # noqa: E731
    domain = load_domain(args.domain)
    kf = KeywordFilter(domain.keywords)
    scenarios = [sc for path in args.scenarios for sc in load_scenarios(path)]
    out = Path(args.out) if args.out else Path("out") / f"experiment-{time.strftime('%Y%m%d-%H%M%S')}"
    out.mkdir(parents=True, exist_ok=True)
    try:
        agents = build_agents(domain, args.hierarchy, flat_time_limit=args.flat_time_limit, policies=policies, log=log)
    except ValueError as err:
        raise SpecError("<command line>", "--policies", str(err)) from None
    plan_seconds = dict(build_agents.timings)
    progress = show_progress(args)

    main = summarise(run_study(domain, agents, scenarios, kf, episodes=args.episodes, progress=progress, desc="study"))
    pace = {}
    if "hierarchical" in agents:
        adaptive = {"hierarchical": agents["hierarchical"]}
        for label, flag in (("paper_fixed_pace", False), ("pace_adaptation", True)):
            rs = run_study(domain, adaptive, scenarios, kf, episodes=args.episodes, pace_adaptation=flag,
                           progress=progress, desc=label)
            by_speed = {}
            for r in rs:
                by_speed.setdefault(r.walking_speed, []).append(r.guidance_completed)
            pace[label] = {"overall": summarise(rs)["hierarchical"]["guidance_success"],
                           "success_by_walking_speed": {f"{v:g}": sum(x) / len(x) for v, x in sorted(by_speed.items())}}
    sweep = {name: {"success": [], "wrong": []} for name in agents}
    for wer in wers:
        s = summarise(run_study(domain, agents, scenarios, kf, episodes=args.sweep_episodes, wer=wer,
                                progress=progress, desc=f"WER {wer:.1f}"))
        for name in agents:
            sweep[name]["success"].append(s[name]["guidance_success"]["rate"])
            sweep[name]["wrong"].append(s[name]["wrong_actions_per_episode"]["mean"])
    png = None
    if wers:
        png = out / "wer_sweep.png"
        plot_sweep(sweep, wers, png)
    report = {
        "scenarios": [sc.name for sc in scenarios], "episodes_per_scenario": args.episodes,
        "plan_seconds": plan_seconds, "policies": main, "pace": pace,
        "wer_sweep": {"word_error_rates": wers, "per_policy": sweep, "png": str(png) if png else None},
        "seconds": round(time.perf_counter() - started, 1),
    }
    (out / "experiment.json").write_text(json.dumps(report, indent=1), encoding="utf-8")
    if args.json:
        print_json(report)
        return 0
    print(f"{'policy':<20} {'guidance success':>22} {'time to goal s':>16} {'clarif./goal':>13} {'wrong/ep':>10} {'return':>16}")
    for name, s in main.items():
        g, t, w, r = s["guidance_success"], s["time_to_goal_s"], s["wrong_actions_per_episode"], s["discounted_return"]
        rate = f"{g['successes']}/{g['n']} [{g['low']:.2f},{g['high']:.2f}]" if g["n"] else "-"
        ttg = f"{t['mean']:.0f}±{t['ci95']:.0f}" if t["n"] else "-"
        cpg = f"{s['clarifications_per_goal']:.2f}" if s["clarifications_per_goal"] is not None else "-"
        print(f"{name:<20} {rate:>22} {ttg:>16} {cpg:>13} {w['mean']:>10.2f} {r['mean']:>9.1f}±{r['ci95']:<6.1f}")
    for label, p in pace.items():
        print(f"{label}: success {p['overall']['successes']}/{p['overall']['n']}; by walking speed (m/s): "
              + ", ".join(f"{k}: {v:.2f}" for k, v in p["success_by_walking_speed"].items()))
    if wers:
        print(sweep_table(sweep, wers))
        print(f"wrote {png} and {out / 'experiment.json'}")
    else:
        print(f"wrote {out / 'experiment.json'}")
    return 0
