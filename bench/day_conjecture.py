"""The conjecture arm on days (docs/day.md, "The conjecture arm"): one JSON object and one picture.

Does the POMDP's advantage over the day tree grow as the channel worsens? For each noise kind
(white, babble) one ``pearl experiment --day`` run, the kinds side by side (``--jobs`` processes
shared between them): her speech through the measured recogniser channel at each SNR, the day
tree, the hierarchical policy planned on the day domain (the designer's speech rows) and its two
twins planned on the speech rows refitted to the channel at each SNR (``--speech-twins 0,0.2``:
without and with keyword insertions). Each run keeps every day as it comes (``days.jsonl``), the
twins' domains and plans (``twins/``; a plan already there for its domain is reused).

With ``--stop-after S`` the runs are ended after S seconds (a stopping rule fixed before the run);
only whole resident-days are kept — every controller at every SNR — so each comparison stays paired.
Per (kind, SNR): the paired day score of each POMDP against the tree with its 95 % t interval; per
kind: the contrast quietest − noisiest SNR of that paired difference (< 0: the advantage grows as
the channel worsens). ``--out`` gets ``conjecture.json`` and ``conjecture.png``.

    python bench/day_conjecture.py --days 3 --snr 30,5 --jobs 2 --stop-after 3000 --out out/day-conjecture
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
KINDS = ("white", "babble")


def whole_days(days: list) -> list:
    """The days of the resident-days that every controller ran at every level (a stopped run's rest)."""
    wanted = {(d["policy"], d["noise"]) for d in days}
    have: dict = {}
    for d in days:
        have.setdefault((d["resident"], d["seed"]), set()).add((d["policy"], d["noise"]))
    whole = {k for k, v in have.items() if v == wanted}
    return [d for d in days if (d["resident"], d["seed"]) in whole]


def summarize_kind(days: list) -> dict:
    """What the arm reports for one kind, from its whole resident-days."""
    from pearl_sim.nursing_home.day_study import snr_contrasts, summarize

    kept = whole_days(days)
    summary = summarize(kept)
    return {
        "resident_days": len({(d["resident"], d["seed"]) for d in kept}), "days_run": len(days),
        "days_kept": len(kept),
        "paired_vs_day_tree": {p: {lvl: d["score"] for lvl, d in by.items()}
                               for p, by in summary["paired_vs_baseline"].items()},
        "day_score": {p: {lvl: s["score"] for lvl, s in by.items()} for p, by in summary["per_policy"].items()},
        "contrast_quietest_minus_noisiest": {p: {**c["contrast"], "quiet_db": c["quiet_db"], "noisy_db": c["noisy_db"]}
                                             for p, c in snr_contrasts(kept).items()},
        "pooled": {p: {lvl: s["pooled"] for lvl, s in by.items()} for p, by in summary["per_policy"].items()},
        "paired_rows": {p: {lvl: {k: v for k, v in d.items() if k != "score"} for lvl, d in by.items()}
                        for p, by in summary["paired_vs_baseline"].items()},
    }


def plot(result: dict, path: Path) -> Path:
    """Per kind: each POMDP's paired day score − the day tree against SNR (quietest left), 95 % CIs."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    kinds = list(result["kinds"])
    fig, axes = plt.subplots(1, len(kinds), figsize=(5.5 * len(kinds), 4.2), sharey=True, squeeze=False)
    for ax, kind in zip(axes[0], kinds):
        arm = result["kinds"][kind]
        for i, (policy, by_snr) in enumerate(arm["paired_vs_day_tree"].items()):
            levels = sorted(by_snr, key=float, reverse=True)
            xs = [j + 0.08 * (i - 1) for j in range(len(levels))]
            d = [by_snr[lvl] for lvl in levels]
            c = arm["contrast_quietest_minus_noisiest"][policy]
            ax.errorbar(xs, [x["mean"] for x in d], yerr=[[x["mean"] - x["low"] for x in d],
                                                          [x["high"] - x["mean"] for x in d]],
                        fmt="o-", capsize=3,
                        label=f"{policy} ({c['quiet_db']:g}−{c['noisy_db']:g} dB: {c['mean']:+.1f} "
                              f"[{c['low']:+.1f}, {c['high']:+.1f}])")
            ax.set_xticks(range(len(levels)), [f"{float(lvl):g} dB" for lvl in levels])
        ax.axhline(0, color="k", lw=0.8)
        ax.set_title(f"{kind} noise ({arm['resident_days']} resident-days): paired day score − day tree", fontsize=9)
        ax.set_xlabel("SNR (quietest left)")
        ax.legend(fontsize=7, loc="lower left")
    axes[0][0].set_ylabel("day score difference (95 % CI)")
    fig.suptitle(f"The conjecture on days (generator seed {result['protocol']['resident_seed']})", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--days", type=int, default=3, help="days per resident (docs/day.md: the arm's amendment)")
    ap.add_argument("--residents", type=int, default=6)
    ap.add_argument("--seed", type=int, default=47, help="resident generator seed (protocol 2's reported population)")
    ap.add_argument("--snr", default="30,20,10,5")
    ap.add_argument("--chatter-shares", default="0,0.2")
    ap.add_argument("--kinds", default=",".join(KINDS))
    ap.add_argument("--jobs", type=int, default=2, help="processes in all, shared between the kinds")
    ap.add_argument("--stop-after", type=float, default=None, metavar="S",
                    help="end the runs after S seconds and keep the whole resident-days (default: run to the end)")
    ap.add_argument("--out", default=str(REPO / "out/day-conjecture"))
    args = ap.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    kinds = [k.strip() for k in args.kinds.split(",") if k.strip()]
    started = time.perf_counter()
    runs = {}
    for i, kind in enumerate(kinds):
        jobs = max(1, args.jobs // len(kinds) + (1 if i < args.jobs % len(kinds) else 0))
        command = [str(Path(sys.executable).parent / "pearl"), "experiment", "--day", "--policies", "hierarchical,day_tree",
                   "--residents", f"generated:{args.residents}", "--seed", str(args.seed), "--days", str(args.days),
                   "--snr", args.snr, "--noise-kind", kind, "--speech-twins", args.chatter_shares,
                   "--jobs", str(jobs), "--out", str(out / kind)]
        print("pearl " + " ".join(command[1:]), file=sys.stderr, flush=True)
        runs[kind] = subprocess.Popen(command, stdout=subprocess.DEVNULL, cwd=REPO, start_new_session=True)
    stopped = {}
    for kind, proc in runs.items():
        left = None if args.stop_after is None else max(0.0, args.stop_after - (time.perf_counter() - started))
        try:
            proc.wait(timeout=left)
            stopped[kind] = False
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, 15)          # the run and its worker processes (its own session)
            proc.wait(timeout=30)
            stopped[kind] = True
    result: dict = {"protocol": {"resident_seed": args.seed, "residents": args.residents, "days_per_resident": args.days,
                                 "snr_db": args.snr, "chatter_shares": args.chatter_shares, "jobs": args.jobs,
                                 "stop_after_s": args.stop_after}, "kinds": {}}
    for kind in kinds:
        lines = (out / kind / "days.jsonl").read_text(encoding="utf-8").splitlines()
        arm = summarize_kind([json.loads(line) for line in lines if line.strip()])
        arm.update(stopped=stopped[kind], run=str(out / kind), exit_code=runs[kind].returncode,
                   twins=sorted(p.name for p in (out / kind / "twins").glob("*.domain.yaml")))
        result["kinds"][kind] = arm
    result["seconds"] = round(time.perf_counter() - started, 1)
    result["files"] = {"json": str(out / "conjecture.json"), "png": str(plot(result, out / "conjecture.png"))}
    (out / "conjecture.json").write_text(json.dumps(result, indent=1), encoding="utf-8")
    print(json.dumps(result, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
