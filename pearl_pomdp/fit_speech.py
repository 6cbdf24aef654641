"""The domain's speech observation rows from a measured channel: ``pearl fit DOMAIN --speech CHANNEL.json``.

A policy plans with the domain's observation model and hears through a recogniser. When
the recogniser has been measured (``pearl calibrate-speech``: P(recognised | meant) per noise
kind and SNR, :mod:`pearl_pomdp.asr.channel`), the model can be made to agree with it at a
chosen operating point (an SNR of that channel): every observation row of every action —
the designer's, or a row ``pearl fit`` already re-estimated from episodes — has its
speech part passed through the measured confusion::

    r'(o) = r(o)                                   for non-speech symbols (touch, laser, ...)
    r'(o) = Σ_k r(k) Ĉ(o | k) + r(u) [o = u]        for speech symbols, k a keyword, u = unknown

with ``Ĉ`` the channel's confusion at that SNR as a Dirichlet posterior mean whose prior is
"heard as meant" worth ``prior_strength`` trials (:func:`~pearl_pomdp.asr.channel.fitted_confusion`).
Row sums are unchanged. The row's ``unknown`` is left as it is: in the domain it is mostly a
step closed by silence (nothing reaches the recogniser), and the measured chatter row
(speech meant as nothing) cannot say how much of it is speech; ``chatter_share`` passes that
fraction of it through the chatter row instead (0 by default).

The result is written the way ``pearl fit`` writes its rows: the domain file unchanged (the
designer's rows and comments above), and in its ``fitted:`` section one
``observations.<Action>."<parents>"`` row per changed row, with the row it replaces as a
comment (``# speech: <channel> at <SNR> dB, was {...}``). Rows ``pearl fit`` wrote for other
tables (transitions) are kept as they were.
"""
from __future__ import annotations

import json
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Dict, List, Optional, Tuple, Union

import numpy as np

from pearl_pomdp.errors import PearlError

__all__ = ["SpeechRow", "speech_rows", "write_speech_fitted"]


@dataclass
class SpeechRow:
    """One observation row passed through the channel."""

    action: str
    row: str                      # the parents' values, "v1,v2" ("*" without parents)
    before: Dict[str, float]
    after: Dict[str, float]


def _dist(symbols: List[str], p: np.ndarray) -> Dict[str, float]:
    return {s: round(float(x), 12) for s, x in zip(symbols, p) if round(float(x), 12) > 0}


def speech_rows(domain, table, snr: float, prior_strength: float = 10.0,
                chatter_share: float = 0.0) -> List[SpeechRow]:
    """Every observation row of ``domain`` whose speech part the channel ``table`` changes at ``snr`` (module doc).

    Raises:
        PearlError: the channel's symbols are not the domain's speech symbols, or ``snr``
            was not measured, or a parameter is out of range.
    """
    from pearl_pomdp.asr.channel import fitted_confusion

    if not 0.0 <= chatter_share <= 1.0:
        raise PearlError(f"--chatter-share {chatter_share:g}: expected a fraction in [0, 1]")
    speech_inputs = [c for c in domain.inputs if c.kind == "speech"]
    speech = [z for c in speech_inputs for z in c.symbols]
    if not speech or set(table.symbols) != set(speech):
        raise PearlError(f"channel symbols {', '.join(table.symbols)} are not the speech symbols of "
                         f"{domain.name} ({', '.join(speech) or 'none'})")
    unknown = speech_inputs[0].unknown or "unknown"
    if float(snr) not in [float(s) for s in table.snr_db]:
        raise PearlError(f"--snr {snr:g}: the channel measured {', '.join(map(table.key, table.snr_db))} dB")
    confusion = fitted_confusion(table, float(snr), prior_strength)
    symbols = list(domain.observations)
    col = {s: i for i, s in enumerate(symbols)}
    # M[i, j]: the share of row mass on speech symbol i that is heard as speech symbol j.
    mix = np.eye(len(symbols))
    for meant in speech:
        i = col[meant]
        heard = confusion.get(meant)
        if heard is None:
            continue            # a meaning the channel did not measure stays as it is
        share = chatter_share if meant == unknown else 1.0
        mix[i, :] = 0.0
        mix[i, i] = 1.0 - share
        for o, q in heard.items():
            mix[i, col[o]] += share * q
    out: List[SpeechRow] = []
    for a, cpt in zip(domain.actions, domain._observations):
        parents = [domain.features[p] for p in cpt.parents]
        for combo in np.ndindex(*cpt.table.shape[:-1]):
            before = np.asarray(cpt.table[combo], dtype=float)
            after = before @ mix
            if np.allclose(after, before, atol=1e-12):
                continue
            key = ",".join(f.values[v] for f, v in zip(parents, combo)) or "*"
            out.append(SpeechRow(a, key, _dist(symbols, before), _dist(symbols, after)))
    return out


_ACTION = re.compile(r"^    (\S+):\s*(#.*)?$")
_ROW = re.compile(r'^      ("(?:[^"\\]|\\.)*"):\s*(\{.*?\})\s*(#.*)?$')


def _split_fitted(text: str, marker: str) -> Tuple[str, List[str], Dict[str, Dict[str, str]], List[str]]:
    """(the text before the fitted section, its lines before ``  observations:``, observation rows
    ``{action: {row key json: the row's line}}``, the lines after the observations block)."""
    if marker not in text:
        return text, [], {}, []
    head, section = text[:text.index(marker)], text[text.index(marker):]
    lines = section.rstrip("\n").split("\n")
    if "  observations:" not in lines:
        return head, lines, {}, []
    start = lines.index("  observations:")
    rows: Dict[str, Dict[str, str]] = {}
    action = None
    end = len(lines)
    for n in range(start + 1, len(lines)):
        line = lines[n]
        if line.strip() and not line.startswith("    "):
            end = n
            break
        m = _ACTION.match(line)
        if m:
            action = m.group(1)
            rows.setdefault(action, {})
            continue
        m = _ROW.match(line)
        if m and action is not None:
            rows[action][m.group(1)] = line
    return head, lines[:start], rows, lines[end:]


def write_speech_fitted(domain_path: Union[str, Path], table, snr: float, out: Union[str, Path],
                        prior_strength: float = 10.0, chatter_share: float = 0.0,
                        label: Optional[str] = None) -> Tuple[Path, List[SpeechRow]]:
    """Write ``domain_path`` with its speech rows fitted from the channel ``table`` at ``snr`` (module doc).

    Returns the file written and the rows changed. The written file is loaded before it is
    kept: a file that does not load is never left behind.
    """
    from pearl_pomdp.atomic import atomic_write
    from pearl_pomdp.fit import FITTED_MARKER
    from pearl_pomdp.model.domain_yaml import load_domain, parse_domain

    domain = load_domain(domain_path)
    rows = speech_rows(domain, table, snr, prior_strength, chatter_share)
    what = label or f"{table.meta.get('noise', 'white')} noise"
    text = Path(domain_path).read_text(encoding="utf-8")
    head, before_obs, old_rows, after_obs = _split_fitted(text, FITTED_MARKER)
    if not head.endswith("\n"):
        head += "\n"
    if not before_obs:
        before_obs = [FITTED_MARKER, "fitted:"]
    note = (f"# speech rows through the measured channel ({what}, {table.meta.get('recogniser', '?')}) at {snr:g} dB, "
            f"prior 'heard as meant' worth {prior_strength:g} trials, chatter share {chatter_share:g} "
            f"(`pearl fit --speech`)")
    new_rows: Dict[str, Dict[str, str]] = {a: dict(r) for a, r in old_rows.items()}
    for r in rows:
        key = json.dumps(r.row)
        old = old_rows.get(r.action, {}).get(key)
        was = json.dumps(r.before)
        if old is not None and "#" in old:
            was += "; " + old.split("#", 1)[1].strip()
        new_rows.setdefault(r.action, {})[key] = (f"      {key}: {json.dumps(r.after)}   "
                                                  f"# speech: {what} at {snr:g} dB, was {was}")
    obs = ["  observations:"]
    for action in domain.actions:
        if new_rows.get(action):
            obs.append(f"    {action}:")
            obs.extend(new_rows[action].values())
    body = head + "\n".join([l for l in before_obs if not l.startswith("# speech rows through")] + [note] + obs
                            + after_obs) + "\n"
    parse_domain(body, source=str(out))   # never write a domain that does not load
    atomic_write(Path(out), body.encode("utf-8"))
    return Path(out), rows
