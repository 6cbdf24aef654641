"""Input channels: how each observation modality of a domain reaches the belief tracker.

A factored domain declares, for each modality, the channel its symbols arrive on
(``modalities.<Modality>.input`` in the domain file; docs/domain-format.md, "Inputs")::

    Battery:
      symbols: [battery_low, battery_ok]
      input: {kind: number, topic: /battery_state, type: sensor_msgs/msg/BatteryState,
              field: percentage, range: [0, 1], hysteresis: 0.05,
              bins: {battery_low: [0, 0.2], battery_ok: [0.2, 1]}}

Three kinds of channel:

* ``speech``: recognised text. Text that is itself a symbol of the modality is that symbol;
  other text goes through the domain's keyword filter (:class:`pearl_pomdp.speech.KeywordFilter`,
  restricted to the modality's symbols); text with no keyword is the channel's ``unknown``
  symbol (or invalid when it declares none).
* ``symbol``: each message is one symbol of the modality (a touchscreen button, a landmark);
  anything else is invalid.
* ``number``: each message carries a number, discretised into the symbol of the declared bin
  it falls in (:class:`NumberDiscretiser`), with hysteresis: the channel leaves its current bin
  only when the value is more than ``hysteresis`` outside it, so a battery level dithering at a
  boundary does not flap between ``low`` and ``ok``. With ``report: change`` (the default) an
  observation is made only when the symbol changes (the first reading always is one): a
  battery publishing ten times a second must not close every step of the dialogue.

This module is ROS-free: it parses and checks the declarations (errors name the file, the
field and what is wrong) and does the number → symbol step. Which ROS message types carry
each kind, and how a number is read out of them, is the ``belief_tracker`` node's business
(:mod:`pearl_pomdp.nodes.channel_messages`). The tracker subscribes to exactly the channels
a domain declares; there is no list of channels in the code.

Where a domain says nothing (a modality written as a plain list of symbols, as in files
older than channels), the channel is generic: named after the modality in lower case, on
topic ``/pearl/<name>`` as ``std_msgs/msg/String``; kind ``speech`` when the domain's
``keywords:`` name a symbol of the modality, else ``symbol``; a speech channel's ``unknown``
symbol is its one symbol without keywords (none when it has zero or several). A flat model
(no domain) has one channel, ``observation`` on ``/pearl/observation``, carrying every symbol.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import Any, Callable, Dict, List, Mapping, Optional, Sequence, Tuple

__all__ = ["KINDS", "REPORTS", "RELIABILITIES", "Bin", "InputChannel", "NumberDiscretiser", "parse_input",
           "default_channel", "flat_channels", "check_topics", "DEFAULT_TOPIC_PREFIX", "TEXT_TYPE", "SPEECH_TYPE",
           "SPEECH_TYPES"]

#: The kinds of input channel.
KINDS = ("speech", "symbol", "number")
#: When a number channel makes an observation: on a change of its symbol, or on every reading.
REPORTS = ("change", "every")
#: The reliability a channel's subscription asks for (``best_effort`` matches sensor drivers).
RELIABILITIES = ("reliable", "best_effort")
#: Namespace of a channel's topic when the domain names none.
DEFAULT_TOPIC_PREFIX = "/pearl/"
#: The message type of a symbol channel when the domain names none (and of a modality's generic channel).
TEXT_TYPE = "std_msgs/msg/String"
#: The message type of a declared speech channel when the domain names none: what the recogniser
#: node publishes (text, confidence, symbol).
SPEECH_TYPE = "pearl_interfaces/msg/RecognisedSpeech"
#: The types a speech channel reads: the typed message, or plain text (a bag recorded before it
#: holds the recogniser's JSON in a String; a hand-made publisher may send bare text).
SPEECH_TYPES = (SPEECH_TYPE, TEXT_TYPE)
#: Keys an ``input:`` mapping may have.
INPUT_KEYS = ("kind", "topic", "type", "field", "qos", "depth", "unknown", "silence", "bins", "range", "hysteresis",
              "report")

_TOPIC = re.compile(r"^/?[A-Za-z_~{][A-Za-z0-9_{}]*(/[A-Za-z_][A-Za-z0-9_]*)*$")
_TYPE = re.compile(r"^[A-Za-z][A-Za-z0-9_]*/msg/[A-Z][A-Za-z0-9]*$")
_FIELD = re.compile(r"^[a-z_][a-z0-9_]*(\.[a-z_][a-z0-9_]*)*$")


@dataclass(frozen=True)
class Bin:
    """One bin of a number channel: values in ``[low, high)`` are ``symbol`` (the top bin includes ``high``)."""

    symbol: str
    low: float
    high: float


@dataclass(frozen=True)
class InputChannel:
    """How one modality's symbols reach the tracker.

    Attributes:
        name: the input's name (the modality's, lower-cased): :meth:`BeliefTracker.on_input`'s
            key, the node's parameter prefix ``inputs.<name>.*`` and the counters' suffix.
        modality: the domain's modality (``Speech``).
        kind: ``speech``, ``symbol`` or ``number``.
        symbols: the observation symbols it carries, in the modality's order.
        topic: the ROS topic the node subscribes to (a node parameter can remap it).
        type: the ROS message type name (``std_msgs/msg/String``); the node checks it is one it reads.
        field: a number channel's message field (``percentage``); ``""``: the type's usual one.
        qos: the subscription's reliability, ``reliable`` or ``best_effort``.
        depth: the subscription's keep-last queue depth.
        unknown: a speech channel's symbol for text without a keyword (``None``: such text is invalid).
        silence: the symbol a step closes with when nothing arrives within the tracker's
            ``step_timeout`` (declared on at most one channel of a domain; else ``None``).
        bins: a number channel's bins, lowest first (they tile :attr:`range`).
        range: a number channel's ``(low, high)``; readings outside it are invalid.
        hysteresis: how far outside its bin a reading must be before the symbol changes.
        report: a number channel's ``change`` (observe only a new symbol) or ``every``.
        declared: False for the generic channel of a modality that declares no ``input:``.
    """

    name: str
    modality: str
    kind: str
    symbols: Tuple[str, ...]
    topic: str
    type: str = TEXT_TYPE
    field: str = ""
    qos: str = "reliable"
    depth: int = 20
    unknown: Optional[str] = None
    silence: Optional[str] = None
    bins: Tuple[Bin, ...] = ()
    range: Optional[Tuple[float, float]] = None
    hysteresis: float = 0.0
    report: str = "change"
    declared: bool = True

    def bin_of(self, value: float) -> Optional[int]:
        """The index of the bin holding ``value`` (``None`` outside :attr:`range` or not a number)."""
        if self.range is None or not math.isfinite(value) or not self.range[0] <= value <= self.range[1]:
            return None
        for i, b in enumerate(self.bins):
            if value < b.high:
                return i
        return len(self.bins) - 1   # value == range high: the top bin


class NumberDiscretiser:
    """A number channel's value → symbol, with hysteresis (see the module doc).

    The bins tile the range; with ``h`` = the channel's hysteresis and the current bin
    ``[low, high)``, a reading ``x`` keeps the current symbol while ``low - h <= x < high + h``
    (the top bin: ``x <= high + h``) and otherwise takes the symbol of the bin it lies in.
    The first reading takes its own bin. A battery with bins ``low [0, 0.2)``, ``ok [0.2, 1]``
    and ``h = 0.05`` reads ``0.3 → ok``, ``0.17 → ok`` (inside the band), ``0.14 → low``,
    ``0.22 → low``, ``0.25 → ok``.
    """

    def __init__(self, channel: InputChannel):
        if channel.kind != "number" or not channel.bins:
            raise ValueError(f"input {channel.name!r} is not a number channel with bins")
        self.channel = channel
        self.current: Optional[int] = None

    def reset(self) -> None:
        """Forget the current bin (the next reading takes its own bin)."""
        self.current = None

    @property
    def symbol(self) -> Optional[str]:
        """The current symbol (``None`` before the first valid reading)."""
        return None if self.current is None else self.channel.bins[self.current].symbol

    def read(self, value: float) -> Optional[str]:
        """The symbol of ``value`` given the current one (and it becomes current), or ``None``
        for a value outside the range or not finite (the current symbol is kept)."""
        c = self.channel
        index = c.bin_of(value)
        if index is None:
            return None
        if self.current is not None and index != self.current:
            b, h = c.bins[self.current], c.hysteresis
            top = self.current == len(c.bins) - 1
            if b.low - h <= value and (value <= b.high + h if top else value < b.high + h):
                index = self.current
        self.current = index
        return c.bins[index].symbol


Fail = Callable[[str, str, Any, Any], Exception]


def _number(value: Any) -> Optional[float]:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        return None
    return float(value)


def default_channel(modality: str, symbols: Sequence[str], keywords: Mapping[str, Sequence[str]]) -> InputChannel:
    """The generic channel of a modality that declares no ``input:`` (see the module doc)."""
    name = modality.lower()
    spoken = [z for z in symbols if z in keywords]
    if not spoken:
        return InputChannel(name, modality, "symbol", tuple(symbols), DEFAULT_TOPIC_PREFIX + name, declared=False)
    silent = [z for z in symbols if z not in keywords]
    return InputChannel(name, modality, "speech", tuple(symbols), DEFAULT_TOPIC_PREFIX + name,
                        unknown=silent[0] if len(silent) == 1 else None, declared=False)


def flat_channels(observations: Sequence[str], kind: str = "symbol") -> List[InputChannel]:
    """The one channel of a flat model (no domain): ``observation``, every symbol, ``/pearl/observation``
    (``kind`` ``speech`` when a keyword filter is given for it)."""
    return [InputChannel("observation", "observation", kind, tuple(observations),
                         DEFAULT_TOPIC_PREFIX + "observation", declared=False)]


def parse_input(modality: str, symbols: Sequence[str], node: Any, keywords: Mapping[str, Sequence[str]],
                where: str, fail: Fail, container: Any, key: Any) -> InputChannel:
    """The :class:`InputChannel` of ``modalities.<modality>.input`` (``node``, the parsed mapping).

    ``fail(where, problem, container, key)`` builds the error to raise (the domain loader's:
    it names the file and the line).

    Raises:
        what ``fail`` builds: an unknown key or kind, a malformed topic/type/field, an unknown
        symbol, bins that overlap, leave gaps or do not cover the range, a bad hysteresis.
    """
    if not isinstance(node, dict):
        raise fail(where, "expected a mapping such as {kind: symbol, topic: /robot/door}", container, key)
    for k in node:
        if k not in INPUT_KEYS:
            raise fail(f"{where}.{k}", f"unknown key; expected one of {', '.join(INPUT_KEYS)}", node, k)
    name = modality.lower()
    kind = node.get("kind")
    if kind not in KINDS:
        raise fail(f"{where}.kind", f"unknown kind {kind!r}; expected one of {', '.join(KINDS)}",
                   node if "kind" in node else container, "kind" if "kind" in node else key)

    def text(k: str, default: str, pattern: "re.Pattern[str]", what: str) -> str:
        value = node.get(k, default)
        if not isinstance(value, str) or not pattern.match(value):
            raise fail(f"{where}.{k}", f"{value!r} is not {what}", node, k)
        return value

    topic = text("topic", DEFAULT_TOPIC_PREFIX + name, _TOPIC, "a ROS topic name (/robot/battery_state)")
    type_name = text("type", {"number": "std_msgs/msg/Float32", "speech": SPEECH_TYPE}.get(kind, TEXT_TYPE), _TYPE,
                     "a ROS message type (package/msg/Name, e.g. std_msgs/msg/String)")
    field = text("field", "", _FIELD, "a message field name (percentage, data)") if "field" in node else ""
    if field and kind != "number":
        raise fail(f"{where}.field", f"only a number input reads a field; a {kind} input reads the text", node, "field")
    qos = node.get("qos", "reliable")
    if qos not in RELIABILITIES:
        raise fail(f"{where}.qos", f"unknown qos {qos!r}; expected one of {', '.join(RELIABILITIES)}", node, "qos")
    depth = node.get("depth", 20)
    if isinstance(depth, bool) or not isinstance(depth, int) or not 1 <= depth <= 1000:
        raise fail(f"{where}.depth", f"{depth!r} is not a queue depth in [1, 1000]", node, "depth")

    def symbol_of(k: str) -> Optional[str]:
        if k not in node:
            return None
        value = node[k]
        if value not in symbols:
            raise fail(f"{where}.{k}", f"{value!r} is not a symbol of modality {modality} "
                                       f"(symbols: {', '.join(symbols)})", node, k)
        return str(value)

    silence = symbol_of("silence")
    extra: Dict[str, Any] = {}
    if kind == "speech":
        extra["unknown"] = symbol_of("unknown")
        if extra["unknown"] is not None and extra["unknown"] in keywords:
            raise fail(f"{where}.unknown", f"{extra['unknown']!r} has keywords; the symbol for text without a "
                                           "keyword cannot have any", node, "unknown")
    elif "unknown" in node:
        raise fail(f"{where}.unknown", "only a speech input has an unknown symbol", node, "unknown")
    number_keys = [k for k in ("bins", "range", "hysteresis", "report") if k in node]
    if kind != "number":
        if number_keys:
            raise fail(f"{where}.{number_keys[0]}", f"only a number input has {number_keys[0]}", node, number_keys[0])
        return InputChannel(name, modality, str(kind), tuple(symbols), topic, type_name, field, str(qos), depth,
                            silence=silence, **extra)

    bins, value_range = _parse_bins(node, symbols, modality, f"{where}", fail, container, key)
    hysteresis = node.get("hysteresis", 0.0)
    h = _number(hysteresis)
    width = min(b.high - b.low for b in bins)
    if h is None or h < 0:
        raise fail(f"{where}.hysteresis", f"{hysteresis!r} is not a number >= 0", node, "hysteresis")
    if len(bins) > 1 and h >= width:
        raise fail(f"{where}.hysteresis", f"{h:g} is not smaller than the narrowest bin ({width:g} wide): "
                                          "a reading in a neighbouring bin could never move the input to it", node, "hysteresis")
    report = node.get("report", "change")
    if report not in REPORTS:
        raise fail(f"{where}.report", f"unknown report {report!r}; expected one of {', '.join(REPORTS)}", node,
                   "report")
    return InputChannel(name, modality, "number", tuple(symbols), topic, type_name, field, str(qos), depth,
                        silence=silence, bins=bins, range=value_range, hysteresis=float(h), report=str(report))


def _parse_bins(node: dict, symbols: Sequence[str], modality: str, where: str, fail: Fail, container: Any,
                key: Any) -> Tuple[Tuple[Bin, ...], Tuple[float, float]]:
    """A number input's bins (lowest first) and range: they must tile the range exactly."""
    spec = node.get("bins")
    if not isinstance(spec, dict) or not spec:
        raise fail(f"{where}.bins", "a number input needs bins: {symbol: [low, high], …}",
                   node if "bins" in node else container, "bins" if "bins" in node else key)
    bins = []
    for sym, edges in spec.items():
        bwhere = f"{where}.bins.{sym}"
        if sym not in symbols:
            raise fail(bwhere, f"{sym!r} is not a symbol of modality {modality} (symbols: {', '.join(symbols)})",
                       spec, sym)
        lo_hi = [_number(e) for e in edges] if isinstance(edges, list) and len(edges) == 2 else [None]
        if None in lo_hi or lo_hi[0] >= lo_hi[1]:  # type: ignore[operator]
            raise fail(bwhere, f"{edges!r} is not [low, high] with low < high", spec, sym)
        bins.append(Bin(str(sym), float(lo_hi[0]), float(lo_hi[1])))  # type: ignore[arg-type]
    missing = [z for z in symbols if z not in spec]
    if missing:
        raise fail(f"{where}.bins", f"symbol {missing[0]!r} of modality {modality} has no bin "
                                    "(every symbol of a number input is a bin)", node, "bins")
    bins.sort(key=lambda b: b.low)
    if "range" in node:
        raw = node["range"]
        edges = [_number(e) for e in raw] if isinstance(raw, list) and len(raw) == 2 else [None]
        if None in edges or edges[0] >= edges[1]:  # type: ignore[operator]
            raise fail(f"{where}.range", f"{raw!r} is not [low, high] with low < high", node, "range")
        value_range = (float(edges[0]), float(edges[1]))  # type: ignore[arg-type]
    else:
        value_range = (bins[0].low, bins[-1].high)
    if bins[0].low != value_range[0]:
        raise fail(f"{where}.bins", f"the bins do not cover the range {list(value_range)}: nothing covers "
                                    f"[{value_range[0]:g}, {bins[0].low:g})", node, "bins")
    for below, above in zip(bins, bins[1:]):
        if above.low > below.high:
            raise fail(f"{where}.bins", f"the bins do not cover the range {list(value_range)}: nothing covers "
                                        f"[{below.high:g}, {above.low:g}) between {below.symbol} and {above.symbol}",
                       node, "bins")
        if above.low < below.high:
            raise fail(f"{where}.bins", f"bins {below.symbol} and {above.symbol} overlap on "
                                        f"[{above.low:g}, {min(below.high, above.high):g})", node, "bins")
    if bins[-1].high != value_range[1]:
        raise fail(f"{where}.bins", f"the bins do not cover the range {list(value_range)}: nothing covers "
                                    f"({bins[-1].high:g}, {value_range[1]:g}]", node, "bins")
    return tuple(bins), value_range


def check_topics(channels: Sequence[InputChannel]) -> Optional[Tuple[InputChannel, InputChannel]]:
    """The first two channels on one topic (``None`` when every topic is its own)."""
    seen: Dict[str, InputChannel] = {}
    for c in channels:
        topic = c.topic if c.topic.startswith(("/", "~")) else "/" + c.topic
        if topic in seen:
            return seen[topic], c
        seen[topic] = c
    return None
