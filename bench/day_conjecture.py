"""The conjecture arm on days (docs/day.md, "The conjecture arm"): one JSON object and one picture.

Does the POMDP's advantage over the day tree grow as the channel worsens? For each noise kind
(white, babble) one ``pearl experiment --day`` run: her speech through the measured recogniser
channel at each SNR, the day tree, the hierarchical policy planned on the day domain (the
designer's speech rows) and its two twins planned on the speech rows refitted to the channel at
each SNR (``--speech-twins 0,0.2``: without and with keyword insertions). Per (kind, SNR) the
paired day score of each POMDP against the tree with its 95 % t interval, and per kind the
contrast quietest − noisiest SNR of that paired difference (< 0: the advantage grows as the
channel worsens). Each run's folder keeps its days (``days.jsonl``), the fitted twins' domains and
plans (``twins/``) and its own report; ``--out`` gets ``conjecture.json`` and ``conjecture.png``.

    python bench/day_conjecture.py --days 3 --jobs 2 --out out/day-conjecture
"""
from __future__ import annotations

import argparse
import contextlib
import json
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
KINDS = ("white", "babble")


def _arm(kind: str, args, out: Path) -> dict:
    """One kind's run of `pearl experiment --day` (its tables on stderr); its report."""
    from pearl_pomdp.cli import main as pearl

    command = ["experiment", "--day", "--policies", "hierarchical,day_tree", "--residents", f"generated:{args.residents}",
               "--seed", str(args.seed), "--days", str(args.days), "--snr", args.snr, "--noise-kind", kind,
               "--speech-twins", args.chatter_shares, "--jobs", str(args.jobs), "--out", str(out / kind)]
    print("pearl " + " ".join(command), file=sys.stderr, flush=True)
    with contextlib.redirect_stdout(sys.stderr):
        code = pearl(command)
    if code != 0:
        raise SystemExit(f"pearl experiment --day ({kind}) failed with exit code {code}")
    return json.loads((out / kind / "day-study.json").read_text(encoding="utf-8"))


def plot(result: dict, path: Path) -> Path:
    """Per kind: each POMDP's paired day score − the day tree against SNR (quietest left), 95 % CIs."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    kinds = list(result["kinds"])
    fig, axes = plt.subplots(1, len(kinds), figsize=(5.5 * len(kinds), 4.2), sharey=True, squeeze=False)
    for ax, kind in zip(axes[0], kinds):
        paired = result["kinds"][kind]["paired_vs_day_tree"]
        for i, (policy, by_snr) in enumerate(paired.items()):
            levels = sorted(by_snr, key=float, reverse=True)
            xs = [j + 0.08 * (i - 1) for j in range(len(levels))]
            d = [by_snr[lvl] for lvl in levels]
            contrast = result["kinds"][kind]["contrast_quietest_minus_noisiest"][policy]
            ax.errorbar(xs, [x["mean"] for x in d], yerr=[[x["mean"] - x["low"] for x in d],
                                                          [x["high"] - x["mean"] for x in d]],
                        fmt="o-", capsize=3,
                        label=f"{policy} ({contrast['quiet_db']:g}−{contrast['noisy_db']:g} dB: "
                              f"{contrast['mean']:+.1f} [{contrast['low']:+.1f}, "
                              f"{contrast['high']:+.1f}])")
            ax.set_xticks(range(len(levels)), [f"{float(lvl):g} dB" for lvl in levels])
        ax.axhline(0, color="k", lw=0.8)
        ax.set_title(f"{kind} noise: paired day score − day tree")
        ax.set_xlabel("SNR (quietest left)")
        ax.legend(fontsize=7, loc="lower left")
    axes[0][0].set_ylabel("day score difference (95 % CI)")
    fig.suptitle(f"The conjecture on days: {result['protocol']['days_per_cell']} days per cell "
                 f"(generator seed {result['protocol']['resident_seed']})", fontsize=10)
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
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--out", default=str(REPO / "out/day-conjecture"))
    args = ap.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    started = time.perf_counter()
    result: dict = {"protocol": {"resident_seed": args.seed, "residents": args.residents, "days_per_resident": args.days,
                                 "days_per_cell": args.days * args.residents, "snr_db": args.snr,
                                 "chatter_shares": args.chatter_shares, "jobs": args.jobs}, "kinds": {}}
    for kind in [k.strip() for k in args.kinds.split(",") if k.strip()]:
        report = _arm(kind, args, out)
        result["kinds"][kind] = {
            "paired_vs_day_tree": {p: {lvl: d["score"] for lvl, d in by.items()}
                                   for p, by in report["paired_vs_baseline"].items()},
            "day_score": {p: {lvl: s["score"] for lvl, s in by.items()} for p, by in report["per_policy"].items()},
            "contrast_quietest_minus_noisiest": {p: {**c["contrast"], "quiet_db": c["quiet_db"],
                                                     "noisy_db": c["noisy_db"]}
                                                 for p, c in report["snr_contrast_vs_baseline"].items()},
            "pooled": {p: {lvl: s["pooled"] for lvl, s in by.items()} for p, by in report["per_policy"].items()},
            "plan_seconds": report["plan_seconds"],
            "twins": report["protocol"]["speech_twins"]["twins"],
            "day_seconds": report["day_seconds"], "seconds": report["seconds"], "days": report["protocol"]["days"],
            "run": str(out / kind),
        }
    result["seconds"] = round(time.perf_counter() - started, 1)
    result["files"] = {"json": str(out / "conjecture.json"), "png": str(plot(result, out / "conjecture.png"))}
    (out / "conjecture.json").write_text(json.dumps(result, indent=1), encoding="utf-8")
    print(json.dumps(result, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
