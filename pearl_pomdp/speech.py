"""Keyword filter: the recogniser's text → one Speech observation symbol.

The paper applies "a keyword filter to the output of the speech recognizer
(e.g. 'Give me the weather forecast for tomorrow.' → SpeechKeyword=weather)".
:class:`KeywordFilter` does exactly that, with a rule a designer can predict:

1. The text is lower-cased, curly quotes are straightened and everything except
   letters, digits and apostrophes becomes a word break: ``"What's the TIME?"``
   → ``what's the time``.
2. A keyword is a word or a phrase of several words; it matches when its words
   occur *contiguously and whole* in the text (``"go"`` does not match ``"good"``,
   ``"what time"`` does not match ``"what is the time"``).
3. **Priority is the order of the symbols** in the keyword table: the first
   symbol (in table order) with any matching keyword wins, wherever in the text
   it occurs. Designers list specific symbols before generic ones, so "go to the
   kitchen" is ``kitchen`` and not the generic ``go``, and "yes, what time is it"
   is ``time``. (A longest-match rule would let the two-word "go to" beat the
   one-word "kitchen".)
4. No keyword at all → ``unknown_symbol``; the filter counts it
   (:attr:`KeywordFilter.unknown_count`) and keeps the last few texts so that
   nothing is silently dropped (docs/design.md §9). Empty text is also unknown: that is
   what a recogniser returns when the timeout closes a step.
"""
from __future__ import annotations

import math
import re
from collections import deque
from dataclasses import dataclass
from typing import Deque, Dict, Iterator, List, Mapping, Optional, Sequence, Tuple

__all__ = ["KeywordFilter", "normalise", "tokens", "parse_speech_message", "speech_message", "Utterance",
           "utterance"]

_QUOTES = str.maketrans({"\u2019": "'", "\u2018": "'", "\u02bc": "'", "`": "'"})
_BREAK = re.compile(r"[^0-9a-z']+")


def normalise(text: str) -> str:
    """Lower-case, straighten quotes, and turn every non-word character into one space."""
    t = str(text).translate(_QUOTES).lower()
    t = _BREAK.sub(" ", t)
    # Apostrophes are part of a word only inside it ("let's"), not as quotes around it.
    return " ".join(w.strip("'") for w in t.split() if w.strip("'"))


def parse_speech_message(data: str) -> Tuple[str, float]:
    """``(text, confidence)`` of a ``/pearl/speech`` message's data; never raises.

    Bags recorded before the typed ``pearl_interfaces/msg/RecognisedSpeech`` (:class:`Utterance`) hold
    the recogniser's JSON object ``{"text": "...", "confidence": 0.83}`` in a ``std_msgs/String``;
    any other sender of a String may send plain text, which means confidence 1.0. Data counts as the JSON
    form only when it is an object with a string ``text`` and a number ``confidence`` in
    [0, 1] (not a bool); anything else — other JSON, a malformed object, a confidence out
    of range — is taken as plain text with confidence 1.0, so nothing a person could have
    said is lost.
    """
    import json

    text = data if isinstance(data, str) else str(data)
    stripped = text.strip()
    if stripped.startswith("{") and stripped.endswith("}"):
        try:
            obj = json.loads(stripped)
        except (ValueError, RecursionError):
            return text, 1.0
        if isinstance(obj, dict) and isinstance(obj.get("text"), str):
            conf = obj.get("confidence")
            if (isinstance(conf, (int, float)) and not isinstance(conf, bool) and math.isfinite(conf)
                    and 0.0 <= conf <= 1.0):
                return obj["text"], float(conf)
    return text, 1.0


@dataclass(frozen=True)
class Utterance:
    """What a speech recogniser heard, as the typed ``/pearl/speech`` message carries it
    (``pearl_interfaces/msg/RecognisedSpeech``).

    Attributes:
        text: the recognised words (``""``: nothing understood).
        confidence: the recogniser's confidence in [0, 1].
        symbol: the speech symbol the recogniser already mapped the text to; ``""`` (the usual
            case): the tracker's keyword filter maps :attr:`text`.
    """

    text: str
    confidence: float = 1.0
    symbol: str = ""


def utterance(text: str, confidence: float, symbol: str = "") -> Utterance:
    """An :class:`Utterance` from a typed message's fields; never raises. A confidence that is not a
    number in [0, 1] (NaN, 7.0) is taken as 1.0, as :func:`parse_speech_message` takes a malformed one:
    nothing a person could have said is lost."""
    conf = float(confidence) if isinstance(confidence, (int, float)) and not isinstance(confidence, bool) else 1.0
    if not (math.isfinite(conf) and 0.0 <= conf <= 1.0):
        conf = 1.0
    return Utterance(str(text), conf, str(symbol).strip())


def speech_message(text: str, confidence: float) -> str:
    """The JSON data of a speech ``std_msgs/String`` as the recogniser published it before the typed
    message (inverse of :func:`parse_speech_message`; the simulator's worlds still write it)."""
    import json

    return json.dumps({"text": str(text), "confidence": round(min(1.0, max(0.0, float(confidence))), 4)})


def tokens(text: str) -> List[str]:
    """The words of ``text`` after :func:`normalise`."""
    return normalise(text).split()


class KeywordFilter:
    """Maps recognised text to a Speech symbol (see the module docstring for the rule).

    Args:
        keywords: symbol → list of keywords/phrases; the mapping's order is the priority.
        unknown_symbol: returned when no keyword matches (must not be a key of ``keywords``).
        keep_unknown: how many unmatched texts to remember in :attr:`unknown_texts`.

    Attributes:
        unknown_count: how many texts matched no keyword.
        unknown_texts: the last ``keep_unknown`` of them (for logs and replay reports).
        counts: symbol → how many texts were classified as it (unknown included).

    Raises:
        ValueError: an empty keyword, a keyword that normalises to nothing, the unknown
            symbol used as a key, or the same phrase given for two symbols.
    """

    def __init__(self, keywords: Mapping[str, Sequence[str]], unknown_symbol: str = "unknown", keep_unknown: int = 20):
        if unknown_symbol in keywords:
            raise ValueError(f"the unknown symbol {unknown_symbol!r} cannot have keywords")
        self.unknown_symbol = unknown_symbol
        self._table: List[Tuple[str, List[Tuple[str, ...]]]] = []
        owner: Dict[Tuple[str, ...], str] = {}
        for symbol, words in keywords.items():
            if isinstance(words, str):
                raise ValueError(f"keywords of {symbol!r} must be a list of strings, got the string {words!r}")
            phrases = []
            for w in words:
                phrase = tuple(tokens(w))
                if not phrase:
                    raise ValueError(f"keyword {w!r} of symbol {symbol!r} has no words")
                if phrase in owner and owner[phrase] != symbol:
                    raise ValueError(f"keyword {' '.join(phrase)!r} is given for both {owner[phrase]!r} and {symbol!r}")
                owner[phrase] = symbol
                phrases.append(phrase)
            self._table.append((str(symbol), phrases))
        self.unknown_count = 0
        self.unknown_texts: Deque[str] = deque(maxlen=keep_unknown)
        self.counts: Dict[str, int] = {}

    @classmethod
    def from_domain(cls, domain, unknown_symbol: Optional[str] = None) -> "KeywordFilter":
        """The filter of a :class:`~pearl_pomdp.model.factored.FactoredDomain` (its ``keywords:`` section).

        ``unknown_symbol`` defaults to the ``unknown`` symbol of the domain's first speech input
        (``modalities.<M>.input.unknown``; :mod:`pearl_pomdp.channels`).

        Raises:
            ValueError: the domain has no keywords, or no such unknown symbol.
        """
        if not domain.keywords:
            raise ValueError(f"domain {domain.name!r} ({domain.source}) has no 'keywords' section")
        symbol = unknown_symbol or next((c.unknown for c in getattr(domain, "inputs", ())
                                         if c.kind == "speech" and c.unknown), None)
        if symbol is None:
            raise ValueError(f"domain {domain.name!r} ({domain.source}) declares no unknown symbol for unmatched "
                             "speech (modalities.<Speech>.input.unknown)")
        if symbol not in domain.observations:
            raise ValueError(f"domain {domain.name!r} has no observation symbol {symbol!r} for unmatched speech")
        return cls(domain.keywords, unknown_symbol=symbol)

    @property
    def symbols(self) -> List[str]:
        """Symbols in priority order (the unknown symbol last)."""
        return [s for s, _ in self._table] + [self.unknown_symbol]

    def matches(self, text: str) -> List[Tuple[str, str, int]]:
        """Every ``(symbol, keyword, word position)`` found in ``text``, in priority order (for explanations)."""
        words = tokens(text)
        found = []
        for symbol, phrases in self._table:
            for phrase in phrases:
                for pos in _find(words, phrase):
                    found.append((symbol, " ".join(phrase), pos))
        return found

    def classify(self, text: str) -> str:
        """The Speech symbol of ``text``: the highest-priority symbol with a matching keyword, else unknown."""
        words = tokens(text)
        for symbol, phrases in self._table:
            if any(next(_find(words, p), None) is not None for p in phrases):
                self.counts[symbol] = self.counts.get(symbol, 0) + 1
                return symbol
        self.unknown_count += 1
        self.unknown_texts.append(str(text))
        self.counts[self.unknown_symbol] = self.counts.get(self.unknown_symbol, 0) + 1
        return self.unknown_symbol

    def __call__(self, text: str) -> str:
        return self.classify(text)


def _find(words: Sequence[str], phrase: Tuple[str, ...]) -> Iterator[int]:
    n = len(phrase)
    for i in range(len(words) - n + 1):
        if tuple(words[i:i + n]) == phrase:
            yield i
