"""The guidance study on the core executive (no DDS): policies × residents × noise × seeds.

Every policy — hierarchical POMDP, flat point-based POMDP, QMDP, most-likely-state and
the py_trees behaviour tree (the main non-POMDP baseline; ``scripted`` by name) — meets
the same residents (``--residents``: the paper's six and/or seeded generated profiles,
``pearl_sim/nursing_home/residents.py``) on the same three tasks, at each noise level (recogniser word
error rate) and seed. Reported per policy and noise level: guidance success, time to goal,
clarifications per goal, unprompted questions, wrong actions and return with 95 % CIs, and
the PAIRED per-episode differences against the behaviour tree; the issue's acceptance goal
is evaluated. Writes ``study.json``, ``episodes.csv`` and ``study.png`` into ``--out``.
Protocol and reading of the numbers: ``docs/study.md``.

`pearl experiment` with the defaults runs every policy on 12 residents × 3 tasks × 4 noise
levels × 2 seeds (minutes, with a 30 s flat solve); a quick look at the cheap policies:

Examples:
  pearl experiment --policies qmdp,behaviour_tree --residents generated:1 --episodes 1 --noise 0,0.5
"""
from __future__ import annotations

import argparse
import sys
import time
from typing import Any, Dict
from pathlib import Path

from pearl_pomdp.cli._inputs import require_file
from pearl_pomdp.cli._progress import add_progress_arguments, show_progress

COMMAND = "experiment"
HELP = "run the guidance study (policies × residents × speech noise) on the core executive"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from pearl_sim.worlds import share_path
    from pearl_sim.policies import DEFAULT_FLAT_TRIALS, DEFAULT_POLICIES, POLICY_NAMES

    parser.add_argument("--study", default=None,
                        help="study file (default: the domain's world's, config/scenarios/study.yaml for the Pearl "
                             "domain: the paper's residents and the shared scenario fields)")
    parser.add_argument("--domain", default=share_path("config/pearl.domain.yaml"),
                        help="factored domain the policies are planned for (default: the Pearl domain); its name "
                             "chooses the simulated world (pearl_sim/worlds.py: pearl, reception)")
    parser.add_argument("--hierarchy", default=None,
                        help="action hierarchy of the hierarchical policy (default: NAME.hierarchy.yaml beside the "
                             "domain)")
    parser.add_argument("--residents", default="paper,generated:6",
                        help="'paper' (the six of the study file), 'generated:N' (seeded profiles), or both, comma-separated")
    parser.add_argument("--seed", type=int, default=None,
                        help="seed of the resident generator (default 0; --day: 29, the day protocol's reported population)")
    parser.add_argument("--episodes", type=int, default=None,
                        help="seeds per resident, task and noise level (default 2; reception: 20 per episode)")
    parser.add_argument("--noise", "--wer", dest="noise", default=None,
                        help="recogniser word error rates (noise levels), comma-separated (default 0,0.2,0.4,0.6; "
                             "reception: 0,0.2,0.4)")
    parser.add_argument("--snr", default=None, metavar="DB,…",
                        help="noise axis in SNR (dB) through the measured recogniser channel (--channel) instead "
                             "of word error rates, e.g. 30,20,10,5")
    parser.add_argument("--channel", default=share_path("config/speech/pearl_channel.json"),
                        help="calibrated speech channel for --snr (`pearl calibrate-speech --out`); white noise "
                             "with --noise-kind")
    parser.add_argument("--noise-kind", default=None, metavar="KIND,…",
                        help="with --snr: the noise axis is (kind, SNR), kinds of white,babble, each heard through "
                             "its own measured channel (--channel, --babble-channel)")
    parser.add_argument("--babble-channel", default=share_path("config/speech/pearl_channel_babble.json"),
                        help="calibrated speech channel of babble noise (`pearl calibrate-speech --noise babble`)")
    parser.add_argument("--speech-rows", default=None, metavar="FITTED.yaml",
                        help="also run each POMDP policy planned with this domain's observation rows (e.g. from "
                             "`pearl fit DOMAIN --speech CHANNEL.json --snr DB`), named POLICY@measured; the world "
                             "and the scores stay the --domain's")
    parser.add_argument("--measured-policies", default=None, metavar="P,…",
                        help="with --speech-rows: which policies get a @measured twin (default: every POMDP one)")
    parser.add_argument("--policies", default=None,
                        help=f"comma-separated subset of {', '.join(POLICY_NAMES)} (default {','.join(DEFAULT_POLICIES)}; "
                             "reception: hierarchical,flat_pointbased,qmdp,behaviour_tree)")
    parser.add_argument("--flat-trials", type=int, default=None, metavar="N",
                        help="trials of the flat point-based solve (default %d): the same policy on any machine"
                             % DEFAULT_FLAT_TRIALS)
    parser.add_argument("--flat-time-limit", type=float, default=None, metavar="S",
                        help="instead of --flat-trials, S seconds of wall clock (the policy then depends on the "
                             "machine's speed and load)")
    parser.add_argument("--day", action="store_true",
                        help="the study on working days (docs/day.md): controllers × generated residents × --days "
                             "× --noise on DayWorld, scored by the nurse's checklist; default domain "
                             "config/pearl_day.domain.yaml (fitted on training days), --residents generated:6, "
                             "--seed 29, --noise 0.25,0.5, policies hierarchical,flat_pointbased,qmdp,day_tree; "
                             "or --snr DB,… --noise-kind white|babble (one kind per run): her speech through the "
                             "measured recogniser channel")
    parser.add_argument("--speech-twins", default=None, metavar="F,…",
                        help="with --day --snr: also run the hierarchical policy planned on the domain's speech rows "
                             "refitted to the measured channel at each SNR (`pearl fit DOMAIN --speech CHANNEL --snr "
                             "DB --chatter-share F`, prior strength 10), one twin per chatter share F, named "
                             "hierarchical@channel-chatterF; the fitted domains and plans go to OUT/twins/ "
                             "(docs/day.md, the conjecture arm: 0,0.2)")
    parser.add_argument("--days", type=int, default=None, metavar="N",
                        help="with --day: days per resident (default 4; bench/study_power.py --days decides it)")
    parser.add_argument("--jobs", type=int, default=1, help="worker processes for the episodes (default 1)")
    parser.add_argument("--cluster", default=None, metavar="ADDRESS",
                        help="run the episodes on the Dask scheduler at ADDRESS (e.g. tcp://host:8786) instead of "
                             "--jobs processes: the same results (pearl_sim/cluster.py)")
    parser.add_argument("--cluster-timeout", type=float, default=None, metavar="S",
                        help="seconds to wait for the --cluster scheduler (default 10)")
    parser.add_argument("--out", default=None, help="folder for study.json, episodes.csv, study.png (default out/study-<time>)")
    parser.add_argument("--json", action="store_true",
                        help="print one JSON object (with per_scenario and every episode's actions, as study.json)")
    add_progress_arguments(parser)


def _validate(args):
    """Every input checked before any planning or episode (one clear error)."""
    from pearl_pomdp.errors import SpecError
    from pearl_sim.policies import POLICY_NAMES
    from pearl_sim.nursing_home.residents import parse_population, resident_scenarios, study_template

    if args.episodes < 1:
        raise SpecError("<command line>", "--episodes", f"{args.episodes}: at least 1 seed per cell is needed")
    if args.jobs < 1:
        raise SpecError("<command line>", "--jobs", f"{args.jobs}: at least 1 process")
    if args.flat_time_limit is not None and not args.flat_time_limit > 0:
        raise SpecError("<command line>", "--flat-time-limit", f"must be > 0 seconds, got {args.flat_time_limit}")
    if args.flat_trials is not None and args.flat_trials < 1:
        raise SpecError("<command line>", "--flat-trials", f"must be at least 1, got {args.flat_trials}")
    if args.flat_trials is not None and args.flat_time_limit is not None:
        raise SpecError("<command line>", "--flat-trials", "give --flat-trials or --flat-time-limit, not both")
    policies = [p.strip() for p in args.policies.split(",") if p.strip()]
    unknown = [p for p in policies if p not in POLICY_NAMES]
    if unknown:
        raise SpecError("<command line>", "--policies", f"unknown policy {unknown[0]!r}; known: {', '.join(POLICY_NAMES)}")
    if not policies:
        raise SpecError("<command line>", "--policies", "no policy given")
    option, text = ("--snr", args.snr) if args.snr is not None else ("--noise", args.noise)
    try:
        noise = [float(x) for x in text.split(",") if x.strip()]
    except ValueError:
        raise SpecError("<command line>", option, f"{text!r}: expected comma-separated numbers") from None
    if not noise:
        raise SpecError("<command line>", option, "no noise level given")
    kinds: list = []
    if args.noise_kind is not None:
        from pearl_pomdp.asr.audio import NOISE_KINDS

        if args.snr is None:
            raise SpecError("<command line>", "--noise-kind", "needs --snr (the kinds are heard at SNRs)")
        kinds = list(dict.fromkeys(k.strip() for k in args.noise_kind.split(",") if k.strip()))
        bad_kind = [k for k in kinds if k not in NOISE_KINDS]
        if bad_kind or not kinds:
            raise SpecError("<command line>", "--noise-kind",
                            f"{bad_kind[0] if bad_kind else args.noise_kind!r} is not one of {', '.join(NOISE_KINDS)}")
    if args.cluster is not None and not args.cluster.strip():
        raise SpecError("<command line>", "--cluster", "empty scheduler address")
    if args.snr is not None:
        bad = [x for x in noise if not -20.0 <= x <= 60.0]
        if bad:
            raise SpecError("<command line>", "--snr", f"{bad[0]} dB is outside [-20, 60]")
        if not kinds or "white" in kinds:
            require_file(args.channel, "speech channel file (--channel, from `pearl calibrate-speech --out`)")
        if "babble" in kinds:
            require_file(args.babble_channel,
                         "babble speech channel file (--babble-channel, from `pearl calibrate-speech --noise babble`)")
    else:
        bad = [x for x in noise if not 0.0 <= x <= 1.0]
        if bad:
            raise SpecError("<command line>", "--noise", f"{bad[0]} is not a word error rate in [0, 1]")
    require_file(args.study, "study file (--study)")
    require_file(args.domain, "domain file (--domain)")
    if "hierarchical" in policies:
        require_file(args.hierarchy, "hierarchy file (--hierarchy)")
    profiles = parse_population(args.residents, args.study, seed=args.seed)
    cases = resident_scenarios(study_template(args.study), profiles, source=args.study)
    args.kinds = kinds
    args.measured = []
    if args.speech_rows is not None:
        require_file(args.speech_rows, "domain with measured speech rows (--speech-rows)")
        pomdps = [p for p in policies if p not in ("behaviour_tree", "scripted")]
        wanted = pomdps if args.measured_policies is None else [p.strip() for p in args.measured_policies.split(",")
                                                                 if p.strip()]
        bad = [p for p in wanted if p not in pomdps]
        if bad or not wanted:
            raise SpecError("<command line>", "--measured-policies",
                            f"{bad[0] if bad else 'none'!r} is not a POMDP policy of --policies ({', '.join(pomdps)})")
        args.measured = wanted
    elif args.measured_policies is not None:
        raise SpecError("<command line>", "--measured-policies", "needs --speech-rows")
    return policies, sorted(set(noise)), profiles, cases


def _pearl_defaults(args: argparse.Namespace) -> None:
    """The nursing-home study's defaults for what the command line left out."""
    from pearl_sim.worlds import share_path
    from pearl_sim.policies import DEFAULT_POLICIES

    args.study = args.study or share_path("config/scenarios/study.yaml")
    args.hierarchy = args.hierarchy or share_path("config/pearl.hierarchy.yaml")
    args.episodes = 2 if args.episodes is None else args.episodes
    args.noise = "0,0.2,0.4,0.6" if args.noise is None else args.noise
    args.policies = ",".join(DEFAULT_POLICIES) if args.policies is None else args.policies


def run(args: argparse.Namespace) -> int:
    from pearl_pomdp.errors import SpecError
    from pearl_sim.world_study import WorldExperiment, run_world_experiment
    from pearl_sim.worlds import load_attribute, world_for

    if args.day:
        from pearl_sim.nursing_home.day_study import run_cli as run_day_study

        return int(run_day_study(args))
    if args.speech_twins is not None:
        raise SpecError("<command line>", "--speech-twins", "is the day study's (--day --snr); the episode study's "
                                                            "twins are --speech-rows")
    require_file(args.domain, "domain file (--domain)")
    world = world_for(args.domain)
    args.seed = 0 if args.seed is None else args.seed
    if world.experiment is None:
        raise SpecError(args.domain, "name", f"the {world.name} world has no `pearl experiment`")
    target = load_attribute(world.experiment)
    if isinstance(target, WorldExperiment):
        return run_world_experiment(args, world, target)
    return int(target(args))


def run_nursing_home(args: argparse.Namespace) -> int:
    """``pearl experiment`` in the nursing home (the world's own runner: residents, SNR axes, the cluster)."""
    _pearl_defaults(args)
    return _run_pearl(args)


def _run_pearl(args: argparse.Namespace) -> int:
    import json
    import logging

    from pearl_pomdp.cli import print_json
    from pearl_sim.policies import DEFAULT_FLAT_TRIALS
    from pearl_pomdp.model.domain_yaml import load_domain
    from pearl_sim.nursing_home import study
    from pearl_sim.nursing_home.experiment import build_agents

    policies, noise, profiles, cases = _validate(args)
    if args.cluster is not None:
        from pearl_sim.cluster import connect

        connect(args.cluster, args.cluster_timeout or 10.0).close()   # an address that does not answer: before planning
    started = time.perf_counter()
    out = Path(args.out) if args.out else Path("out") / f"study-{time.strftime('%Y%m%d-%H%M%S')}"
    out.mkdir(parents=True, exist_ok=True)
    log = lambda text: print(text, file=sys.stderr, flush=True)  # noqa: E731
    terminal = show_progress(args)
    domain = load_domain(args.domain)
    flat_trials = None if args.flat_time_limit is not None else (args.flat_trials or DEFAULT_FLAT_TRIALS)
    agents = build_agents(domain, args.hierarchy, flat_time_limit=args.flat_time_limit, flat_trials=flat_trials,
                          policies=policies,
                          log=log if terminal else None)
    if args.measured:
        from pearl_sim.nursing_home.agents import Controller

        measured_domain = load_domain(args.speech_rows)
        twins = build_agents(measured_domain, args.hierarchy, flat_time_limit=args.flat_time_limit,
                             flat_trials=flat_trials, policies=args.measured, log=log if terminal else None)
        for name, agent in twins.items():
            agents[f"{name}@measured"] = Controller(f"{name}@measured", agent.decider, domain=measured_domain)
            agents.timings[f"{name}@measured"] = twins.timings[name]
    plan_seconds = dict(agents.timings)
    kinds = args.kinds
    grid = study.cells(len(cases), noise, args.episodes, kinds=kinds or ("",))
    # The tracker's recoveries from impossible observations are logged per step; in a study of
    # thousands of episodes they drown the progress bar (the counters stay in each tracker).
    logging.getLogger("pearl_pomdp").setLevel(logging.ERROR)
    t0 = time.perf_counter()
    snr = args.snr is not None
    channel = str(Path(args.channel).resolve()) if snr else None
    channels = {k: str(Path(args.channel if k == "white" else args.babble_channel).resolve()) for k in kinds}
    episodes = study.run_cells(domain, agents, cases, grid, jobs=args.jobs, progress=terminal, channel=channel,
                               channels=channels, cluster=args.cluster, cluster_timeout=args.cluster_timeout)
    episode_seconds = time.perf_counter() - t0
    table = study.per_policy(episodes)
    diffs = study.paired(episodes) if study.BASELINE in agents else {}
    png = out / "study.png"
    goal: Any
    if kinds:
        # One acceptance evaluation and one figure per noise kind (its SNRs, quietest first).
        goal = {k: study.acceptance(study.of_kind(table, k), study.of_kind(diffs, k), snr=True) for k in kinds}
        for k in kinds:
            study.plot_study(study.of_kind(table, k), study.of_kind(diffs, k), out / f"study-{k}.png", snr=True)
        png = out / f"study-{kinds[0]}.png"
    else:
        goal = study.acceptance(table, diffs, snr=snr)
        study.plot_study(table, diffs, png, snr=snr)
    csv_path = out / "episodes.csv"
    study.write_csv(episodes, csv_path)
    report: Dict[str, Any] = {
        "protocol": {"residents": [p.name for p in profiles], "resident_spec": args.residents, "resident_seed": args.seed,
                     "tasks": sorted({c.task for c in cases}), "noise_levels": noise,
                     "noise_axis": ("noise_kind,snr_db" if kinds else "snr_db") if snr else "word_error_rate",
                     "channel": channel, "noise_kinds": kinds, "channels": channels, "cluster": args.cluster,
                     "seeds_per_cell": args.episodes,
                     "policies": list(agents), "baseline": study.BASELINE, "speech_rows": args.speech_rows,
                     "episodes": len(episodes),
                     "jobs": args.jobs},
        "plan_seconds": plan_seconds,
        "per_policy": table,
        "per_scenario": study.per_scenario(episodes),
        "paired_vs_baseline": diffs,
        # The paper's effect: does each policy's advantage grow as recognition gets worse?
        "growth_vs_baseline": study.growth_contrasts(episodes) if kinds and study.BASELINE in agents else None,
        "acceptance": goal,
        "files": {"png": str(png), "csv": str(csv_path), "json": str(out / "study.json")},
        "episode_seconds": round(episode_seconds, 1),
        "seconds": round(time.perf_counter() - started, 1),
    }
    report["episodes"] = study.episodes_json(episodes)
    (out / "study.json").write_text(json.dumps(report, indent=1), encoding="utf-8")
    if args.json:
        print_json(report)
        return 0
    if kinds:
        for k in kinds:
            print(f"noise kind {k}:")
            _print_table(study.of_kind(table, k), study.of_kind(diffs, k), goal[k])
    else:
        _print_table(table, diffs, goal)
    where = f"on {args.cluster}" if args.cluster else f"{args.jobs} job(s)"
    print(f"{len(episodes)} episodes in {episode_seconds:.1f} s ({where}); wrote {png}, {csv_path}, "
          f"{out / 'study.json'}")
    return 0


def _print_table(table, diffs, goal) -> None:
    from pearl_sim.nursing_home.study import BASELINE

    print(f"{'policy':<18} {'noise':>5} {'success':>20} {'ttg s':>10} {'clar/goal':>9} {'unprompt':>8} "
          f"{'wrong/ep':>12} {'return':>14} {'Δwrong vs BT':>18} {'Δsuccess vs BT':>18}")
    for policy, by_noise in table.items():
        for level, s in by_noise.items():
            g, t, w, r = s["guidance_success"], s["time_to_goal_s"], s["wrong_actions_per_episode"], s["discounted_return"]
            rate = f"{g['successes']}/{g['n']} [{g['low']:.2f},{g['high']:.2f}]"
            ttg = f"{t['mean']:.0f}±{t['ci95']:.0f}" if t["n"] else "-"
            cpg = f"{s['clarifications_per_goal']:.2f}" if s["clarifications_per_goal"] is not None else "-"
            up = s["unprompted_questions_per_episode"]["mean"]
            dw = ds = "-"
            if policy != BASELINE and policy in diffs:
                d = diffs[policy][level]
                dw = f"{d['wrong_actions']['mean']:+.2f} [{d['wrong_actions']['low']:+.2f},{d['wrong_actions']['high']:+.2f}]"
                ds = f"{d['success']['mean']:+.2f} [{d['success']['low']:+.2f},{d['success']['high']:+.2f}]"
            print(f"{policy:<18} {level:>5} {rate:>20} {ttg:>10} {cpg:>9} {up:>8.2f} "
                  f"{w['mean']:>6.2f}±{w['ci95']:<5.2f} {r['mean']:>7.1f}±{r['ci95']:<5.1f} {dw:>18} {ds:>18}")
    if goal is not None:
        print(f"acceptance goal (hierarchical vs {BASELINE}): {'MET' if goal['met'] else 'NOT MET'} — "
              f"quietest level success within CI: {goal['success_within_baseline_ci']}, return within CI: "
              f"{goal['return_within_baseline_ci']}; "
              + "; ".join(f"noise {k}: fewer wrong actions {v['fewer_wrong_actions']}, "
                          f"at least equal success {v['at_least_equal_success']}"
                          for k, v in goal["noisiest_levels"].items()))
