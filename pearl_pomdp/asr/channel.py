"""The measured speech channel: P(recognised symbol | meant symbol, SNR), with counts.

:func:`calibrate` speaks every utterance of every meant symbol with every voice,
``repeats`` times, at every SNR — espeak-ng → noise (:func:`~pearl_pomdp.asr.audio.mix_at_snr`)
→ the domain recogniser → the keyword filter — and counts what came out. The result,
a :class:`ChannelTable`, is JSON (``pearl calibrate-speech --out channel.json``)::

    {"format": "pearl-speech-channel/1", "domain": ..., "recogniser": "pocketsphinx-5.1.1:domain-…",
     "noise": "white", "voices": {...}, "repeats": 2, "seed": 0,
     "snr_db": [30, 20, 10], "symbols": ["time", ..., "unknown"], "meant": ["yes", ..., "unknown"],
     "cells": {"20": {"time": {"n": 24, "counts": {"time": 23, "unknown": 1},
                                "samples": [["what time is it", 0.91, "time"], ...]}}}}

``samples`` keeps (recognised text, confidence, symbol) of up to :data:`MAX_SAMPLES`
trials per cell, so :class:`MeasuredChannel` can hand the simulation a real recogniser
output in microseconds instead of decoding audio for every one of thousands of episodes.

Every trial's noise is seeded from its content (seed, text, voice, SNR, repeat) and its
result is cached by the hash of that content plus the recogniser's identity under
:func:`~pearl_pomdp.asr.recognizer.cache_dir`, so a repeated calibration, or one with one
more SNR, only decodes what is new.
"""
from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Dict, List, Mapping, Optional, Sequence, Tuple, Union

import numpy as np

from pearl_pomdp.asr.audio import mix_at_snr
from pearl_pomdp.asr.babble import TRACK_ID, babble_track
from pearl_pomdp.errors import PearlError, SpecError

__all__ = ["ChannelTable", "MeasuredChannel", "ChannelError", "calibrate", "default_utterances", "babble_track",
           "wilson_interval",
           "trial_seed", "FORMAT", "MAX_SAMPLES"]

FORMAT = "pearl-speech-channel/1"
#: Recognised texts kept per (SNR, meant symbol) cell for the sampler.
MAX_SAMPLES = 64

def wilson_interval(hits: int, n: int, z: float = 1.96) -> Tuple[float, float]:
    """Wilson score interval of a proportion ``hits / n`` (``(0, 1)`` for no trials)."""
    if n <= 0:
        return 0.0, 1.0
    p = hits / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * float(np.sqrt(p * (1 - p) / n + z * z / (4 * n * n))) / (1 + z * z / n)
    return max(0.0, centre - half), min(1.0, centre + half)


class ChannelError(PearlError):
    """A channel file is unreadable or does not cover what is asked of it."""


def trial_seed(*parts: object) -> int:
    """A 63-bit seed from the content of a trial (order-independent of other trials)."""
    h = hashlib.sha256("\x1f".join(map(str, parts)).encode()).digest()
    return int.from_bytes(h[:8], "little") >> 1


def default_utterances(keywords: Mapping[str, Sequence[str]], unknown_symbol: str = "unknown") -> Dict[str, List[str]]:
    """Each keyword in carrier phrases (``"{k}"``, ``"{k} please"``, ``"tell me the {k}"``) + OOV chatter."""
    out: Dict[str, List[str]] = {}
    for symbol, phrases in keywords.items():
        out[symbol] = [c.format(k=p) for p in phrases for c in ("{k}", "{k} please", "tell me the {k}")]
    out[unknown_symbol] = ["hello pearl", "thank you", "that is nice", "good morning", "where are my glasses"]
    return out


@dataclass
class ChannelTable:
    """Counts and samples of a calibration (see the module doc for the JSON form)."""

    snr_db: List[float]
    symbols: List[str]
    meant: List[str]
    cells: Dict[str, Dict[str, dict]]
    meta: Dict[str, object] = field(default_factory=dict)

    @staticmethod
    def key(snr: float) -> str:
        return f"{float(snr):g}"

    def probability(self, meant: str, snr: float) -> Dict[str, float]:
        """P(recognised symbol | meant, snr) at a measured SNR (every symbol, zeros included)."""
        cell = self._cell(meant, snr)
        n = max(1, cell["n"])
        return {s: cell["counts"].get(s, 0) / n for s in self.symbols}

    def accuracy(self, snr: float, meant_symbols: Optional[Sequence[str]] = None) -> float:
        """Fraction of trials at ``snr`` whose recognised symbol is the meant one.

        ``meant_symbols`` restricts the count to those meanings (e.g. the keyword symbols,
        leaving out chatter meant as ``unknown``).
        """
        hit = total = 0
        for meant in (self.meant if meant_symbols is None else meant_symbols):
            cell = self._cell(meant, snr)
            hit += cell["counts"].get(meant, 0)
            total += cell["n"]
        return hit / total if total else float("nan")

    def confusion(self, snr: float) -> Dict[str, Dict[str, int]]:
        """Counts ``{meant: {recognised: trials}}`` at ``snr`` over every symbol (zeros included)."""
        return {m: {s: int(self._cell(m, snr)["counts"].get(s, 0)) for s in self.symbols} for m in self.meant}

    def error_rates(self, snr: float, unknown_symbol: str = "unknown") -> Dict[str, dict]:
        """Insertion and deletion rates at ``snr``, each ``{"count", "n", "rate", "ci95": [lo, hi]}`` (Wilson).

        * ``insertion``: a keyword recognised that was not said — a keyword other than the
          meant one (``unknown`` meant, or another keyword meant), over every trial;
        * ``insertion_from_chatter``: the same over trials meant as ``unknown_symbol`` only
          (chatter, nothing for the robot), ``substitution``: over trials meant as a keyword;
        * ``deletion``: a meant keyword heard as ``unknown_symbol``, over keyword trials.

        What a clarification question guards against is an insertion: a controller that
        acts on a heard keyword does the wrong thing; a deletion only delays.
        """
        counts = self.confusion(snr)
        keywords = [s for s in self.symbols if s != unknown_symbol]

        def rate(hits: int, n: int) -> dict:
            lo, hi = wilson_interval(hits, n)
            return {"count": hits, "n": n, "rate": hits / n if n else None, "ci95": [lo, hi]}

        chatter = counts.get(unknown_symbol, {})
        said_keyword = [m for m in counts if m != unknown_symbol]
        from_chatter = sum(chatter.get(k, 0) for k in keywords)
        substituted = sum(counts[m][k] for m in said_keyword for k in keywords if k != m)
        n_chatter = sum(chatter.values())
        n_keyword = sum(sum(counts[m].values()) for m in said_keyword)
        deleted = sum(counts[m].get(unknown_symbol, 0) for m in said_keyword)
        return {"insertion": rate(from_chatter + substituted, n_chatter + n_keyword),
                "insertion_from_chatter": rate(from_chatter, n_chatter),
                "substitution": rate(substituted, n_keyword),
                "deletion": rate(deleted, n_keyword)}

    def _cell(self, meant: str, snr: float) -> dict:
        row = self.cells.get(self.key(snr))
        if row is None:
            raise ChannelError(f"channel has no SNR {snr:g} dB; measured: {', '.join(map(self.key, self.snr_db))}")
        if meant not in row:
            raise ChannelError(f"channel has no meant symbol {meant!r}; measured: {', '.join(self.meant)}")
        return row[meant]

    def to_json(self) -> dict:
        return {"format": FORMAT, **self.meta, "snr_db": self.snr_db, "symbols": self.symbols, "meant": self.meant,
                "cells": self.cells}

    def save(self, path: Union[str, Path]) -> None:
        from pearl_pomdp.atomic import atomic_write

        atomic_write(path, json.dumps(self.to_json(), indent=1) + "\n")

    @classmethod
    def load(cls, path: Union[str, Path]) -> "ChannelTable":
        """Read a channel JSON file.

        Raises:
            ChannelError: unreadable, another format, or a field missing (the message names it).
        """
        path = Path(path)
        try:
            data = json.loads(path.read_text(encoding="utf-8"))
        except FileNotFoundError:
            raise ChannelError(f"{path}: no such channel file") from None
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as err:
            raise ChannelError(f"{path}: not a channel JSON file ({err})") from None
        if not isinstance(data, dict) or data.get("format") != FORMAT:
            raise ChannelError(f"{path}: format: expected {FORMAT!r} (from pearl calibrate-speech)")
        for name in ("snr_db", "symbols", "meant", "cells"):
            if name not in data:
                raise ChannelError(f"{path}: {name}: missing")
        meta = {k: v for k, v in data.items() if k not in ("format", "snr_db", "symbols", "meant", "cells")}
        table = cls([float(s) for s in data["snr_db"]], list(data["symbols"]), list(data["meant"]), data["cells"], meta)
        for snr in table.snr_db:
            for meant in table.meant:
                try:
                    cell = table._cell(meant, snr)
                    if not isinstance(cell["n"], int) or not isinstance(cell["counts"], dict):
                        raise KeyError("n")
                except (ChannelError, KeyError, TypeError):
                    raise ChannelError(f"{path}: cells.{table.key(snr)}.{meant}: missing or malformed") from None
        return table


class MeasuredChannel:
    """Samples recogniser outputs from a :class:`ChannelTable` (fast: no audio).

    At an SNR between two measured ones, the cell is chosen between the two neighbours
    with probability proportional to closeness (a linear interpolation of the
    confusion); outside the measured range the nearest SNR is used.
    """

    def __init__(self, table: ChannelTable):
        self.table = table
        self._snrs = np.array(sorted(table.snr_db))

    @classmethod
    def load(cls, path: Union[str, Path]) -> "MeasuredChannel":
        return cls(ChannelTable.load(path))

    def _pick_snr(self, snr: float, rng: np.random.Generator) -> float:
        s = self._snrs
        if snr <= s[0]:
            return float(s[0])
        if snr >= s[-1]:
            return float(s[-1])
        i = int(np.searchsorted(s, snr))
        lo, hi = s[i - 1], s[i]
        return float(hi) if rng.random() < (snr - lo) / (hi - lo) else float(lo)

    def sample(self, meant: str, snr_db: float, rng: np.random.Generator) -> Tuple[str, float, str]:
        """``(recognised text, confidence, symbol)`` for a resident meaning ``meant`` at ``snr_db``.

        Raises:
            ChannelError: ``meant`` was not measured.
        """
        cell = self.table._cell(meant, self._pick_snr(float(snr_db), rng))
        samples = cell.get("samples") or []
        if samples:
            text, conf, symbol = samples[int(rng.integers(len(samples)))]
            return str(text), float(conf), str(symbol)
        counts = cell["counts"]
        symbols = list(counts)
        p = np.array([counts[s] for s in symbols], dtype=float)
        symbol = symbols[int(rng.choice(len(symbols), p=p / p.sum()))]
        return symbol, 1.0, symbol


class _ResultCache:
    """``{trial hash: [text, confidence]}`` of one recogniser, in one JSON file under the cache dir."""

    def __init__(self, identity: str, folder: Optional[Path]):
        self.path = None if folder is None else folder / f"{hashlib.sha256(identity.encode()).hexdigest()[:16]}.json"
        self.data: Dict[str, list] = {}
        self.dirty = 0
        if self.path is not None and self.path.exists():
            try:
                loaded = json.loads(self.path.read_text(encoding="utf-8"))
                self.data = loaded if isinstance(loaded, dict) else {}
            except (OSError, ValueError):
                self.data = {}  # a damaged cache is rebuilt, never trusted

    def get(self, key: str) -> Optional[list]:
        return self.data.get(key)

    def put(self, key: str, value: list) -> None:
        self.data[key] = value
        self.dirty += 1
        if self.dirty >= 100:
            self.flush()

    def flush(self) -> None:
        if self.path is None or not self.dirty:
            return
        from pearl_pomdp.atomic import atomic_write

        self.path.parent.mkdir(parents=True, exist_ok=True)
        atomic_write(self.path, json.dumps(self.data, separators=(",", ":")))
        self.dirty = 0


def calibrate(recognizer, keyword_filter, utterances: Mapping[str, Sequence[str]], snrs: Sequence[float],
              voices: Sequence[str] = ("clear",), repeats: int = 1, noise: str = "white", seed: int = 0,
              progress: Optional[Callable[[int, int], None]] = None, cache: bool = True,
              meta: Optional[Mapping[str, object]] = None) -> ChannelTable:
    """Measure the channel (module doc).

    Args:
        recognizer: a :class:`~pearl_pomdp.asr.recognizer.Recognizer`.
        keyword_filter: the domain's :class:`~pearl_pomdp.speech.KeywordFilter`.
        utterances: meant symbol → what a resident says to mean it.
        snrs: SNRs in dB.
        voices: voice preset names (:data:`~pearl_pomdp.asr.synthesizer.VOICES`).
        repeats: noise draws per (utterance, voice, SNR).
        noise: ``white`` or ``babble``.
        seed: base seed of every noise draw.
        progress: called with (done, total) after each trial.
        cache: reuse and store results under the user cache dir.
        meta: extra fields for the JSON (domain name, file).

    Raises:
        ValueError: no SNR, no utterance, repeats < 1.
        pearl_pomdp.asr.synthesizer.SynthesisError: an unknown voice (before any decoding).
    """
    from pearl_pomdp.asr.recognizer import cache_dir
    from pearl_pomdp.asr.synthesizer import get_voice, synthesize

    if not snrs:
        raise ValueError("no SNR to measure")
    if repeats < 1:
        raise ValueError(f"repeats {repeats} is less than 1")
    if not any(utterances.values()):
        raise ValueError("no utterance to speak")
    voice_objs = {v: get_voice(v) for v in voices}
    babble = babble_track() if noise == "babble" else None
    # White noise is generated from the trial's seed alone; babble also depends on the track.
    noise_id = TRACK_ID if noise == "babble" else noise
    store = _ResultCache(recognizer.identity, cache_dir() / "speech-channel" if cache else None)
    symbols = list(keyword_filter.symbols)
    cells: Dict[str, Dict[str, dict]] = {}
    total = len(snrs) * len(voices) * repeats * sum(len(u) for u in utterances.values())
    done = 0
    clean: Dict[Tuple[str, str], np.ndarray] = {}
    try:
        for snr in snrs:
            row = cells.setdefault(ChannelTable.key(snr), {})
            for meant, says in utterances.items():
                cell = row.setdefault(meant, {"n": 0, "counts": {}, "samples": []})
                for text in says:
                    for vname, voice in voice_objs.items():
                        for rep in range(repeats):
                            level = float(snr) + voice.snr_offset_db
                            key = trial_seed(seed, text, sorted(voice.to_dict().items()), level, noise_id, rep)
                            hit = store.get(str(key))
                            if hit is None:
                                if (text, vname) not in clean:
                                    clean[(text, vname)] = synthesize(text, voice)
                                audio = mix_at_snr(clean[(text, vname)], level, np.random.default_rng(key), noise, babble)
                                rec = recognizer.recognise(audio, where=f"calibration {text!r}")
                                hit = [rec.text, round(rec.confidence, 4)]
                                store.put(str(key), hit)
                            symbol = keyword_filter.classify(hit[0])
                            cell["n"] += 1
                            cell["counts"][symbol] = cell["counts"].get(symbol, 0) + 1
                            if len(cell["samples"]) < MAX_SAMPLES:
                                cell["samples"].append([hit[0], hit[1], symbol])
                            done += 1
                            if progress is not None:
                                progress(done, total)
    finally:
        store.flush()
    info = {"recogniser": recognizer.identity, "noise": noise, "noise_id": noise_id, "repeats": repeats, "seed": seed,
            "voices": {v: voice_objs[v].to_dict() for v in voices}, "utterances": {k: list(v) for k, v in utterances.items()}}
    info.update(meta or {})
    return ChannelTable([float(s) for s in snrs], symbols, list(utterances), cells, info)


def fitted_confusion(table: ChannelTable, snr: float, prior_strength: float) -> Dict[str, Dict[str, float]]:
    """Posterior-mean P(heard | meant) at a measured SNR, Dirichlet prior = "heard as meant".

    For a meant symbol ``m`` with counts ``c(o|m)`` over ``n_m`` trials:
    ``Ĉ(o|m) = (κ·[o = m] + c(o|m)) / (κ + n_m)`` with ``κ = prior_strength``. The prior is
    the designer's table (which writes what the resident means as what is heard): with no
    trials the fitted rows equal the designer's, with many they follow the measurement.
    """
    if prior_strength < 0:
        raise ValueError(f"prior strength {prior_strength} is negative")
    out = {}
    for meant in table.meant:
        cell = table._cell(meant, snr)
        denom = prior_strength + cell["n"]
        if denom <= 0:
            continue
        row = {o: cell["counts"].get(o, 0) / denom for o in table.symbols}
        row[meant] = row.get(meant, 0.0) + prior_strength / denom
        out[meant] = row
    return out


def fit_observation_rows(domain_path: Union[str, Path], table: ChannelTable, snr: float,
                         prior_strength: float = 20.0) -> Tuple[dict, int]:
    """The domain file's data with every Speech part of every observation row passed through the channel.

    Each row ``r`` (a table row, or a row of a ``mix`` component) becomes
    ``r'(o) = r(o)`` for non-speech symbols and ``r'(o) = Σ_m r(m) Ĉ(o|m)`` for speech symbols,
    with ``Ĉ`` from :func:`fitted_confusion` (a meant symbol the channel did not measure is
    kept as it is). Row sums are unchanged. Returns ``(data, rows changed)``; the data loads
    with :func:`pearl_pomdp.model.domain_yaml.parse_domain` after ``yaml.safe_dump``.

    Raises:
        ChannelError: the channel's symbols are not the domain's Speech symbols.
    """
    from pearl_pomdp.model.domain_yaml import as_number, load_domain
    from pearl_pomdp.yaml_lines import parse_yaml

    domain = load_domain(domain_path)
    # The symbols of the domain's speech inputs (Pearl's Speech modality).
    speech = [z for c in domain.inputs if c.kind == "speech" for z in c.symbols]
    if not speech or set(table.symbols) - set(speech):
        raise ChannelError(f"channel symbols {', '.join(table.symbols)} are not the Speech symbols of "
                           f"{domain.name} ({', '.join(speech) or 'none'})")
    confusion = fitted_confusion(table, snr, prior_strength)
    data = _plain(parse_yaml(Path(domain_path).read_text(encoding="utf-8"), str(domain_path)))
    changed = 0

    def probability(value) -> float:
        number = as_number(value)
        if number is None:   # (load_domain has checked every row: not reached for a domain it loaded)
            raise SpecError(domain_path, "observations", f"{value!r} is not a probability")
        return number

    def fit(row):
        nonlocal changed
        probs = {row: 1.0} if isinstance(row, str) else {str(k): probability(v) for k, v in row.items()}
        out = {o: p for o, p in probs.items() if o not in speech}
        for m, p in probs.items():
            if m not in speech:
                continue
            for o, q in confusion.get(m, {m: 1.0}).items():
                if q > 0:
                    out[o] = out.get(o, 0.0) + p * q
        total = sum(probs.values())
        rounded = {o: round(p, 9) for o, p in out.items() if round(p, 9) > 0}
        top = max(rounded, key=lambda o: rounded[o])
        rounded[top] = round(rounded[top] + total - sum(rounded.values()), 9)
        if rounded != {o: round(p, 9) for o, p in probs.items()}:
            changed += 1
        return rounded

    def fit_table(spec):
        if isinstance(spec, dict) and isinstance(spec.get("table"), dict):
            spec["table"] = {k: fit(v) for k, v in spec["table"].items()}

    for spec in (data.get("observations") or {}).values():
        if isinstance(spec, dict) and isinstance(spec.get("mix"), list):
            for comp in spec["mix"]:
                fit_table(comp)
        else:
            fit_table(spec)
    return data, changed


def _plain(node):
    """Loader containers (with line marks) as plain dicts and lists, for yaml.safe_dump."""
    if isinstance(node, dict):
        return {(_plain(k)): _plain(v) for k, v in node.items()}
    if isinstance(node, list):
        return [_plain(v) for v in node]
    return node
