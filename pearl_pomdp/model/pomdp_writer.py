"""Cassandra's ``.pomdp`` file format: the lossless writer (:func:`format_pomdp`,
:func:`write_pomdp`); :mod:`pearl_pomdp.model.pomdp_format` reads what it writes back identically.

The number texts (:func:`real_text`, :func:`probability_text`) are shared with the PomdpX writer.
"""
from __future__ import annotations

import re
from pathlib import Path
from typing import List, Optional, Sequence, Tuple, Union

import numpy as np

from pearl_pomdp.atomic import atomic_write
from pearl_pomdp.model.pomdp import Pomdp, issparse
from pearl_pomdp.model.pomdp_format import NAME_PATTERN, RESERVED_WORDS

__all__ = ["format_pomdp", "write_pomdp", "real_text", "probability_text", "deduplicated"]

PathLike = Union[str, Path]


def _file_names(names: Sequence[str], prefix: str) -> Tuple[Optional[List[str]], bool]:
    """Names as the file will hold them: ``None`` for a count, else a valid, unique list.

    Returns (names or None, renamed?). Names that are not valid identifiers are made so
    (other characters become ``_``; a leading non-letter gets ``prefix``); duplicates get ``_2``…
    """
    names = [str(n) for n in names]
    if names == [str(j) for j in range(len(names))]:
        return None, False
    if all(NAME_PATTERN.match(n) and n not in RESERVED_WORDS for n in names):
        return names, False

    def identifier(n: str) -> str:
        m = re.sub(r"[^A-Za-z0-9_\-]", "_", n)
        m = m if m and m[0].isalpha() else prefix + m
        return m + "_" if m in RESERVED_WORDS else m

    return deduplicated([identifier(n) for n in names]), True


def deduplicated(names: Sequence[str]) -> List[str]:
    """``names`` with each repeat suffixed ``_2``, ``_3``, … (the first keeps its name)."""
    out: List[str] = []
    used = set()
    for m in names:
        base, j = m, 2
        while m in used:
            m = f"{base}_{j}"
            j += 1
        used.add(m)
        out.append(m)
    return out


def real_text(x: float) -> str:
    """Lossless float text (shortest repr; ``-0`` keeps the sign of a negative zero)."""
    x = float(x)
    if x == 0.0:
        return "-0" if np.signbit(x) else "0"
    if x == 1.0:
        return "1"
    return repr(x)


def probability_text(x: float) -> str:
    """A probability: as :func:`real_text`, but any zero is ``0`` (a probability has no sign)."""
    x = float(x)
    return "0" if x == 0.0 else real_text(x)


def format_pomdp(model: Pomdp) -> str:
    """The model as ``.pomdp`` text that :func:`~pearl_pomdp.model.pomdp_format.parse_pomdp` reads back *identically*.

    Floats are written with ``repr`` (shortest round-trip form). Small dense transition
    matrices are written as rows (``T: a : s`` + row); large or sparse ones as
    ``T: a : s : s' p`` lines for the nonzero entries; ``identity``/``uniform`` are used when
    exact. Rewards are written per cell (``R: a : s : * : * v``) after a per-action default
    (``R: a : * : * : * c``) when most cells share it. ``metadata["values"] == "cost"`` writes
    costs (negated rewards) under ``values: cost``. Names that are not valid ``.pomdp``
    identifiers are renamed (and the file says so in a comment).
    """
    S, A, Z = model.num_states, model.num_actions, model.num_observations
    out: List[str] = []
    w = out.append
    st_names, st_ren = _file_names(model.states, "s")
    ac_names, ac_ren = _file_names(model.actions, "a")
    ob_names, ob_ren = _file_names(model.observations, "o")
    title = " ".join(str(model.name).split()).encode("ascii", "replace").decode("ascii")
    w(f"# {title}: written by pearl_pomdp ({S} states, {A} actions, {Z} observations)")
    if st_ren or ac_ren or ob_ren:
        w("# names that are not .pomdp identifiers were renamed (other characters became '_')")
    w("")
    w(f"discount: {repr(float(model.discount))}")
    cost = model.metadata.get("values") == "cost"
    w(f"values: {'cost' if cost else 'reward'}")
    st = st_names if st_names is not None else [str(j) for j in range(S)]
    ac = ac_names if ac_names is not None else [str(j) for j in range(A)]
    ob = ob_names if ob_names is not None else [str(j) for j in range(Z)]
    w(f"states: {S if st_names is None else ' '.join(st_names)}")
    w(f"actions: {A if ac_names is None else ' '.join(ac_names)}")
    w(f"observations: {Z if ob_names is None else ' '.join(ob_names)}")
    w("")
    b0 = np.asarray(model.b0, dtype=float)
    support = b0 > 0
    k = int(support.sum())
    if np.array_equal(b0, np.full(S, 1.0 / S)):
        w("start: uniform")
    elif k and np.array_equal(b0, support.astype(float) / float(k)):
        w("start include: " + " ".join(st[j] for j in np.flatnonzero(support)))
    else:
        w("start: " + " ".join(probability_text(x) for x in b0))
    w("")

    for a in range(A):
        Ta = model.T[a]
        if issparse(Ta):
            import scipy.sparse as sp

            Tc = sp.csr_matrix(Ta)
            Tc.sum_duplicates()
            Tc.eliminate_zeros()
            Tc.sort_indices()
            dense = None
            nnz = Tc.nnz
        else:
            dense = np.asarray(Ta, dtype=float)
            nnz = int(np.count_nonzero(dense))
            Tc = None
        if nnz == S and (dense is not None and np.array_equal(dense, np.eye(S))
                         or Tc is not None and np.array_equal(Tc.indices, np.arange(S))
                         and np.array_equal(Tc.indptr, np.arange(S + 1)) and (Tc.data == 1.0).all()):
            w(f"T: {ac[a]} identity")
            continue
        if dense is not None and nnz == S * S and (dense == 1.0 / S).all():
            w(f"T: {ac[a]} uniform")
            continue
        if dense is not None and S <= 100 and nnz >= 0.25 * S * S:
            for s in range(S):
                w(f"T: {ac[a]} : {st[s]} " + " ".join(probability_text(x) for x in dense[s]))
            continue
        if Tc is None:
            import scipy.sparse as sp

            Tc = sp.csr_matrix(dense)
            Tc.sort_indices()
        indptr, indices, data = Tc.indptr, Tc.indices, Tc.data
        for s in range(S):
            lo, hi = indptr[s], indptr[s + 1]
            pre = f"T: {ac[a]} : {st[s]} : "
            for j in range(lo, hi):
                w(f"{pre}{st[indices[j]]} {probability_text(data[j])}")
    w("")

    O = np.asarray(model.O, dtype=float)
    for a in range(A):
        Oa = O[a]
        if (Oa == Oa[0]).all():
            if (Oa[0] == 1.0 / Z).all():
                w(f"O: {ac[a]} uniform")
            else:
                w(f"O: {ac[a]} : * " + " ".join(probability_text(x) for x in Oa[0]))
            continue
        dense_rows = Z <= 16 or np.count_nonzero(Oa) >= 0.25 * S * Z
        for s in range(S):
            if dense_rows:
                w(f"O: {ac[a]} : {st[s]} " + " ".join(probability_text(x) for x in Oa[s]))
            else:
                for o in np.flatnonzero(Oa[s]):
                    w(f"O: {ac[a]} : {st[s]} : {ob[o]} {probability_text(Oa[s, o])}")
    w("")

    R = np.asarray(model.R, dtype=float)
    if cost:
        R = -R
    for a in range(A):
        col = R[:, a]
        vals, counts = np.unique(col, return_counts=True)
        c = float(vals[np.argmax(counts)])
        if counts.max() * 2 <= S or c == 0.0:
            c = 0.0  # (+0: a file's unset cells are +0; negative zeros are written explicitly)
        if c != 0.0:
            w(f"R: {ac[a]} : * : * : * {real_text(c)}")
        # a cell differs from the default if its value or the sign of a zero differs
        for cell in np.flatnonzero((col != c) | (np.signbit(col) != np.signbit(c))):
            w(f"R: {ac[a]} : {st[cell]} : * : * {real_text(col[cell])}")
    w("")
    return "\n".join(out)


def write_pomdp(model: Pomdp, path: PathLike) -> Path:
    """Write ``model`` as a ``.pomdp`` file atomically (temporary file + rename); returns the path."""
    return atomic_write(path, format_pomdp(model), encoding="ascii")
