"""The simulated resident speaks through the real speech channel (issue 13).

What she means (an intent such as ``time``) and what she says ("what time is it")
become recogniser text and a confidence in one of three ways, chosen by the scenario's
``speech:`` mapping::

    speech:
      channel: recogniser      # recogniser | measured | word_error (default: word_error)
      snr_db: 20               # recogniser, measured: SNR at her microphone (dB)
      noise: white             # recogniser: white | babble
      measured: channel.json   # measured: a file from `pearl calibrate-speech` (relative to the scenario)
      word_error_rate: 0.2     # word_error: pearl_sim.asr's hand-made error model

    resident:
      voice: slow              # a preset of pearl_pomdp.asr.synthesizer.VOICES or {name, rate, pitch, ...}

* ``recogniser``: espeak-ng speaks the utterance in her voice, noise is added at
  ``snr_db`` (+ her voice's ``snr_offset_db``), and the domain's pocketsphinx recogniser
  decodes it — the same :class:`~pearl_pomdp.asr.recognizer.Recognizer` the robot's
  ``speech_recognizer`` node runs. About 0.1 s of CPU per utterance.
* ``measured``: a recogniser output recorded for the same meaning at (about) that SNR is
  drawn from a calibrated channel (:class:`~pearl_pomdp.asr.channel.MeasuredChannel`):
  microseconds per utterance, for thousands of episodes.
* ``word_error``: :class:`pearl_sim.asr.SpeechRecogniser` (confidence 1.0).

Every channel has one call, :meth:`SpeechChannel.hear`, and returns
:class:`Heard` (text, confidence); the world turns it into the ``/pearl/speech`` message
(plain text, or ``pearl_pomdp.speech.speech_message`` JSON with the confidence).
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Dict, Mapping, Optional, Sequence, Tuple, Union

import numpy as np

from pearl_pomdp.errors import SpecError

__all__ = ["Heard", "SpeechChannel", "RecogniserChannel", "MeasuredSpeechChannel", "WordErrorChannel",
           "make_speech_channel", "CHANNELS", "CHATTER_INTENT"]

CHANNELS = ("recogniser", "measured", "word_error")
#: The world's intent for speech that means nothing to the robot; the channel calls it ``unknown``.
CHATTER_INTENT = "chatter"


@dataclass(frozen=True)
class Heard:
    """What the recogniser made of one utterance."""

    text: str
    confidence: float


class SpeechChannel:
    """Base: ``hear(intent, utterance, voice, rng) → Heard``."""

    name = "base"

    def hear(self, intent: str, utterance: str, voice: Union[str, Mapping, None], rng: np.random.Generator) -> Heard:
        """Recognised text and confidence for a resident meaning ``intent`` and saying ``utterance``."""
        raise NotImplementedError


class RecogniserChannel(SpeechChannel):
    """espeak-ng → noise at ``snr_db`` → pocketsphinx on the domain's keywords (module doc).

    Args:
        keywords: the domain's ``keywords:`` (symbol → phrases).
        snr_db: SNR at the microphone, before the voice's ``snr_offset_db``.
        noise: ``white`` or ``babble``.
        recognizer: a ready :class:`~pearl_pomdp.asr.recognizer.Recognizer` (shared between worlds).
    """

    name = "recogniser"

    def __init__(self, keywords: Mapping[str, Sequence[str]], snr_db: float = 20.0, noise: str = "white",
                 recognizer=None):
        from pearl_pomdp.asr.audio import NOISE_KINDS
        from pearl_pomdp.asr.recognizer import Recognizer

        if noise not in NOISE_KINDS:
            raise ValueError(f"noise {noise!r} is not one of {', '.join(NOISE_KINDS)}")
        self.snr_db = float(snr_db)
        self.noise = noise
        self.recognizer = recognizer or Recognizer(keywords)
        self._clean: Dict[Tuple[str, str], np.ndarray] = {}

    def hear(self, intent, utterance, voice, rng) -> Heard:
        from pearl_pomdp.asr.audio import mix_at_snr
        from pearl_pomdp.asr.channel import babble_track
        from pearl_pomdp.asr.synthesizer import get_voice, synthesize

        v = get_voice(voice if voice is not None else "clear")
        key = (utterance, repr(v))
        if key not in self._clean:
            if len(self._clean) > 512:
                self._clean.clear()
            self._clean[key] = synthesize(utterance, v)
        babble = babble_track() if self.noise == "babble" else None
        audio = mix_at_snr(self._clean[key], self.snr_db + v.snr_offset_db, rng, self.noise, babble)
        rec = self.recognizer.recognise(audio, where=f"resident saying {utterance!r}")
        return Heard(rec.text, rec.confidence)


class MeasuredSpeechChannel(SpeechChannel):
    """Draws recogniser outputs from a calibrated channel file (module doc).

    The voice's ``snr_offset_db`` still applies; the file's own voices are the population
    the outputs were measured on (``pearl calibrate-speech --voices``).
    """

    name = "measured"

    def __init__(self, table_or_path, snr_db: float = 20.0, unknown_symbol: str = "unknown"):
        from pearl_pomdp.asr.channel import ChannelTable, MeasuredChannel

        table = table_or_path if isinstance(table_or_path, ChannelTable) else ChannelTable.load(table_or_path)
        self.channel = MeasuredChannel(table)
        self.snr_db = float(snr_db)
        self.unknown_symbol = unknown_symbol

    def hear(self, intent, utterance, voice, rng) -> Heard:
        from pearl_pomdp.asr.synthesizer import get_voice

        offset = get_voice(voice).snr_offset_db if voice is not None else 0.0
        meant = self.unknown_symbol if intent == CHATTER_INTENT else intent
        text, confidence, _symbol = self.channel.sample(meant, self.snr_db + offset, rng)
        return Heard(text, confidence)


class WordErrorChannel(SpeechChannel):
    """Today's hand-made word-error model (:class:`pearl_sim.asr.SpeechRecogniser`); confidence 1."""

    name = "word_error"

    def __init__(self, word_error_rate: float = 0.2, seed: int = 0):
        from pearl_sim.asr import SpeechRecogniser

        self.model = SpeechRecogniser(word_error_rate=word_error_rate, seed=seed)

    def hear(self, intent, utterance, voice, rng) -> Heard:
        return Heard(self.model.recognise(utterance), 1.0)


_RECOGNISERS: Dict[str, Any] = {}


def _shared_recognizer(keywords: Mapping[str, Sequence[str]]):
    """One Recognizer per keyword table per process (building one takes ~0.2 s)."""
    from pearl_pomdp.asr.recognizer import Recognizer

    key = repr(sorted((k, tuple(v)) for k, v in keywords.items()))
    if key not in _RECOGNISERS:
        _RECOGNISERS[key] = Recognizer(keywords)
    return _RECOGNISERS[key]


def make_speech_channel(spec: Optional[Mapping[str, Any]], keywords: Mapping[str, Sequence[str]],
                        source: Union[str, Path] = "<scenario>", seed: int = 0) -> SpeechChannel:
    """The channel a scenario's ``speech:`` mapping asks for (module doc), validated.

    Args:
        spec: the ``speech:`` mapping (``None``/empty: the word-error model at 0.2).
        keywords: the domain's keywords (for the recogniser).
        source: the scenario file (error messages; base of a relative ``measured`` path).
        seed: seed of the word-error model.

    Raises:
        SpecError: an unknown channel or field, a value out of range, a missing channel file
            (the message names ``speech.<field>`` in ``source``).
    """
    spec = dict(spec or {})
    allowed = {"channel", "snr_db", "noise", "measured", "word_error_rate"}
    extra = sorted(set(spec) - allowed)
    if extra:
        raise SpecError(source, f"speech.{extra[0]}", f"unknown field; known: {', '.join(sorted(allowed))}")
    channel = spec.get("channel", "word_error")
    if channel not in CHANNELS:
        raise SpecError(source, "speech.channel", f"{channel!r} is not one of {', '.join(CHANNELS)}")

    def number(name: str, default: float, lo: float, hi: float) -> float:
        value = spec.get(name, default)
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not lo <= value <= hi:
            raise SpecError(source, f"speech.{name}", f"{value!r} is not a number in [{lo:g}, {hi:g}]")
        return float(value)

    if channel == "word_error":
        return WordErrorChannel(number("word_error_rate", 0.2, 0.0, 1.0), seed=seed)
    snr = number("snr_db", 20.0, -20.0, 60.0)
    if channel == "recogniser":
        noise = spec.get("noise", "white")
        if noise not in ("white", "babble"):
            raise SpecError(source, "speech.noise", f"{noise!r} is not one of white, babble")
        return RecogniserChannel(keywords, snr, noise, recognizer=_shared_recognizer(keywords))
    path = spec.get("measured")
    if not isinstance(path, str) or not path:
        raise SpecError(source, "speech.measured", "channel: measured needs the file of `pearl calibrate-speech --out`")
    full = Path(path)
    if not full.is_absolute() and source and Path(str(source)).exists():
        full = Path(str(source)).parent / full
    from pearl_pomdp.asr.channel import ChannelError

    try:
        return MeasuredSpeechChannel(full, snr)
    except ChannelError as err:
        raise SpecError(source, "speech.measured", str(err)) from None
