"""``pearl experiment --domain config/ward.domain.yaml``: the ward study (docs/ward.md).

Builds the compared controllers once (the hierarchy beside the domain, DESPOT online at every step,
the ward behaviour tree), runs every controller in every cell of the study file × noise levels ×
seeds through the one step loop, and reports per controller and noise level the return, task
success, requests met, medications taken, wrong actions and decision times with 95 % CIs, and the
paired differences against the tree and between the POMDP controllers. Writes ``study.json``.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any, Dict, List

__all__ = ["run_cli", "run_demo_cli", "DEFAULT_NOISE", "DEFAULT_SEEDS"]

#: The protocol's noise levels (recogniser word error rates) and seeds per episode and level.
DEFAULT_NOISE = "0.1,0.3"
DEFAULT_SEEDS = 10

_jobs: Dict[str, Any] = {}


def _one(item):
    from pearl_sim.ward.study import run_ward_episode

    sc, noise, k, name = item
    w = _jobs
    return run_ward_episode(sc, w["agents"][name], w["domain"], w["params"], seed=sc.seed + 1000 * k,
                            word_error_rate=noise, model=w["model"])


def run_cli(args: argparse.Namespace) -> int:
    """Run the ward study from ``pearl experiment``'s arguments (the nursing-home-only ones refused)."""
    from pearl_pomdp.cli import print_json
    from pearl_pomdp.cli._inputs import require_file
    from pearl_pomdp.cli._progress import show_progress
    from pearl_pomdp.cli.plan import resolve_hierarchy_path
    from pearl_pomdp.errors import SpecError
    from pearl_pomdp.model.factored import load_domain
    from pearl_sim.cli.demo import _share
    from pearl_sim.ward import study
    from pearl_sim.ward.scenario import load_ward_scenarios
    from pearl_sim.worlds import WORLDS

    world = WORLDS["ward"]
    if args.snr is not None:
        raise SpecError("<command line>", "--snr", "the ward world has the word-error recogniser only; use --noise")
    for option, value in (("--noise-kind", getattr(args, "noise_kind", None)),
                          ("--speech-rows", getattr(args, "speech_rows", None)),
                          ("--measured-policies", getattr(args, "measured_policies", None)),
                          ("--cluster", getattr(args, "cluster", None)),
                          ("--flat-trials", getattr(args, "flat_trials", None)),
                          ("--flat-time-limit", getattr(args, "flat_time_limit", None))):
        if value is not None:
            raise SpecError("<command line>", option, "is not for the ward study (docs/ward.md: the flat solve does "
                                                      "not close at this size; online and the hierarchy are compared)")
    if args.residents != "paper,generated:6":
        raise SpecError("<command line>", "--residents", "the ward's residents are in its study file (--study)")
    seeds = DEFAULT_SEEDS if args.episodes is None else args.episodes
    if seeds < 1:
        raise SpecError("<command line>", "--episodes", f"{seeds}: at least 1 seed per cell is needed")
    if args.jobs < 1:
        raise SpecError("<command line>", "--jobs", f"{args.jobs}: at least 1 process")
    text = DEFAULT_NOISE if args.noise is None else args.noise
    try:
        noise = sorted({float(x) for x in text.split(",") if x.strip()})
    except ValueError:
        raise SpecError("<command line>", "--noise", f"{text!r}: expected comma-separated numbers") from None
    if not noise or any(not 0.0 <= x <= 1.0 for x in noise):
        raise SpecError("<command line>", "--noise", f"{text!r}: word error rates in [0, 1] are needed")
    policies = list(study.DEFAULT_POLICIES) if args.policies is None else [
        p.strip() for p in args.policies.split(",") if p.strip()]
    known = {"hierarchical", "online", "behaviour_tree", "qmdp"}
    bad = [p for p in policies if p not in known and not p.startswith("online:")]
    if bad or not policies:
        raise SpecError("<command line>", "--policies", f"{bad[0] if bad else ''!r}: the ward world compares "
                        f"{', '.join(sorted(known))} and online:TRIALS")
    from pearl_pomdp.online.decider import online_trials

    for p in policies:
        online_trials(p, "--policies")          # a bad online:TRIALS fails before the model is compiled
    study_path = args.study or _share(world.study)
    require_file(study_path, "study file (--study)")
    params = _share(world.params_file)
    scenarios = load_ward_scenarios(study_path)
    hierarchy = resolve_hierarchy_path(args.domain, args.hierarchy) if "hierarchical" in policies else None
    if "hierarchical" in policies and hierarchy is None:
        raise SpecError(args.domain, "", "no hierarchy beside the domain for the hierarchical policy (--hierarchy)")
    started = time.perf_counter()
    terminal = show_progress(args)
    log = (lambda t: print(t, file=sys.stderr, flush=True)) if terminal else None  # noqa: E731
    domain = load_domain(args.domain)
    agents = study.ward_agents(domain, hierarchy, policies=policies, seed=args.seed, log=log)
    t0 = time.perf_counter()
    items = [(sc, x, k, name) for x in noise for sc in scenarios for k in range(seeds) for name in agents]
    _jobs.update(agents=agents, domain=domain, params=params, model=domain.compile())
    try:
        if args.jobs > 1:
            import multiprocessing

            with multiprocessing.get_context("fork").Pool(args.jobs) as pool:
                episodes: List[Any] = list(pool.imap(_one, items, chunksize=4))
        else:
            from tqdm import tqdm

            episodes = [_one(i) for i in tqdm(items, desc="ward study", disable=not terminal, leave=False)]
    finally:
        _jobs.clear()
    episode_seconds = time.perf_counter() - t0
    summary = study.summarise(episodes)
    out = Path(args.out) if args.out else Path("out") / f"ward-study-{time.strftime('%Y%m%d-%H%M%S')}"
    out.mkdir(parents=True, exist_ok=True)
    report = {
        "world": "ward",
        "protocol": {"study": str(study_path), "episodes_per_cell": [s.name for s in scenarios], "noise_levels": noise,
                     "noise_axis": "word_error_rate", "seeds_per_cell": seeds, "policies": policies,
                     "baseline": study.BASELINE, "episodes": len(episodes), "jobs": args.jobs,
                     "params_file": str(params), "hierarchy": str(hierarchy) if hierarchy else None},
        "plan_seconds": dict(agents.timings),
        **summary,
        "episode_seconds": round(episode_seconds, 1),
        "seconds": round(time.perf_counter() - started, 1),
        "files": {"json": str(out / "study.json")},
    }
    (out / "study.json").write_text(json.dumps(dict(report, episodes=study.episodes_json(episodes)), indent=1),
                                    encoding="utf-8")
    if args.json:
        print_json(report)
        return 0
    print(study.format_table(summary))
    print(f"{len(episodes)} episodes in {episode_seconds:.1f} s ({args.jobs} job(s)); wrote {out / 'study.json'}")
    return 0


def run_demo_cli(args: argparse.Namespace) -> int:
    """``pearl demo --domain config/ward.domain.yaml``: not built for the ward (a one-line error).

    Raises:
        SpecError: always; names the domain and what to run instead.
    """
    from pearl_pomdp.errors import SpecError

    raise SpecError(args.domain, "name", "'ward' has no `pearl demo` (docs/ward.md): run the study with "
                                         "`pearl experiment --domain config/ward.domain.yaml` or the nodes with "
                                         "`pearl launch ... params_file:=config/ward_nodes.yaml policy:=online:5`")
