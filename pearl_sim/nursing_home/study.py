"""The guidance study: policies × residents × tasks × noise × seeds, with paired statistics.

Protocol (``docs/study.md``): every policy meets every *cell* — a resident
(:mod:`pearl_sim.nursing_home.residents`) on a task, at a noise level (the recogniser's word error
rate, combined with the resident's articulation), with a seed — and the same cell gives the
same world (same seed, same resident, same noise) to every policy, so the per-episode
differences against the behaviour tree are **paired**. Each episode runs through
:func:`pearl_sim.nursing_home.experiment.run_episode` (the core executive: the robot's step loop).

Episodes are spread over processes with ``jobs`` (``multiprocessing`` with the *fork*
start method: the planned policies are built once in the parent and inherited). Every
episode is seeded by its cell alone and results are collected in cell order, so the
numbers do not depend on ``jobs`` (``test/test_study.py`` checks ``jobs=2`` against ``jobs=1``).
"""
from __future__ import annotations

import csv
from dataclasses import dataclass, replace
from typing import Dict, List, Optional, Sequence

from pearl_sim.nursing_home.experiment import EpisodeResult, run_episode
from pearl_sim.nursing_home.residents import StudyCase, effective_word_error_rate
from pearl_sim.stats import proportion_ci, t_ci
from pearl_sim.workers import fork_pool

__all__ = ["Cell", "StudyEpisode", "cells", "run_cells", "per_policy", "paired", "acceptance", "write_csv",
           "plot_study", "BASELINE", "PAIRED_METRICS"]

#: The policy every other one is compared with, episode by episode.
BASELINE = "behaviour_tree"
#: Per-episode metrics whose paired differences are reported.
PAIRED_METRICS = ("success", "wrong_actions", "discounted_return", "clarifications", "unprompted_questions",
                  "time_to_goal")


@dataclass(frozen=True)
class Cell:
    """One world: case index (resident × task), noise level, seed index, and noise kind
    (``""`` on the word-error axis and the single-channel SNR axis; ``white``/``babble`` on
    the (kind, SNR) axis, each kind heard through its own measured channel)."""

    case: int
    noise: float
    k: int
    kind: str = ""


def level_label(kind: str, noise: float) -> str:
    """The key of a noise level in the tables: ``"10"``, or ``"babble:10"`` on the (kind, SNR) axis."""
    return f"{kind}:{noise:g}" if kind else f"{noise:g}"


def label_value(label: str) -> float:
    """The number of a level label (``"babble:10"`` → 10.0)."""
    return float(label.rsplit(":", 1)[-1])


def label_kind(label: str) -> str:
    """The noise kind of a level label (``""`` when it has none)."""
    return label.rsplit(":", 1)[0] if ":" in label else ""


@dataclass
class StudyEpisode:
    """An episode's scores and the cell it ran in."""

    policy: str
    resident: str
    task: str
    noise: float
    word_error_rate: float
    seed: int
    result: EpisodeResult
    noise_kind: str = ""

    @property
    def level(self) -> str:
        """The noise level's label (:func:`level_label`)."""
        return level_label(self.noise_kind, self.noise)

    def row(self) -> dict:
        r = self.result
        return {"policy": self.policy, "resident": self.resident, "task": self.task, "noise_kind": self.noise_kind,
                "noise": self.noise,
                "word_error_rate": round(self.word_error_rate, 6), "seed": self.seed,
                "guidance_completed": int(r.guidance_completed), "guidance_wanted": int(r.guidance_wanted),
                "time_to_goal_s": r.time_to_goal,
                "clarifications": r.clarifications, "unprompted_questions": r.unprompted_questions,
                "goals_achieved": r.goals_achieved, "wrong_actions": r.wrong_actions,
                "residents_lost": r.residents_lost, "discounted_return": r.discounted_return, "steps": r.steps}


def cells(n_cases: int, noise_levels: Sequence[float], seeds: int, kinds: Sequence[str] = ("",)) -> List[Cell]:
    """Every noise kind × case × noise level × seed, in a fixed order."""
    return [Cell(c, float(n), k, kind) for kind in kinds for n in noise_levels for c in range(n_cases)
            for k in range(seeds)]


# The work a forked worker inherits (set by run_cells before the pool starts).
_WORK: dict = {}


def _run_one(job) -> StudyEpisode:
    return run_job(_WORK, job)


def run_job(work: dict, job) -> StudyEpisode:
    """One episode: ``job`` = (policy, :class:`Cell`) with ``work`` = the study's domain, agents,
    cases and speech channels (what :func:`run_cells` hands every worker)."""
    policy, cell = job
    domain, agents, cases = work["domain"], work["agents"], work["cases"]
    case: StudyCase = cases[cell.case]
    sc = case.scenario
    channel = work["channels"][cell.kind] if cell.kind else work.get("channel")
    if channel:
        # SNR axis: the room's SNR through the measured recogniser channel (pooled over the
        # calibration's voices); her articulation is not applied on this axis.
        wer = float("nan")
        sc = replace(sc, speech={"channel": "measured", "snr_db": float(cell.noise), "measured": str(channel),
                                 "word_error_rate": sc.word_error_rate})
    else:
        wer = effective_word_error_rate(cell.noise, case.articulation_wer)
        sc = replace(sc, word_error_rate=wer, resident=replace(sc.resident, word_error_rate=None))
    seed = sc.seed + 1000 * cell.k
    result = run_episode(sc, agents[policy], domain, seed=seed)
    return StudyEpisode(policy, case.resident, case.task, cell.noise, wer, seed, result, cell.kind)


def run_cells(domain, agents: Dict[str, object], cases: Sequence[StudyCase], grid: Sequence[Cell],
              jobs: int = 1, progress: bool = False, channel: Optional[str] = None,
              channels: Optional[Dict[str, str]] = None, cluster: Optional[str] = None,
              cluster_timeout: Optional[float] = None) -> List[StudyEpisode]:
    """Every policy in every cell; ``jobs`` worker processes (1: this process), or the
    workers of the Dask cluster at ``cluster`` (:mod:`pearl_sim.cluster`: the same episodes).

    ``channel``: a calibrated speech channel (``pearl calibrate-speech --out``); the cells'
    noise levels are then SNRs in dB through it, else word error rates. ``channels``: noise
    kind → channel file, for cells with a ``kind`` (the (kind, SNR) axis).
    """
    from tqdm import tqdm

    work = [(policy, cell) for cell in grid for policy in agents]
    payload = dict(domain=domain, agents=agents, cases=list(cases), channel=channel, channels=dict(channels or {}))
    missing = sorted({c.kind for c in grid if c.kind} - set(payload["channels"]))
    if missing:
        raise ValueError(f"no speech channel for noise kind {missing[0]!r}")
    if cluster is not None:
        from pearl_sim.cluster import run_on_cluster

        return run_on_cluster(cluster, payload, work, progress=progress, timeout=cluster_timeout)
    _WORK.update(payload)
    try:
        bar = tqdm(total=len(work), desc="study", disable=not progress, leave=False)
        out: List[StudyEpisode] = []
        if jobs <= 1:
            for job in work:
                out.append(_run_one(job))
                bar.update()
        else:
            with fork_pool(int(jobs)) as pool:
                for episode in pool.map(_run_one, work, chunksize=max(1, len(work) // (jobs * 16))):
                    out.append(episode)
                    bar.update()
        bar.close()
        return out
    finally:
        _WORK.clear()


# ---------------------------------------------------------------- statistics
def _value(e: StudyEpisode, metric: str) -> Optional[float]:
    r = e.result
    if metric == "success":
        return float(r.guidance_completed)
    if metric == "time_to_goal":
        return r.time_to_goal
    return float(getattr(r, metric))


def per_policy(episodes: Sequence[StudyEpisode]) -> Dict[str, Dict[str, dict]]:
    """policy → noise level → scores with 95 % CIs."""
    groups: Dict[str, Dict[tuple, List[StudyEpisode]]] = {}
    for e in episodes:
        groups.setdefault(e.policy, {}).setdefault((e.noise_kind, e.noise), []).append(e)
    out: Dict[str, Dict[str, dict]] = {}
    for policy, by_noise in groups.items():
        out[policy] = {}
        for (kind, noise), es in sorted(by_noise.items()):
            rs = [e.result for e in es]
            goals = sum(r.goals_achieved for r in rs)
            out[policy][level_label(kind, noise)] = {
                "episodes": len(rs),
                "guidance_success": proportion_ci(sum(r.guidance_completed for r in rs), len(rs)),
                # Of the episodes where she wanted the walk (she may decline the reminder's offer).
                "wanted_guidance_success": proportion_ci(sum(r.guidance_completed for r in rs if r.guidance_wanted),
                                                         sum(r.guidance_wanted for r in rs)),
                "time_to_goal_s": t_ci([r.time_to_goal for r in rs if r.time_to_goal is not None]),
                "clarifications_per_goal": (sum(r.clarifications for r in rs) / goals) if goals else None,
                "clarifications_per_episode": t_ci([r.clarifications for r in rs]),
                "unprompted_questions_per_episode": t_ci([r.unprompted_questions for r in rs]),
                "wrong_actions_per_episode": t_ci([r.wrong_actions for r in rs]),
                "residents_lost": int(sum(r.residents_lost for r in rs)),
                "discounted_return": t_ci([r.discounted_return for r in rs]),
            }
    return out


def paired(episodes: Sequence[StudyEpisode], baseline: str = BASELINE) -> Dict[str, Dict[str, dict]]:
    """policy → noise → metric → mean and 95 % CI of (policy − baseline) over matched cells.

    Cells are matched on (resident, task, noise kind, noise, seed). ``time_to_goal`` pairs
    only cells where both completed the guidance.
    """
    index = {(e.policy, e.resident, e.task, (e.noise_kind, e.noise), e.seed): e for e in episodes}
    policies = sorted({e.policy for e in episodes} - {baseline})
    noises = sorted({(e.noise_kind, e.noise) for e in episodes})
    out: Dict[str, Dict[str, dict]] = {}
    for policy in policies:
        out[policy] = {}
        for noise in noises:
            diffs: Dict[str, List[float]] = {m: [] for m in PAIRED_METRICS}
            for (p, resident, task, n, seed), e in index.items():
                if p != policy or n != noise:
                    continue
                base = index.get((baseline, resident, task, n, seed))
                if base is None:
                    continue
                for m in PAIRED_METRICS:
                    a, b = _value(e, m), _value(base, m)
                    if a is not None and b is not None:
                        diffs[m].append(a - b)
            out[policy][level_label(*noise)] = {m: t_ci(v) for m, v in diffs.items()}
    return out


def growth(episodes: Sequence[StudyEpisode], policy: str, worse: str, better: str, metric: str = "discounted_return",
           baseline: str = BASELINE) -> dict:
    """Does ``policy``'s advantage over ``baseline`` grow from level ``better`` to level ``worse``?

    Per matched cell (resident, task, seed) present at both levels for both policies:
    ``g = (policy − baseline)[worse] − (policy − baseline)[better]``; returns its mean and
    Student-t 95 % CI (:func:`t_ci`). Levels are labels (``"babble:10"``). For the return,
    ``g > 0`` means the advantage grows as recognition gets worse; for wrong actions, ``g < 0``.
    """
    index = {(e.policy, e.level, e.resident, e.task, e.seed): e for e in episodes}
    gs: List[float] = []
    for (p, level, resident, task, seed), e in index.items():
        if p != policy or level != worse:
            continue
        found = [index.get((q, lv, resident, task, seed)) for q, lv in
                 ((baseline, worse), (policy, better), (baseline, better))]
        others = [o for o in found if o is not None]
        if len(others) < 3:
            continue
        values = [_value(x, metric) for x in [e, *others]]
        if any(v is None for v in values):
            continue
        a, b, c, d = (float(v) for v in values)  # type: ignore[arg-type]
        gs.append((a - b) - (c - d))
    return t_ci(gs)


def growth_contrasts(episodes: Sequence[StudyEpisode], baseline: str = BASELINE) -> Dict[str, Dict[str, dict]]:
    """Every policy's :func:`growth` of the return and wrong-action advantage over ``baseline``
    for each kind's noisiest vs quietest SNR, and for babble vs white at each SNR both have.

    Keys ``"babble:10 vs babble:30"``; each value ``{"discounted_return": …, "wrong_actions": …}``.
    """
    levels = sorted({(e.noise_kind, e.noise) for e in episodes})
    pairs = []
    for kind in sorted({k for k, _ in levels}):
        snrs = sorted(n for k, n in levels if k == kind)
        if len(snrs) >= 2:
            pairs.append((level_label(kind, snrs[0]), level_label(kind, snrs[-1])))
    for k, n in levels:
        if k == "babble" and ("white", n) in levels:
            pairs.append((level_label("babble", n), level_label("white", n)))
    policies = sorted({e.policy for e in episodes} - {baseline})
    return {f"{worse} vs {better}": {p: {m: growth(episodes, p, worse, better, m, baseline)
                                         for m in ("discounted_return", "wrong_actions")} for p in policies}
            for worse, better in pairs}


def of_kind(table: Dict[str, Dict[str, dict]], kind: str) -> Dict[str, Dict[str, dict]]:
    """The levels of one noise kind, keyed by their SNR alone (``"babble:10"`` → ``"10"``)."""
    return {policy: {f"{label_value(k):g}": v for k, v in by_level.items() if label_kind(k) == kind}
            for policy, by_level in table.items()}


def acceptance(table: Dict[str, Dict[str, dict]], diffs: Dict[str, Dict[str, dict]], policy: str = "hierarchical",
               baseline: str = BASELINE, snr: bool = False) -> Optional[dict]:
    """The issue's goal, evaluated (``None`` when the policy or the baseline was not run).

    Quietest level: ``policy``'s success rate lies inside the baseline's Wilson 95 % CI and
    its mean return inside the baseline's 95 % CI. Two noisiest levels: the paired 95 % CI of
    wrong actions (policy − baseline) lies below 0, and the mean paired success difference is
    ≥ 0 (at least equal success).
    """
    if policy not in table or baseline not in table or policy not in diffs:
        return None
    # Quietest first: the lowest word error rate, or the highest SNR.
    levels = sorted(table[baseline], key=label_value, reverse=snr)
    quiet = levels[0]
    b, p = table[baseline][quiet], table[policy][quiet]
    bs, br = b["guidance_success"], b["discounted_return"]
    tol = 1e-9   # the Wilson bound of a 100 % rate is 1 up to rounding
    success_within = bs["low"] - tol <= p["guidance_success"]["rate"] <= bs["high"] + tol
    return_within = br["mean"] - br["ci95"] - tol <= p["discounted_return"]["mean"] <= br["mean"] + br["ci95"] + tol
    noisy = {}
    for level in levels[-2:] if len(levels) >= 2 else levels:
        d = diffs[policy][level]
        noisy[level] = {"fewer_wrong_actions": d["wrong_actions"]["n"] > 1 and d["wrong_actions"]["high"] < 0,
                        "at_least_equal_success": d["success"]["mean"] is not None and d["success"]["mean"] >= 0,
                        "wrong_actions_diff": d["wrong_actions"], "success_diff": d["success"]}
    met = success_within and return_within and all(v["fewer_wrong_actions"] and v["at_least_equal_success"]
                                                   for v in noisy.values())
    return {"quietest_level": quiet, "success_within_baseline_ci": success_within,
            "return_within_baseline_ci": return_within, "noisiest_levels": noisy, "met": bool(met)}


# ---------------------------------------------------------------- outputs
def write_csv(episodes: Sequence[StudyEpisode], path) -> None:
    """One row per episode."""
    rows = [e.row() for e in episodes]
    with open(path, "w", newline="", encoding="utf-8") as fh:
        writer = csv.DictWriter(fh, fieldnames=list(rows[0]) if rows else ["policy"])
        writer.writeheader()
        writer.writerows(rows)


def plot_study(table: Dict[str, Dict[str, dict]], diffs: Dict[str, Dict[str, dict]], path,
               baseline: str = BASELINE, snr: bool = False) -> None:
    """PNG, three panels vs noise, one line per policy with its 95 % CI band: guidance success
    (Wilson), wrong actions per episode, and the paired wrong-action difference to ``baseline``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(16, 4.8))
    for policy, by_noise in table.items():
        xs = sorted(by_noise, key=float)
        x = [float(v) for v in xs]
        s = [by_noise[v]["guidance_success"] for v in xs]
        line, = axes[0].plot(x, [g["rate"] for g in s], marker="o", label=policy)
        axes[0].fill_between(x, [g["low"] for g in s], [g["high"] for g in s], alpha=0.15, color=line.get_color())
        w = [by_noise[v]["wrong_actions_per_episode"] for v in xs]
        axes[1].plot(x, [m["mean"] for m in w], marker="o", label=policy, color=line.get_color())
        axes[1].fill_between(x, [m["mean"] - m["ci95"] for m in w], [m["mean"] + m["ci95"] for m in w], alpha=0.15,
                             color=line.get_color())
        if policy in diffs:
            d = [diffs[policy][v]["wrong_actions"] for v in xs]
            axes[2].plot(x, [m["mean"] for m in d], marker="o", label=f"{policy} − {baseline}", color=line.get_color())
            axes[2].fill_between(x, [m["low"] for m in d], [m["high"] for m in d], alpha=0.15, color=line.get_color())
    axes[2].axhline(0.0, color="black", linewidth=0.8)
    # Symmetric log above 0.1: a policy with ~3 wrong actions per episode must not flatten the
    # others' 0–0.2 onto the axis (linear below 0.1, so 0 and differences of either sign show).
    for ax in axes[1:]:
        ax.set_yscale("symlog", linthresh=0.1)
        ax.grid(True, which="both", alpha=0.3)
    for ax, title, ylabel in ((axes[0], "Guidance success (Wilson 95 % CI)", "success rate"),
                              (axes[1], "Wrong actions (95 % CI)", "wrong actions per episode"),
                              (axes[2], f"Paired difference to {baseline} (95 % CI)", "Δ wrong actions per episode")):
        ax.set_title(title)
        ax.set_xlabel("SNR (dB), measured recogniser channel" if snr else "word error rate (noise level)")
        if snr:
            ax.invert_xaxis()   # noisier to the right, as on the word-error-rate axis
        ax.set_ylabel(ylabel)
        if ax.get_legend_handles_labels()[0]:      # the paired panel is empty without a baseline
            ax.legend(fontsize=8)
    axes[0].set_ylim(-0.02, 1.02)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def episodes_json(episodes: Sequence[StudyEpisode]) -> List[dict]:
    """JSON-ready rows: the CSV's, plus the episode's action sequence (``actions``)."""
    return [dict(e.row(), actions=list(e.result.actions)) for e in episodes]


def per_scenario(episodes: Sequence[StudyEpisode]) -> Dict[str, Dict[str, dict]]:
    """Scenario (``resident-task``) → policy → its scores there, over every noise level and seed.

    What a reader needs to see where a policy fails (a slow resident, the task with a question)
    that the pooled table hides: guidance success (of the episodes that needed one), unprompted
    questions, wrong actions, clarifications and the discounted return, as means.
    """
    cells: Dict[str, Dict[str, List[StudyEpisode]]] = {}
    for e in episodes:
        cells.setdefault(f"{e.resident}-{e.task}", {}).setdefault(e.policy, []).append(e)
    out: Dict[str, Dict[str, dict]] = {}
    for name in sorted(cells):
        out[name] = {}
        for policy, es in cells[name].items():
            rs = [e.result for e in es]
            needed = [r for r in rs if r.guidance_needed]
            n = len(rs)
            out[name][policy] = {
                "episodes": n,
                "guidance_success": (sum(r.guidance_completed for r in needed) / len(needed)) if needed else None,
                "wanted_guidance_success": (sum(r.guidance_completed for r in rs if r.guidance_wanted)
                                            / sum(r.guidance_wanted for r in rs))
                if any(r.guidance_wanted for r in rs) else None,
                "unprompted_questions_per_episode": sum(r.unprompted_questions for r in rs) / n,
                "wrong_actions_per_episode": sum(r.wrong_actions for r in rs) / n,
                "clarifications_per_episode": sum(r.clarifications for r in rs) / n,
                "discounted_return": sum(r.discounted_return for r in rs) / n,
            }
    return out

