"""The speech channel: recogniser speed, and per noise kind and SNR the confusion, insertions and deletions.

* ``real_time_factor``: decode wall time / audio length over the same utterances
  (the simulated residents' sentences, clear voice, 30 dB white noise), once with the
  language model generated from the domain's keywords and once with pocketsphinx's
  default large en-us model. Goal (issue 13): <= 0.2 with the domain model.
* ``channel``: per noise kind (``white``, ``babble``: docs/speech.md § Noise) and SNR,
  `pearl calibrate-speech`'s measurement of the residents' utterances in every voice preset,
  ``--repeats`` noise draws each: the confusion matrix over the domain's speech symbols
  (``{meant: {recognised: trials}}``, voices pooled), the **insertion** rate (a keyword
  recognised that was not said: chatter heard as a keyword, or another keyword; over every
  trial) split into ``insertion_from_chatter`` and ``substitution``, the **deletion** rate (a
  said keyword heard as ``unknown``), each with its Wilson 95 % interval; ``keyword_accuracy``
  (goal >= 0.95 at 20 dB, white) and per voice. Trials are seeded by their content, so a cached
  result is the same decode (``--no-cache`` decodes everything again).
* ``babble_vs_white_insertion_at_10db``: the two insertion rates at 10 dB, their difference
  and its Newcombe (Wilson-based) 95 % interval: does babble insert keywords more often?

* ``sim_channel``: wall time per utterance of ``pearl_sim.speech_channel`` — the
  ``recogniser`` channel (synthesis cached per sentence + noise + decode) and the
  ``measured`` channel sampled from the clear-voice calibration table above; what a
  simulated episode pays per thing the resident says.

Prints one JSON object.

    .venv/bin/python bench/speech.py [--snr 30,20,10,5] [--noise white,babble] [--voices clear,slow,quiet,slurred]
        [--repeats 2] [--no-cache]
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))


def real_time_factor(recognizer, clips) -> dict:
    audio = decode = 0.0
    for pcm in clips:
        rec = recognizer.recognise(pcm)
        audio += rec.audio_seconds
        decode += rec.decode_seconds
    return {"rtf": round(decode / audio, 4), "audio_seconds": round(audio, 2), "decode_seconds": round(decode, 3)}


def sim_channel_cost(domain, sentences, utterances) -> dict:
    from pearl_pomdp.asr.channel import calibrate
    from pearl_pomdp.speech import KeywordFilter
    from pearl_sim.speech_channel import MeasuredSpeechChannel, make_speech_channel

    rng = np.random.default_rng(1)
    intents = [m for m, says in utterances.items() for _ in says]
    rec = make_speech_channel({"channel": "recogniser", "snr_db": 20}, domain.keywords)
    t0 = time.perf_counter()
    for intent, s in zip(intents, sentences):
        rec.hear(intent, s, "clear", rng)
    per_rec = (time.perf_counter() - t0) / len(sentences)
    table = calibrate(rec.recognizer, KeywordFilter.from_domain(domain), utterances, [20.0], ["clear"], cache=True)
    measured = MeasuredSpeechChannel(table, snr_db=20.0)
    n = 20000
    t0 = time.perf_counter()
    for i in range(n):
        measured.hear(intents[i % len(intents)], "", "clear", rng)
    per_meas = (time.perf_counter() - t0) / n
    return {"recogniser_seconds_per_utterance": round(per_rec, 4),
            "measured_microseconds_per_utterance": round(per_meas * 1e6, 2)}


def newcombe_difference(h1: int, n1: int, h2: int, n2: int):
    """95 % interval of p1 - p2 from the two Wilson intervals (Newcombe 1998, method 10)."""
    from pearl_pomdp.asr.channel import wilson_interval

    p1, p2 = h1 / n1, h2 / n2
    l1, u1 = wilson_interval(h1, n1)
    l2, u2 = wilson_interval(h2, n2)
    d = p1 - p2
    return (d - float(np.sqrt((p1 - l1) ** 2 + (u2 - p2) ** 2)), d + float(np.sqrt((u1 - p1) ** 2 + (p2 - l2) ** 2)))


def measure_kind(recognizer, kf, utterances, snrs, voices, repeats, kind, keyword_symbols, cache=True) -> dict:
    """One noise kind: per SNR the confusion over the speech symbols (voices pooled), insertion
    and deletion rates with Wilson CIs, keyword accuracy; per voice the keyword accuracy."""
    from pearl_pomdp.asr.channel import ChannelTable, calibrate, wilson_interval

    t0 = time.perf_counter()
    tables = []
    for v in voices:
        print(f"channel: {kind} noise, voice {v} ...", file=sys.stderr)
        tables.append(calibrate(recognizer, kf, utterances, snrs, [v], repeats, kind, seed=0, cache=cache))
    pooled = ChannelTable(tables[0].snr_db, tables[0].symbols, tables[0].meant, {}, {})
    for t in tables:
        for key, row in t.cells.items():
            for meant, cell in row.items():
                agg = pooled.cells.setdefault(key, {}).setdefault(meant, {"n": 0, "counts": {}})
                agg["n"] += cell["n"]
                for sym, c in cell["counts"].items():
                    agg["counts"][sym] = agg["counts"].get(sym, 0) + c
    per_snr = {}
    for snr in snrs:
        conf = pooled.confusion(snr)
        hits = sum(conf[m][m] for m in keyword_symbols)
        n = sum(sum(conf[m].values()) for m in keyword_symbols)
        rates = pooled.error_rates(snr, kf.unknown_symbol)
        per_snr[pooled.key(snr)] = {
            "confusion": conf,
            "error_rates": {k: {"count": r["count"], "n": r["n"], "rate": round(r["rate"], 4),
                                "ci95": [round(x, 4) for x in r["ci95"]]} for k, r in rates.items()},
            "keyword_accuracy": round(hits / n, 4),
            "keyword_accuracy_ci95": [round(x, 4) for x in wilson_interval(hits, n)],
            "all_accuracy": round(pooled.accuracy(snr), 4)}
    return {"snr_db": snrs, "voices": voices, "repeats": repeats, "cache": cache,
            "trials": sum(c["n"] for row in pooled.cells.values() for c in row.values()),
            "per_snr": per_snr,
            "per_voice_keyword_accuracy": {v: {t.key(s): round(t.accuracy(s, keyword_symbols), 4) for s in snrs}
                                           for v, t in zip(voices, tables)},
            "goal_keyword_accuracy_at_20db": 0.95,
            "seconds": round(time.perf_counter() - t0, 1)}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--domain", default=str(REPO / "config" / "pearl.domain.yaml"))
    parser.add_argument("--snr", default="30,20,10,5", help="SNRs in dB (default: the study's axis)")
    parser.add_argument("--voices", default="clear,slow,quiet,slurred")
    parser.add_argument("--repeats", type=int, default=2,
                        help="noise draws per utterance, voice and SNR (2: 136 keyword trials per SNR)")
    parser.add_argument("--noise", default="white,babble", help="noise kinds, comma separated (default: %(default)s)")
    parser.add_argument("--no-cache", action="store_true",
                        help="decode every channel trial now (the cached result of a trial is the same decode: "
                             "a trial is seeded by its content)")
    args = parser.parse_args(argv)

    from pearl_pomdp.asr.audio import mix_at_snr
    from pearl_pomdp.asr.channel import calibrate
    from pearl_pomdp.asr.recognizer import Recognizer
    from pearl_pomdp.asr.synthesizer import synthesize
    from pearl_sim.cli.calibrate_speech import resident_utterances
    from pearl_pomdp.model.domain_yaml import load_domain
    from pearl_pomdp.speech import KeywordFilter

    domain = load_domain(args.domain)
    kf = KeywordFilter.from_domain(domain)
    utterances = resident_utterances(kf.unknown_symbol)
    out = {"bench": "speech", "domain": domain.name, "load_before": [round(x, 2) for x in os.getloadavg()]}

    rng = np.random.default_rng(0)
    sentences = [s for says in utterances.values() for s in says]
    clips = [mix_at_snr(synthesize(s, "clear"), 30.0, rng) for s in sentences]
    t0 = time.perf_counter()
    domain_rec = Recognizer(domain.keywords)
    out["domain_model_build_seconds"] = round(time.perf_counter() - t0, 3)
    print("real-time factor: domain model ...", file=sys.stderr)
    out["real_time_factor"] = {"utterances": len(clips), "domain": real_time_factor(domain_rec, clips)}
    print("real-time factor: default en-us LM ...", file=sys.stderr)
    out["real_time_factor"]["default_lm"] = real_time_factor(Recognizer(None), clips)
    out["real_time_factor"]["goal_domain_rtf"] = 0.2
    out["real_time_factor"]["goal_met"] = out["real_time_factor"]["domain"]["rtf"] <= 0.2

    snrs = [float(s) for s in args.snr.split(",")]
    voices = [v for v in args.voices.split(",") if v]
    kinds = [k for k in args.noise.split(",") if k]
    keyword_symbols = [s for s in utterances if s != kf.unknown_symbol]
    out["channel"] = {}
    for kind in kinds:
        out["channel"][kind] = measure_kind(domain_rec, kf, utterances, snrs, voices, args.repeats, kind,
                                            keyword_symbols, cache=not args.no_cache)
    out["sim_channel"] = sim_channel_cost(domain, sentences, utterances)
    # The question: does babble insert keywords more often than white noise at 10 dB?
    if {"white", "babble"} <= set(kinds) and 10.0 in snrs:
        w, b = (out["channel"][k]["per_snr"]["10"]["error_rates"]["insertion"] for k in ("white", "babble"))
        out["babble_vs_white_insertion_at_10db"] = {
            "white": [w["count"], w["n"]], "babble": [b["count"], b["n"]],
            "difference": round(b["rate"] - w["rate"], 4),
            "ci95": [round(x, 4) for x in newcombe_difference(b["count"], b["n"], w["count"], w["n"])],
            "babble_inserts_more": newcombe_difference(b["count"], b["n"], w["count"], w["n"])[0] > 0}
    out["load_after"] = [round(x, 2) for x in os.getloadavg()]
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
