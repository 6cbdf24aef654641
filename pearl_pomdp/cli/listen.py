"""Recognise one utterance: a WAV file (or `-` for the microphone) → text, confidence, symbol.

The first check a roboticist runs: does the recogniser hear the domain's keywords?

Examples:
  pearl listen --say "what time is it" --snr 10 --save-wav recording.wav   # espeak-ng → noise → recogniser
  pearl listen recording.wav                      # text, confidence and keyword symbol
  pearl listen recording.wav --json               # {"text", "confidence", "symbol", ...}

With a microphone (the optional sounddevice package): `pearl listen - --seconds 4`.

Any WAV rate or channel count is converted to 16 kHz mono (and said so). Audio longer
than --max-seconds is an error, not minutes of decoding. `symbol` is the domain's
keyword symbol, or `unknown` when no keyword was heard (null without a domain).
"""
from __future__ import annotations

import argparse
import sys

COMMAND = "listen"
HELP = "recognise a WAV file or the microphone with the domain's recogniser; print text, confidence, symbol"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("audio", nargs="?", help="16-bit PCM WAV file, or '-' for the default microphone")
    parser.add_argument("--domain", default="config/pearl.domain.yaml",
                        help="factored domain whose keywords build the language model (default: %(default)s)")
    parser.add_argument("--default-lm", action="store_true",
                        help="decode with pocketsphinx's large en-us model instead of the domain's")
    parser.add_argument("--say", metavar="TEXT", help="synthesise TEXT with espeak-ng instead of reading audio")
    parser.add_argument("--voice", default="clear", help="voice preset for --say (clear, slow, quiet, slurred)")
    parser.add_argument("--snr", type=float, default=None, help="add white noise at this SNR (dB) before decoding")
    parser.add_argument("--seconds", type=float, default=5.0, help="microphone recording length (default: 5)")
    parser.add_argument("--max-seconds", type=float, default=60.0, help="longest audio accepted (default: 60)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the added noise")
    parser.add_argument("--save-wav", metavar="PATH", help="also write the audio that was decoded (16 kHz mono WAV)")
    parser.add_argument("--json", action="store_true", help="print one JSON object")


def _record(seconds: float):
    from pearl_pomdp.asr.audio import AudioError

    try:
        import sounddevice
    except (ImportError, OSError) as err:
        raise AudioError(f"microphone ('-'): sounddevice/PortAudio unavailable ({err}); give a WAV file") from None
    try:
        data = sounddevice.rec(int(seconds * 16000), samplerate=16000, channels=1, dtype="int16", blocking=True)
    except Exception as err:  # PortAudioError: no input device
        raise AudioError(f"microphone ('-'): no usable input device: {err}") from None
    import numpy as np

    return np.asarray(data[:, 0], dtype=np.int16)


def run(args: argparse.Namespace) -> int:
    from pearl_pomdp.asr.audio import AudioError, mix_at_snr, read_wav, write_wav
    from pearl_pomdp.asr.recognizer import Recognizer
    from pearl_pomdp.cli import print_json
    from pearl_pomdp.model.domain_yaml import load_domain
    from pearl_pomdp.speech import KeywordFilter

    if (args.audio is None) == (args.say is None):
        raise AudioError("give exactly one of: a WAV file, '-' (microphone), --say TEXT")
    notes = []
    if args.say is not None:
        from pearl_pomdp.asr.synthesizer import synthesize

        pcm, source = synthesize(args.say, args.voice), f"espeak-ng {args.voice!r}: {args.say!r}"
    elif args.audio == "-":
        pcm, source = _record(args.seconds), "microphone"
    else:
        pcm, rate = read_wav(args.audio)
        source = args.audio
        if rate != 16000:
            notes.append(f"resampled from {rate} Hz")
    if args.snr is not None:
        import numpy as np

        pcm = mix_at_snr(pcm, args.snr, np.random.default_rng(args.seed))
        notes.append(f"white noise at {args.snr:g} dB SNR")
    if args.save_wav:
        write_wav(args.save_wav, pcm)
        notes.append(f"audio written to {args.save_wav}")
    domain = load_domain(args.domain)
    recognizer = Recognizer(None if args.default_lm else domain.keywords, max_seconds=args.max_seconds)
    rec = recognizer.recognise(pcm, where=source)
    symbol = KeywordFilter.from_domain(domain).classify(rec.text) if domain.keywords else None
    if rec.clipped > recognizer.clip_warning:
        notes.append(f"clipped: {100 * rec.clipped:.1f} % of samples at full scale")
    if args.json:
        print_json({"text": rec.text, "confidence": round(rec.confidence, 4), "symbol": symbol,
                    "audio_seconds": round(rec.audio_seconds, 3), "decode_seconds": round(rec.decode_seconds, 4),
                    "recogniser": recognizer.identity, "notes": notes})
        return 0
    print(f"source:     {source}" + (f" ({'; '.join(notes)})" if notes else ""))
    print(f"text:       {rec.text!r}")
    print(f"confidence: {rec.confidence:.2f}")
    print(f"symbol:     {symbol}")
    print(f"decoded {rec.audio_seconds:.2f} s of audio in {rec.decode_seconds:.2f} s ({recognizer.identity})",
          file=sys.stderr)
    return 0
