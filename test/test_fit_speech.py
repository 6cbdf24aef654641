"""`pearl fit DOMAIN --speech CHANNEL.json --snr DB`: the speech rows through a measured confusion."""
import json

import numpy as np
import pytest

from pearl_pomdp.asr.channel import ChannelTable
from pearl_pomdp.errors import PearlError
from pearl_pomdp.fit_speech import speech_rows, write_speech_fitted
from pearl_pomdp.model.domain_yaml import load_domain

DOMAIN = "config/pearl.domain.yaml"
SYMBOLS = ["time", "weather", "go", "no", "yes", "unknown"]


def _channel():
    """At 10 dB: 'yes' heard as 'no' 2 times in 10, chatter heard as 'go' once in 10; the rest perfect."""
    cells = {m: {"n": 10, "counts": {m: 10}} for m in SYMBOLS}
    cells["yes"] = {"n": 10, "counts": {"yes": 8, "no": 2}}
    cells["unknown"] = {"n": 10, "counts": {"unknown": 9, "go": 1}}
    return ChannelTable([10.0], SYMBOLS, SYMBOLS, {"10": cells}, {"noise": "babble", "recogniser": "test"})


def test_rows_pass_through_the_confusion_by_hand(tmp_path):
    """Prior strength 0: Ĉ(yes|yes) = 0.8, Ĉ(no|yes) = 0.2; unknown kept (chatter share 0)."""
    before = load_domain(DOMAIN)
    out, rows = write_speech_fitted(DOMAIN, _channel(), 10, tmp_path / "f.yaml", prior_strength=0.0)
    after = load_domain(out)
    z = {s: i for i, s in enumerate(before.observations)}
    changed = 0
    for a, (b, f) in enumerate(zip(before._observations, after._observations)):
        for combo in np.ndindex(*b.table.shape[:-1]):
            r, r2 = b.table[combo], f.table[combo]
            expected = r.copy()
            expected[z["yes"]] = 0.8 * r[z["yes"]]
            expected[z["no"]] = r[z["no"]] + 0.2 * r[z["yes"]]
            assert r2 == pytest.approx(expected, abs=1e-9), (before.actions[a], combo)
            changed += int(r[z["yes"]] > 0)
    assert len(rows) == changed > 20
    # The designer's text is unchanged above the fitted section; a replaced row is a comment.
    text, original = out.read_text(), open(DOMAIN).read()
    from pearl_pomdp.fit import FITTED_MARKER

    assert text[:text.index(FITTED_MARKER)] == original[:original.index(FITTED_MARKER)]
    line = next(l for l in text.splitlines() if l.startswith('      "yes":') and "# speech: babble noise at 10 dB" in l)
    assert ", was {" in line and "fitted: n=" in line     # the row it replaces, and the one that one replaced
    # Transitions fitted by `pearl fit` are kept.
    assert np.array_equal(before.compile().T, after.compile().T)


def test_chatter_share_passes_unknown_through_the_chatter_row():
    domain = load_domain(DOMAIN)
    a = domain.actions.index("RingDoorBell")
    no_row = domain._observations[a].table[domain.features[domain._observations[a].parents[0]].values.index("no")]
    z = {s: i for i, s in enumerate(domain.observations)}
    rows = {(r.action, r.row): r for r in speech_rows(domain, _channel(), 10, prior_strength=0.0, chatter_share=0.5)}
    after = rows[("RingDoorBell", "no")].after
    assert after["go"] == pytest.approx(0.5 * 0.1 * no_row[z["unknown"]], abs=1e-9)
    assert after["unknown"] == pytest.approx(no_row[z["unknown"]] * (1 - 0.05), abs=1e-9)
    assert sum(after.values()) == pytest.approx(1.0)


def test_bad_channel_or_operating_point_is_one_clear_error(tmp_path, capsys):
    from pearl_pomdp.cli import main

    domain = load_domain(DOMAIN)
    with pytest.raises(PearlError, match=r"--snr 20: the channel measured 10 dB"):
        speech_rows(domain, _channel(), 20)
    other = ChannelTable([10.0], ["yes", "unknown"], ["yes"], {"10": {"yes": {"n": 1, "counts": {"yes": 1}}}})
    with pytest.raises(PearlError, match="are not the speech symbols of pearl"):
        speech_rows(domain, other, 10)
    assert main(["fit", DOMAIN, "--speech", "config/speech/pearl_channel_babble.json", "--out",
                 str(tmp_path / "x.yaml")]) == 2
    assert "--snr: --speech needs the operating point" in capsys.readouterr().err
    assert main(["fit", DOMAIN, "--speech", "config/speech/pearl_channel_babble.json", "--snr", "10",
                 "--out", str(tmp_path / "b.yaml"), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["noise"] == "babble" and report["snr_db"] == 10 and len(report["rows"]) > 20
    load_domain(tmp_path / "b.yaml")
