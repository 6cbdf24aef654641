"""The study on days (docs/day.md, Part 2): controllers × residents × days × noise, paired by day.

:func:`run_day` runs one controller through one :class:`~pearl_sim.nursing_home.day.DayWorld` day
in the core executive (the step loop every world shares) and returns the day's checklist and score,
optionally the episode as ``pearl fit`` reads it (actions, observations, true states) and the
timeline a picture of the day is drawn from. :func:`run_days` runs a grid of them (``jobs``
processes); :func:`summarize` gives per controller and noise level the mean of every checklist row
with a 95 % t interval, and the per-day paired difference against the day tree.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any, Callable, Dict, List, Optional, Sequence

from pearl_sim.nursing_home.day import DAY_SECONDS, DayPlan, DayWorld, day_scenario, day_score, plan_day

__all__ = ["DayCase", "day_cases", "generated_case", "day_world", "run_day", "run_days", "summarize", "BASELINE", "SCORED_ROWS", "day_agents",
           "twin_name", "fit_channel_twins", "plan_channel_twins", "snr_contrasts"]

#: The day study's non-POMDP baseline: the episode tree with the day's Dock rule.
BASELINE = "day_tree"
#: The checklist rows summarised per controller (scalars; the score besides).
SCORED_ROWS = ("reminders_on_time_share", "walks_completed_share", "questions_answered_share", "unprompted_per_hour",
               "wrong_actions", "battery_empty", "docked_at_end", "station_share", "metres_driven", "battery_low_s")


@dataclass(frozen=True)
class DayCase:
    """One resident's day: her profile, her articulation and the day's seed."""

    resident: str
    fields: Dict[str, Any]
    articulation_wer: float
    day: int
    seed: int


def day_cases(profiles, days: int, first_day: int = 0) -> List[DayCase]:
    """Every profile × ``days`` days; resident *i*'s day *k* has seed ``1000·i + k`` (the protocol's rule)."""
    return [DayCase(p.name, dict(p.fields), float(p.articulation_wer), k, 1000 * i + k)
            for i, p in enumerate(profiles) for k in range(first_day, first_day + int(days))]


def generated_case(resident_seed: int, resident: int, seed: int) -> DayCase:
    """Day ``seed`` of the generator's ``resident`` (1-based) at ``resident_seed``: what ``pearl day`` runs."""
    from pearl_sim.nursing_home.residents import generate_residents

    profile = generate_residents(resident, seed=resident_seed)[-1]
    return DayCase(profile.name, dict(profile.fields), float(profile.articulation_wer), seed, seed)


def day_world(case: DayCase, domain, noise: float, plan: Optional[DayPlan] = None,
              channel: Optional[str] = None) -> DayWorld:
    """The world of ``case``'s day in ``domain``: her speech through the recogniser at word error rate
    ``noise`` (with her articulation), or with ``channel`` (a measured channel file) at ``noise`` dB SNR.
    ``plan``: the day's draws (default :func:`plan_day` of its seed)."""
    from pearl_sim.nursing_home.residents import effective_word_error_rate

    plan = plan if plan is not None else plan_day(case.seed)
    speech = ({"channel": "measured", "snr_db": float(noise), "measured": str(channel)} if channel else None)
    scenario = day_scenario(dict(case.fields), effective_word_error_rate(noise, case.articulation_wer) if not channel
                            else 0.0, case.seed, name=f"{case.resident}-day{case.day}", plan=plan, speech=speech)
    return DayWorld(scenario, plan, domain=domain)


def day_agents(domain, hierarchy_path, policies: Sequence[str], flat_trials: int = 100,
               log: Optional[Callable[[str], None]] = None):
    """name → controller for the day study: the POMDPs planned on ``domain`` and the day tree."""
    from pearl_sim.nursing_home.behaviour_tree import PearlBehaviourTree
    from pearl_sim.planning import plan_controller, plan_each

    model = domain.compile()

    def build(name: str):
        if name == BASELINE:
            return PearlBehaviourTree(BASELINE, list(model.actions), day_rules=True)
        return plan_controller(name, domain, model, hierarchy_path, flat_trials=flat_trials)

    return plan_each(policies, build, log=log)


#: The conjecture arm's prior for the twins' refitted speech rows: "heard as meant" worth 10 trials (docs/day.md).
TWIN_PRIOR_STRENGTH = 10.0


def twin_name(chatter_share: float) -> str:
    """The name of the hierarchy planned on speech rows refitted to the channel with ``chatter_share``."""
    return f"hierarchical@channel-chatter{float(chatter_share):g}"


def _plan_twin(task) -> float:
    """Plan the hierarchy on one twin's fitted domain file and save it (a worker's job); its seconds."""
    from pearl_pomdp.hierarchy import load_hierarchy, plan
    from pearl_pomdp.model.domain_yaml import load_domain

    domain_file, hierarchy_path, policy_dir = task
    t0 = time.perf_counter()
    domain = load_domain(domain_file)
    plan(domain, load_hierarchy(hierarchy_path, domain)).save(policy_dir)
    return time.perf_counter() - t0


def fit_channel_twins(domain_path, channel_path, kind: str, levels: Sequence[float],
                      chatter_shares: Sequence[float], folder) -> List[Dict[str, Any]]:
    """The conjecture arm's twins' domains (docs/day.md): for every SNR of ``levels`` and chatter share
    of ``chatter_shares``, the domain's speech rows refitted to the measured channel at that SNR —
    ``pearl fit DOMAIN --speech CHANNEL --snr DB --chatter-share F``, prior strength 10 — written to
    ``folder/<kind>-<DB>dB-chatter<F>.domain.yaml``.

    Returns one record per twin: ``name, snr_db, chatter_share, domain`` (the file), ``policy``
    (the directory its plan is saved in, :func:`plan_channel_twins`) and ``speech_rows_changed``.
    """
    from pathlib import Path

    from pearl_pomdp.asr.channel import ChannelTable
    from pearl_pomdp.fit_speech import write_speech_fitted

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    table = ChannelTable.load(channel_path)
    records: List[Dict[str, Any]] = []
    for level in levels:
        for share in chatter_shares:
            stem = f"{kind}-{float(level):g}dB-chatter{float(share):g}"
            domain_file, rows = write_speech_fitted(domain_path, table, float(level), folder / f"{stem}.domain.yaml",
                                                    TWIN_PRIOR_STRENGTH, float(share), label=f"{kind} noise")
            records.append({"name": twin_name(share), "snr_db": float(level), "chatter_share": float(share),
                            "domain": str(domain_file), "policy": str(folder / f"{stem}.policy"),
                            "speech_rows_changed": len(rows)})
    return records


def plan_channel_twins(domain_path, hierarchy_path, channel_path, kind: str, levels: Sequence[float],
                       chatter_shares: Sequence[float], folder, jobs: int = 1,
                       meanwhile: Optional[Callable[[], Any]] = None):
    """The conjecture arm's twins: their domains (:func:`fit_channel_twins`) and the hierarchy planned
    on each, saved beside it (``….policy/``, a directory ``pearl day --nodes --policy-dir`` reads).

    The plans run in ``jobs`` processes; ``meanwhile`` (e.g. planning the other controllers) runs in
    this process while they do, and its result is returned.

    A plan already saved in ``folder`` for exactly its twin's fitted domain (the model's fingerprint)
    is loaded instead of planned again (``plan_reused``): a stopped run resumes its plans.

    Returns ``(by_level, records, meanwhile_result)``: ``by_level`` maps each SNR to
    ``{twin name: Controller}`` (each twin tracks its belief in its own fitted domain); ``records``
    are :func:`fit_channel_twins`' with the seconds each plan took (``plan_seconds``, ``None`` when
    reused).
    """
    from pearl_pomdp.hierarchy.execute import load_hierarchical_policy
    from pearl_pomdp.model.domain_yaml import load_domain
    from pearl_sim.planning import Controller

    from pathlib import Path

    from pearl_pomdp.errors import PearlError

    records = fit_channel_twins(domain_path, channel_path, kind, levels, chatter_shares, folder)
    saved: Dict[str, Any] = {}
    for r in records:
        # A run's folder resumes: a plan already saved there for exactly this fitted domain (its
        # model's fingerprint) is loaded, not planned again.
        if Path(r["policy"]).is_dir():
            try:
                saved[r["policy"]] = load_hierarchical_policy(r["policy"], load_domain(r["domain"]))
            except PearlError:
                pass
    tasks = [(r["domain"], str(hierarchy_path), r["policy"]) for r in records if r["policy"] not in saved]
    if jobs <= 1 or not tasks:
        extra = meanwhile() if meanwhile is not None else None
        seconds = [_plan_twin(t) for t in tasks]
    else:
        from pearl_sim.workers import fork_pool

        with fork_pool(min(jobs, len(tasks))) as pool:
            pending = pool.map(_plan_twin, tasks)      # submitted now: planned while `meanwhile` runs
            extra = meanwhile() if meanwhile is not None else None
            seconds = list(pending)
    took = dict(zip([t[2] for t in tasks], seconds))
    by_level: Dict[float, Dict[str, Any]] = {}
    for record in records:
        record["plan_seconds"] = round(took[record["policy"]], 1) if record["policy"] in took else None
        record["plan_reused"] = record["policy"] in saved
        domain = load_domain(record["domain"])
        policy = saved.get(record["policy"]) or load_hierarchical_policy(record["policy"], domain)
        by_level.setdefault(record["snr_db"], {})[record["name"]] = Controller(record["name"], policy, domain=domain)
    return by_level, records, extra


def run_day(controller, domain, case: DayCase, noise: float, model=None, record: bool = False,
            timeline: bool = False, until: Optional[float] = None, plan: Optional[DayPlan] = None,
            channel: Optional[str] = None, own_model=None) -> Dict[str, Any]:
    """One day of ``controller`` for ``case`` at recogniser word error rate ``noise`` — or, with
    ``channel`` (a measured recogniser channel, ``pearl calibrate-speech --out``), with her speech
    heard through that channel at ``noise`` dB SNR (her articulation is not applied on this axis, as
    in the episode study's). A controller with its own ``domain`` (a twin planned on refitted speech
    rows) tracks its belief in that domain (``own_model``: its compiled POMDP, compiled here if not
    given); the world and the score are ``domain``'s.

    Returns ``policy, resident, day, seed, noise, score, checklist, seconds`` and, with ``record``,
    ``episode`` (``pearl fit``'s ``.jsonl`` fields; the day then ends early if the battery runs
    empty) and, with ``timeline``, one row per action:
    ``t, action, robot, resident, battery``.
    """
    from pearl_sim.nursing_home.experiment import episode_executive
    from pearl_sim.loop import ExecutiveBackend, run_episode

    t0 = time.perf_counter()
    world = day_world(case, domain, noise, plan, channel)
    scenario = world.scenario
    # The robot's model: the controller's own (a twin planned on refitted speech rows) or the world's.
    own = getattr(controller, "domain", None)
    if own is not None and own_model is None:
        own_model = own.compile()
    executive = (episode_executive(controller, own, scenario, own_model) if own is not None
                 else episode_executive(controller, domain, scenario, model))
    states: List[Dict[str, str]] = []
    rows: List[Dict[str, Any]] = []

    def before(action: str) -> None:
        if record:
            states.append(world.truth())
        if timeline:
            rows.append({"t": round(world.time, 1), "action": action, "robot": world.robot_at,
                         "resident": world.resident_state(), "battery": round(world.battery, 4)})

    # A day recorded for `pearl fit` ends when the battery does: the model has no state for a robot
    # that has stopped (its drives never arrive whatever the tables say), so those steps are not
    # Pearl's dynamics. The checklist of such a day is the truncated day's.
    end = DAY_SECONDS if until is None else float(until)
    stop = (lambda: world.time >= end or world.dead) if record else (lambda: world.time >= end)
    run_episode(world, ExecutiveBackend(executive), before_action=before, stop_when=stop)
    checklist = world.checklist()
    out: Dict[str, Any] = {"policy": controller.name, "resident": case.resident, "day": case.day, "seed": case.seed,
                           "noise": float(noise), "score": day_score(checklist), "checklist": checklist,
                           "seconds": round(time.perf_counter() - t0, 2)}
    if record:
        states.append(world.truth())
        steps = executive.steps
        out["episode"] = {"scenario": scenario.name, "seed": case.seed, "actions": [s.action for s in steps],
                          "observations": [s.observation for s in steps], "states": states[:len(steps) + 1]}
    if timeline:
        out["timeline"] = rows
    return out


@dataclass
class _Job:
    policy: str
    case: DayCase
    noise: float
    record: bool = False
    channel: Optional[str] = None


_WORKER: Dict[str, Any] = {}


def _init_worker(domain, agents, by_level=None) -> None:
    _WORKER.update(domain=domain, agents=agents, by_level=by_level or {}, model=domain.compile(), own_models={})


def _run_job(job: _Job) -> Dict[str, Any]:
    import logging

    logging.getLogger("pearl_pomdp").setLevel(logging.ERROR)
    controller = _WORKER["by_level"].get(job.noise, {}).get(job.policy) or _WORKER["agents"][job.policy]
    own = getattr(controller, "domain", None)
    own_model = None
    if own is not None:    # a twin's own model, compiled once per worker
        own_model = _WORKER["own_models"].get(id(own))
        if own_model is None:
            own_model = _WORKER["own_models"][id(own)] = own.compile()
    return run_day(controller, _WORKER["domain"], job.case, job.noise, model=_WORKER["model"],
                   record=job.record, channel=job.channel, own_model=own_model)


def run_days(domain, agents, cases: Sequence[DayCase], noise_levels: Sequence[float], jobs: int = 1,
             record: bool = False, progress: bool = False,
             each: Optional[Callable[[Dict[str, Any]], None]] = None,
             channel: Optional[str] = None,
             by_level: Optional[Dict[float, Dict[str, Any]]] = None) -> List[Dict[str, Any]]:
    """Every controller × case × noise level; the results in a fixed order whatever ``jobs`` is.
    ``channel``: the noise levels are SNRs (dB) through this measured recogniser channel (:func:`run_day`).
    ``by_level``: level → {name: controller} run at that level only, besides ``agents`` (the conjecture
    arm's twins, planned per SNR: :func:`plan_channel_twins`).

    ``each`` is called with every day's result as soon as it is in (in that order): a long study
    keeps what it has done (``pearl experiment --day`` appends each day to ``days.jsonl``)."""
    by_level = {float(k): v for k, v in (by_level or {}).items()}
    # Day by day, every level of a day before the next day: a study stopped part way keeps whole
    # days at every level (what a paired contrast between levels needs).
    work = [_Job(name, case, float(level), record, channel) for case in cases for level in noise_levels
            for name in [*agents, *by_level.get(float(level), {})]]
    iterator: Any
    if jobs <= 1:
        _init_worker(domain, agents, by_level)
        return _progress(map(_run_job, work), len(work), progress, each)
    from pearl_sim.workers import fork_pool

    with fork_pool(jobs, initializer=_init_worker, initargs=(domain, agents, by_level)) as pool:
        return _progress(pool.map(_run_job, work), len(work), progress, each)


def _progress(iterator, total: int, show: bool, each=None) -> List[Dict[str, Any]]:
    if show:
        from tqdm import tqdm

        iterator = tqdm(iterator, total=total, desc="days", unit="day")
    out = []
    for result in iterator:
        out.append(result)
        if each is not None:
            each(result)
    return out


def _shares(c: Dict[str, Any]) -> Dict[str, float]:
    def share(part: str, whole: str) -> float:
        return c[part] / c[whole] if c[whole] else 1.0

    return {"reminders_on_time_share": share("reminders_on_time", "reminders_due"),
            "walks_completed_share": min(1.0, share("walks_completed", "walks_wanted")),
            "questions_answered_share": share("questions_answered", "questions_raised"),
            "unprompted_per_hour": float(c["unprompted_per_hour"]), "wrong_actions": float(c["wrong_actions"]),
            "battery_empty": float(bool(c["battery_empty"])), "docked_at_end": float(bool(c["docked_at_end"])),
            "station_share": float(c["station_share"]), "metres_driven": float(c["metres_driven"]),
            "battery_low_s": float(c["battery_low_s"])}


def _ratio(part: float, whole: float) -> Optional[float]:
    """``part / whole``, or ``None`` when nothing was due (a share of nothing)."""
    return part / whole if whole else None


def _at_least(share: Optional[float], bound: float) -> bool:
    return share is None or share >= bound


def _fmt(share: Optional[float], width: int) -> str:
    return f"{'-':>{width}}" if share is None else f"{share:>{width}.2f}"


def summarize(days: Sequence[Dict[str, Any]], baseline: str = BASELINE) -> Dict[str, Any]:
    """Per controller and noise level: every row's mean with a 95 % t interval, pooled totals
    (reminders on time of all due, …), and the paired per-day difference against ``baseline``."""
    from pearl_sim.stats import t_ci

    by: Dict[str, Dict[float, List[Dict[str, Any]]]] = {}
    for d in days:
        by.setdefault(d["policy"], {}).setdefault(d["noise"], []).append(d)
    per_policy: Dict[str, Any] = {}
    for policy, levels in by.items():
        per_policy[policy] = {}
        for level, rows in sorted(levels.items()):
            shares = [_shares(r["checklist"]) for r in rows]
            total = {k: sum(r["checklist"][k] for r in rows) for k in
                     ("reminders_due", "reminders_on_time", "walks_wanted", "walks_completed", "questions_raised",
                      "questions_answered", "unprompted", "wrong_actions")}
            hours = sum(r["checklist"]["hours"] for r in rows)
            per_policy[policy][str(level)] = {
                "days": len(rows), "score": t_ci([r["score"] for r in rows]),
                "rows": {k: t_ci([s[k] for s in shares]) for k in SCORED_ROWS},
                "pooled": {"reminders_on_time_share": _ratio(total["reminders_on_time"], total["reminders_due"]),
                           "walks_completed_share": _ratio(total["walks_completed"], total["walks_wanted"]),
                           "questions_answered_share": _ratio(total["questions_answered"], total["questions_raised"]),
                           "unprompted_per_hour": total["unprompted"] / max(1e-9, hours),
                           "days_battery_empty": sum(bool(r["checklist"]["battery_empty"]) for r in rows),
                           "days_docked_at_end": sum(bool(r["checklist"]["docked_at_end"]) for r in rows),
                           **total},
            }
    paired: Dict[str, Any] = {}
    base = {(d["resident"], d["seed"], d["noise"]): d for d in days if d["policy"] == baseline}
    for policy, levels in by.items():
        if policy == baseline:
            continue
        paired[policy] = {}
        for level, rows in sorted(levels.items()):
            pairs = [(r, base[(r["resident"], r["seed"], r["noise"])]) for r in rows
                     if (r["resident"], r["seed"], r["noise"]) in base]
            if not pairs:
                continue
            diffs = {"score": t_ci([a["score"] - b["score"] for a, b in pairs])}
            for k in SCORED_ROWS:
                diffs[k] = t_ci([_shares(a["checklist"])[k] - _shares(b["checklist"])[k] for a, b in pairs])
            paired[policy][str(level)] = diffs
    return {"per_policy": per_policy, "paired_vs_baseline": paired}


def snr_contrasts(days: Sequence[Dict[str, Any]], baseline: str = BASELINE) -> Dict[str, Any]:
    """Does each controller's advantage over ``baseline`` grow as the channel worsens (SNR axis)?

    Per day present at the quietest and the noisiest SNR for both the controller and the baseline
    (same resident, same seed): ``c = (policy − baseline)[quietest] − (policy − baseline)[noisiest]``
    of the day score; its mean and 95 % t interval. ``c < 0``: the advantage grows as the channel
    worsens (the paper's conjecture). ``{policy: {"quiet_db", "noisy_db", "contrast"}}``; empty with
    fewer than two levels.
    """
    from pearl_sim.stats import t_ci

    levels = sorted({float(d["noise"]) for d in days})
    if len(levels) < 2:
        return {}
    noisy, quiet = levels[0], levels[-1]
    score = {(d["policy"], float(d["noise"]), d["resident"], d["seed"]): d["score"] for d in days}
    out: Dict[str, Any] = {}
    for policy in dict.fromkeys(d["policy"] for d in days):
        if policy == baseline:
            continue
        values = []
        for (p, level, resident, seed), s in score.items():
            if p != policy or level != quiet:
                continue
            tree_quiet, own_noisy, tree_noisy = (score.get(k) for k in (
                (baseline, quiet, resident, seed), (policy, noisy, resident, seed), (baseline, noisy, resident, seed)))
            if tree_quiet is not None and own_noisy is not None and tree_noisy is not None:
                values.append((s - tree_quiet) - (own_noisy - tree_noisy))
        out[policy] = {"quiet_db": quiet, "noisy_db": noisy, "contrast": t_ci(values)}
    return out


@dataclass
class Acceptance:
    """The day issue's acceptance for one controller at one noise level (docs/day.md)."""

    checks: Dict[str, bool] = field(default_factory=dict)

    @property
    def met(self) -> bool:
        return all(self.checks.values())


def acceptance(summary: Dict[str, Any], policy: str = "hierarchical") -> Dict[str, Any]:
    """The acceptance rows for ``policy`` at each noise level, each true or false as measured."""
    out: Dict[str, Any] = {}
    table = summary["per_policy"]
    for level, s in table.get(policy, {}).items():
        p = s["pooled"]
        best = max(v[level]["score"]["mean"] for v in table.values() if level in v)
        d = summary["paired_vs_baseline"].get(policy, {}).get(level)
        a = Acceptance({
            "reminders_on_time_95": _at_least(p["reminders_on_time_share"], 0.95),
            "walks_completed_95": _at_least(p["walks_completed_share"], 0.95),
            "questions_answered_90": _at_least(p["questions_answered_share"], 0.90),
            "unprompted_per_hour_0.2": p["unprompted_per_hour"] <= 0.2,
            "battery_never_empty": p["days_battery_empty"] == 0,
            "docked_at_end_95": p["days_docked_at_end"] >= 0.95 * s["days"],
            "station_share_80": s["rows"]["station_share"]["mean"] >= 0.80,
            "best_score_within_1pct": s["score"]["mean"] >= best - 0.01 * abs(best),
            "paired_score_vs_tree_ci_above_0": bool(d is not None and d["score"]["low"] is not None
                                                    and d["score"]["low"] > 0),
        })
        out[level] = {"checks": a.checks, "met": a.met}
    return out


#: The day study's controllers by default, and those it accepts.
DAY_POLICIES = ("hierarchical", "flat_pointbased", "qmdp", BASELINE)
DAY_POLICY_NAMES = ("hierarchical", "flat_pointbased", "qmdp", "most_likely_state", BASELINE)


def run_cli(args) -> int:
    """``pearl experiment --day``: the study on days, printed as a table or one JSON object."""
    import json
    import logging
    import sys
    from pathlib import Path

    from pearl_pomdp.cli import print_json
    from pearl_pomdp.cli._inputs import require_file
    from pearl_pomdp.cli._progress import show_progress
    from pearl_pomdp.errors import SpecError
    from pearl_pomdp.model.domain_yaml import load_domain
    from pearl_sim.worlds import share_path
    from pearl_sim.nursing_home.residents import parse_population

    started = time.perf_counter()
    if args.domain == share_path("config/pearl.domain.yaml"):
        args.domain = share_path("config/pearl_day.domain.yaml")
    hierarchy = args.hierarchy or share_path("config/pearl.hierarchy.yaml")
    days = 4 if args.days is None else int(args.days)
    if days < 1:
        raise SpecError("<command line>", "--days", f"{days}: at least 1 day per resident")
    if args.jobs < 1:
        raise SpecError("<command line>", "--jobs", f"{args.jobs}: at least 1 process")
    if args.speech_rows is not None or args.cluster is not None:
        raise SpecError("<command line>", "--day", "runs with --jobs on --noise word error rates or --snr "
                                                  "(--speech-rows and --cluster are the episode study's; its twins "
                                                  "are --speech-twins)")
    channel: Optional[str] = None
    kind: Optional[str] = None
    if args.snr is not None:
        # The SNR axis: her speech through the measured recogniser channel of one noise kind per run.
        if args.noise is not None:
            raise SpecError("<command line>", "--snr", "give --snr or --noise, not both")
        kinds = [k.strip() for k in (args.noise_kind or "white").split(",") if k.strip()]
        if len(kinds) != 1 or kinds[0] not in ("white", "babble"):
            raise SpecError("<command line>", "--noise-kind", f"{args.noise_kind!r}: --day takes one kind per run, "
                                                               "white or babble")
        kind = kinds[0]
        channel = str(Path(args.channel if kind == "white" else args.babble_channel).resolve())
        require_file(channel, f"{kind} speech channel file (--{'channel' if kind == 'white' else 'babble-channel'})")
        option, text, low, high, what = "--snr", args.snr, -20.0, 60.0, "SNRs in dB within [-20, 60]"
    else:
        if args.noise_kind is not None:
            raise SpecError("<command line>", "--noise-kind", "needs --snr (the kinds are heard at SNRs)")
        option, text, low, high, what = "--noise", ("0.25,0.5" if args.noise is None else args.noise), 0.0, 1.0, \
            "word error rates in [0, 1]"
    try:
        noise = sorted({float(x) for x in text.split(",") if x.strip()})
    except ValueError:
        raise SpecError("<command line>", option, f"{text!r}: expected comma-separated numbers") from None
    if not noise or any(not low <= x <= high for x in noise):
        raise SpecError("<command line>", option, f"{text!r}: {what}")
    policies = [p.strip() for p in (args.policies or ",".join(DAY_POLICIES)).split(",") if p.strip()]
    bad = [p for p in policies if p not in DAY_POLICY_NAMES]
    if bad or not policies:
        raise SpecError("<command line>", "--policies",
                        f"{bad[0] if bad else 'none'!r}: the day study runs {', '.join(DAY_POLICY_NAMES)}")
    require_file(args.domain, "domain file (--domain)")
    require_file(hierarchy, "hierarchy file (--hierarchy)")
    shares = _chatter_shares(args.speech_twins, channel, noise)
    spec = "generated:6" if args.residents == "paper,generated:6" else args.residents
    if "paper" in spec.split(","):
        raise SpecError("<command line>", "--residents", "the day study takes generated:N residents (the paper's "
                                                         "six have no profile for hearing, memory and articulation)")
    seed = 29 if args.seed is None else int(args.seed)
    profiles = parse_population(spec, None, seed=seed)
    cases = day_cases(profiles, days)
    terminal = show_progress(args)
    log = (lambda line: print(line, file=sys.stderr, flush=True)) if terminal else None
    domain = load_domain(args.domain)
    out = Path(args.out) if args.out else Path("out") / f"day-study-{time.strftime('%Y%m%d-%H%M%S')}"
    out.mkdir(parents=True, exist_ok=True)
    twins: Dict[float, Dict[str, Any]] = {}
    twin_records: List[Dict[str, Any]] = []
    if shares:
        # The conjecture arm's twins, planned in --jobs processes while this one plans the others.
        assert channel is not None and kind is not None
        twins, twin_records, agents = plan_channel_twins(
            args.domain, hierarchy, channel, kind, noise, shares, out / "twins", jobs=args.jobs,
            meanwhile=lambda: day_agents(domain, hierarchy, policies, log=log))
        if log:
            for r in twin_records:
                log(f"planned {r['name']} at {r['snr_db']:g} dB in {r['plan_seconds']:.1f} s")
    else:
        agents = day_agents(domain, hierarchy, policies, log=log)
    logging.getLogger("pearl_pomdp").setLevel(logging.ERROR)
    t0 = time.perf_counter()
    with (out / "days.jsonl").open("w", encoding="utf-8") as sink:
        def keep(day: Dict[str, Any]) -> None:
            sink.write(json.dumps(day) + "\n")
            sink.flush()

        results = run_days(domain, agents, cases, noise, jobs=args.jobs, progress=terminal, each=keep, channel=channel,
                           by_level=twins)
    day_seconds = time.perf_counter() - t0
    summary = summarize(results)
    if channel is not None and BASELINE in policies:
        summary["snr_contrast_vs_baseline"] = snr_contrasts(results)
    png = plot_study(summary, out / "day-study.png", snr_kind=kind)
    report = {
        "protocol": {"domain": str(args.domain), "hierarchy": str(hierarchy), "residents": [p.name for p in profiles],
                     "resident_spec": spec, "resident_seed": seed, "days_per_resident": days, "noise_levels": noise,
                     "noise_axis": "snr_db" if channel else "word_error_rate", "noise_kind": kind, "channel": channel,
                     "policies": policies + [twin_name(f) for f in shares], "baseline": BASELINE,
                     "speech_twins": {"chatter_shares": shares, "prior_strength": TWIN_PRIOR_STRENGTH,
                                      "twins": twin_records} if shares else None,
                     "jobs": args.jobs, "days": len(results)},
        "plan_seconds": {k: round(v, 1) for k, v in agents.timings.items()},
        **summary,
        "acceptance": acceptance(summary) if "hierarchical" in policies and BASELINE in policies else None,
        "files": {"json": str(out / "day-study.json"), "png": str(png), "days": str(out / "days.jsonl")},
        "day_seconds": round(day_seconds, 1), "seconds": round(time.perf_counter() - started, 1),
        "days": results,
    }
    (out / "day-study.json").write_text(json.dumps(report, indent=1), encoding="utf-8")
    if args.json:
        print_json(report)
        return 0
    print_table(summary)
    for policy, c in summary.get("snr_contrast_vs_baseline", {}).items():
        d = c["contrast"]
        if d["n"]:
            print(f"{policy}: advantage over {BASELINE} at {c['quiet_db']:g} dB − at {c['noisy_db']:g} dB "
                  f"{d['mean']:+.1f} [{d['low']:+.1f}, {d['high']:+.1f}] (< 0: it grows as the channel worsens)")
    print(f"{len(results)} days in {day_seconds:.1f} s ({args.jobs} job(s)); wrote {png}, {out / 'day-study.json'}")
    return 0


def _chatter_shares(text: Optional[str], channel: Optional[str], levels: Sequence[float]) -> List[float]:
    """``--speech-twins F,…``: the chatter shares of the twins, checked against the run (one clear error)."""
    from pearl_pomdp.asr.channel import ChannelError, ChannelTable
    from pearl_pomdp.errors import SpecError

    if text is None:
        return []
    if channel is None:
        raise SpecError("<command line>", "--speech-twins", "needs --snr (the twins' speech rows are refitted to the "
                                                            "measured channel at each SNR)")
    try:
        shares = list(dict.fromkeys(float(x) for x in text.split(",") if x.strip()))
    except ValueError:
        raise SpecError("<command line>", "--speech-twins", f"{text!r}: expected comma-separated chatter shares") \
            from None
    if not shares or any(not 0.0 <= f <= 1.0 for f in shares):
        raise SpecError("<command line>", "--speech-twins", f"{text!r}: chatter shares are fractions in [0, 1]")
    try:
        measured = [float(x) for x in ChannelTable.load(channel).snr_db]
    except ChannelError as err:
        raise SpecError(channel, "snr_db", str(err)) from None
    missing = [x for x in levels if float(x) not in measured]
    if missing:
        raise SpecError(channel, "snr_db", f"--speech-twins refits at every --snr, and {missing[0]:g} dB was not "
                                           f"measured (measured: {', '.join(f'{x:g}' for x in measured)})")
    return shares


def print_table(summary: Dict[str, Any]) -> None:
    """One line per controller and noise level: the day score and the checklist's pooled rows."""
    print(f"{'policy':<30} {'noise':>5} {'days':>4} {'score':>13} {'Δscore vs tree':>22} {'rem.ontime':>10} "
          f"{'walks':>6} {'questions':>9} {'unpr/h':>6} {'wrong/d':>7} {'empty':>5} {'docked':>6} {'station':>7}")
    for policy, levels in summary["per_policy"].items():
        for level, s in levels.items():
            p, sc = s["pooled"], s["score"]
            d = summary["paired_vs_baseline"].get(policy, {}).get(level)
            delta = f"{d['score']['mean']:+.1f} [{d['score']['low']:+.1f},{d['score']['high']:+.1f}]" if d else "-"
            print(f"{policy:<30} {level:>5} {s['days']:>4} {sc['mean']:>7.1f}±{sc['ci95']:<5.1f} {delta:>22} "
                  f"{_fmt(p['reminders_on_time_share'], 10)} {_fmt(p['walks_completed_share'], 6)} "
                  f"{_fmt(p['questions_answered_share'], 9)} "
                  f"{p['unprompted_per_hour']:>6.2f} {s['rows']['wrong_actions']['mean']:>7.2f} "
                  f"{p['days_battery_empty']:>5} {p['days_docked_at_end']:>6} {s['rows']['station_share']['mean']:>7.2f}")


def plot_study(summary: Dict[str, Any], path, snr_kind: Optional[str] = None) -> Any:
    """Day score per controller and noise level with 95 % intervals, and the paired difference to the tree
    (``snr_kind``: the levels are SNRs in dB of that noise kind, through the measured channel)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    table = summary["per_policy"]
    levels = sorted({lvl for v in table.values() for lvl in v}, key=float)
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(11, 4))
    width = 0.8 / max(1, len(table))
    for i, (policy, by) in enumerate(table.items()):
        xs = [j + i * width for j, lvl in enumerate(levels) if lvl in by]
        ys = [by[lvl]["score"]["mean"] for lvl in levels if lvl in by]
        es = [by[lvl]["score"]["ci95"] for lvl in levels if lvl in by]
        ax.bar(xs, ys, width, yerr=es, capsize=3, label=policy)
    names = [f"{snr_kind} {lvl} dB" if snr_kind else f"noise {lvl}" for lvl in levels]
    ax.set_xticks([j + 0.4 - width / 2 for j in range(len(levels))], names)
    ax.set_ylabel("day score (100 = perfect day)")
    ax.set_title("Day score, mean ± 95 % CI")
    ax.legend(fontsize=8)
    for i, (policy, by) in enumerate(summary["paired_vs_baseline"].items()):
        pts = [(j, by[lvl]["score"]) for j, lvl in enumerate(levels) if lvl in by]
        bx.errorbar([j + 0.1 * i for j, _ in pts], [d["mean"] for _, d in pts],
                    yerr=[[d["mean"] - d["low"] for _, d in pts], [d["high"] - d["mean"] for _, d in pts]],
                    fmt="o", capsize=3, label=policy)
    bx.axhline(0, color="k", lw=0.8)
    bx.set_xticks(range(len(levels)), names)
    bx.set_title(f"Paired day score − {BASELINE} (95 % CI)")
    if summary["paired_vs_baseline"]:
        bx.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
