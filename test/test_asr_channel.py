"""The measured channel: calibration counts, the content-hash cache, the JSON file, the sampler."""
from __future__ import annotations

import json

import numpy as np
import pytest

import pocketsphinx  # noqa: F401  (a missing install fails, it is not skipped)
import espeakng_loader  # noqa: F401  (a missing install fails, it is not skipped)

from pearl_pomdp.asr.channel import ChannelError, ChannelTable, MeasuredChannel, calibrate  # noqa: E402
from pearl_pomdp.asr.recognizer import Recognizer  # noqa: E402
from pearl_pomdp.model.domain_yaml import load_domain  # noqa: E402
from pearl_pomdp.speech import KeywordFilter  # noqa: E402

from ros_helpers import DOMAIN  # noqa: E402

UTTERANCES = {"time": ["what time is it"], "yes": ["yes please"], "unknown": ["hello pearl"]}


class CountingRecognizer:
    """The real recogniser, counting its decodes (to see the cache work)."""

    def __init__(self, inner):
        self.inner, self.identity, self.decodes = inner, inner.identity, 0

    def recognise(self, *args, **kwargs):
        self.decodes += 1
        return self.inner.recognise(*args, **kwargs)


@pytest.fixture(scope="module")
def measured(tmp_path_factory):
    import os

    cache = tmp_path_factory.mktemp("cache")
    old = os.environ.get("PEARL_CACHE_DIR")
    os.environ["PEARL_CACHE_DIR"] = str(cache)
    try:
        domain = load_domain(DOMAIN)
        rec = CountingRecognizer(Recognizer(domain.keywords))
        kf = KeywordFilter.from_domain(domain)
        table = calibrate(rec, kf, UTTERANCES, [30.0, -10.0], ["clear"], repeats=2, seed=0)
        first = rec.decodes
        again = calibrate(rec, kf, UTTERANCES, [30.0, -10.0], ["clear"], repeats=2, seed=0)
        yield table, again, first, rec.decodes - first, cache, kf
    finally:
        if old is None:
            os.environ.pop("PEARL_CACHE_DIR", None)
        else:
            os.environ["PEARL_CACHE_DIR"] = old


def test_calibration_counts_every_trial(measured):
    table, _, first, _, _, kf = measured
    assert first == 2 * 3 * 2  # SNRs x utterances x repeats
    for snr in (30.0, -10.0):
        for meant in UTTERANCES:
            cell = table.cells[table.key(snr)][meant]
            assert cell["n"] == 2 and sum(cell["counts"].values()) == 2
            assert all(kf.classify(text) == symbol for text, _, symbol in cell["samples"])
    # Clear speech at 30 dB is heard; at -10 dB the channel is measurably worse.
    assert table.accuracy(30.0) == 1.0
    assert table.accuracy(-10.0) < 1.0
    assert sum(table.probability("time", 30.0).values()) == pytest.approx(1.0)


def test_second_calibration_comes_from_the_cache(measured):
    table, again, _, second, cache, _ = measured
    assert second == 0
    assert again.cells == table.cells
    assert list((cache / "speech-channel").glob("*.json"))


def test_channel_file_round_trip_and_errors(measured, tmp_path):
    table = measured[0]
    table.save(tmp_path / "ch.json")
    back = ChannelTable.load(tmp_path / "ch.json")
    assert back.cells == table.cells and back.snr_db == [30.0, -10.0] and back.meta["repeats"] == 2
    with pytest.raises(ChannelError, match="no SNR 12 dB"):
        back.probability("time", 12.0)
    (tmp_path / "bad.json").write_text(json.dumps({"format": "other"}))
    with pytest.raises(ChannelError, match="bad.json: format"):
        ChannelTable.load(tmp_path / "bad.json")
    data = table.to_json()
    del data["cells"]["30"]["yes"]
    (tmp_path / "cut.json").write_text(json.dumps(data))
    with pytest.raises(ChannelError, match=r"cells.30.yes: missing"):
        ChannelTable.load(tmp_path / "cut.json")


def test_sampler_draws_recorded_outputs_with_the_measured_frequencies():
    cells = {"20": {"yes": {"n": 4, "counts": {"yes": 3, "unknown": 1},
                            "samples": [["yes", 0.9, "yes"], ["yes please", 0.8, "yes"], ["yeah", 0.7, "yes"],
                                        ["the", 0.1, "unknown"]]}},
             "0": {"yes": {"n": 2, "counts": {"unknown": 2}, "samples": [["", 0.0, "unknown"], ["a", 0.05, "unknown"]]}}}
    ch = MeasuredChannel(ChannelTable([20.0, 0.0], ["yes", "unknown"], ["yes"], cells))
    rng = np.random.default_rng(0)
    at20 = [ch.sample("yes", 20.0, rng)[2] for _ in range(2000)]
    assert at20.count("yes") / 2000 == pytest.approx(0.75, abs=0.03)
    at10 = [ch.sample("yes", 10.0, rng)[2] for _ in range(2000)]  # halfway: interpolated
    assert at10.count("yes") / 2000 == pytest.approx(0.375, abs=0.04)
    assert {ch.sample("yes", 50.0, rng)[0] for _ in range(200)} <= {"yes", "yes please", "yeah", "the"}
    with pytest.raises(ChannelError, match="no meant symbol 'go'"):
        ch.sample("go", 20.0, rng)


def test_fitted_confusion_is_the_dirichlet_posterior_mean():
    from pearl_pomdp.asr.channel import fitted_confusion

    cells = {"20": {"yes": {"n": 10, "counts": {"yes": 6, "no": 1, "unknown": 3}, "samples": []}}}
    table = ChannelTable([20.0], ["yes", "no", "unknown"], ["yes"], cells)
    c = fitted_confusion(table, 20.0, prior_strength=10.0)["yes"]
    assert c == pytest.approx({"yes": (10 + 6) / 20, "no": 1 / 20, "unknown": 3 / 20})
    assert fitted_confusion(table, 20.0, 0.0)["yes"] == pytest.approx({"yes": 0.6, "no": 0.1, "unknown": 0.3})
    with pytest.raises(ValueError, match="negative"):
        fitted_confusion(table, 20.0, -1.0)


def test_fitted_domain_loads_and_moves_speech_rows_only(measured, tmp_path):
    import yaml

    from pearl_pomdp.asr.channel import fit_observation_rows
    from pearl_pomdp.model.domain_yaml import parse_domain

    table = measured[0]
    designer = load_domain(DOMAIN).compile()
    data, changed = fit_observation_rows(DOMAIN, table, -10.0, prior_strength=5.0)
    fitted = parse_domain(yaml.safe_dump(data, sort_keys=False), "fitted").compile()
    assert changed > 0 and fitted.O.shape == designer.O.shape
    np.testing.assert_allclose(fitted.O.sum(axis=2), 1.0, atol=1e-8)
    speech = [designer.observations.index(o) for o in ("time", "weather", "go", "no", "yes", "unknown")]
    touch = [i for i in range(len(designer.observations)) if i not in speech]
    np.testing.assert_allclose(fitted.O[:, :, touch], designer.O[:, :, touch], atol=1e-8)
    assert np.abs(fitted.O[:, :, speech] - designer.O[:, :, speech]).max() > 0.01
    # An overwhelming prior keeps the designer's table.
    same, _ = fit_observation_rows(DOMAIN, table, -10.0, prior_strength=1e12)
    np.testing.assert_allclose(parse_domain(yaml.safe_dump(same, sort_keys=False), "same").compile().O,
                               designer.O, atol=1e-8)


def test_insertion_and_deletion_rates_count_the_confusion_by_hand():
    """Insertion: a keyword heard that was not said (chatter heard as a keyword, or another
    keyword); deletion: a said keyword heard as unknown. Counts and Wilson bounds by hand."""
    symbols = ["yes", "no", "go", "unknown"]
    cells = {"10": {
        "yes": {"n": 10, "counts": {"yes": 7, "no": 1, "unknown": 2}},      # 1 substitution, 2 deletions
        "go": {"n": 10, "counts": {"go": 8, "no": 2}},                      # 2 substitutions
        "unknown": {"n": 20, "counts": {"unknown": 17, "go": 2, "yes": 1}},  # 3 insertions from chatter
    }}
    table = ChannelTable([10.0], symbols, ["yes", "go", "unknown"], cells)
    assert table.confusion(10) == {"yes": {"yes": 7, "no": 1, "go": 0, "unknown": 2},
                                   "go": {"yes": 0, "no": 2, "go": 8, "unknown": 0},
                                   "unknown": {"yes": 1, "no": 0, "go": 2, "unknown": 17}}
    rates = table.error_rates(10)
    assert (rates["insertion"]["count"], rates["insertion"]["n"]) == (6, 40)
    assert (rates["insertion_from_chatter"]["count"], rates["insertion_from_chatter"]["n"]) == (3, 20)
    assert (rates["substitution"]["count"], rates["substitution"]["n"]) == (3, 20)
    assert (rates["deletion"]["count"], rates["deletion"]["n"]) == (2, 20)
    assert rates["insertion"]["rate"] == pytest.approx(0.15)
    # Wilson 95 % of 6/40: centre (0.15 + 1.96²/80)/(1 + 1.96²/40) = 0.1807, half-width 0.1101.
    lo, hi = rates["insertion"]["ci95"]
    assert lo == pytest.approx(0.0706, abs=5e-4) and hi == pytest.approx(0.2907, abs=5e-4)
