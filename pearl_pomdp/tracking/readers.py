"""Input readers: one class per input kind turns an input message into an observation symbol,
by the rules of :mod:`pearl_pomdp.tracking`'s module doc ("Inputs → observation symbols").
:data:`READERS` is the one place the core switches on an input's kind; :func:`input_readers`
builds a reader for every input of a model.
"""
from __future__ import annotations

from typing import Any, Dict, Mapping, Optional, Sequence, Tuple, Type

from pearl_pomdp.channels import InputChannel, NumberDiscretiser
from pearl_pomdp.model.pomdp import Pomdp
from pearl_pomdp.speech import KeywordFilter, Utterance, parse_speech_message

__all__ = ["InputReader", "SpeechReader", "SymbolReader", "NumberReader", "READERS", "input_readers"]

#: What :meth:`InputReader.read` returns: ``(symbol or None, how it was heard, text, confidence)``
#: (see :attr:`pearl_pomdp.tracking.InputOutcome.heard`).
Reading = Tuple[Optional[str], str, str, float]


class InputReader:
    """One input: its channel, the symbols it may carry and how many messages were invalid."""

    def __init__(self, channel: InputChannel) -> None:
        self.channel = channel
        self.allowed = frozenset(channel.symbols)
        self.reset()

    @classmethod
    def for_input(cls, channel: InputChannel, keywords: Mapping[str, Sequence[str]],
                  keyword_filter: Optional[KeywordFilter], confidence_floor: float) -> "InputReader":
        """The reader of ``channel`` (the arguments as :func:`input_readers`'; a kind takes what it needs)."""
        return cls(channel)

    def reset(self) -> None:
        """Zero the counts (and forget what a reading remembers)."""
        self.invalid = 0

    def counts(self) -> Dict[str, int]:
        """This input's own counters (``invalid_<input>``, ``unchanged_<input>``)."""
        return {f"invalid_{self.channel.name}": self.invalid}

    def read(self, data: Any) -> Reading:
        """One message of this input (see :meth:`pearl_pomdp.tracking.BeliefTracker.on_input`)."""
        raise NotImplementedError


class SymbolReader(InputReader):
    """A ``symbol`` input: the string must be one of its symbols (blanks around it ignored)."""

    def read(self, data: Any) -> Reading:
        text = str(data)
        symbol = text.strip()
        if symbol not in self.allowed:
            self.invalid += 1
            return None, "invalid", text, 1.0
        return symbol, "symbol", text, 1.0


class SpeechReader(InputReader):
    """A ``speech`` input: a symbol as itself, other text through the keyword filter, a keyword
    below ``confidence_floor`` as the unknown symbol.

    Args:
        keyword_filter: the filter over the input's symbols (``None``: text must be a symbol).
    """

    def __init__(self, channel: InputChannel, keyword_filter: Optional[KeywordFilter], confidence_floor: float):
        self.keyword_filter, self.confidence_floor = keyword_filter, float(confidence_floor)
        super().__init__(channel)

    @classmethod
    def for_input(cls, channel: InputChannel, keywords: Mapping[str, Sequence[str]],
                  keyword_filter: Optional[KeywordFilter], confidence_floor: float) -> "InputReader":
        own = {z: list(keywords[z]) for z in keywords if z in channel.symbols}
        # No unknown symbol: text without a keyword classifies as "" (no symbol: invalid).
        return cls(channel, keyword_filter if keyword_filter is not None else (
            KeywordFilter(own, unknown_symbol=channel.unknown or "") if own else None), confidence_floor)

    def reset(self) -> None:
        super().reset()
        self.no_keyword = 0
        self.low_confidence = 0

    def read(self, data: Any) -> Reading:
        if isinstance(data, Utterance):   # a symbol the recogniser mapped is taken as heard
            text, confidence = data.text, data.confidence
            symbol, heard = self.classify((data.symbol if data.symbol in self.allowed else "") or text, confidence)
        else:
            text, confidence = parse_speech_message(str(data))
            symbol, heard = self.classify(text, confidence)
        return symbol, heard, text, confidence

    def classify(self, text: str, confidence: float = 1.0) -> Tuple[Optional[str], str]:
        """``(symbol or None, how it was heard)`` of recognised text."""
        stripped = text.strip()
        keyword_filter = self.keyword_filter
        if stripped in self.allowed:
            symbol, heard = stripped, "symbol"
        elif keyword_filter is not None:
            symbol = keyword_filter.classify(text)
            heard = "no_keyword" if symbol == keyword_filter.unknown_symbol else "keyword"
            if heard == "no_keyword":
                self.no_keyword += 1
        else:
            self.invalid += 1
            return None, "invalid"
        unknown = keyword_filter.unknown_symbol if keyword_filter is not None else None
        if heard in ("symbol", "keyword") and confidence < self.confidence_floor and unknown \
                and symbol != unknown:
            self.low_confidence += 1
            symbol, heard = unknown, "low_confidence"
        if symbol not in self.allowed:
            self.invalid += 1
            return None, "invalid"
        return symbol, heard


class NumberReader(InputReader):
    """A ``number`` input: the reading's bin, with hysteresis; with ``report: change`` a reading
    that keeps the symbol is ``"unchanged"`` (no observation); one of its symbols as text is taken."""

    def __init__(self, channel: InputChannel) -> None:
        self.discretiser = NumberDiscretiser(channel)
        super().__init__(channel)

    def reset(self) -> None:
        super().reset()
        self.unchanged = 0
        self.last: Optional[str] = None
        self.discretiser.reset()

    def counts(self) -> Dict[str, int]:
        return {**super().counts(), f"unchanged_{self.channel.name}": self.unchanged}

    def read(self, data: Any) -> Reading:
        text = data if isinstance(data, str) else str(data)
        if isinstance(data, str) and data.strip() in self.allowed:
            symbol = data.strip()
            # The hysteresis goes on from the symbol given (the next reading may keep it).
            self.discretiser.current = [b.symbol for b in self.channel.bins].index(symbol)
            self.last = symbol
            return symbol, "symbol", text, 1.0
        value: Optional[float]
        try:
            value = float(data)   # a number, or a number as text
        except (TypeError, ValueError):
            value = None
        read = self.discretiser.read(value) if value is not None else None
        if read is None:
            self.invalid += 1
            return None, "invalid", text, 1.0
        if self.channel.report == "change" and read == self.last:
            self.unchanged += 1
            return read, "unchanged", text, 1.0
        self.last = read
        return read, "number", text, 1.0


#: The reader class of each input kind (:data:`pearl_pomdp.channels.KINDS`).
READERS: Dict[str, Type[InputReader]] = {"speech": SpeechReader, "symbol": SymbolReader, "number": NumberReader}


def input_readers(model: Pomdp, channels: Sequence[InputChannel], keywords: Mapping[str, Sequence[str]],
                  keyword_filter: Optional[KeywordFilter] = None,
                  confidence_floor: float = 0.0) -> Dict[str, InputReader]:
    """Input name → its reader, in the order of ``channels``.

    Args:
        model: the compiled :class:`~pearl_pomdp.model.pomdp.Pomdp`.
        channels: the inputs (:class:`~pearl_pomdp.channels.InputChannel`), each with its own name.
        keywords: the domain's ``keywords:`` (symbol → phrases), or ``{}``.
        keyword_filter: a ready keyword filter for every speech input (default: the domain's
            keywords over the input's symbols, with its unknown symbol).
        confidence_floor: speech below this recogniser confidence counts as the unknown symbol.

    Raises:
        ValueError: two inputs with one name, or an input symbol the model does not have.
    """
    symbols = set(model.observations)
    out: Dict[str, InputReader] = {}
    for c in channels:
        if c.name in out:
            raise ValueError(f"two inputs are called {c.name!r} (modalities {out[c.name].channel.modality} "
                             f"and {c.modality})")
        missing = [z for z in c.symbols if z not in symbols]
        if missing:
            raise ValueError(f"input {c.name!r} carries {missing[0]!r}, which is not an observation of {model.name}")
        out[c.name] = READERS[c.kind].for_input(c, keywords, keyword_filter, confidence_floor)
    return out
