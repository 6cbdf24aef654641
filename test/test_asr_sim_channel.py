"""pearl_sim.speech_channel: the resident's utterance through recogniser / measured / word-error channels."""
from __future__ import annotations

import numpy as np
import pytest

import pocketsphinx  # noqa: F401  (a missing install fails, it is not skipped)
import espeakng_loader  # noqa: F401  (a missing install fails, it is not skipped)

from pearl_pomdp.asr.channel import ChannelTable  # noqa: E402
from pearl_pomdp.errors import SpecError  # noqa: E402
from pearl_pomdp.model.domain_yaml import load_domain  # noqa: E402
from pearl_pomdp.speech import KeywordFilter  # noqa: E402
from pearl_sim.speech_channel import Heard, make_speech_channel  # noqa: E402

from ros_helpers import DOMAIN  # noqa: E402


@pytest.fixture(scope="module")
def domain():
    return load_domain(DOMAIN)


def test_recogniser_channel_hears_her_at_30_db_and_not_at_minus_20(domain):
    kf = KeywordFilter.from_domain(domain)
    ch = make_speech_channel({"channel": "recogniser", "snr_db": 30}, domain.keywords)
    rng = np.random.default_rng(0)
    heard = ch.hear("time", "what time is it", "clear", rng)
    assert isinstance(heard, Heard) and kf.classify(heard.text) == "time" and heard.confidence > 0.1
    drowned = make_speech_channel({"channel": "recogniser", "snr_db": -20}, domain.keywords)
    assert drowned.recognizer is ch.recognizer  # one model per process
    assert [kf.classify(drowned.hear("time", "what time is it", "clear", rng).text) for _ in range(3)] != ["time"] * 3


def test_measured_channel_samples_the_file(domain, tmp_path):
    cells = {"20": {m: {"n": 1, "counts": {m: 1}, "samples": [[f"said {m}", 0.5, m]]} for m in ("time", "unknown")}}
    ChannelTable([20.0], ["time", "unknown"], ["time", "unknown"], cells).save(tmp_path / "ch.json")
    scenario = tmp_path / "s.yaml"
    scenario.write_text("{}")
    ch = make_speech_channel({"channel": "measured", "measured": "ch.json", "snr_db": 20}, domain.keywords, scenario)
    rng = np.random.default_rng(0)
    assert ch.hear("time", "what time is it", "clear", rng) == Heard("said time", 0.5)
    assert ch.hear("chatter", "hello pearl", None, rng) == Heard("said unknown", 0.5)


def test_word_error_channel_is_the_old_model(domain):
    ch = make_speech_channel({"channel": "word_error", "word_error_rate": 0.0}, domain.keywords)
    assert ch.hear("yes", "yes please", None, np.random.default_rng(0)) == Heard("yes please", 1.0)
    assert make_speech_channel(None, domain.keywords).name == "word_error"


@pytest.mark.parametrize("spec, field", [
    ({"channel": "sphinx"}, "speech.channel"), ({"channel": "recogniser", "snr_db": "loud"}, "speech.snr_db"),
    ({"channel": "recogniser", "noise": "pink"}, "speech.noise"), ({"channel": "measured"}, "speech.measured"),
    ({"channel": "measured", "measured": "nope.json"}, "speech.measured"), ({"snr": 3}, "speech.snr"),
])
def test_bad_speech_fields_name_the_field(domain, spec, field):
    with pytest.raises(SpecError, match=field.replace(".", r"\.")):
        make_speech_channel(spec, domain.keywords, "scenario.yaml")


def test_babble_noise_is_talkers_at_the_requested_snr(domain):
    from pearl_pomdp.asr.audio import mix_at_snr
    from pearl_pomdp.asr.channel import babble_track
    from pearl_pomdp.asr.synthesizer import synthesize

    track = babble_track()
    assert len(track) > 2 * 16000 and np.std(track) > 100
    speech = synthesize("yes please", "clear")
    mixed = mix_at_snr(speech, 10.0, np.random.default_rng(0), "babble", track, pad_seconds=0.3).astype(float)
    noise = mixed[4800:4800 + len(speech)] - speech
    assert 10 * np.log10(np.mean(speech.astype(float) ** 2) / np.mean(noise ** 2)) == pytest.approx(10.0, abs=0.2)
    kf = KeywordFilter.from_domain(domain)
    ch = make_speech_channel({"channel": "recogniser", "snr_db": 30, "noise": "babble"}, domain.keywords)
    assert kf.classify(ch.hear("yes", "yes please", "clear", np.random.default_rng(1)).text) == "yes"
