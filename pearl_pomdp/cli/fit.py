"""Fit a domain's transition and observation tables to recorded episodes.

    pearl fit DOMAIN EPISODES… --out FITTED.yaml [--prior-strength K] [--min-count N] [--untied] [--json]
    pearl fit DOMAIN --speech CHANNEL.json --snr DB --out FITTED.yaml [--prior-strength K] [--chatter-share F]

EPISODES are bag directories (``pearl demo`` / ``pearl record`` output: each closed step's
action and observation from /pearl/belief (older bags: /pearl/belief_marginals), the true
state from the world's /WORLD/sim/truth, e.g. /pearl/sim/truth, when a simulator recorded it) or ``.jsonl`` files with one episode per line
(``{"actions": [...], "observations": [...], "states": [...]}``, states optional).

Each table row (one configuration of the row's parents) becomes
``(K · designer row + counts) / (K + n)``: counted from the true states when every episode
has them, else expected counts by EM over the DBN (the log-likelihood of each iteration is
printed). Rows with fewer than N observations keep the designer's row. A table written once
for many actions (under ``defaults.effects``, or a feature nothing mentions) is estimated once
from all their data, as the domain declares (``--untied``: per action). FITTED.yaml is the
domain file unchanged — the designer's comments included — plus a ``fitted:`` section whose
rows are marked with their data count and the designer's row they replace.

Output: per table the rows fitted, the data behind them and the largest change; with
--json one object with "tables", "rows" (every fitted row, before and after), "kept"
(rows with too little data), "with_truth", "loglik" (EM history), "out".

Examples:
  pearl demo --out out/fit-demo --json > /dev/null
  pearl fit config/pearl.domain.yaml out/fit-demo/bag --out out/pearl.fitted.domain.yaml
  pearl fit config/pearl.domain.yaml --speech config/speech/pearl_channel_babble.json --snr 10 \
      --out out/pearl.babble10.yaml
"""
from __future__ import annotations

import argparse

COMMAND = "fit"
HELP = "fit a domain's transition and observation tables to recorded episodes (counts with truth, EM without)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("domain", metavar="DOMAIN", help="factored domain .yaml (the designer's tables are the prior)")
    parser.add_argument("episodes", metavar="EPISODES", nargs="*", help="bag directories or .jsonl episode files")
    parser.add_argument("--speech", metavar="CHANNEL.json", default=None,
                        help="instead of episodes: fit the speech observation rows to a measured channel "
                             "(`pearl calibrate-speech --out`) at --snr (pearl_pomdp/fit_speech.py)")
    parser.add_argument("--snr", type=float, default=None, metavar="DB",
                        help="with --speech: the operating point, one of the channel's measured SNRs")
    parser.add_argument("--chatter-share", type=float, default=0.0, metavar="F",
                        help="with --speech: the share of a row's `unknown` that is speech (through the "
                             "channel's chatter row); default 0: `unknown` is silence")
    parser.add_argument("--out", required=True, help="fitted domain file to write")
    parser.add_argument("--prior-strength", type=float, default=10.0, metavar="K",
                        help="pseudo-counts of the designer's row (default 10; 0: data only)")
    parser.add_argument("--min-count", type=float, default=5.0, metavar="N",
                        help="rows with less data keep the designer's row (default 5)")
    parser.add_argument("--em-iterations", type=int, default=30, metavar="I",
                        help="EM iterations at most, without true states (default 30)")
    parser.add_argument("--no-truth", action="store_true",
                        help="fit by EM even where the episodes record the true state (a bag whose truth does not "
                             "cover its steps)")
    parser.add_argument("--untied", action="store_true",
                        help="fit each action's copy of a table written once under defaults.effects (or a persisting "
                             "feature) on that action's data alone; by default they are estimated together")
    parser.add_argument("--json", action="store_true", help="print one JSON object")


def run(args: argparse.Namespace) -> int:
    from pathlib import Path

    from pearl_pomdp.cli import print_json
    from pearl_pomdp.cli._inputs import require_file
    from pearl_pomdp.errors import PearlError
    from pearl_pomdp.fit import fit_domain, load_episodes, write_fitted
    from pearl_pomdp.model.domain_yaml import load_domain

    require_file(args.domain, "domain file (DOMAIN)")
    if Path(args.out).resolve() == Path(args.domain).resolve():
        raise PearlError(f"--out {args.out}: would overwrite the domain it fits; choose another file")
    if args.speech is not None:
        if args.episodes:
            raise PearlError("EPISODES: give episodes or --speech CHANNEL.json, not both")
        return _run_speech(args)
    if not args.episodes:
        raise PearlError("EPISODES: give bag directories or .jsonl episode files (or --speech CHANNEL.json)")
    domain = load_domain(args.domain)
    episodes = load_episodes(args.episodes, truth=not args.no_truth)
    result = fit_domain(domain, episodes, prior_strength=args.prior_strength, min_count=args.min_count,
                        em_iterations=args.em_iterations, tied=not args.untied)
    out = write_fitted(args.domain, result, args.out, args.prior_strength)
    load_domain(out)  # what was written must load: a fitted file that does not is a bug, not a user error
    tables = result.tables()
    if args.json:
        print_json({"out": str(out), "episodes": result.episodes, "steps": result.steps,
                    "with_truth": result.with_truth, "loglik": result.history, "tables": tables,
                    "rows": [{"table": r.table, "row": r.row, "n": r.n, "before": r.before, "after": r.after}
                             for r in result.rows],
                    "kept": [{"table": t, "row": row, "n": n} for t, row, n in result.kept]})
        return 0
    how = "counted from the true states" if result.with_truth else f"EM, {len(result.history)} iterations"
    print(f"{result.episodes} episode(s), {result.steps} steps ({how})")
    if result.history:
        print("log-likelihood: " + " → ".join(f"{x:.3f}" for x in result.history))
    width = max((len(t) for t in tables), default=10)
    print(f"{'table':<{width}}  fitted  kept  data   max change")
    for name, t in tables.items():
        print(f"{name:<{width}}  {t['rows_fitted']:>6}  {t['rows_kept']:>4}  {t['n']:>5.0f}  {t['max_change']:.3f}")
    print(f"wrote {out} ({len(result.rows)} fitted rows; rows with fewer than {args.min_count:g} observations "
          f"keep the designer's table)")
    return 0


def _run_speech(args: argparse.Namespace) -> int:
    """``pearl fit DOMAIN --speech CHANNEL.json --snr DB``: the speech rows from a measured channel."""
    from pearl_pomdp.asr.channel import ChannelError, ChannelTable
    from pearl_pomdp.cli import print_json
    from pearl_pomdp.errors import PearlError
    from pearl_pomdp.fit_speech import write_speech_fitted

    if args.snr is None:
        raise PearlError("--snr: --speech needs the operating point (one of the channel's measured SNRs)")
    try:
        table = ChannelTable.load(args.speech)
    except ChannelError as err:
        raise PearlError(f"--speech {err}") from None
    out, rows = write_speech_fitted(args.domain, table, args.snr, args.out, args.prior_strength, args.chatter_share)
    if args.json:
        print_json({"out": str(out), "channel": args.speech, "noise": table.meta.get("noise"), "snr_db": args.snr,
                    "prior_strength": args.prior_strength, "chatter_share": args.chatter_share,
                    "rows": [{"action": r.action, "row": r.row, "before": r.before, "after": r.after} for r in rows]})
        return 0
    print(f"wrote {out}: {len(rows)} observation rows through {args.speech} ({table.meta.get('noise')} noise) at "
          f"{args.snr:g} dB (prior strength {args.prior_strength:g}, chatter share {args.chatter_share:g}); "
          "the rows they replace are comments beside them")
    return 0
