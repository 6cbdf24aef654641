"""The domain recogniser (pocketsphinx on the keyword language model) and the VAD segmenter.

Audio is synthesised by espeak-ng and mixed with seeded white noise, so every case is
reproducible; decoding is whole-utterance with batch CMN, so a result does not depend on
the order of the tests.
"""
from __future__ import annotations

import numpy as np
import pytest

import pocketsphinx  # noqa: F401  (a missing install fails, it is not skipped)
import espeakng_loader  # noqa: F401  (a missing install fails, it is not skipped)

from pearl_pomdp.asr.audio import AudioError, mix_at_snr  # noqa: E402
from pearl_pomdp.asr.grammar import CHATTER, build_language_model, filler_sentences  # noqa: E402
from pearl_pomdp.asr.recognizer import Recognizer, UtteranceSegmenter, UtteranceTooLong  # noqa: E402
from pearl_pomdp.asr.synthesizer import synthesize  # noqa: E402
from pearl_pomdp.model.domain_yaml import load_domain  # noqa: E402
from pearl_pomdp.speech import KeywordFilter  # noqa: E402

from ros_helpers import DOMAIN  # noqa: E402


@pytest.fixture(scope="module")
def pearl():
    domain = load_domain(DOMAIN)
    return Recognizer(domain.keywords), KeywordFilter.from_domain(domain)


@pytest.mark.parametrize("said, symbol", [
    ("what time is it", "time"), ("yes", "yes"), ("no thank you", "no"),
    ("give me the weather forecast for tomorrow", "weather"), ("take me to physio please", "go"),
    ("hello pearl", "unknown"), ("thank you", "unknown"),
])
def test_keywords_at_20_db_and_chatter_is_unknown(pearl, said, symbol):
    recognizer, kf = pearl
    audio = mix_at_snr(synthesize(said, "clear"), 20.0, np.random.default_rng(3))
    rec = recognizer.recognise(audio)
    assert kf.classify(rec.text) == symbol, rec
    assert 0.0 < rec.confidence <= 1.0 and rec.decode_seconds > 0.0  # speed: bench/speech.py


def test_confidence_falls_with_the_snr(pearl):
    recognizer, _ = pearl
    clean = synthesize("what time is it", "clear")
    conf = {snr: np.mean([recognizer.recognise(mix_at_snr(clean, snr, np.random.default_rng(s))).confidence
                          for s in range(3)]) for snr in (30.0, 0.0)}
    assert conf[30.0] > conf[0.0] + 0.1, conf


def test_silence_noise_and_empty_audio_give_no_keyword(pearl):
    recognizer, kf = pearl
    rng = np.random.default_rng(5)
    for audio in (np.zeros(16000, np.int16), (rng.standard_normal(16000) * 800).astype(np.int16),
                  np.zeros(0, np.int16), np.zeros(10, np.int16)):
        rec = recognizer.recognise(audio)
        assert kf.classify(rec.text) == "unknown", rec
    assert recognizer.recognise(np.zeros(0, np.int16)).confidence == 0.0


def test_clipped_audio_is_decoded_and_reported(pearl):
    recognizer, kf = pearl
    loud = np.clip(synthesize("yes", "clear").astype(np.int32) * 40, -32768, 32767).astype(np.int16)
    rec = recognizer.recognise(loud)
    assert rec.clipped > recognizer.clip_warning


def test_ten_minute_utterance_and_wrong_rate_are_errors_without_decoding(pearl):
    recognizer, _ = pearl
    with pytest.raises(UtteranceTooLong, match="600.0 s is longer than the limit of 20 s"):
        recognizer.recognise(np.ones(600 * 16000, np.int16))  # refused before decoding
    with pytest.raises(AudioError, match="sample rate 8000 Hz"):
        recognizer.recognise(np.zeros(8000, np.int16), sample_rate=8000)


def test_language_model_has_keywords_fillers_and_no_forced_keyword():
    domain = load_domain(DOMAIN)
    import pocketsphinx

    probe = pocketsphinx.Decoder(loglevel="FATAL", lm=None)
    lm = build_language_model(domain.keywords, probe.lookup_word)
    assert lm.missing == []
    # physiotherapy is not in the CMU dictionary: spelt from physio + therapy.
    assert lm.dictionary["physiotherapy"] == probe.lookup_word("physio") + " " + probe.lookup_word("therapy")
    kf = KeywordFilter(domain.keywords)
    assert all(kf.classify(s) == "unknown" for s in filler_sentences(domain.keywords, count=300))
    assert "hello" in lm.dictionary and "\\1-grams:" in lm.arpa
    assert all(kf.classify(c) == "unknown" for c in CHATTER)


def test_default_model_is_the_large_one():
    rec = Recognizer(None)
    assert rec.language_model is None and rec.identity.endswith("default-en-us")


def test_segmenter_cuts_two_utterances_and_drops_an_overlong_one():
    rng = np.random.default_rng(0)
    one, two = synthesize("yes please", "clear"), synthesize("what time is it", "clear")
    gap = np.zeros(16000, np.int16)
    stream = np.concatenate([gap, one, gap, two, gap])
    seg = UtteranceSegmenter()
    out = []
    for i in range(0, len(stream), 1234):  # chunk size unrelated to the VAD frame
        out += seg.feed(stream[i:i + 1234])
    out += seg.flush()
    assert len(out) == 2 and seg.utterances == 2
    for got, sent in zip(out, (one, two)):
        assert abs(len(got) - len(sent)) < 0.6 * 16000
    long_seg = UtteranceSegmenter(max_seconds=1.0)
    speechy = np.concatenate([synthesize("give me the weather forecast for tomorrow", "slow")] * 2)
    res = long_seg.feed(np.concatenate([gap, speechy, gap])) + long_seg.flush()
    assert long_seg.too_long >= 1 and all(len(u) <= 16000 + 480 for u in res)
    del rng


def test_unwritable_cache_dir_falls_back_to_a_temporary_folder(tmp_path, monkeypatch):
    blocked = tmp_path / "file-not-dir"
    blocked.write_text("x")
    monkeypatch.setenv("PEARL_CACHE_DIR", str(blocked))  # mkdir under a file fails
    rec = Recognizer({"yes": ["yes"], "no": ["no"]})
    assert rec.language_model is not None and not any(blocked.parent.glob("file-not-dir/*"))
