"""parse_speech_message: the /pearl/speech contract (plain text = confidence 1.0, or JSON)."""
from __future__ import annotations

import pytest

from pearl_pomdp.speech import parse_speech_message, speech_message

CASES = [
    ("what time is it", ("what time is it", 1.0)),
    ('{"text": "yes please", "confidence": 0.83}', ("yes please", 0.83)),
    ('  {"text": "no", "confidence": 0} ', ("no", 0.0)),
    ('{"text": "no", "confidence": 1}', ("no", 1.0)),
    ('{"text": "x", "confidence": 1.5}', ('{"text": "x", "confidence": 1.5}', 1.0)),     # out of range
    ('{"text": "x", "confidence": -0.1}', ('{"text": "x", "confidence": -0.1}', 1.0)),
    ('{"text": "x", "confidence": true}', ('{"text": "x", "confidence": true}', 1.0)),   # bool is not a number
    ('{"text": "x", "confidence": NaN}', ('{"text": "x", "confidence": NaN}', 1.0)),
    ('{"text": "x"}', ('{"text": "x"}', 1.0)),                                           # no confidence
    ('{"text": 3, "confidence": 0.5}', ('{"text": 3, "confidence": 0.5}', 1.0)),         # text not a string
    ('{not json}', ('{not json}', 1.0)),
    ('["yes", 0.5]', ('["yes", 0.5]', 1.0)),
    ("", ("", 1.0)),
]


@pytest.mark.parametrize("data, expected", CASES)
def test_parse_speech_message(data, expected):
    assert parse_speech_message(data) == expected


def test_parse_never_raises_on_hostile_input():
    for data in ("{" * 100000 + "}" * 100000, "{\"text\": \"" + "a" * 10 ** 6 + "\", \"confidence\": 0.5}", "\x00{}"):
        text, conf = parse_speech_message(data)
        assert isinstance(text, str) and 0.0 <= conf <= 1.0


def test_speech_message_round_trips_and_clamps():
    assert parse_speech_message(speech_message("what time is it", 0.456789)) == ("what time is it", 0.4568)
    assert parse_speech_message(speech_message("yes", 7.0)) == ("yes", 1.0)
