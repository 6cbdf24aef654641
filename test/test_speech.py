"""Keyword filter: recogniser text → one Speech symbol (priority = keyword table order)."""
from pathlib import Path

import pytest

from pearl_pomdp.model.domain_yaml import load_domain
from pearl_pomdp.speech import KeywordFilter, normalise

PEARL = Path(__file__).resolve().parents[1] / "config" / "pearl.domain.yaml"


@pytest.fixture()
def pearl_filter():
    return KeywordFilter.from_domain(load_domain(PEARL))


@pytest.mark.parametrize("text,symbol", [
    ("Give me the weather forecast for tomorrow.", "weather"),   # the paper's example
    ("What time is it?", "time"),
    ("WHAT'S THE TIME", "time"),
    ("whether it rains", "weather"),                             # the recogniser's homophone
    ("yes, what time is it", "time"),                            # specific request beats yes/no
    ("Let's go!", "go"),
    ("take me to my appointment", "go"),
    ("no, not now", "no"),
    ("okay", "yes"),
    ("good morning", "unknown"),                                 # 'go' must not match inside 'good'
    ("I'm going", "unknown"),                                    # nor inside 'going'
    ("", "unknown"),                                             # a timeout closes the step with no text
])
def test_pearl_keywords(pearl_filter, text, symbol):
    assert pearl_filter.classify(text) == symbol


def test_unknown_text_is_counted_and_kept(pearl_filter):
    for text in ["hmm", "what time", "blah blah"]:
        pearl_filter.classify(text)
    assert pearl_filter.unknown_count == 2
    assert list(pearl_filter.unknown_texts) == ["hmm", "blah blah"]
    assert pearl_filter.counts == {"unknown": 2, "time": 1}


def test_priority_is_table_order_not_position_or_length():
    kf = KeywordFilter({"kitchen": ["kitchen"], "robot": ["go to", "go"]}, unknown_symbol="none")
    assert kf.classify("go to the kitchen") == "kitchen"         # a longest-match rule would say 'robot'
    kf2 = KeywordFilter({"robot": ["go to"], "kitchen": ["kitchen"]}, unknown_symbol="none")
    assert kf2.classify("go to the kitchen") == "robot"
    assert kf.matches("go to the kitchen") == [("kitchen", "kitchen", 3), ("robot", "go to", 0), ("robot", "go", 0)]


def test_phrases_match_whole_contiguous_words():
    kf = KeywordFilter({"time": ["what time"]})
    assert kf.classify("so what time is it") == "time"
    assert kf.classify("what is the time") == "unknown"
    assert normalise("  Don’t   GO!! ") == "don't go"


@pytest.mark.parametrize("keywords,problem", [
    ({"unknown": ["x"]}, "cannot have keywords"),
    ({"a": ["  ", "x"]}, "has no words"),
    ({"a": ["go"], "b": ["Go!"]}, "given for both 'a' and 'b'"),
    ({"a": "go"}, "must be a list"),
])
def test_bad_keyword_tables(keywords, problem):
    with pytest.raises(ValueError, match=problem):
        KeywordFilter(keywords)


def test_from_domain_needs_keywords():
    from pearl_pomdp.model.domain_yaml import parse_domain

    d = parse_domain("discount: 0.9\nfeatures: {X: [a]}\nmodalities: {M: [unknown]}\nactions: {A: {}}\n"
                     "observations: {default: {table: {'*': unknown}}}\nrewards: []\n")
    with pytest.raises(ValueError, match="has no 'keywords' section"):
        KeywordFilter.from_domain(d)
