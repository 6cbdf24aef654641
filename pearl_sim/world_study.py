"""``pearl experiment`` for the worlds of one study file (the reception, the ward): the common runner.

Each such world (``pearl_sim/reception/experiment.py``, ``pearl_sim/ward/experiment.py``) says what
is its own — its defaults, which of ``pearl experiment``'s options it refuses and why, the policies
it compares, how it builds them, its scenario loader, its episode runner and its study module — in
a :class:`WorldExperiment`; :func:`run_world_experiment` does the rest, the same for every such
world: the option checks, the noise levels, the cells (study file × noise levels × seeds ×
controllers) run on this machine's processes, the summary, ``study.json`` and the printout.
The pieces of their study modules that are the same are here too: the tracker's step rules of a
scenario (:func:`episode_settings`), one episode through the one step loop scored by its discounted
return (:func:`run_scored_episode`), the per-policy rows (:func:`per_policy_rows`) and the paired
differences over the same cells (:func:`paired_differences`).
The nursing-home study (``pearl_sim/nursing_home/experiment.py``) has its own runner: residents, SNR axes and a
cluster this one does not have.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, Dict, List, Optional, Sequence, Tuple, Union

if TYPE_CHECKING:  # pragma: no cover
    from pearl_sim.worlds import SimWorld

__all__ = ["WorldExperiment", "run_world_experiment", "StandardStudy", "WorldEpisode", "episode_settings", "run_scored_episode",
           "per_policy_rows", "paired_differences"]

#: ``pearl experiment --residents``' default: these worlds' people are in their study file, so any other
#: value is refused (``WorldExperiment.residents_reason``).
_DEFAULT_RESIDENTS = "paper,generated:6"
#: The options of ``pearl experiment`` only the nursing-home study reads; another world's
#: :class:`WorldExperiment` refuses them (``refused``).
NURSING_HOME_ONLY = ("--noise-kind", "--speech-rows", "--measured-policies", "--cluster")


@dataclass(frozen=True)
class WorldExperiment:
    """What one world brings to :func:`run_world_experiment`.

    Attributes:
        default_noise: the protocol's word error rates when ``--noise`` is not given (comma-separated).
        default_seeds: seeds per cell when ``--episodes`` is not given.
        refused: ``pearl experiment`` options (as typed, e.g. ``--cluster``) this world refuses, in the
            order they are checked; ``refused_reason`` is the error's text.
        refused_reason: why the options of ``refused`` are refused.
        residents_reason: why any ``--residents`` but the default is refused.
        study: the world's study module: ``DEFAULT_POLICIES``, ``BASELINE``, ``summarise(episodes)``,
            ``episodes_json(episodes)`` and ``format_table(summary)``.
        load_scenarios: the world's study file (path) -> its scenarios (each with ``name`` and ``seed``).
        run_episode: ``(scenario, agent, domain, params_file, seed=, word_error_rate=, model=)`` -> one
            episode of the world's study module.
        check_policies: raises ``SpecError`` naming ``--policies`` for a list the world does not compare.
        build_agents: ``(domain, hierarchy path or None, policies, args, log)`` -> the controllers by name
            (with ``timings``), planned once before the episodes.
        chunksize: episodes handed to a process at a time with ``--jobs`` > 1.
    """

    default_noise: str
    default_seeds: int
    refused: Tuple[str, ...]
    refused_reason: str
    residents_reason: str
    study: Any
    load_scenarios: Callable[[Any], Sequence[Any]]
    run_episode: Callable[..., Any]
    check_policies: Callable[[List[str]], None]
    build_agents: Callable[[Any, Optional[Path], List[str], argparse.Namespace, Any], Any]
    chunksize: int


#: What the episodes of a study run share: set before the pool forks (so the workers have it without
#: pickling the planned controllers), cleared after.
_jobs: Dict[str, Any] = {}


def _one(item):
    sc, noise, k, name = item
    w = _jobs
    return w["run_episode"](sc, w["agents"][name], w["domain"], w["params"], seed=sc.seed + 1000 * k,
                            word_error_rate=noise, model=w["model"])


def run_world_experiment(args: argparse.Namespace, files: "SimWorld", world: WorldExperiment) -> int:
    """Run the study of ``files`` (the registered world: its name, study file, node parameters) as
    ``world`` says, from ``pearl experiment``'s arguments; print the table or (``--json``) the report.

    Writes ``study.json`` (the report and every episode) into ``--out`` (default
    ``out/NAME-study-DATE-TIME``).

    Returns:
        0.

    Raises:
        SpecError: an option the world refuses, a bad ``--episodes``, ``--jobs``, ``--noise`` or
            ``--policies``, or a missing study file.
    """
    from pearl_pomdp.cli import print_json
    from pearl_pomdp.cli._inputs import require_file
    from pearl_pomdp.cli._progress import show_progress
    from pearl_pomdp.cli.plan import resolve_hierarchy_path
    from pearl_pomdp.errors import SpecError
    from pearl_pomdp.model.domain_yaml import load_domain
    study = world.study
    name = files.name
    if args.snr is not None:
        raise SpecError("<command line>", "--snr", f"the {name} world has the word-error recogniser only; "
                                                   "use --noise")
    for option in world.refused:
        if getattr(args, option[2:].replace("-", "_"), None) is not None:
            raise SpecError("<command line>", option, world.refused_reason)
    if args.residents != _DEFAULT_RESIDENTS:
        raise SpecError("<command line>", "--residents", world.residents_reason)
    # (A world that refuses the flat options never gets here with both.)
    if args.flat_trials is not None and args.flat_time_limit is not None:
        raise SpecError("<command line>", "--flat-trials", "give --flat-trials or --flat-time-limit, not both")
    seeds = world.default_seeds if args.episodes is None else args.episodes
    if seeds < 1:
        raise SpecError("<command line>", "--episodes", f"{seeds}: at least 1 seed per cell is needed")
    if args.jobs < 1:
        raise SpecError("<command line>", "--jobs", f"{args.jobs}: at least 1 process")
    text = world.default_noise if args.noise is None else args.noise
    try:
        noise = sorted({float(x) for x in text.split(",") if x.strip()})
    except ValueError:
        raise SpecError("<command line>", "--noise", f"{text!r}: expected comma-separated numbers") from None
    if not noise or any(not 0.0 <= x <= 1.0 for x in noise):
        raise SpecError("<command line>", "--noise", f"{text!r}: word error rates in [0, 1] are needed")
    policies = list(study.DEFAULT_POLICIES) if args.policies is None else [
        p.strip() for p in args.policies.split(",") if p.strip()]
    world.check_policies(policies)
    study_path = args.study or files.path(files.study)
    require_file(study_path, "study file (--study)")
    params = files.path(files.params_file) if files.params_file else None
    scenarios = world.load_scenarios(study_path)
    # No hierarchy beside the domain: the hierarchical controller plans the flat hierarchy (as `pearl plan`).
    hierarchy = resolve_hierarchy_path(args.domain, args.hierarchy) if "hierarchical" in policies else None
    started = time.perf_counter()
    terminal = show_progress(args)
    log = (lambda t: print(t, file=sys.stderr, flush=True)) if terminal else None  # noqa: E731
    domain = load_domain(args.domain)
    agents = world.build_agents(domain, hierarchy, policies, args, log)
    t0 = time.perf_counter()
    items = [(sc, x, k, name) for x in noise for sc in scenarios for k in range(seeds) for name in agents]
    _jobs.update(agents=agents, domain=domain, params=params, model=domain.compile(), run_episode=world.run_episode)
    try:
        if args.jobs > 1:
            from pearl_sim.workers import fork_pool

            with fork_pool(args.jobs) as pool:
                episodes: List[Any] = list(pool.map(_one, items, chunksize=world.chunksize))
        else:
            from tqdm import tqdm

            episodes = [_one(i) for i in tqdm(items, desc=f"{name} study", disable=not terminal, leave=False)]
    finally:
        _jobs.clear()
    episode_seconds = time.perf_counter() - t0
    summary = study.summarise(episodes)
    out = Path(args.out) if args.out else Path("out") / f"{name}-study-{time.strftime('%Y%m%d-%H%M%S')}"
    out.mkdir(parents=True, exist_ok=True)
    report = {
        "world": name,
        "protocol": {"study": str(study_path), "episodes_per_cell": [s.name for s in scenarios], "noise_levels": noise,
                     "noise_axis": "word_error_rate", "seeds_per_cell": seeds, "policies": policies,
                     "baseline": study.BASELINE, "episodes": len(episodes), "jobs": args.jobs,
                     "params_file": str(params) if params else None,
                     "hierarchy": str(hierarchy) if hierarchy else ("flat" if "hierarchical" in policies else None)},
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


def episode_settings(scenario, params_file: Union[str, Path, None]):
    """The belief tracker's step rules for ``scenario``: the params file's (``None``: the code's defaults,
    as the nodes run without one), then the scenario's (``scenario.tracker_parameters()``)."""
    from pearl_pomdp.params import step_settings
    from pearl_pomdp.tracking import StepSettings

    if params_file is None:
        return StepSettings.from_params(dict(scenario.tracker_parameters()))
    return step_settings(params_file, **scenario.tracker_parameters())


def run_scored_episode(world, executive, domain, model, on_step=None,
                       on_start: Optional[Callable[[str], None]] = None) -> Tuple[Any, float]:
    """Run ``world`` with ``executive`` through the one step loop (:func:`pearl_sim.loop.run_episode`).

    Args:
        world: the simulated world (``truth()``: its true state, feature → value).
        executive: the core executive deciding for the robot.
        domain, model: the domain and its compiled POMDP (R and γ of the return).
        on_step: ``(world, result, waits, executive)`` after every action, or ``None``.
        on_start: ``(action)`` when an action starts (before it is scored), or ``None``.

    Returns:
        The loop's trace and the discounted return Σ_t γ^t R[s_t, a_t], s_t the world's true state
        when a_t starts.
    """
    from pearl_sim.loop import ExecutiveBackend, run_episode

    index = {a: i for i, a in enumerate(model.actions)}
    score = {"total": 0.0, "discount": 1.0}

    def start(action: str) -> None:
        if on_start is not None:
            on_start(action)
        state = domain.state_index(world.truth())
        score["total"] += score["discount"] * float(model.R[state, index[action]])
        score["discount"] *= model.discount

    def after(result, waits) -> None:
        if on_step is not None:
            on_step(world, result, waits, executive)

    trace = run_episode(world, ExecutiveBackend(executive), before_action=start, on_action=after)
    return trace, score["total"]


def per_policy_rows(episodes: Sequence[Any], scores: Sequence[str],
                    extra: Callable[[List[Any]], Dict[str, Any]]) -> Dict[str, Dict[str, dict]]:
    """policy → noise level (``f"{noise:g}"``) → a row: every score's mean with a 95 % t CI, task
    success with a Wilson CI (``success_rate``), the world's ``extra(episodes)`` and ``episodes``.

    Policies in the order they first appear, noise levels ascending.
    """
    from pearl_sim.stats import proportion_ci, t_ci

    groups: Dict[str, Dict[float, List[Any]]] = {}
    for e in episodes:
        groups.setdefault(e.policy, {}).setdefault(e.noise, []).append(e)
    per_policy: Dict[str, Dict[str, dict]] = {}
    for policy, by_noise in groups.items():
        per_policy[policy] = {}
        for noise, es in sorted(by_noise.items()):
            row: Dict[str, Any] = {s: t_ci([float(getattr(e, s)) for e in es]) for s in scores}
            row["success_rate"] = proportion_ci(sum(e.success for e in es), len(es))
            row.update(extra(es))
            row["episodes"] = len(es)
            per_policy[policy][f"{noise:g}"] = row
    return per_policy


def paired_differences(episodes: Sequence[Any], scores: Sequence[str], policy: str,
                       other: str) -> Dict[str, Dict[str, dict]]:
    """noise level → score → mean and 95 % t CI of ``policy`` − ``other`` over the cells both ran
    (the same scenario, noise level and seed: the same world), for every noise level of ``episodes``."""
    from pearl_sim.stats import t_ci

    index = {(e.policy, e.scenario, e.noise, e.seed): e for e in episodes}
    out = {}
    for noise in sorted({e.noise for e in episodes}):
        diffs: Dict[str, List[float]] = {s: [] for s in scores}
        for (p, sc, n, seed), e in index.items():
            base = index.get((other, sc, n, seed))
            if p != policy or n != noise or base is None:
                continue
            for s in scores:
                diffs[s].append(float(getattr(e, s)) - float(getattr(base, s)))
        out[f"{noise:g}"] = {s: t_ci(v) for s, v in diffs.items()}
    return out


@dataclass
class WorldEpisode:
    """One episode of a :class:`StandardStudy`: the cell it ran in and its scores."""

    policy: str
    scenario: str
    noise: float
    seed: int
    discounted_return: float
    success: bool
    wrong_actions: int
    steps: int
    seconds: float
    #: The world's own scores (``StandardStudy.score``), by name.
    scores: Dict[str, float]
    actions: List[str]
    wrong: List[str]

    def __getattr__(self, name: str):
        # The world's scores read like fields (per_policy_rows and paired_differences use getattr).
        scores = self.__dict__.get("scores", {})
        if name in scores:
            return scores[name]
        raise AttributeError(name)


@dataclass(frozen=True)
class StandardStudy:
    """A world's study that the frame runs whole: a world that brings these needs no study module.

    Every controller meets every cell; an episode runs through the one step loop
    (:func:`run_scored_episode`), scored by its discounted return, ``success``, ``wrong_actions``
    and the world's own scores; the summary, the paired differences against :attr:`baseline`, the
    episodes' JSON and the table are the frame's. It answers what :class:`WorldExperiment` asks of
    a ``study`` (``DEFAULT_POLICIES``, ``BASELINE``, ``summarise``, ``episodes_json``, ``format_table``)
    and gives ``run_episode`` and ``build_agents``.

    Attributes:
        make_world: ``(scenario, seed, word_error_rate)`` -> a fresh world (``metrics.wrong_actions``,
            ``metrics.wrong``, ``time``, ``seed``, ``word_error_rate``).
        score: the world after its episode -> ``{"success": bool, name: number, …}``.
        tree: the world's behaviour tree (a controller with ``name`` and ``decider``), given the
            domain's actions.
        policies: the compared controllers (POMDP ones planned by :func:`pearl_sim.planning.plan_controller`,
            ``online`` / ``online:N`` by DESPOT, and ``behaviour_tree``).
        baseline: the controller the others are paired against.
    """

    make_world: Callable[[Any, Optional[int], Optional[float]], Any]
    score: Callable[[Any], Dict[str, Any]]
    tree: Callable[[List[str]], Any]
    policies: Tuple[str, ...] = ("hierarchical", "qmdp", "behaviour_tree")
    baseline: str = "behaviour_tree"

    @property
    def DEFAULT_POLICIES(self) -> Tuple[str, ...]:  # noqa: N802 (the study-module attribute WorldExperiment reads)
        return self.policies

    @property
    def BASELINE(self) -> str:  # noqa: N802
        return self.baseline

    def run_episode(self, scenario, agent, domain, params_file, seed: Optional[int] = None,
                    word_error_rate: Optional[float] = None, model=None) -> WorldEpisode:
        """Run ``agent`` in a fresh world of ``scenario`` through the one step loop, and score it."""
        from pearl_pomdp.executive import Executive

        model = model if model is not None else domain.compile()
        world = self.make_world(scenario, seed, word_error_rate)
        if hasattr(agent.decider, "reset"):
            agent.decider.reset()
        executive = Executive(model, agent.decider, domain=domain, settings=episode_settings(scenario, params_file))
        trace, total = run_scored_episode(world, executive, domain, model)
        scores = dict(self.score(world))
        success = bool(scores.pop("success"))
        return WorldEpisode(policy=agent.name, scenario=scenario.name, noise=float(world.word_error_rate),
                            seed=world.seed, discounted_return=total, success=success,
                            wrong_actions=world.metrics.wrong_actions, steps=len(trace.actions),
                            seconds=float(world.time), scores=scores, actions=list(trace.actions),
                            wrong=list(world.metrics.wrong))

    def build_agents(self, domain, hierarchy, policies: List[str], args: argparse.Namespace, log):
        """The controllers by name, planned once (``.timings``): the tree, ``online[:N]``, or a POMDP one."""
        from pearl_pomdp.online.decider import OnlineDecider, online_settings, online_trials
        from pearl_sim.planning import Controller, plan_controller, plan_each

        model = domain.compile()

        def build(name: str):
            if name == self.baseline:
                return self.tree(list(model.actions))
            trials = online_trials(name, "--policies")
            if trials is not None:
                return Controller(name, OnlineDecider(model, settings=online_settings(trials, None, "--policies"),
                                                      seed=args.seed))
            return plan_controller(name, domain, model, hierarchy, seed=args.seed, flat_trials=args.flat_trials,
                                   flat_time_limit=args.flat_time_limit)

        return plan_each(policies, build, log)

    def check_policies(self, policies: List[str]) -> None:
        """Raises ``SpecError`` naming ``--policies`` for a controller this study cannot build."""
        from pearl_pomdp.errors import SpecError
        from pearl_pomdp.online.decider import online_trials
        from pearl_sim.planning import POMDP_POLICIES

        known = set(POMDP_POLICIES) | {self.baseline}
        bad = [p for p in policies if p not in known and online_trials(p, "--policies") is None]
        if bad or not policies:
            raise SpecError("<command line>", "--policies", f"{bad[0] if bad else ''!r}: this world compares "
                            f"{', '.join(sorted(known))} and online[:TRIALS]")

    def _score_names(self, episodes: Sequence[WorldEpisode]) -> Tuple[str, ...]:
        own = sorted({k for e in episodes for k in e.scores})
        return ("discounted_return", "success", "wrong_actions", *own)

    def summarise(self, episodes: Sequence[WorldEpisode]) -> dict:
        """``per_policy`` (policy → noise → score → mean and 95 % t CI; success with a Wilson CI) and
        ``paired_vs_baseline`` (policy → noise → score → policy − baseline over the same cells)."""
        scores = self._score_names(episodes)
        per_policy = per_policy_rows(episodes, scores, lambda es: {})
        return {"per_policy": per_policy,
                "paired_vs_baseline": {p: paired_differences(episodes, scores, p, self.baseline) for p in per_policy
                                       if p != self.baseline and self.baseline in per_policy}}

    @staticmethod
    def episodes_json(episodes: Sequence[WorldEpisode]) -> List[dict]:
        """JSON-ready rows, one per episode (the world's scores beside the frame's)."""
        from dataclasses import asdict

        return [{**{k: v for k, v in asdict(e).items() if k != "scores"}, **e.scores} for e in episodes]

    def format_table(self, summary: dict) -> str:
        """The study's table: return ± CI, its paired difference to the baseline, success, wrong actions."""
        lines = [f"{'policy':<16} {'noise':>5} {'return':>14} {'Δreturn vs ' + self.baseline + ' [95% CI]':>34} "
                 f"{'success':>18} {'wrong/ep':>9}"]
        for policy, by_noise in summary["per_policy"].items():
            for level, row in by_noise.items():
                r, s = row["discounted_return"], row["success_rate"]
                d = "-"
                if policy in summary["paired_vs_baseline"]:
                    p = summary["paired_vs_baseline"][policy][level]["discounted_return"]
                    d = f"{p['mean']:+.2f} [{p['low']:+.2f}, {p['high']:+.2f}]"
                lines.append(f"{policy:<16} {level:>5} {r['mean']:>7.2f} ± {r['ci95']:<5.2f} {d:>34} "
                             f"{s['successes']:>3}/{s['n']:<3} [{s['low']:.2f},{s['high']:.2f}] "
                             f"{row['wrong_actions']['mean']:>9.2f}")
        return "\n".join(lines)

    def experiment(self, load_scenarios: Callable[[Any], Sequence[Any]], default_noise: str = "0,0.2",
                   default_seeds: int = 5, chunksize: int = 4) -> WorldExperiment:
        """This study as the :class:`WorldExperiment` a :class:`~pearl_sim.worlds.SimWorld` names; the
        nursing-home-only options (``--noise-kind``, ``--speech-rows``, ``--measured-policies``,
        ``--cluster``) are refused."""
        return WorldExperiment(
            default_noise=default_noise, default_seeds=default_seeds,
            refused=NURSING_HOME_ONLY,
            refused_reason="is for the nursing-home study; this world's study runs on this machine's processes "
                           "(--jobs) with word error rates",
            residents_reason="this world's people are in its study file (--study)",
            study=self, load_scenarios=load_scenarios, run_episode=self.run_episode,
            check_policies=self.check_policies, build_agents=self.build_agents, chunksize=chunksize)
