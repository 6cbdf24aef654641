"""Text → speech with espeak-ng (through ctypes, library and voice data from ``espeakng-loader``).

espeak-ng keeps one global synthesiser per process, so :class:`Synthesizer` is a
process-wide object guarded by a lock: every call sets the voice and its
parameters, synthesises synchronously (``AUDIO_OUTPUT_SYNCHRONOUS``: samples come to
a callback, nothing is played) and resamples espeak's 22 050 Hz to 16 kHz.

A :class:`Voice` is an espeak voice name (``en-us``, optionally ``+variant`` such as
``en-us+grandma``) plus rate (words per minute), pitch and pitch range (0–100), volume
(0–200) and the gap between words (units of 10 ms). :data:`VOICES` holds the named
presets used for simulated residents; ``snr_offset_db`` makes a *quiet* voice reach
the microphone that many dB below the scenario's SNR.
"""
from __future__ import annotations

import ctypes
import threading
from dataclasses import asdict, dataclass
from typing import Dict, List, Mapping, Optional, Union

import numpy as np

from pearl_pomdp.asr.audio import SAMPLE_RATE, resample
from pearl_pomdp.errors import PearlError

__all__ = ["Voice", "VOICES", "SynthesisError", "Synthesizer", "get_voice", "synthesize"]

# espeak_AUDIO_OUTPUT / espeak_PARAMETER / espeak_POSITION_TYPE values from speak_lib.h.
_AUDIO_OUTPUT_SYNCHRONOUS = 2
_POS_CHARACTER = 1
_CHARS_UTF8 = 1
_PARAM = {"rate": 1, "volume": 2, "pitch": 3, "range": 4, "wordgap": 7}
_EE_OK = 0
#: Longest text synthesised in one call (characters): a paragraph, not a book.
MAX_TEXT_CHARS = 2000


class SynthesisError(PearlError):
    """espeak-ng is missing, a voice is unknown, or a parameter is out of range."""


@dataclass(frozen=True)
class Voice:
    """How one speaker sounds (see the module doc for the units)."""

    name: str = "en-us"
    rate: int = 160
    pitch: int = 50
    pitch_range: int = 50
    volume: int = 100
    word_gap: int = 0
    snr_offset_db: float = 0.0

    def __post_init__(self) -> None:
        checks = {"rate": (self.rate, 80, 450), "pitch": (self.pitch, 0, 100),
                  "pitch_range": (self.pitch_range, 0, 100), "volume": (self.volume, 0, 200),
                  "word_gap": (self.word_gap, 0, 100)}
        for field_name, (value, lo, hi) in checks.items():
            if not lo <= value <= hi:
                raise SynthesisError(f"voice {self.name!r}: {field_name} {value} is not in [{lo}, {hi}]")

    def to_dict(self) -> Dict[str, Union[str, int, float]]:
        return asdict(self)


#: Named voices of simulated residents: a clear speaker (espeak's default en-us, the voice
#: Sphinx hears best of those measured: bench/speech.py) and three impaired variants
#: (``slow``: 115 wpm with pauses between words; ``quiet``: reaches the microphone 6 dB
#: below the room's SNR; ``slurred``: espeak's elderly "grandpa" variant, low and monotone).
VOICES: Dict[str, Voice] = {
    "clear": Voice("en-us", rate=160),
    "slow": Voice("en-us+m3", rate=115, pitch=40, word_gap=3),
    "quiet": Voice("en-us+f2", rate=150, pitch=50, snr_offset_db=-6.0),
    "slurred": Voice("en-us+grandpa", rate=140, pitch=35, pitch_range=10),
}


def get_voice(spec: Union[str, Voice, Mapping]) -> Voice:
    """A :class:`Voice` from a preset name, a mapping of its fields, or a Voice.

    Raises:
        SynthesisError: an unknown preset name or an unknown field.
    """
    if isinstance(spec, Voice):
        return spec
    if isinstance(spec, str):
        if spec not in VOICES:
            raise SynthesisError(f"unknown voice {spec!r}; presets: {', '.join(VOICES)} "
                                 "(or give fields: name, rate, pitch, ...)")
        return VOICES[spec]
    if isinstance(spec, Mapping):
        fields = set(Voice.__dataclass_fields__)
        extra = set(spec) - fields
        if extra:
            raise SynthesisError(f"voice: unknown field(s) {', '.join(sorted(extra))}; known: {', '.join(sorted(fields))}")
        return Voice(**dict(spec))
    raise SynthesisError(f"voice {spec!r} is neither a preset name nor a mapping")


_CALLBACK = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.POINTER(ctypes.c_short), ctypes.c_int, ctypes.c_void_p)


class Synthesizer:
    """The process's espeak-ng (use :meth:`instance`); :meth:`synthesize` is thread-safe."""

    _instance: Optional["Synthesizer"] = None
    _instance_lock = threading.Lock()

    def __init__(self) -> None:
        try:
            import espeakng_loader
        except ImportError:
            raise SynthesisError("espeak-ng is not installed: pip install espeakng-loader "
                                 "(or pip install 'pearl_pomdp[speech]')") from None
        try:
            lib = ctypes.CDLL(espeakng_loader.get_library_path())
            data = espeakng_loader.get_data_path()
        except (OSError, RuntimeError) as err:
            raise SynthesisError(f"cannot load libespeak-ng from espeakng-loader: {err}") from None
        lib.espeak_Initialize.argtypes = [ctypes.c_int, ctypes.c_int, ctypes.c_char_p, ctypes.c_int]
        lib.espeak_Initialize.restype = ctypes.c_int
        lib.espeak_SetVoiceByName.argtypes = [ctypes.c_char_p]
        lib.espeak_SetParameter.argtypes = [ctypes.c_int, ctypes.c_int, ctypes.c_int]
        lib.espeak_Synth.argtypes = [ctypes.c_char_p, ctypes.c_size_t, ctypes.c_uint, ctypes.c_int, ctypes.c_uint,
                                     ctypes.c_uint, ctypes.c_void_p, ctypes.c_void_p]
        self.native_rate = lib.espeak_Initialize(_AUDIO_OUTPUT_SYNCHRONOUS, 0, data.encode(), 0)
        if self.native_rate <= 0:
            raise SynthesisError(f"espeak-ng failed to initialise with its data at {data}")
        self._lib = lib
        self._chunks: List[np.ndarray] = []
        self._callback = _CALLBACK(self._on_samples)  # kept: espeak holds the pointer
        lib.espeak_SetSynthCallback(self._callback)
        self._lock = threading.Lock()

    @classmethod
    def instance(cls) -> "Synthesizer":
        """The one synthesiser of this process (espeak-ng is a global library)."""
        with cls._instance_lock:
            if cls._instance is None:
                cls._instance = cls()
            return cls._instance

    def _on_samples(self, wav, n, _events) -> int:
        if n > 0 and wav:
            self._chunks.append(np.ctypeslib.as_array(wav, shape=(n,)).copy())
        return 0

    def synthesize(self, text: str, voice: Union[str, Voice, Mapping] = "clear") -> np.ndarray:
        """``text`` spoken by ``voice`` as 16 kHz int16 samples (empty text → no samples).

        Raises:
            SynthesisError: unknown voice, text longer than :data:`MAX_TEXT_CHARS`, or espeak failing.
        """
        v = get_voice(voice)
        text = str(text).strip()
        if not text:
            return np.zeros(0, dtype=np.int16)
        if len(text) > MAX_TEXT_CHARS:
            raise SynthesisError(f"text of {len(text)} characters is longer than {MAX_TEXT_CHARS}; split it")
        raw = text.encode("utf-8") + b"\0"
        with self._lock:
            if self._lib.espeak_SetVoiceByName(v.name.encode()) != _EE_OK:
                raise SynthesisError(f"espeak-ng has no voice {v.name!r} (e.g. en-us, en, en-gb-x-rp, en-us+f3, en-us+grandma)")
            for key, value in (("rate", v.rate), ("pitch", v.pitch), ("range", v.pitch_range),
                               ("volume", v.volume), ("wordgap", v.word_gap)):
                self._lib.espeak_SetParameter(_PARAM[key], int(value), 0)
            self._chunks = []
            err = self._lib.espeak_Synth(raw, len(raw), 0, _POS_CHARACTER, 0, _CHARS_UTF8, None, None)
            self._lib.espeak_Synchronize()
            chunks, self._chunks = self._chunks, []
        if err != _EE_OK:
            raise SynthesisError(f"espeak-ng failed to synthesise {text[:40]!r} (error {err})")
        if not chunks:
            return np.zeros(0, dtype=np.int16)
        a = resample(np.concatenate(chunks).astype(np.float64), self.native_rate, SAMPLE_RATE)
        return np.clip(np.round(a), -32768, 32767).astype(np.int16)


def synthesize(text: str, voice: Union[str, Voice, Mapping] = "clear") -> np.ndarray:
    """Shortcut for ``Synthesizer.instance().synthesize(text, voice)``."""
    return Synthesizer.instance().synthesize(text, voice)
