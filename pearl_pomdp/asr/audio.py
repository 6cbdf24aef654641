"""16 kHz mono 16-bit PCM: checks, WAV files, resampling and noise at a given SNR.

Everything in :mod:`pearl_pomdp.asr` passes audio as a 1-D ``numpy.int16`` array of
samples at :data:`SAMPLE_RATE` (what the Sphinx en-us acoustic model expects).

SNR is defined over the *speech* samples: ``snr_db = 10 log10(P_speech / P_noise)``
with ``P`` the mean square of the synthesised utterance (no leading/trailing silence)
and of the noise over the same span. Noise also fills :data:`PAD_SECONDS` before and
after the utterance, as a microphone would hear the room before and after she speaks.
"""
from __future__ import annotations

import wave
from pathlib import Path
from typing import Optional, Tuple, Union

import numpy as np

from pearl_pomdp.errors import PearlError

__all__ = ["SAMPLE_RATE", "PAD_SECONDS", "NOISE_KINDS", "AudioError", "check_pcm", "to_int16", "resample",
           "read_wav", "write_wav", "white_noise", "mix_at_snr", "clipped_fraction"]

#: Samples per second of every array in this package (the Sphinx en-us model's rate).
SAMPLE_RATE = 16000
#: Noise-only audio around an utterance (s): the recogniser's VAD and cepstral mean need it.
PAD_SECONDS = 0.3
#: Noise kinds :func:`mix_at_snr` accepts (``babble`` needs a babble track, see channel.py).
NOISE_KINDS = ("white", "babble")
#: Fraction of samples at full scale above which audio counts as clipped.
CLIP_LIMIT = 0.01


class AudioError(PearlError):
    """Audio that the recogniser cannot use (wrong rate, wrong shape, empty, unreadable file)."""


def check_pcm(pcm: np.ndarray, sample_rate: int, where: str) -> np.ndarray:
    """``pcm`` as a 1-D int16 array at :data:`SAMPLE_RATE`, or an :class:`AudioError` naming ``where``.

    Raises:
        AudioError: a rate other than 16000 Hz, a non-1-D array, a non-integer/float dtype.
    """
    if int(sample_rate) != SAMPLE_RATE:
        raise AudioError(f"{where}: sample rate {sample_rate} Hz, expected {SAMPLE_RATE} Hz mono 16-bit PCM")
    a = np.asarray(pcm)
    if a.ndim != 1:
        raise AudioError(f"{where}: audio has shape {a.shape}, expected one channel (1-D samples)")
    return to_int16(a, where)


def to_int16(a: np.ndarray, where: str = "audio") -> np.ndarray:
    """Samples as int16: integers are checked, floats (−1..1 full scale or int16-scaled) converted."""
    a = np.asarray(a)
    if a.dtype == np.int16:
        return a
    if np.issubdtype(a.dtype, np.integer):
        if a.size and (a.min() < -32768 or a.max() > 32767):
            raise AudioError(f"{where}: integer samples outside the 16-bit range")
        return a.astype(np.int16)
    if np.issubdtype(a.dtype, np.floating):
        if a.size and not np.all(np.isfinite(a)):
            raise AudioError(f"{where}: audio has NaN or infinite samples")
        scale = 32767.0 if a.size and np.max(np.abs(a)) <= 1.0 else 1.0
        return np.clip(np.round(a * scale), -32768, 32767).astype(np.int16)
    raise AudioError(f"{where}: samples of type {a.dtype}, expected int16 PCM")


def resample(a: np.ndarray, rate_in: int, rate_out: int = SAMPLE_RATE) -> np.ndarray:
    """Polyphase resampling (scipy) of float or int samples; returns float64 samples, same scale."""
    from math import gcd

    from scipy.signal import resample_poly

    if rate_in <= 0:
        raise AudioError(f"sample rate {rate_in} Hz is not positive")
    if rate_in == rate_out:
        return np.asarray(a, dtype=np.float64)
    g = gcd(int(rate_in), int(rate_out))
    return resample_poly(np.asarray(a, dtype=np.float64), rate_out // g, rate_in // g)


def read_wav(path: Union[str, Path], convert: bool = True) -> Tuple[np.ndarray, int]:
    """``(int16 samples at 16 kHz mono, original rate)`` of a PCM WAV file.

    With ``convert`` (the default) other rates are resampled and channels averaged;
    without it anything but 16 kHz mono 16-bit is an error.

    Raises:
        AudioError: unreadable or non-PCM file, or (``convert=False``) another format.
    """
    path = Path(path)
    try:
        with wave.open(str(path), "rb") as w:
            rate, channels, width, n = w.getframerate(), w.getnchannels(), w.getsampwidth(), w.getnframes()
            raw = w.readframes(n)
    except FileNotFoundError:
        raise AudioError(f"{path}: no such file") from None
    except (wave.Error, EOFError, OSError) as err:
        raise AudioError(f"{path}: not a PCM WAV file ({err})") from None
    if width not in (1, 2, 4):
        raise AudioError(f"{path}: {8 * width}-bit samples, expected 8, 16 or 32-bit PCM")
    dtype = {1: np.uint8, 2: np.int16, 4: np.int32}[width]
    a = np.frombuffer(raw, dtype=dtype).astype(np.float64)
    if width == 1:
        a = (a - 128.0) * 256.0
    elif width == 4:
        a = a / 65536.0
    if channels > 1:
        a = a[: len(a) // channels * channels].reshape(-1, channels).mean(axis=1)
    if not convert and (rate != SAMPLE_RATE or channels != 1 or width != 2):
        raise AudioError(f"{path}: {rate} Hz, {channels} channel(s), {8 * width}-bit; expected {SAMPLE_RATE} Hz "
                         "mono 16-bit PCM")
    a = resample(a, rate)
    return np.clip(np.round(a), -32768, 32767).astype(np.int16), rate


def write_wav(path: Union[str, Path], pcm: np.ndarray) -> None:
    """Write 16 kHz mono 16-bit PCM to ``path``."""
    pcm = to_int16(pcm)
    with wave.open(str(path), "wb") as w:
        w.setnchannels(1)
        w.setsampwidth(2)
        w.setframerate(SAMPLE_RATE)
        w.writeframes(pcm.tobytes())


def white_noise(n: int, rng: np.random.Generator) -> np.ndarray:
    """``n`` samples of unit-variance Gaussian white noise."""
    return rng.standard_normal(int(n))


def clipped_fraction(pcm: np.ndarray) -> float:
    """Fraction of samples at (or within one step of) full scale."""
    a = np.asarray(pcm)
    if a.size == 0:
        return 0.0
    return float(np.mean(np.abs(a.astype(np.int32)) >= 32766))


def mix_at_snr(speech: np.ndarray, snr_db: Optional[float], rng: np.random.Generator, kind: str = "white",
               babble: Optional[np.ndarray] = None, pad_seconds: float = PAD_SECONDS) -> np.ndarray:
    """Speech plus noise at ``snr_db`` (module doc), padded with noise; int16 at 16 kHz.

    Args:
        speech: the clean utterance (int16 or float samples, int16 scale).
        snr_db: signal-to-noise ratio in dB; ``None`` adds no noise (padding is silence).
        rng: the generator the noise (and the babble offset) is drawn from.
        kind: ``white`` or ``babble``.
        babble: for ``babble``, a long track of several talkers to cut a random span from.
        pad_seconds: noise-only seconds before and after the utterance.

    Raises:
        ValueError: an unknown noise kind, or babble without a track.
    """
    if kind not in NOISE_KINDS:
        raise ValueError(f"noise kind {kind!r} is not one of {', '.join(NOISE_KINDS)}")
    s = np.asarray(speech, dtype=np.float64)
    pad = int(round(pad_seconds * SAMPLE_RATE))
    total = len(s) + 2 * pad
    out = np.zeros(total)
    out[pad:pad + len(s)] = s
    if snr_db is not None and len(s):
        if kind == "white":
            noise = white_noise(total, rng)
        else:
            if babble is None or len(babble) < 2:
                raise ValueError("babble noise needs a babble track")
            track = np.asarray(babble, dtype=np.float64)
            reps = int(np.ceil((total + len(track)) / len(track)))
            start = int(rng.integers(len(track)))
            noise = np.tile(track, reps)[start:start + total]
        p_speech = float(np.mean(s ** 2))
        p_noise = float(np.mean(noise[pad:pad + len(s)] ** 2)) or 1.0
        out += noise * np.sqrt(p_speech / (p_noise * 10.0 ** (float(snr_db) / 10.0)))
    return np.clip(np.round(out), -32768, 32767).astype(np.int16)
