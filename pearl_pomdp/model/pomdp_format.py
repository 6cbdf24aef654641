"""Cassandra's ``.pomdp`` file format: the reader (the lossless writer is
:mod:`pearl_pomdp.model.pomdp_writer`).

The grammar is pomdp-solve 5.5's (``src/mdp/parser.y``, ``scanner.l``), all of it:

* preamble, in any order: ``discount: γ``, ``values: reward|cost``,
  ``states:``/``actions:``/``observations:`` as a count (names are then ``"0"``, ``"1"``, …)
  or a list of names (``[A-Za-z][A-Za-z0-9_-]*``, not a reserved word);
* start belief: ``start:`` followed by ``S`` probabilities, ``uniform`` or one state name;
  ``start include: s …`` / ``start exclude: s …`` (names or indices; the result is uniform over
  the states kept); no ``start`` at all means uniform;
* ``T: a : s : s' p``, ``T: a : s`` + a row of ``S`` numbers (or ``uniform`` / ``reset``),
  ``T: a`` + an ``S×S`` matrix (or ``uniform`` / ``identity``);
* ``O: a : s' : o p``, ``O: a : s'`` + a row of ``Z`` numbers (or ``uniform``),
  ``O: a`` + an ``S×Z`` matrix (or ``uniform``);
* ``R: a : s : s' : o v``, ``R: a : s : s'`` + a row of ``Z`` values,
  ``R: a : s`` + an ``S×Z`` matrix of values;
* ``*`` is a wildcard in any position; states/actions/observations may be named or numbered;
  ``#`` starts a comment; statements may span lines; **a later statement overrides earlier
  ones** for every entry it covers (TagAvoid writes ``T: * : * : * 0.0`` then exceptions).

Semantics taken from pomdp-solve:

* Rewards may depend on ``(a, s, s', o)``; each entry takes the value of the *last* ``R:``
  statement covering it (unset entries are 0), and the model keeps their expectation
  ``R[s, a] = Σ_s' T[a][s, s'] Σ_o O[a, s', o] R(a, s, s', o)`` (pomdp-solve's
  ``computeRewards``). Where every reachable ``(s', o)`` of a cell has the same value ``c``
  (the common ``R: a : s : * : * c``), ``R[s, a] = c`` exactly. We take the expectation with the
  renormalised ``T`` and ``O`` (pomdp-solve uses the rows as written; the two differ by at most
  the row-sum deviation, ≤ 1e-5 relative).
* An ``R: a : s`` matrix is stored sparsely by pomdp-solve: its zero entries (``|v| < 1e-10``)
  do not override earlier statements (the row form ``R: a : s : s'`` does override with zeros).
* ``values: cost`` negates every reward after the reduction (the model always holds rewards;
  ``metadata["values"]`` remembers ``"cost"`` and the writer writes costs back).
* Probabilities are unsigned numbers in ``[0, 1]``. Each row of ``T`` and ``O`` and an explicit
  start vector must sum to 1 within :data:`SUM_TOLERANCE` = 1e-5 (pomdp-solve's ``EPSILON``;
  e.g. TagAvoid's start sums to 0.99999946, 1d.POMDP's rows of ``0.333333`` to 0.999999). Rows
  further than :data:`RENORMALISE_ABOVE` from 1 are divided by their sum, so the model holds
  exact distributions; reading a file we wrote changes nothing (the writer is lossless).

Deviations, all on the lenient side: ``start`` may come anywhere after the preamble (``reset``
rows use the final start belief); ``values:`` may be omitted (reward); ``start include: *`` means
every state. A file without ``observations:`` (an MDP) is rejected, as is a discount of 0.

Performance: a streaming tokenizer (``str.split`` after blanking comments) and vectorised
assembly; ``T`` is collected as (action, s, s', p) triplets with "row cleared at statement k"
markers and resolved with one sort, so large sparse models never allocate an ``A×S×S`` array
(RockSample_7_8, 12,545 states and 10 MB, loads in about a second).

Errors are :class:`~pearl_pomdp.errors.ModelFormatError`: file, line, the statement and what is
wrong (unknown name, wrong count of numbers, a row that does not sum to 1 — which row, what sum).
"""
from __future__ import annotations

import bisect
import re
from pathlib import Path
from typing import Any, Dict, List, NoReturn, Optional, Sequence, Tuple, Union

import numpy as np

from pearl_pomdp.errors import ModelFormatError
from pearl_pomdp.model.pomdp import DENSE_LIMIT, Pomdp, issparse


class _Coo:
    """``row``, ``col``, ``data``, ``nnz`` of a T matrix, dense or CSR, in row-major order
    (what ``csr.tocoo()`` gives for sorted unique entries; a dense one needs no scipy)."""

    def __init__(self, Ta) -> None:
        if issparse(Ta):
            c = Ta.tocoo()
            self.row, self.col, self.data = c.row, c.col, c.data
        else:
            self.row, self.col = np.nonzero(Ta)
            self.data = Ta[self.row, self.col]
        self.nnz = int(self.data.size)

__all__ = [
    "read_pomdp",
    "parse_pomdp",
    "SUM_TOLERANCE",
    "RENORMALISE_ABOVE",
    "RESERVED_WORDS",
    "NAME_PATTERN",
]

#: How far a row of T/O or a start vector may be from summing to 1 (pomdp-solve's EPSILON).
SUM_TOLERANCE = 1e-5
#: Rows further than this from 1 (but within SUM_TOLERANCE) are divided by their sum.
RENORMALISE_ABOVE = 1e-10
#: Words the scanner reserves: never names.
RESERVED_WORDS = frozenset(
    "discount values states actions observations T O R uniform identity reward cost start include exclude reset".split()
)
_STATEMENTS = frozenset("discount values states actions observations start T O R".split())
#: A name in the file (states, actions, observations), when it is not a reserved word.
NAME_PATTERN = re.compile(r"[A-Za-z][A-Za-z0-9_\-]*\Z")
# pomdp-solve: IntLiteral, UnsignedReal (digits first); we also accept ".5".
_NUMBER = re.compile(r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?\Z")
_COMMENT = re.compile(r"#[^\n]*")
_EOF = "\x00<end of file>"
_DIGITS = frozenset("0123456789.")
_INF = float("inf")
#: Largest count in ``states: N`` (and actions, observations).
_MAX_COUNT = 10_000_000
#: Largest dense observation table A×S×Z (O is always dense).
_MAX_O_ENTRIES = 200_000_000
#: Largest number of entries the wildcard/uniform expansions of one file may produce.
_EXPANSION_BUDGET = 30_000_000

PathLike = Union[str, Path]


class _Numbered(Sequence):
    """The names ``"0" .. "n-1"`` of numbered entities, without storing them."""

    def __init__(self, n: int):
        self.n = n

    def __len__(self) -> int:
        return self.n

    def __getitem__(self, j):
        if isinstance(j, slice):
            return [str(k) for k in range(self.n)[j]]
        if not -self.n <= j < self.n:
            raise IndexError(j)
        return str(j % self.n)
_KINDS = ("states", "actions", "observations")


# =====================================================================================  reader
def read_pomdp(path: PathLike) -> Pomdp:
    """Read a ``.pomdp`` file (full pomdp-solve grammar) into a :class:`Pomdp`.

    ``T[a][s, s']``, ``O[a, s', o]``, ``R[s, a]`` (rewards, already reduced over ``s'`` and
    ``o`` and negated for ``values: cost``), ``b0[s]``. ``T`` is sparse when ``S²`` exceeds
    :data:`pearl_pomdp.model.pomdp.DENSE_LIMIT`. ``model.name`` is the file name without its
    last suffix; ``model.metadata`` holds ``values``, ``start`` (how the start was given),
    ``source``, ``renormalised`` (rows divided by their sum) and ``reward_depends_on_next``.

    Raises:
        ModelFormatError: the file is not a valid POMDP (names file, line and problem).
        FileNotFoundError: no such file.
    """
    path = Path(path)
    try:
        raw = path.read_bytes()
    except IsADirectoryError:
        raise ModelFormatError(path, "", "is a directory, not a .pomdp file") from None
    try:
        text = raw.decode("ascii")
    except UnicodeDecodeError as err:
        line = raw[: err.start].count(b"\n") + 1
        # Non-ASCII is only legal inside comments (pomdp-solve's scanner).
        text = raw.decode("latin-1")
        cleaned = _COMMENT.sub("", text)
        if not cleaned.isascii():
            bad = next(i for i, ch in enumerate(cleaned) if ord(ch) > 127)
            line = cleaned.count("\n", 0, bad) + 1
            raise ModelFormatError(path, "", f"illegal character {cleaned[bad]!r} (only ASCII outside comments)", line=line) from None
    return parse_pomdp(text, source=str(path), name=_stem(path.name))


def _stem(filename: str) -> str:
    stem = filename.rsplit(".", 1)[0] if "." in filename else filename
    return stem or "pomdp"


def parse_pomdp(text: str, source: str = "<string>", name: Optional[str] = None) -> Pomdp:
    """Parse the text of a ``.pomdp`` file; see :func:`read_pomdp`.

    Args:
        text: the file contents.
        source: what errors call the file (a path, or ``"<string>"``).
        name: model name; defaults to the stem of ``source`` (``"pomdp"`` for ``<string>``).
    """
    if name is None:
        name = "pomdp" if source.startswith("<") else _stem(Path(source).name)
    parser = _Parser(text, source)
    return parser.parse(name)


class _Parser:
    """Token-stream parser; collects events, then assembles arrays (see module docstring)."""

    def __init__(self, text: str, source: str):
        self.source = source
        self.text = text
        cleaned = _COMMENT.sub("", text)
        if not cleaned.isascii():
            bad = next(i for i, ch in enumerate(cleaned) if ord(ch) > 127)
            raise ModelFormatError(source, "", f"illegal character {cleaned[bad]!r} (only ASCII outside comments)",
                                   line=cleaned.count("\n", 0, bad) + 1)
        self.cleaned = cleaned.replace(":", " : ")
        self.toks: List[str] = self.cleaned.split()
        self.n = len(self.toks)
        self.toks.extend([_EOF] * 12)  # sentinels: look-ahead never runs off the end
        self._line_ends: Optional[List[int]] = None
        self.i = 0
        self.names: Dict[str, Optional[Sequence[str]]] = {k: None for k in _KINDS}
        self.index: Dict[str, Dict[str, int]] = {}
        self.counts: Dict[str, int] = {}
        self.discount: Optional[float] = None
        self.values: Optional[str] = None
        self.start: Optional[Tuple] = None  # (form, data, token index)
        self.seen: Dict[str, int] = {}
        # events: every statement after the preamble gets a sequence number (its order)
        self.seq = 0
        self.ev_tok: List[int] = []
        # concrete single-entry events, the bulk of large files
        # a, s, s' (or o), p, seq: indices and sequence numbers are ints, p a float.
        self.t_pts: Tuple[List[Any], ...] = ([], [], [], [], [])
        self.o_pts: Tuple[List[Any], ...] = ([], [], [], [], [])
        self.t_special: List[tuple] = []
        self.o_special: List[tuple] = []
        self.r_cell: Tuple[List, ...] = ([], [], [], [])  # a, s, v, seq  (R: a : s : * : * v)
        self.r_cell_wild: List[tuple] = []
        self.r_fine_pts: Tuple[List, ...] = ([], [], [], [], [], [])  # a, s, s', o, v, seq
        self.r_fine: List[tuple] = []

    # ------------------------------------------------------------------ locations / errors
    def line_of(self, k: int) -> Optional[int]:
        """1-based line of token ``k`` (computed on demand: only errors need it)."""
        if self._line_ends is None:
            ends, total = [], 0
            for line in self.cleaned.split("\n"):
                total += len(line.split())
                ends.append(total)
            self._line_ends = ends
        if k >= self.n:  # end of file: the line of the last token
            k = max(self.n - 1, 0)
        return bisect.bisect_right(self._line_ends, k) + 1

    def fail(self, k: Optional[int], where: str, problem: str) -> NoReturn:
        raise ModelFormatError(self.source, where, problem, line=None if k is None else self.line_of(k))

    def show(self, k: int) -> str:
        t = self.toks[k]
        return "end of file" if t == _EOF else repr(t)

    def where(self, k0: int, k1: int) -> str:
        """The statement text from token k0 up to k1 (exclusive), compact."""
        parts = []
        for t in self.toks[k0:min(k1, k0 + 12)]:
            if t == ":":
                parts.append(":")
            else:
                parts.append(t)
        # "T: lisen" fails at "lisen": the field is "T", not "T:" (the message adds ": ").
        s = " ".join(parts).replace(" :", ":").rstrip(":")
        return s if len(s) <= 80 else s[:77] + "..."

    def row_token(self, k0: int, s: int, width: int) -> int:
        """The first token of row ``s`` written by the T/O statement at token ``k0``.

        ``T: a`` / ``O: a`` followed by numbers is a matrix whose row ``s`` starts ``s·width``
        numbers in; ``T: a : s`` / ``O: a : s`` followed by numbers is that one row. Any other
        form (points, ``uniform``, ``identity``) has no row of its own: its first token.
        """
        toks = self.toks
        if k0 + 3 >= self.n:
            return k0
        if toks[k0 + 3] != ":":
            first = k0 + 3
            offset = s * width
        elif k0 + 5 < self.n and toks[k0 + 5] != ":":
            first, offset = k0 + 5, 0
        else:
            return k0
        if toks[first][0] not in _DIGITS and toks[first][0] not in "+-.":
            return k0
        return min(first + offset, self.n - 1)

    def expect_colon(self, k0: int):
        if self.toks[self.i] != ":":
            self.fail(self.i, self.where(k0, self.i), f"expected ':' after {self.toks[self.i - 1]!r}, found {self.show(self.i)}")
        self.i += 1

    # ------------------------------------------------------------------ numbers
    def number(self, k0: int, what: str, prob: bool) -> float:
        """One number at the cursor; ``prob`` numbers are unsigned and in [0, 1]."""
        toks, i = self.toks, self.i
        t = toks[i]
        sign = 1.0
        if t in ("-", "+"):
            sign = -1.0 if t == "-" else 1.0
            i += 1
            t = toks[i]
        if not _NUMBER.match(t):
            self.fail(i, self.where(k0, self.i), f"expected {what}, found {self.show(i)}")
        v = sign * float(t)
        if prob and not (0.0 <= v <= 1.0 and t[0] not in "+-" and sign > 0):
            self.fail(i, self.where(k0, self.i), f"probability {t if sign > 0 else '-' + t} is not in [0, 1]")
        if not np.isfinite(v):
            self.fail(i, self.where(k0, self.i), f"number {t} is out of range")
        self.i = i + 1
        return v

    def numbers(self, k0: int, count: int, what: str, prob: bool) -> List[float]:
        """Exactly ``count`` numbers (a row or matrix); names the count found when wrong."""
        toks = self.toks
        start = i = self.i
        vals: List[float] = []
        append = vals.append
        match = _NUMBER.match
        while True:
            t = toks[i]
            c = t[0]
            if c in _DIGITS:
                if not match(t):
                    self.fail(i, self.where(k0, start), f"bad number {t!r}")
                append(float(t))
                i += 1
            elif c == "-" or c == "+":
                if t == "+" or t == "-":
                    nxt = toks[i + 1]
                    if not match(nxt) or nxt[0] in "+-":
                        self.fail(i, self.where(k0, start), f"bad number {t!r} {nxt!r}")
                    if prob and t == "-":
                        self.fail(i, self.where(k0, start), f"probability -{nxt} is not in [0, 1]")
                    append(float(nxt) * (-1.0 if t == "-" else 1.0))
                    i += 2
                else:
                    if not match(t):
                        self.fail(i, self.where(k0, start), f"bad number {t!r}")
                    if prob and c == "-":
                        self.fail(i, self.where(k0, start), f"probability {t} is not in [0, 1]")
                    append(float(t))
                    i += 1
            else:
                break
        if len(vals) != count:
            found = len(vals)
            self.fail(start if found == 0 else i - 1, self.where(k0, start),
                      f"{what} has {found} number{'s' if found != 1 else ''}, expected {count}"
                      + (f" (found {self.show(i)})" if found == 0 else ""))
        if vals:
            hi, lo = max(vals), min(vals)
            if prob and hi > 1.0:
                j = next(j for j, v in enumerate(vals) if v > 1.0)
                self.fail(start, self.where(k0, start), f"probability {toks[start + j]} (entry {j}) is greater than 1")
            if hi == _INF or lo == -_INF:
                self.fail(start, self.where(k0, start), f"{what} has a number out of range")
        self.i = i
        return vals

    # ------------------------------------------------------------------ references
    def ref(self, kind: str, k0: int) -> Optional[int]:
        """A state/action/observation at the cursor: index, or None for ``*``."""
        t = self.toks[self.i]
        if t == "*":
            self.i += 1
            return None
        v = self.index[kind].get(t)
        if v is None and t.isdigit() and int(t) < self.counts[kind]:
            v = int(t)  # a numbered reference to a named entity
        if v is None:
            noun = kind[:-1]
            if t.isdigit():
                self.fail(self.i, self.where(k0, self.i), f"{noun} index {t} is out of range (0..{self.counts[kind] - 1})")
            if t == _EOF or t == ":" or t in _STATEMENTS:
                self.fail(self.i, self.where(k0, self.i), f"expected a {noun} (name, index or '*'), found {self.show(self.i)}")
            names = self.names[kind] or []
            known = ", ".join(names[:8]) + (", ..." if len(names) > 8 else "")
            self.fail(self.i, self.where(k0, self.i), f"unknown {noun} {t!r} (known: {known})")
        self.i += 1
        return v

    # ------------------------------------------------------------------ main loop
    def parse(self, name: str) -> Pomdp:
        toks = self.toks
        n = self.n
        while self.i < n:
            k0 = self.i
            t = toks[k0]
            if t == "T":
                if not (self.seq and self._fast_t(k0)):
                    self.probabilities(k0, "T")
            elif t == "O":
                if not (self.seq and self._fast_o(k0)):
                    self.probabilities(k0, "O")
            elif t == "R":
                if not (self.seq and self._fast_r(k0)):
                    self.reward(k0)
            elif t in ("discount", "values", "states", "actions", "observations"):
                self.preamble(k0, t)
            elif t == "start":
                self.start_statement(k0)
            else:
                self.fail(k0, "", f"unexpected {self.show(k0)}; expected a statement "
                          "(discount, values, states, actions, observations, start, T, O, R)")
        return self.assemble(name)

    # Fast paths for the statement shapes that make up large files. Each returns False (having
    # consumed nothing) whenever anything is unusual; the general parser then handles the
    # statement and reports any error. Tokens are padded with end-of-file sentinels.
    def _fast_t(self, k0: int) -> bool:
        """``T : a : s : s' p`` with all three named/numbered (no wildcard)."""
        toks = self.toks
        if toks[k0 + 1] != ":" or toks[k0 + 3] != ":" or toks[k0 + 5] != ":":
            return False
        sidx = self.index["states"]
        a = self.index["actions"].get(toks[k0 + 2])
        s = sidx.get(toks[k0 + 4])
        s2 = sidx.get(toks[k0 + 6])
        pt = toks[k0 + 7]
        if a is None or s is None or s2 is None or pt[0] not in _DIGITS or "_" in pt:
            return False
        try:
            p = float(pt)
        except ValueError:
            return False
        if not 0.0 <= p <= 1.0:
            return False
        pts = self.t_pts
        pts[0].append(a)
        pts[1].append(s)
        pts[2].append(s2)
        pts[3].append(p)
        pts[4].append(self.seq)
        self.ev_tok.append(k0)
        self.seq += 1
        self.i = k0 + 8
        return True

    def _fast_o(self, k0: int) -> bool:
        """``O : a : s' p1 … pZ`` or ``O : a : s' : o p`` without wildcards."""
        toks = self.toks
        if toks[k0 + 1] != ":" or toks[k0 + 3] != ":":
            return False
        a = self.index["actions"].get(toks[k0 + 2])
        s = self.index["states"].get(toks[k0 + 4])
        if a is None or s is None:
            return False
        pts = self.o_pts
        if toks[k0 + 5] == ":":
            o = self.index["observations"].get(toks[k0 + 6])
            pt = toks[k0 + 7]
            if o is None or pt[0] not in _DIGITS or "_" in pt:
                return False
            try:
                p = float(pt)
            except ValueError:
                return False
            if not 0.0 <= p <= 1.0:
                return False
            pts[0].append(a)
            pts[1].append(s)
            pts[2].append(o)
            pts[3].append(p)
            end = k0 + 8
        else:
            Z = self.counts["observations"]
            if Z > 64:
                return False
            row_toks = toks[k0 + 5:k0 + 5 + Z]
            after = toks[k0 + 5 + Z] if k0 + 5 + Z < len(toks) else _EOF
            if after[0] in _DIGITS or after[0] in "+-" or any(t[0] not in _DIGITS or "_" in t for t in row_toks):
                return False
            try:
                row = [float(t) for t in row_toks]
            except ValueError:
                return False
            if len(row) != Z or max(row) > 1.0:
                return False
            pts[0].extend([a] * Z)
            pts[1].extend([s] * Z)
            pts[2].extend(range(Z))
            pts[3].extend(row)
            pts[4].extend([self.seq] * (Z - 1))
            end = k0 + 5 + Z
        pts[4].append(self.seq)
        self.ev_tok.append(k0)
        self.seq += 1
        self.i = end
        return True

    def _fast_r(self, k0: int) -> bool:
        """``R : a : s : * : * v`` with a and s named/numbered."""
        toks = self.toks
        if (toks[k0 + 1] != ":" or toks[k0 + 3] != ":" or toks[k0 + 5] != ":" or toks[k0 + 6] != "*"
                or toks[k0 + 7] != ":" or toks[k0 + 8] != "*"):
            return False
        a = self.index["actions"].get(toks[k0 + 2])
        s = self.index["states"].get(toks[k0 + 4])
        vt = toks[k0 + 9]
        if a is None or s is None or "_" in vt or vt in ("+", "-") or not (vt[0] in _DIGITS or vt[0] in "+-"):
            return False
        try:
            v = float(vt)
        except ValueError:
            return False
        if v == _INF or v == -_INF or v != v:
            return False
        c = self.r_cell
        c[0].append(a)
        c[1].append(s)
        c[2].append(v)
        c[3].append(self.seq)
        self.ev_tok.append(k0)
        self.seq += 1
        self.i = k0 + 10
        return True

    def need_preamble(self, k0: int):
        if len(self.index) == 3 and self.discount is not None:
            return
        missing = [f"'{k}:'" for k in ("discount",) if self.discount is None]
        missing += [f"'{k}:'" for k in _KINDS if k not in self.index]
        what = repr(self.toks[k0]) if k0 < self.n else "the end of the file"
        extra = " (a file without observations is an MDP; pearl reads POMDPs)" if "'observations:'" in missing else ""
        self.fail(k0, "", f"missing {', '.join(missing)} before {what}{extra}")

    def preamble(self, k0: int, kw: str):
        if kw in self.seen:
            self.fail(k0, kw, f"'{kw}:' given twice (first on line {self.line_of(self.seen[kw])})")
        if self.seq:
            self.fail(k0, kw, f"'{kw}:' must come before the first start/T/O/R statement")
        self.seen[kw] = k0
        self.i += 1
        self.expect_colon(k0)
        if kw == "discount":
            v = self.number(k0, "the discount factor", prob=False)
            if not 0.0 < v <= 1.0:
                self.fail(k0, kw, f"discount {v!r} is not in (0, 1]")
            self.discount = v
        elif kw == "values":
            t = self.toks[self.i]
            if t not in ("reward", "cost"):
                self.fail(self.i, kw, f"expected 'reward' or 'cost', found {self.show(self.i)}")
            self.values = t
            self.i += 1
        else:
            t = self.toks[self.i]
            noun = kw[:-1]
            if t.isdigit():
                count = int(t)
                if not 1 <= count <= _MAX_COUNT:
                    self.fail(self.i, kw, f"number of {kw} must be between 1 and {_MAX_COUNT:,}, got {count}")
                self.i += 1
                # Numbered entities: names are built only once the model's size is checked
                # (a 40-byte "states: 9999999" must not allocate a name list first); `ref`
                # resolves numbers without an index.
                self.names[kw] = _Numbered(count)
                self.index[kw] = {}
                self.counts[kw] = count
                return
            else:
                names = []
                while True:
                    t = self.toks[self.i]
                    if t == _EOF or t in _STATEMENTS:
                        break
                    if not NAME_PATTERN.match(t):
                        self.fail(self.i, kw, f"bad {noun} name {t!r} (a name is a letter followed by letters, digits, '_' or '-')")
                    if t in RESERVED_WORDS:
                        self.fail(self.i, kw, f"{noun} name {t!r} is a reserved word")
                    names.append(t)
                    self.i += 1
                if not names:
                    self.fail(k0, kw, f"expected a count or a list of {noun} names, found {self.show(self.i)}")
                index = {}
                for j, nm in enumerate(names):
                    if nm in index:
                        self.fail(k0, kw, f"{noun} name {nm!r} listed twice")
                    index[nm] = j
            self.names[kw] = names
            self.index[kw] = {nm: j for j, nm in enumerate(names)}
            self.counts[kw] = len(names)

    def check_size(self, k0: int) -> None:
        S, A, Z = self.counts["states"], self.counts["actions"], self.counts["observations"]
        if A * S * Z > _MAX_O_ENTRIES:
            self.fail(k0, "", f"model too large: O would hold {A}×{S}×{Z} = {A * S * Z:,} entries "
                      f"(limit {_MAX_O_ENTRIES:,})")

    def next_event(self, k0: int) -> int:
        if not self.seq:
            self.need_preamble(k0)
            self.check_size(k0)
        s = self.seq
        self.seq += 1
        self.ev_tok.append(k0)
        return s

    # ------------------------------------------------------------------ start
    def start_statement(self, k0: int):
        self.need_preamble(k0)
        if self.start is not None:
            self.fail(k0, "start", f"start belief given twice (first on line {self.line_of(self.start[2])})")
        self.i += 1
        t = self.toks[self.i]
        S = self.counts["states"]
        if t in ("include", "exclude"):
            self.i += 1
            self.expect_colon(k0)
            states = []
            while True:
                t = self.toks[self.i]
                if t == _EOF or t in _STATEMENTS:
                    break
                v = self.ref("states", k0)
                states.append(v)
            if not states:
                self.fail(self.i, self.where(k0, self.i), f"'start {t}:' lists no states")
            form = self.toks[k0 + 1]
            keep = np.zeros(S, bool) if form == "include" else np.ones(S, bool)
            for v in states:
                if v is None:
                    keep[:] = form == "include"
                else:
                    keep[v] = form == "include"
            if not keep.any():
                self.fail(k0, "start exclude", "excludes every state")
            b0 = keep.astype(float) / float(keep.sum())
            self.start = (form, b0, k0)
            return
        self.expect_colon(k0)
        t = self.toks[self.i]
        if t == "uniform":
            self.i += 1
            self.start = ("uniform", np.full(S, 1.0 / S), k0)
        elif t in self.index["states"] and not t.isdigit():
            self.i += 1
            b0 = np.zeros(S)
            b0[self.index["states"][t]] = 1.0
            self.start = ("state", b0, k0)
        elif NAME_PATTERN.match(t) and t not in RESERVED_WORDS:
            self.ref("states", k0)  # raises: unknown state
        else:
            b0 = np.array(self.numbers(k0, S, "the start vector", prob=True))
            total = b0.sum()
            if abs(total - 1.0) > SUM_TOLERANCE:
                self.fail(k0, "start", f"start probabilities sum to {total:.9g}, expected 1 (tolerance {SUM_TOLERANCE:g})")
            self.start = ("vector", b0, k0)

    # ------------------------------------------------------------------ T / O
    def probabilities(self, k0: int, kind: str):
        """A ``T:`` or ``O:`` statement (``kind``): one entry, a row or a matrix, as numbers or a
        word (T: ``uniform``/``reset`` rows, ``uniform``/``identity`` matrices; O: ``uniform``)."""
        seq = self.next_event(k0)
        self.i += 1
        self.expect_colon(k0)
        a = self.ref("actions", k0)
        toks = self.toks
        S = self.counts["states"]
        is_t = kind == "T"
        last, n = ("states", S) if is_t else ("observations", self.counts["observations"])
        pts, special = (self.t_pts, self.t_special) if is_t else (self.o_pts, self.o_special)
        if toks[self.i] == ":":
            self.i += 1
            s = self.ref("states", k0)
            if toks[self.i] == ":":
                self.i += 1
                x = self.ref(last, k0)
                p = self.number(k0, "a probability", prob=True)
                if a is not None and s is not None and x is not None:
                    pts[0].append(a)
                    pts[1].append(s)
                    pts[2].append(x)
                    pts[3].append(p)
                    pts[4].append(seq)
                else:
                    special.append((seq, "point", a, s, x, p))
                return
            t = toks[self.i]
            if t == "uniform" or (is_t and t == "reset"):
                self.i += 1
                special.append((seq, "row", a, s, None, t))
                return
            if not is_t and t in ("reset", "identity"):
                self.fail(self.i, self.where(k0, self.i), f"'{t}' is not valid for O (only 'uniform' or numbers)")
            what = f"a row of T (one probability per state, {S})" if is_t else \
                f"a row of O (one probability per observation, {n})"
            row = self.numbers(k0, n, what, prob=True)
            if not is_t and a is not None and s is not None:
                # concrete O rows are the bulk of some files (RockSample): keep them as points
                pts[0].extend([a] * n)
                pts[1].extend([s] * n)
                pts[2].extend(range(n))
                pts[3].extend(row)
                pts[4].extend([seq] * n)
            else:
                special.append((seq, "row", a, s, None, np.array(row)))
            return
        t = toks[self.i]
        if t == "uniform" or (is_t and t == "identity"):
            self.i += 1
            special.append((seq, "matrix", a, None, None, t))
        elif is_t and t == "reset":
            self.fail(self.i, self.where(k0, self.i), "'reset' is only valid for one row (T: a : s reset)")
        elif not is_t and t in ("reset", "identity"):
            self.fail(self.i, self.where(k0, self.i), f"'{t}' is not valid for O (only 'uniform' or numbers)")
        else:
            what = f"a T matrix ({S}×{S} probabilities)" if is_t else f"an O matrix ({S}×{n} probabilities)"
            mat = np.array(self.numbers(k0, S * n, what, prob=True))
            special.append((seq, "matrix", a, None, None, mat.reshape(S, n)))

    # ------------------------------------------------------------------ R
    def reward(self, k0: int):
        seq = self.next_event(k0)
        self.i += 1
        self.expect_colon(k0)
        a = self.ref("actions", k0)
        toks = self.toks
        S, Z = self.counts["states"], self.counts["observations"]
        if toks[self.i] != ":":
            self.fail(self.i, self.where(k0, self.i),
                      "'R: a' followed by a matrix is the MDP form; a POMDP needs 'R: a : s ...'")
        self.i += 1
        s = self.ref("states", k0)
        if toks[self.i] == ":":
            self.i += 1
            s2 = self.ref("states", k0)
            if toks[self.i] == ":":
                self.i += 1
                o = self.ref("observations", k0)
                v = self.number(k0, "a reward value", prob=False)
                if s2 is None and o is None:
                    if a is not None and s is not None:
                        c = self.r_cell
                        c[0].append(a)
                        c[1].append(s)
                        c[2].append(v)
                        c[3].append(seq)
                    else:
                        self.r_cell_wild.append((seq, a, s, v))
                elif a is not None and s is not None and s2 is not None and o is not None:
                    f = self.r_fine_pts
                    for lst, x in zip(f, (a, s, s2, o, v, seq)):
                        lst.append(x)
                else:
                    self.r_fine.append((seq, "point", a, s, s2, o, v))
                return
            row = np.array(self.numbers(k0, Z, f"a reward row (one value per observation, {Z})", prob=False))
            self.r_fine.append((seq, "row", a, s, s2, None, row))
            return
        mat = np.array(self.numbers(k0, S * Z, f"a reward matrix ({S}×{Z} values, next state × observation)", prob=False))
        self.r_fine.append((seq, "matrix", a, s, None, None, mat.reshape(S, Z)))

    # ================================================================== assembly
    def _sel(self, v: Optional[int], n: int) -> np.ndarray:
        return np.arange(n) if v is None else np.array([v])

    def _table(self, pts, specials, A: int, S: int, K: int, label: str, b0: Optional[np.ndarray]):
        """Resolve T (K = S) or O (K = Z) events: last statement wins per entry.

        Returns sorted unique linear keys ``(a*S + s)*K + k`` of the nonzero entries, their
        values (rows renormalised), and the number of rows renormalised.
        """
        a_l, s_l, k_l, v_l, q_l = [np.asarray(x) for x in pts]
        keys = [a_l.astype(np.int64) * S * K + s_l.astype(np.int64) * K + k_l.astype(np.int64)]
        vals = [v_l.astype(float)]
        seqs = [q_l.astype(np.int64)]
        clear = np.full((A, S), -1, dtype=np.int64)
        budget = _EXPANSION_BUDGET
        for seq, form, a, s, k, data in specials:
            asel, ssel = self._sel(a, A), self._sel(s, S)
            if form == "point" and k is not None:
                aa, ss = np.meshgrid(asel, ssel, indexing="ij")
                key = (aa.ravel().astype(np.int64) * S + ss.ravel()) * K + k
                val = np.full(key.size, data)
            else:
                # the statement covers whole rows: clear them, then add its nonzero entries
                if form == "matrix":
                    clear[asel, :] = seq
                    ssel = np.arange(S)
                else:
                    clear[np.ix_(asel, ssel)] = seq
                if form == "point":
                    row = None if data == 0.0 else np.full(K, data)
                    rows = None
                elif isinstance(data, str):
                    if data == "uniform":
                        row, rows = np.full(K, 1.0 / K), None
                    elif data == "reset":
                        row, rows = b0, None
                    else:  # identity
                        row, rows = None, "identity"
                elif form == "row":
                    row, rows = data, None
                else:
                    row, rows = None, data
                if row is None and rows is None:
                    continue
                if isinstance(rows, str):  # identity: S entries per action
                    aa = np.repeat(asel, S).astype(np.int64)
                    ss = np.tile(np.arange(S), asel.size)
                    key = (aa * S + ss) * K + ss
                    val = np.ones(key.size)
                elif rows is not None:
                    r_s, r_k = np.nonzero(rows)
                    base = (r_s.astype(np.int64) * K + r_k)
                    key = (np.repeat(asel.astype(np.int64) * S * K, base.size) + np.tile(base, asel.size))
                    val = np.tile(rows[r_s, r_k], asel.size)
                else:
                    assert row is not None   # (a row that is None and no rows was skipped above)
                    nz = np.flatnonzero(row)
                    n = asel.size * ssel.size * nz.size
                    if n > budget:
                        self.fail(self.ev_tok[seq], label, f"this statement expands to {n:,} entries; too large "
                                  f"for a model with {S} states (write the entries sparsely)")
                    rowkey = (asel[:, None].astype(np.int64) * S + ssel[None, :]).ravel() * K
                    key = (rowkey[:, None] + nz[None, :]).ravel()
                    val = np.tile(row[nz], rowkey.size)
            budget -= key.size
            if budget < 0:
                self.fail(self.ev_tok[seq], label, f"the {label} statements expand to more than "
                          f"{_EXPANSION_BUDGET:,} entries; too large")
            keys.append(key)
            vals.append(val)
            seqs.append(np.full(key.size, seq, dtype=np.int64))
        key = np.concatenate(keys)
        val = np.concatenate(vals)
        seq = np.concatenate(seqs)
        row_of = key // K
        keep = seq >= clear.ravel()[row_of]
        if not keep.all():
            key, val, seq, row_of = key[keep], val[keep], seq[keep], row_of[keep]
        order = np.lexsort((seq, key))
        key, val, seq, row_of = key[order], val[order], seq[order], row_of[order]
        last = np.ones(key.size, bool)
        last[:-1] = key[1:] != key[:-1]
        key, val, seq, row_of = key[last], val[last], seq[last], row_of[last]
        sums = np.bincount(row_of, weights=val, minlength=A * S)
        bad = np.flatnonzero(np.abs(sums - 1.0) > SUM_TOLERANCE)
        if bad.size:
            r = int(bad[0])
            a, s = divmod(r, S)
            last_seq = max(int(seq[row_of == r].max(initial=-1)), int(clear[a, s]))
            actions, states = self.names["actions"], self.names["states"]
            assert actions is not None and states is not None   # the preamble named them
            where = f"{label}: {actions[a]} : {states[s]}"
            if last_seq < 0:
                self.fail(None, where, f"row sums to 0: no {label} entries for this action and state "
                          f"({bad.size} such row{'s' if bad.size != 1 else ''} in all)")
            self.fail(self.row_token(self.ev_tok[last_seq], s, K), where,
                      f"row sums to {sums[r]:.9g}, expected 1 (tolerance {SUM_TOLERANCE:g}; "
                      f"line of the row in the last {label} statement for it)")
        nz = val != 0.0
        key, val, row_of = key[nz], val[nz], row_of[nz]
        fix = np.abs(sums - 1.0) > RENORMALISE_ABOVE
        renorm = int(fix.sum())
        if renorm:
            val = np.where(fix[row_of], val / sums[row_of], val)
        return key, val, renorm

    def assemble(self, name: str) -> Pomdp:
        self.need_preamble(self.n)
        self.check_size(self.n)
        S, A, Z = self.counts["states"], self.counts["actions"], self.counts["observations"]
        start_form = "default"
        if self.start is None:
            b0 = np.full(S, 1.0 / S)
        else:
            start_form, b0, _ = self.start
        start_renorm = False
        if start_form == "vector" and abs(b0.sum() - 1.0) > RENORMALISE_ABOVE:
            b0 = b0 / b0.sum()
            start_renorm = True

        tkey, tval, t_ren = self._table(self.t_pts, self.t_special, A, S, S, "T", b0)
        okey, oval, o_ren = self._table(self.o_pts, self.o_special, A, S, Z, "O", None)

        # T: one matrix per action straight from the sorted unique keys, dense up to
        # DENSE_LIMIT (as Pomdp would store it; no scipy import), else CSR
        T: List[Any] = []
        if S * S <= DENSE_LIMIT:
            dense = np.zeros(A * S * S)
            dense[tkey] = tval
            T = list(dense.reshape(A, S, S))
        else:
            import scipy.sparse as sp

            ta = tkey // (S * S)
            rest = tkey - ta * (S * S)
            ts, tsp = rest // S, rest % S
            bounds = np.searchsorted(ta, np.arange(A + 1))
            for a in range(A):
                lo, hi = bounds[a], bounds[a + 1]
                indptr = np.searchsorted(ts[lo:hi], np.arange(S + 1)).astype(np.int64)
                T.append(sp.csr_matrix((tval[lo:hi], tsp[lo:hi], indptr), shape=(S, S)))
        O_flat = np.zeros(A * S * Z)
        O_flat[okey] = oval
        O = O_flat.reshape(A, S, Z)

        R, depends = self.rewards(A, S, Z, T, O)
        values = self.values or "reward"
        if values == "cost":
            R = -R
        states, actions, observations = self.names["states"], self.names["actions"], self.names["observations"]
        assert states is not None and actions is not None and observations is not None and self.discount is not None
        try:   # (the preamble checks made every name list and the discount present)
            model = Pomdp.create(list(states), list(actions), list(observations),
                                 T, O, R, b0=b0, discount=self.discount, name=name, tolerance=1e-6)
        except ValueError as err:  # should not happen after our checks; keep the contract
            raise ModelFormatError(self.source, "", str(err)) from None
        model.metadata.update({
            "format": "pomdp",
            "source": self.source,
            "values": values,
            "start": start_form,
            "renormalised": {"T_rows": t_ren, "O_rows": o_ren, "start": start_renorm},
            "reward_depends_on_next": depends,
        })
        return model

    # ------------------------------------------------------------------ rewards
    def rewards(self, A: int, S: int, Z: int, T: List[Any], O: np.ndarray) -> Tuple[np.ndarray, bool]:
        """``R[s, a]`` by pomdp-solve's rule (last statement wins per (a, s, s', o), expectation)."""
        # cells (a, s): statements whose s' and o are both '*'
        ca, cs, cv, cq = [np.asarray(x) for x in self.r_cell]
        keys = [ca.astype(np.int64) * S + cs.astype(np.int64)]
        vals = [cv.astype(float)]
        seqs = [cq.astype(np.int64)]
        for seq, a, s, v in self.r_cell_wild:
            aa, ss = np.meshgrid(self._sel(a, A), self._sel(s, S), indexing="ij")
            k = (aa.astype(np.int64) * S + ss).ravel()
            keys.append(k)
            vals.append(np.full(k.size, v))
            seqs.append(np.full(k.size, seq, dtype=np.int64))
        key, val, seq = np.concatenate(keys), np.concatenate(vals), np.concatenate(seqs)
        order = np.lexsort((seq, key))
        key, val, seq = key[order], val[order], seq[order]
        last = np.ones(key.size, bool)
        last[:-1] = key[1:] != key[:-1]
        flat_val = np.zeros(A * S)
        flat_seq = np.full(A * S, -1, dtype=np.int64)
        flat_val[key[last]] = val[last]
        flat_seq[key[last]] = seq[last]
        cell_val = flat_val.reshape(A, S)
        cell_seq = flat_seq.reshape(A, S)
        R = cell_val.T.copy()

        fa, fs, fsp, fo, fv, fq = [np.asarray(x) for x in self.r_fine_pts]
        if not self.r_fine and fa.size == 0:
            return R, False
        # concrete (a, s, s', o) statements: last one per key
        pkey = ((fa.astype(np.int64) * S + fs) * S + fsp) * Z + fo
        order = np.lexsort((fq, pkey))
        pkey, pval, pseq = pkey[order], fv[order].astype(float), fq[order].astype(np.int64)
        last = np.ones(pkey.size, bool)
        last[:-1] = pkey[1:] != pkey[:-1]
        pkey, pval, pseq = pkey[last], pval[last], pseq[last]
        fine_actions = set(int(x) for x in np.unique(fa))
        for ev in self.r_fine:
            fine_actions.update(range(A) if ev[2] is None else [ev[2]])
        depends = False
        for a in sorted(fine_actions):
            Ta = _Coo(T[a])
            Oa = O[a]
            # support: (s, s', o) with T[a][s, s'] > 0 and O[a, s', o] > 0
            nz_sp, nz_o = np.nonzero(Oa)
            cnt = np.bincount(nz_sp, minlength=S)
            first = np.concatenate(([0], np.cumsum(cnt)[:-1]))
            reps = cnt[Ta.col]
            idx = np.repeat(np.arange(Ta.nnz), reps)
            offs = np.arange(idx.size) - np.repeat(np.cumsum(reps) - reps, reps)
            s_ = Ta.row[idx].astype(np.int64)
            sp_ = Ta.col[idx].astype(np.int64)
            o_ = nz_o[first[sp_] + offs].astype(np.int64)
            prob = Ta.data[idx] * Oa[sp_, o_]
            best_seq = cell_seq[a, s_].copy()
            best_val = cell_val[a, s_].copy()
            if pkey.size:
                q = ((a * S + s_) * S + sp_) * Z + o_
                pos = np.searchsorted(pkey, q)
                pos_c = np.minimum(pos, pkey.size - 1)
                hit = (pkey[pos_c] == q) & (pseq[pos_c] > best_seq)
                best_seq[hit] = pseq[pos_c[hit]]
                best_val[hit] = pval[pos_c[hit]]
            for seq, form, ea, es, esp, eo, data in self.r_fine:
                if ea is not None and ea != a:
                    continue
                m = seq > best_seq
                if es is not None:
                    m &= s_ == es
                if esp is not None:
                    m &= sp_ == esp
                if eo is not None:
                    m &= o_ == eo
                if form == "matrix":
                    # pomdp-solve stores an R matrix sparsely: its (near-)zero entries
                    # (|v| < 1e-10, IS_ZERO) are absent and do not override earlier statements
                    m &= np.abs(data[sp_, o_]) >= 1e-10
                if not m.any():
                    continue
                best_seq[m] = seq
                if form == "point":
                    best_val[m] = data
                elif form == "row":
                    best_val[m] = data[o_[m]]
                else:
                    best_val[m] = data[sp_[m], o_[m]]
            won = best_seq > cell_seq[a, s_]
            if not won.any():
                continue
            depends = True
            mixed = np.bincount(s_[won], minlength=S) > 0
            expect = np.bincount(s_, weights=prob * best_val, minlength=S)
            R[mixed, a] = expect[mixed]
        return R, depends
