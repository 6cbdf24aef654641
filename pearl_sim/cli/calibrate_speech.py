"""Measure the speech channel: P(recognised symbol | meant symbol, SNR), with counts.

Every utterance is spoken by espeak-ng in each voice, mixed with noise at each SNR,
decoded by the domain's recogniser and passed through the keyword filter; the counts,
and sample recogniser outputs per cell, are written as JSON for the simulation's fast
`measured` channel (docs/speech.md). Results are cached by content under the user
cache dir, so a rerun (or one more SNR) only decodes what is new.

Utterances: the simulated residents' (pearl_sim, "chatter" meaning `unknown`) plus every
keyword in three carrier phrases; --utterances FILE.yaml (symbol: [sentences]) replaces them.

--write-observation-table OUT.yaml writes the domain with the Speech part of every
observation row passed through the measured confusion at --fit-snr: what the designer's
row says she means is heard as the channel hears it. The confusion is the posterior mean
under a Dirichlet prior equal to the designer's table ("heard as meant") worth
--prior-strength trials, so rows move from the designer's numbers towards the measured
ones as trials accumulate (docs/speech.md).

Each trial is one espeak-ng synthesis and one pocketsphinx decode (~0.1-0.3 s), so the
defaults (5 SNRs x 4 voices x the residents' and carrier sentences) take several minutes;
the shipped config/speech/pearl_channel.json is
`pearl calibrate-speech config/pearl.domain.yaml --snr 30,20,10,5 --no-carriers` (352 trials,
docs/speech.md), config/speech/pearl_channel_babble.json the same with --noise babble (six talkers
reading the IEEE Harvard sentences: pearl_pomdp/asr/babble.py). The examples below are small (seconds).

Examples:
  pearl calibrate-speech config/pearl.domain.yaml --snr 20 --voices clear --no-carriers --out channel.json
  pearl calibrate-speech config/pearl.domain.yaml --snr 20,10 --voices clear --no-carriers --json
"""
from __future__ import annotations

import argparse
import sys
import time

COMMAND = "calibrate-speech"
HELP = "measure P(recognised symbol | meant symbol, SNR) through espeak-ng + noise + the recogniser"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("domain", help="factored domain .yaml (its keywords: build the recogniser and the filter)")
    parser.add_argument("--snr", default="30,20,10,5,0", help="SNRs in dB, comma separated (default: %(default)s)")
    parser.add_argument("--voices", default="clear,slow,quiet,slurred",
                        help="voice presets, comma separated (default: %(default)s)")
    parser.add_argument("--repeats", type=int, default=1, help="noise draws per utterance, voice and SNR (default: 1)")
    parser.add_argument("--noise", choices=("white", "babble"), default="white", help="noise kind (default: white)")
    parser.add_argument("--utterances", metavar="FILE.yaml", help="meant symbol → list of sentences")
    parser.add_argument("--no-carriers", action="store_true", help="leave out the keywords-in-carrier-phrases set")
    parser.add_argument("--seed", type=int, default=0, help="base seed of the noise (default: 0)")
    parser.add_argument("--no-cache", action="store_true", help="decode everything again, store nothing")
    parser.add_argument("--out", metavar="channel.json", help="write the measured channel here")
    parser.add_argument("--write-observation-table", metavar="OUT.yaml",
                        help="write the domain with its Speech observation rows fitted from the measured channel")
    parser.add_argument("--fit-snr", type=float, default=None,
                        help="SNR whose measurement the fit uses (default: 20 if measured, else the first --snr)")
    parser.add_argument("--prior-strength", type=float, default=20.0,
                        help="Dirichlet prior weight of the designer's table, in trials (default: 20)")
    parser.add_argument("--json", action="store_true", help="print one JSON summary object")


def _parse_snrs(text: str):
    from pearl_pomdp.errors import SpecError

    try:
        snrs = [float(x) for x in text.split(",") if x.strip()]
    except ValueError:
        raise SpecError("--snr", "", f"{text!r} is not a comma-separated list of numbers") from None
    if not snrs:
        raise SpecError("--snr", "", "no SNR given")
    return snrs


def resident_utterances(unknown_symbol: str = "unknown"):
    """What the simulated residents say per meaning (pearl_sim.nursing_home.world.UTTERANCES)."""
    from pearl_sim.nursing_home.world import UTTERANCES

    return {(unknown_symbol if k == "chatter" else k): list(v) for k, v in UTTERANCES.items()}


def load_utterances(path: str):
    """``{symbol: [sentences]}`` from a YAML file, or a SpecError naming the field."""
    import yaml

    from pearl_pomdp.errors import SpecError

    try:
        with open(path, encoding="utf-8") as f:
            data = yaml.safe_load(f)
    except yaml.YAMLError as err:
        raise SpecError(path, "", f"not YAML: {err}") from None
    if not isinstance(data, dict) or not data:
        raise SpecError(path, "", "expected a mapping symbol: [sentences]")
    for k, v in data.items():
        if not isinstance(v, list) or not all(isinstance(s, str) and s.strip() for s in v):
            raise SpecError(path, str(k), "expected a list of non-empty sentences")
    return {str(k): list(v) for k, v in data.items()}


def run(args: argparse.Namespace) -> int:
    from pearl_pomdp.asr.channel import calibrate, default_utterances
    from pearl_pomdp.asr.recognizer import Recognizer
    from pearl_pomdp.asr.synthesizer import get_voice
    from pearl_pomdp.cli import print_json
    from pearl_pomdp.errors import SpecError
    from pearl_pomdp.model.domain_yaml import load_domain
    from pearl_pomdp.speech import KeywordFilter

    snrs = _parse_snrs(args.snr)
    voices = [v.strip() for v in args.voices.split(",") if v.strip()]
    for v in voices:
        get_voice(v)  # an unknown voice fails before any work
    if args.repeats < 1:
        raise SpecError("--repeats", "", f"{args.repeats} is less than 1")
    domain = load_domain(args.domain)
    kf = KeywordFilter.from_domain(domain)
    if args.utterances:
        utterances = load_utterances(args.utterances)
    else:
        utterances = resident_utterances(kf.unknown_symbol)
        if not args.no_carriers:
            for sym, says in default_utterances(domain.keywords, kf.unknown_symbol).items():
                utterances[sym] = list(dict.fromkeys(utterances.get(sym, []) + says))
    unknown = sorted(set(utterances) - set(kf.symbols))
    if unknown:
        raise SpecError(args.utterances or "utterances", "", f"meant symbol(s) {', '.join(unknown)} are not speech "
                        f"symbols of {domain.name}: {', '.join(kf.symbols)}")
    recognizer = Recognizer(domain.keywords)
    bar = None
    if sys.stderr.isatty() and not args.json:
        from tqdm import tqdm

        bar = tqdm(total=len(snrs) * len(voices) * args.repeats * sum(map(len, utterances.values())),
                   desc="calibrate-speech", unit="utt", file=sys.stderr)
    progress = (lambda done, total: bar.update(1)) if bar is not None else None
    t0 = time.perf_counter()
    try:
        table = calibrate(recognizer, kf, utterances, snrs, voices, args.repeats, args.noise, args.seed, progress,
                          cache=not args.no_cache, meta={"domain": domain.name, "domain_file": str(args.domain)})
    finally:
        if bar is not None:
            bar.close()
    seconds = time.perf_counter() - t0
    if args.out:
        table.save(args.out)
    fitted = None
    if args.write_observation_table:
        fitted = write_observation_table(args, table, snrs)
    summary = {"domain": domain.name, "recogniser": recognizer.identity, "noise": args.noise, "voices": voices,
               "repeats": args.repeats, "trials": sum(c["n"] for row in table.cells.values() for c in row.values()),
               "seconds": round(seconds, 2),
               "accuracy": {table.key(s): round(table.accuracy(s), 4) for s in snrs},
               "out": args.out, "observation_table": fitted}
    if args.json:
        print_json(summary)
        return 0
    print(f"{summary['trials']} trials in {seconds:.1f} s ({recognizer.identity}, {args.noise} noise, "
          f"voices {', '.join(voices)})")
    for s in snrs:
        row = "  ".join(f"{m}:{table.probability(m, s)[m]:.2f}" for m in table.meant)
        print(f"  {s:>5g} dB  keyword accuracy {table.accuracy(s):.3f}   P(right | meant): {row}")
    if args.out:
        print(f"wrote {args.out}")
    if fitted:
        print(f"wrote {fitted['file']}: {fitted['rows_changed']} observation rows fitted at {fitted['snr_db']:g} dB "
              f"(prior strength {fitted['prior_strength']:g})")
    return 0


def write_observation_table(args: argparse.Namespace, table, snrs) -> dict:
    """Fit the domain's Speech rows from ``table`` and write the fitted domain (checked by loading it)."""
    import yaml

    from pearl_pomdp.asr.channel import fit_observation_rows
    from pearl_pomdp.atomic import atomic_write
    from pearl_pomdp.errors import SpecError
    from pearl_pomdp.model.domain_yaml import parse_domain

    snr = args.fit_snr if args.fit_snr is not None else (20.0 if 20.0 in snrs else snrs[0])
    if snr not in snrs:
        raise SpecError("--fit-snr", "", f"{snr:g} dB was not measured (--snr {args.snr})")
    data, changed = fit_observation_rows(args.domain, table, snr, args.prior_strength)
    header = (f"# {args.domain} with its Speech observation rows fitted by `pearl calibrate-speech` at {snr:g} dB\n"
              f"# ({table.meta.get('recogniser')}, voices {', '.join(table.meta.get('voices', {}))}, "
              f"{table.meta.get('noise')} noise, Dirichlet prior strength {args.prior_strength:g}).\n")
    text = header + yaml.safe_dump(data, sort_keys=False, allow_unicode=True, width=120)
    parse_domain(text, source=args.write_observation_table)  # never write a domain that does not load
    atomic_write(args.write_observation_table, text)
    return {"file": args.write_observation_table, "snr_db": snr, "prior_strength": args.prior_strength,
            "rows_changed": changed}
