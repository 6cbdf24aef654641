"""16 kHz PCM helpers of pearl_pomdp.asr.audio: SNR mixing, checks, WAV files."""
from __future__ import annotations

import wave

import numpy as np
import pytest

from pearl_pomdp.asr.audio import SAMPLE_RATE, AudioError, check_pcm, clipped_fraction, mix_at_snr, read_wav, write_wav


@pytest.mark.parametrize("snr", [30.0, 20.0, 5.0, 0.0, -5.0])
def test_mix_at_snr_gives_the_requested_snr(snr):
    rng = np.random.default_rng(1)
    t = np.arange(SAMPLE_RATE) / SAMPLE_RATE
    speech = (3000 * np.sin(2 * np.pi * 440 * t)).astype(np.int16)
    mixed = mix_at_snr(speech, snr, rng, pad_seconds=0.25).astype(np.float64)
    pad = SAMPLE_RATE // 4
    assert len(mixed) == len(speech) + 2 * pad
    noise = mixed[pad:pad + len(speech)] - speech
    measured = 10 * np.log10(np.mean(speech.astype(float) ** 2) / np.mean(noise ** 2))
    assert measured == pytest.approx(snr, abs=0.1)  # rounding to int16 is the only error
    # The padding is noise of the same level, not silence.
    assert np.std(mixed[:pad]) == pytest.approx(np.std(noise), rel=0.1)


def test_mix_without_noise_pads_with_silence_and_rejects_unknown_noise():
    speech = np.full(100, 1000, dtype=np.int16)
    out = mix_at_snr(speech, None, np.random.default_rng(0), pad_seconds=0.01)
    assert out[:160].tolist() == [0] * 160 and out[160:260].tolist() == [1000] * 100
    with pytest.raises(ValueError, match="noise kind 'pink'"):
        mix_at_snr(speech, 10, np.random.default_rng(0), kind="pink")
    with pytest.raises(ValueError, match="babble track"):
        mix_at_snr(speech, 10, np.random.default_rng(0), kind="babble")


def test_check_pcm_names_the_problem():
    with pytest.raises(AudioError, match="mic: sample rate 44100 Hz, expected 16000 Hz"):
        check_pcm(np.zeros(10, np.int16), 44100, "mic")
    with pytest.raises(AudioError, match=r"shape \(10, 2\)"):
        check_pcm(np.zeros((10, 2), np.int16), 16000, "mic")
    with pytest.raises(AudioError, match="NaN"):
        check_pcm(np.array([0.0, np.nan]), 16000, "mic")
    assert check_pcm(np.array([0.5, -1.0]), 16000, "x").tolist() == [16384, -32767]


def test_clipped_fraction_counts_full_scale_samples():
    a = np.array([0, 32767, -32768, 100], dtype=np.int16)
    assert clipped_fraction(a) == 0.5 and clipped_fraction(np.zeros(0)) == 0.0


def test_wav_round_trip_and_conversion(tmp_path):
    pcm = (np.arange(1600) % 200 * 50 - 5000).astype(np.int16)
    write_wav(tmp_path / "a.wav", pcm)
    back, rate = read_wav(tmp_path / "a.wav", convert=False)
    assert rate == 16000 and np.array_equal(back, pcm)
    # 8 kHz stereo: channels averaged, resampled to twice the samples.
    with wave.open(str(tmp_path / "b.wav"), "wb") as w:
        w.setnchannels(2), w.setsampwidth(2), w.setframerate(8000)
        w.writeframes(np.repeat(pcm[:800], 2).tobytes())
    conv, rate = read_wav(tmp_path / "b.wav")
    assert rate == 8000 and len(conv) == 1600
    with pytest.raises(AudioError, match="8000 Hz, 2 channel"):
        read_wav(tmp_path / "b.wav", convert=False)
    (tmp_path / "c.wav").write_bytes(b"RIFF1234WAVEjunk")
    with pytest.raises(AudioError, match="c.wav: not a PCM WAV file"):
        read_wav(tmp_path / "c.wav")
    with pytest.raises(AudioError, match="no such file"):
        read_wav(tmp_path / "missing.wav")
