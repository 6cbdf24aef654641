"""Speech → text with CMU Sphinx (pocketsphinx 5), on the domain's small vocabulary.

* :class:`Recognizer` decodes one utterance (16 kHz int16) and returns a
  :class:`Recognition`: the text, a confidence in [0, 1] and timings. With
  ``keywords`` it decodes with the language model of :mod:`pearl_pomdp.asr.grammar`
  (the domain's keywords in carrier phrases plus a filler path); without, with
  pocketsphinx's default large en-us model (for comparison: ``bench/speech.py``).
* :class:`UtteranceSegmenter` cuts a stream of audio chunks into utterances with
  pocketsphinx's voice-activity endpointer (WebRTC-style VAD + hangover window).

**Confidence** is the posterior probability of the decoded word sequence in the
recogniser's lattice (pocketsphinx's ``hyp().prob``, from its forward-backward pass over
the word lattice), normalised by length: ``P(words | audio) ** (1 / n_words)``, the
geometric mean per word, so a clear seven-word request is not judged less sure than a
clear "yes". Near 1 when no competing hypothesis is close, lower when the audio fits
several (measured: clear speech at 30 dB ≈ 0.3–0.7, the same at 5 dB ≈ 0.05). Empty
text has confidence 0. It is a property of the
recogniser, not a calibrated probability that the keyword is right; the measured
channel (``pearl calibrate-speech``) records how it relates to being right.

Each utterance is decoded whole (``full_utt``) with *batch* cepstral mean normalisation,
so a recognition depends on that utterance's audio only, not on what was heard before:
results are reproducible and can be cached by content.

Model files (the generated ARPA model and dictionary) are written once, by content
hash, under :func:`cache_dir` (``$PEARL_CACHE_DIR``, else ``$XDG_CACHE_HOME/pearl_pomdp``,
else ``~/.cache/pearl_pomdp``), never in the source tree.
"""
from __future__ import annotations

import os
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import List, Mapping, Optional, Sequence

import numpy as np

from pearl_pomdp.asr.audio import CLIP_LIMIT, SAMPLE_RATE, AudioError, check_pcm, clipped_fraction
from pearl_pomdp.errors import PearlError

__all__ = ["Recognition", "Recognizer", "RecognizerError", "UtteranceSegmenter", "UtteranceTooLong", "cache_dir",
           "MAX_UTTERANCE_SECONDS"]

#: Longest utterance decoded (s). Longer ones are dropped (counted), not decoded for minutes.
MAX_UTTERANCE_SECONDS = 20.0
#: pocketsphinx settings that differ from its defaults (none yet; see bench/speech.py).
DECODER_OPTIONS: Mapping[str, object] = {}
#: Shortest audio worth decoding (s): a syllable.
MIN_UTTERANCE_SECONDS = 0.1


class RecognizerError(PearlError):
    """pocketsphinx is missing or its model cannot be loaded."""


class UtteranceTooLong(AudioError):
    """An utterance longer than the recogniser's limit (dropped and counted, not decoded)."""


def cache_dir() -> Path:
    """Per-user cache of generated models and calibration results (module doc)."""
    if os.environ.get("PEARL_CACHE_DIR"):
        base = Path(os.environ["PEARL_CACHE_DIR"])
    elif os.environ.get("XDG_CACHE_HOME"):
        base = Path(os.environ["XDG_CACHE_HOME"]) / "pearl_pomdp"
    else:
        base = Path.home() / ".cache" / "pearl_pomdp"
    return base


@dataclass(frozen=True)
class Recognition:
    """One decoded utterance.

    Attributes:
        text: the recognised words, lower case, fillers and silences removed ("" when none).
        confidence: posterior of the hypothesis in [0, 1] (module doc); 0 for "".
        audio_seconds: length of the audio decoded.
        decode_seconds: wall time the decoding took (real-time factor = decode / audio).
        clipped: fraction of the samples at full scale (> 1 % suggests a clipped microphone).
    """

    text: str
    confidence: float
    audio_seconds: float
    decode_seconds: float
    clipped: float = 0.0

    def to_dict(self) -> dict:
        return {"text": self.text, "confidence": round(self.confidence, 4), "audio_seconds": round(self.audio_seconds, 3),
                "decode_seconds": round(self.decode_seconds, 4), "clipped": round(self.clipped, 4)}


def _import_pocketsphinx():
    try:
        import pocketsphinx
    except ImportError:
        raise RecognizerError("pocketsphinx is not installed: pip install 'pocketsphinx>=5' "
                              "(or pip install 'pearl_pomdp[speech]')") from None
    return pocketsphinx


class Recognizer:
    """A pocketsphinx decoder for single utterances (see the module doc).

    Args:
        keywords: symbol → keyword phrases (a domain's ``keywords:``); ``None`` decodes with
            pocketsphinx's default large language model.
        extra_sentences: more corpus sentences for the generated model.
        max_seconds: utterances longer than this raise :class:`UtteranceTooLong`.
        decoder_options: extra pocketsphinx settings (``{"lw": 8.0}``); part of :attr:`identity`.

    Attributes:
        language_model: the generated :class:`~pearl_pomdp.asr.grammar.LanguageModel` (or None).
        identity: a string naming the model, part of every cache key of its recognitions.

    Raises:
        RecognizerError: pocketsphinx missing or its model unreadable.
    """

    def __init__(self, keywords: Optional[Mapping[str, Sequence[str]]] = None, extra_sentences: Sequence[str] = (),
                 max_seconds: float = MAX_UTTERANCE_SECONDS, decoder_options: Optional[Mapping[str, object]] = None):
        ps = _import_pocketsphinx()
        options = dict(DECODER_OPTIONS)
        options.update(decoder_options or {})
        tag = "".join(f":{k}={v}" for k, v in sorted(options.items()))
        if max_seconds <= 0:
            raise ValueError(f"max_seconds {max_seconds} is not positive")
        self.max_seconds = float(max_seconds)
        self._lock = threading.Lock()
        self.language_model = None
        try:
            if keywords is None:
                self._decoder = ps.Decoder(loglevel="FATAL", bestpath=True, cmn="batch", **options)
                self.identity = f"pocketsphinx-{_version()}:default-en-us{tag}"
            else:
                from pearl_pomdp.asr.grammar import build_language_model

                probe = ps.Decoder(loglevel="FATAL", lm=None)
                lm = build_language_model(keywords, probe.lookup_word, extra_sentences)
                del probe
                lm_path, dict_path = _write_model(lm)
                self._decoder = ps.Decoder(loglevel="FATAL", lm=str(lm_path), dict=str(dict_path), bestpath=True,
                                           cmn="batch", **options)
                self.language_model = lm
                self.identity = f"pocketsphinx-{_version()}:domain-{lm.digest}{tag}"
        except (RuntimeError, ValueError, KeyError) as err:
            raise RecognizerError(f"pocketsphinx cannot load its model: {err}") from None

    def recognise(self, pcm: np.ndarray, sample_rate: int = SAMPLE_RATE, where: str = "audio") -> Recognition:
        """Decode one utterance.

        Raises:
            AudioError: wrong sample rate or shape (message names ``where``).
            UtteranceTooLong: longer than ``max_seconds``.
        """
        pcm = check_pcm(pcm, sample_rate, where)
        seconds = len(pcm) / SAMPLE_RATE
        clipped = clipped_fraction(pcm)
        if seconds > self.max_seconds:
            raise UtteranceTooLong(f"{where}: utterance of {seconds:.1f} s is longer than the limit of "
                                   f"{self.max_seconds:g} s; dropped")
        if seconds < MIN_UTTERANCE_SECONDS or not np.any(pcm):
            return Recognition("", 0.0, seconds, 0.0, clipped)
        t0 = time.perf_counter()
        with self._lock:
            d = self._decoder
            d.start_utt()
            d.process_raw(pcm.tobytes(), no_search=False, full_utt=True)
            d.end_utt()
            hyp = d.hyp()
            words = [s.word for s in d.seg()] if hyp is not None else []
            prob = float(hyp.prob) if hyp is not None else 0.0
        kept = [_clean(w) for w in words if _is_word(w)]
        text = " ".join(kept)
        confidence = min(1.0, max(0.0, prob)) ** (1.0 / len(kept)) if kept else 0.0
        return Recognition(text, confidence, seconds, time.perf_counter() - t0, clipped)

    @property
    def clip_warning(self) -> float:
        """Clipped fraction above which callers should warn (:data:`~pearl_pomdp.asr.audio.CLIP_LIMIT`)."""
        return CLIP_LIMIT


def _is_word(w: str) -> bool:
    return bool(w) and not (w.startswith("<") or w.startswith("[") or w.startswith("++"))


def _clean(w: str) -> str:
    # Alternate pronunciations are spelt "word(2)".
    return w.split("(", 1)[0]


def _version() -> str:
    try:
        from importlib.metadata import version

        return version("pocketsphinx")
    except Exception:  # noqa: BLE001 - metadata missing in odd installs: the name still identifies it
        return "unknown"


def _write_model(lm) -> "tuple[Path, Path]":
    """The model's ARPA and dictionary files under the cache dir (written once, atomically)."""
    from pearl_pomdp.atomic import atomic_write

    def write(folder: Path) -> "tuple[Path, Path]":
        lm_path, dict_path = folder / "domain.lm", folder / "domain.dict"
        if not (lm_path.exists() and dict_path.exists()):
            folder.mkdir(parents=True, exist_ok=True)
            atomic_write(lm_path, lm.arpa)
            atomic_write(dict_path, "".join(f"{w} {p}\n" for w, p in sorted(lm.dictionary.items())))
        return lm_path, dict_path

    try:
        return write(cache_dir() / "asr" / lm.digest)
    except OSError:
        # A read-only home (some CI runners, robots): a private temporary folder still works.
        import tempfile

        return write(Path(tempfile.mkdtemp(prefix=f"pearl-asr-{lm.digest}-")))


class UtteranceSegmenter:
    """Cuts a stream of 16 kHz int16 chunks into utterances by voice activity.

    Feed chunks of any length; :meth:`feed` returns the utterances that ended in them.
    An utterance longer than ``max_seconds`` is dropped whole (its audio is not kept):
    :attr:`too_long` counts them.

    Args:
        window: seconds of audio the endpointer looks at to decide speech / silence.
        ratio: fraction of speech frames in the window that starts (and, inverted, ends) speech.
        vad_mode: pocketsphinx VAD aggressiveness 0 (loose) … 3 (strict).
        max_seconds: longest utterance kept.
    """

    def __init__(self, window: float = 0.3, ratio: float = 0.9, vad_mode: int = 0,
                 max_seconds: float = MAX_UTTERANCE_SECONDS):
        ps = _import_pocketsphinx()
        self._ep = ps.Endpointer(window=window, ratio=ratio, vad_mode=vad_mode, sample_rate=SAMPLE_RATE)
        self._frame = self._ep.frame_bytes
        self._pending = b""
        self._current: List[bytes] = []
        self._current_bytes = 0
        self._dropping = False
        self.max_bytes = int(max_seconds * SAMPLE_RATE) * 2
        self.too_long = 0
        self.utterances = 0

    def feed(self, pcm: np.ndarray) -> List[np.ndarray]:
        """Add samples; returns the utterances completed by them (each an int16 array)."""
        data = self._pending + np.asarray(pcm, dtype=np.int16).tobytes()
        done: List[np.ndarray] = []
        n = len(data) // self._frame * self._frame
        for i in range(0, n, self._frame):
            self._take(self._ep.process(data[i:i + self._frame]), done)
        self._pending = data[n:]
        return done

    def flush(self) -> List[np.ndarray]:
        """End of stream: the utterance still open (if any)."""
        done: List[np.ndarray] = []
        speech = self._ep.end_stream(self._pending)
        self._pending = b""
        self._take(speech, done, final=True)
        return done

    @property
    def in_speech(self) -> bool:
        """True while an utterance is open."""
        return bool(self._ep.in_speech)

    def _take(self, speech: Optional[bytes], done: List[np.ndarray], final: bool = False) -> None:
        if speech is not None:
            if not self._dropping:
                self._current.append(bytes(speech))
                self._current_bytes += len(speech)
                if self._current_bytes > self.max_bytes:
                    self._dropping, self._current, self._current_bytes = True, [], 0
        if (speech is not None or final) and not self._ep.in_speech:
            if self._dropping:
                self.too_long += 1
            elif self._current:
                done.append(np.frombuffer(b"".join(self._current), dtype=np.int16).copy())
                self.utterances += 1
            self._dropping, self._current, self._current_bytes = False, [], 0
