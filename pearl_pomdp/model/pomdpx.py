"""PomdpX (SARSOP's XML format), flat form: writer and reader.

The flat form has one state variable whose values are the model's states, one observation
variable, one action variable and one reward variable::

    <StateVar vnamePrev="state_0" vnameCurr="state_1" fullyObs="false"><ValueEnum>…</ValueEnum></StateVar>
    <ObsVar vname="obs_sensor">…   <ActionVar vname="action_agent">…   <RewardVar vname="reward_agent"/>
    <InitialStateBelief>      CondProb state_0 | null, Instance "-", ProbTable b0
    <StateTransitionFunction> CondProb state_1 | action_agent state_0   (Instance "a s s'")
    <ObsFunction>             CondProb obs_sensor | action_agent state_1 (Instance "a s' o")
    <RewardFunction>          Func reward_agent | action_agent state_0   (Instance "a s", ValueTable)

This is the layout of SARSOP's own flat examples (``examples/POMDPX/Tiger.pomdpx``,
``Hallway.pomdpx``) and of ``doc/POMDPX/pomdpx.xsd``, checked against SARSOP's parser
(``src/Parser/POMDPX/FactoredPomdp.cpp``): an ``Instance`` has one token per parent plus one for
the variable (``-`` = every value, the table then lists them all; ``*`` = every value, one number
for all), ``identity`` needs the last two tokens to be ``-``, ``uniform`` is only for the initial
belief, numbers are read with ``atof`` (so ``repr`` floats such as ``1e-05`` are fine), every
parent combination of a CondProb needs an entry, and rows are checked to sum to 1.

The writer uses ``repr`` floats, so :func:`read_pomdpx` gives back the identical model (names,
arrays, fingerprint). Sparse models are written as one ``Entry`` per nonzero; small dense ones
as rows (``a s -``). The schema restricts the discount to [0, 1): a model with γ = 1 is written
as is, and SARSOP may refuse it.

The reader accepts the flat form (``ValueEnum`` or ``NumValues`` — SARSOP then names the values
``s0…``, ``o0…``, ``a0…`` —, entries with ``-``, ``*``, ``identity``, ``uniform``; a later entry
overrides an earlier one). Factored PomdpX (several state variables) is not read.
"""
from __future__ import annotations

import re
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import List, NoReturn, Optional, Sequence, Tuple, Union

import numpy as np
import scipy.sparse as sp

from pearl_pomdp.atomic import atomic_write
from pearl_pomdp.errors import ModelFormatError
from pearl_pomdp.model.pomdp import Pomdp
from pearl_pomdp.model.pomdp_format import RENORMALISE_ABOVE, SUM_TOLERANCE
from pearl_pomdp.model.pomdp_writer import deduplicated, probability_text, real_text

__all__ = ["write_pomdpx", "format_pomdpx", "read_pomdpx", "parse_pomdpx"]

PathLike = Union[str, Path]
STATE_PREV, STATE_CURR, OBS, ACTION, REWARD = "state_0", "state_1", "obs_sensor", "action_agent", "reward_agent"
_SAFE = re.compile(r"[A-Za-z0-9_.=,:+\-]+\Z")
_SPECIAL = {"-", "*", "null", "identity", "uniform"}
_BUDGET = 30_000_000


# =====================================================================================  writer
def _token_names(names: Sequence[str], prefix: str) -> List[str]:
    """Names usable as PomdpX tokens (no spaces, not '-', '*', 'null'); unsafe ones rewritten."""
    names = [str(n) for n in names]
    if all(_SAFE.match(n) and n.lower() not in _SPECIAL for n in names):
        return names
    cleaned = [re.sub(r"[^A-Za-z0-9_.=,:+\-]", "_", n) or prefix for n in names]
    return deduplicated([prefix + m if m.lower() in _SPECIAL else m for m in cleaned])


def format_pomdpx(model: Pomdp) -> str:
    """The model as flat PomdpX text (see the module docstring)."""
    S, A, Z = model.num_states, model.num_actions, model.num_observations
    st = _token_names(model.states, "s")
    ac = _token_names(model.actions, "a")
    ob = _token_names(model.observations, "o")
    out: List[str] = []
    w = out.append
    name = re.sub(r"[^A-Za-z0-9_.\-]", "_", model.name) or "pomdp"
    w('<?xml version="1.0" encoding="ISO-8859-1"?>')
    w(f'<pomdpx version="1.0" id="{name}" xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance" '
      'xsi:noNamespaceSchemaLocation="pomdpx.xsd">')
    w(f"<Description>{name}: written by pearl_pomdp ({S} states, {A} actions, {Z} observations)</Description>")
    w(f"<Discount>{repr(float(model.discount))}</Discount>")
    w("<Variable>")
    w(f'<StateVar vnamePrev="{STATE_PREV}" vnameCurr="{STATE_CURR}" fullyObs="false">')
    w(f"<ValueEnum>{' '.join(st)}</ValueEnum>")
    w("</StateVar>")
    w(f'<ObsVar vname="{OBS}">')
    w(f"<ValueEnum>{' '.join(ob)}</ValueEnum>")
    w("</ObsVar>")
    w(f'<ActionVar vname="{ACTION}">')
    w(f"<ValueEnum>{' '.join(ac)}</ValueEnum>")
    w("</ActionVar>")
    w(f'<RewardVar vname="{REWARD}"/>')
    w("</Variable>")

    def entry(inst: str, table: str, kind: str = "ProbTable"):
        w(f"<Entry><Instance>{inst}</Instance><{kind}>{table}</{kind}></Entry>")

    w("<InitialStateBelief>")
    w(f"<CondProb><Var>{STATE_PREV}</Var><Parent>null</Parent><Parameter type=\"TBL\">")
    entry("-", " ".join(probability_text(x) for x in model.b0))
    w("</Parameter></CondProb>")
    w("</InitialStateBelief>")

    w("<StateTransitionFunction>")
    w(f"<CondProb><Var>{STATE_CURR}</Var><Parent>{ACTION} {STATE_PREV}</Parent><Parameter type=\"TBL\">")
    for a in range(A):
        Tc = sp.csr_matrix(model.T[a], dtype=float)
        Tc.sum_duplicates()
        Tc.eliminate_zeros()
        Tc.sort_indices()
        if (Tc.nnz == S and np.array_equal(Tc.indices, np.arange(S)) and np.array_equal(Tc.indptr, np.arange(S + 1))
                and (Tc.data == 1.0).all()):
            entry(f"{ac[a]} - -", "identity")
            continue
        if S <= 100 and Tc.nnz >= 0.25 * S * S:
            dense = Tc.toarray()
            for s in range(S):
                entry(f"{ac[a]} {st[s]} -", " ".join(probability_text(x) for x in dense[s]))
            continue
        for s in range(S):
            for j in range(Tc.indptr[s], Tc.indptr[s + 1]):
                entry(f"{ac[a]} {st[s]} {st[Tc.indices[j]]}", probability_text(Tc.data[j]))
    w("</Parameter></CondProb>")
    w("</StateTransitionFunction>")

    w("<ObsFunction>")
    w(f"<CondProb><Var>{OBS}</Var><Parent>{ACTION} {STATE_CURR}</Parent><Parameter type=\"TBL\">")
    O = np.asarray(model.O, dtype=float)
    for a in range(A):
        Oa = O[a]
        if (Oa == Oa[0]).all():
            entry(f"{ac[a]} * -", " ".join(probability_text(x) for x in Oa[0]))
            continue
        rows = Z <= 16 or np.count_nonzero(Oa) >= 0.25 * S * Z
        for s in range(S):
            if rows:
                entry(f"{ac[a]} {st[s]} -", " ".join(probability_text(x) for x in Oa[s]))
            else:
                for o in np.flatnonzero(Oa[s]):
                    entry(f"{ac[a]} {st[s]} {ob[o]}", probability_text(Oa[s, o]))
    w("</Parameter></CondProb>")
    w("</ObsFunction>")

    w("<RewardFunction>")
    w(f"<Func><Var>{REWARD}</Var><Parent>{ACTION} {STATE_PREV}</Parent><Parameter type=\"TBL\">")
    R = np.asarray(model.R, dtype=float)
    written = 0
    for a in range(A):
        for cell in np.flatnonzero((R[:, a] != 0) | np.signbit(R[:, a])):
            entry(f"{ac[a]} {st[cell]}", real_text(R[cell, a]), "ValueTable")
            written += 1
    if not written:
        entry("* *", "0", "ValueTable")
    w("</Parameter></Func>")
    w("</RewardFunction>")
    w("</pomdpx>")
    w("")
    return "\n".join(out)


def write_pomdpx(model: Pomdp, path: PathLike) -> Path:
    """Write ``model`` as flat PomdpX (SARSOP-readable), atomically; returns the path."""
    return atomic_write(path, format_pomdpx(model), encoding="ascii")


# =====================================================================================  reader
def read_pomdpx(path: PathLike) -> Pomdp:
    """Read a flat PomdpX file (one state variable) into a :class:`Pomdp`.

    Raises:
        ModelFormatError: not well-formed XML, factored, or inconsistent (names file and line
            where the XML parser or the element gives one).
    """
    path = Path(path)
    return parse_pomdpx(path.read_bytes(), source=str(path), name=path.name.rsplit(".", 1)[0] or "pomdp")


def parse_pomdpx(data: Union[str, bytes], source: str = "<string>", name: str = "pomdp") -> Pomdp:
    """Parse PomdpX text; see :func:`read_pomdpx`."""
    try:
        root = ET.fromstring(data)
    except ET.ParseError as err:
        line = err.position[0] if getattr(err, "position", None) else None
        raise ModelFormatError(source, "", f"not well-formed XML: {err}", line=line) from None
    return _Reader(root, source).model(name)


class _Reader:
    def __init__(self, root: ET.Element, source: str):
        self.source = source
        self.root = root
        if root.tag != "pomdpx":
            self.fail("", f"root element is <{root.tag}>, expected <pomdpx>")

    def fail(self, where: str, problem: str) -> NoReturn:
        raise ModelFormatError(self.source, where, problem)

    def text(self, el: Optional[ET.Element], where: str) -> str:
        if el is None or el.text is None:
            self.fail(where, "missing or empty")
        return el.text.strip()

    def values(self, el: ET.Element, where: str, prefix: str) -> List[str]:
        enum = el.find("ValueEnum")
        if enum is not None:
            names = (enum.text or "").split()
            if not names:
                self.fail(f"{where}.ValueEnum", "is empty")
            if len(set(names)) != len(names):
                self.fail(f"{where}.ValueEnum", "lists a value twice")
            return names
        num = el.find("NumValues")
        try:
            n = int(self.text(num, f"{where}.NumValues"))
        except ValueError:
            self.fail(f"{where}.NumValues", "is not an integer")
        if n < 1:
            self.fail(f"{where}.NumValues", f"must be at least 1, got {n}")
        return [f"{prefix}{i}" for i in range(n)]

    def model(self, name: str) -> Pomdp:
        root = self.root
        try:
            discount = float(self.text(root.find("Discount"), "Discount"))
        except ValueError:
            self.fail("Discount", "is not a number")
        var = root.find("Variable")
        if var is None:
            self.fail("Variable", "missing")
        svars, ovars, avars = var.findall("StateVar"), var.findall("ObsVar"), var.findall("ActionVar")
        if len(svars) != 1:
            self.fail("Variable.StateVar", f"{len(svars)} state variables; only the flat form (one) is read")
        if len(ovars) != 1 or len(avars) != 1:
            self.fail("Variable", "needs exactly one ObsVar and one ActionVar")
        sv = svars[0]
        given = [sv.get("vnamePrev"), sv.get("vnameCurr"), ovars[0].get("vname"), avars[0].get("vname")]
        vnames: List[str] = []
        for label, vn in zip(("StateVar.vnamePrev", "StateVar.vnameCurr", "ObsVar.vname", "ActionVar.vname"), given):
            if not vn or not vn.strip() or vn.split() != [vn] or vn in ("null", "-", "*"):
                self.fail(f"Variable.{label}", f"missing or invalid variable name {vn!r}")
            vnames.append(vn)
        self.prev, self.curr, self.oname, self.aname = vnames
        if len(set(vnames)) != 4:
            self.fail("Variable", f"variable names must be distinct, got {' '.join(vnames)}")
        states = self.values(sv, "StateVar", "s")
        observations = self.values(ovars[0], "ObsVar", "o")
        actions = self.values(avars[0], "ActionVar", "a")
        S, A, Z = len(states), len(actions), len(observations)
        self.enum = {self.prev: states, self.curr: states, self.oname: observations, self.aname: actions}
        self.lookup = {k: {n: i for i, n in enumerate(v)} for k, v in self.enum.items()}

        b_key, b_val = self.table("InitialStateBelief", self.prev, ["null"], prob=True)
        b0 = np.zeros(S)
        b0[b_key] = b_val
        t_key, t_val = self.table("StateTransitionFunction", self.curr, [self.aname, self.prev], prob=True)
        o_key, o_val = self.table("ObsFunction", self.oname, [self.aname, self.curr], prob=True)
        r_key, r_val = self.table("RewardFunction", None, [self.aname, self.prev], prob=False)

        total = b0.sum()
        if abs(total - 1.0) > SUM_TOLERANCE:
            self.fail("InitialStateBelief", f"initial belief sums to {total:.9g}, expected 1")
        if abs(total - 1.0) > RENORMALISE_ABOVE:
            b0 = b0 / total
        t_val = self.normalise("StateTransitionFunction", t_key // S, t_key, t_val, A * S, S)
        o_val = self.normalise("ObsFunction", o_key // Z, o_key, o_val, A * S, Z)
        ta, rest = np.divmod(t_key, S * S)
        ts, tsp = np.divmod(rest, S)
        nz = t_val != 0
        T = [sp.csr_matrix((t_val[nz & (ta == a)], (ts[nz & (ta == a)], tsp[nz & (ta == a)])), shape=(S, S))
             for a in range(A)]
        O = np.zeros(A * S * Z)
        O[o_key] = o_val
        R = np.zeros(A * S)
        R[r_key] = r_val
        try:
            model = Pomdp.create(states, actions, observations, T, O.reshape(A, S, Z), R.reshape(A, S).T, b0=b0,
                                 discount=discount, name=name)
        except ValueError as err:
            self.fail("", str(err))
        model.metadata.update({"format": "pomdpx", "source": self.source, "values": "reward"})
        return model

    def normalise(self, where, rows, keys, vals, nrows, width):
        sums = np.bincount(rows, weights=vals, minlength=nrows)
        bad = np.flatnonzero(np.abs(sums - 1.0) > SUM_TOLERANCE)
        if bad.size:
            a, s = divmod(int(bad[0]), nrows // len(self.enum[self.aname]))
            self.fail(where, f"row for action {self.enum[self.aname][a]!r}, state {self.enum[self.prev][s]!r} "
                             f"sums to {sums[bad[0]]:.9g}, expected 1")
        fix = np.abs(sums - 1.0) > RENORMALISE_ABOVE
        return np.where(fix[rows], vals / np.where(sums[rows] == 0, 1, sums[rows]), vals)

    def table(self, section: str, var: Optional[str], parents: List[str], prob: bool) -> Tuple[np.ndarray, np.ndarray]:
        """Resolve one CondProb/Func into (linear keys over parents+var, values); last entry wins."""
        sec = self.root.find(section)
        if sec is None:
            self.fail(section, "missing")
        blocks = sec.findall("CondProb") + sec.findall("Func")
        if len(blocks) != 1:
            self.fail(section, f"{len(blocks)} CondProb/Func elements; the flat form has one")
        block = blocks[0]
        got_var = self.text(block.find("Var"), f"{section}.Var")
        got_parents = self.text(block.find("Parent"), f"{section}.Parent").split()
        if var is None:  # reward: Var is the reward variable
            dims_names = got_parents
            if sorted(dims_names) != sorted(parents):
                self.fail(f"{section}.Parent", f"parents {' '.join(got_parents)}; the flat reader supports "
                                               f"{' '.join(parents)}")
        else:
            if got_var != var:
                self.fail(f"{section}.Var", f"is {got_var!r}, expected {var!r}")
            if sorted(got_parents) != sorted(parents):
                self.fail(f"{section}.Parent", f"is {' '.join(got_parents)!r}, expected {' '.join(parents)!r}")
            dims_names = ([] if got_parents == ["null"] else got_parents) + [var]
        sizes = [len(self.enum[d]) for d in dims_names]
        # our canonical order: parents as given in `parents` (null dropped), then var
        canon = [p for p in parents if p != "null"] + ([var] if var is not None else [])
        perm = [dims_names.index(c) for c in canon]
        csizes = [sizes[p] for p in perm]
        strides = np.cumprod([1] + csizes[::-1])[::-1][1:].astype(np.int64)
        keys, vals, seqs = [], [], []
        fast_k: List[int] = []
        fast_v: List[float] = []
        fast_q: List[int] = []
        lookups = [self.lookup[dn] for dn in dims_names]
        pstrides = [int(strides[perm.index(d)]) for d in range(len(dims_names))]
        last_size = csizes[-1]
        clear = np.full(int(np.prod(csizes[:-1])) if len(csizes) > 1 else 1, -1, dtype=np.int64)
        row_fast = perm[-1] == len(dims_names) - 1 and var is not None
        budget = _BUDGET
        param = block.find("Parameter")
        if param is None:
            self.fail(section, "missing <Parameter>")
        tab_tag = "ProbTable" if prob else "ValueTable"
        for seq, e in enumerate(param.findall("Entry")):
            inst_el, tab_el = e.find("Instance"), e.find(tab_tag)
            inst = (inst_el.text or "").split() if inst_el is not None else []
            table = (tab_el.text or "").strip() if tab_el is not None else ""
            # fast path: every token a value name and one number (the bulk of large files)
            if len(inst) == len(dims_names) and " " not in table:
                try:
                    k = sum(lk[t] * st for lk, t, st in zip(lookups, inst, pstrides))
                    number = float(table)
                except (KeyError, ValueError):
                    pass
                else:
                    if np.isfinite(number) and (not prob or 0.0 <= number <= 1.0):
                        fast_k.append(k)
                        fast_v.append(number)
                        fast_q.append(seq)
                        continue
            # fast path: a row "v1 … vn -" with the variable last
            elif len(inst) == len(dims_names) and inst[-1] == "-" and row_fast:
                try:
                    k = sum(lk[t] * st for lk, t, st in zip(lookups[:-1], inst[:-1], pstrides[:-1]))
                    row = [float(x) for x in table.split()]
                except (KeyError, ValueError):
                    pass
                else:
                    if len(row) == last_size and np.isfinite(row).all() and (not prob or 0.0 <= min(row) <= max(row) <= 1.0):
                        fast_k.extend(range(k, k + last_size))
                        fast_v.extend(row)
                        fast_q.extend([seq] * last_size)
                        continue
            where = f"{section}.Entry[{seq}]"
            if not inst:
                self.fail(where, "missing or empty <Instance>")
            if not table:
                self.fail(where, f"missing or empty <{tab_tag}>")
            if len(inst) != len(dims_names):
                self.fail(where, f"Instance has {len(inst)} tokens, expected {len(dims_names)} ({' '.join(dims_names)})")
            idx, dash_dims = [], []
            for d, (tok, dn) in enumerate(zip(inst, dims_names)):
                if tok in ("*", "-"):
                    idx.append(np.arange(sizes[d]))
                    if tok == "-":
                        dash_dims.append(d)
                else:
                    j = self.lookup[dn].get(tok)
                    if j is None:
                        self.fail(where, f"unknown value {tok!r} of {dn}")
                    idx.append(np.array([j]))
            low = table.lower()
            if prob and low == "identity":
                nd = len(inst)
                if dash_dims[-2:] != [nd - 2, nd - 1] or perm[-1] != nd - 1 or sizes[-2] != sizes[-1] \
                        or perm[-2] != nd - 2:
                    self.fail(where, "'identity' needs '-' as the last two Instance tokens (previous state, variable)")
                # clear the rows it covers, then the diagonal
                grids = np.meshgrid(*idx[:-1], indexing="ij")
                rowkey = np.zeros(grids[0].size, dtype=np.int64)
                for c, p in enumerate(perm[:-1]):
                    rowkey += grids[p].ravel().astype(np.int64) * (strides[c] // last_size)
                clear[rowkey] = seq
                key = rowkey * last_size + grids[-1].ravel()
                keys.append(key)
                vals.append(np.ones(key.size))
                seqs.append(np.full(key.size, seq))
                continue
            n = int(np.prod([i.size for i in idx]))
            budget -= n
            if budget < 0:
                self.fail(where, "entries expand to too many values")
            grids = np.meshgrid(*idx, indexing="ij")
            if prob and low == "uniform":
                v = np.full(grids[0].shape, 1.0 / sizes[-1])
            else:
                try:
                    nums = np.array([float(x) for x in table.split()])
                except ValueError:
                    self.fail(where, f"table {table[:40]!r} is not a list of numbers")
                want = int(np.prod([sizes[d] for d in dash_dims])) if dash_dims else 1
                if nums.size != want:
                    self.fail(where, f"table has {nums.size} numbers, expected {want}")
                if not np.isfinite(nums).all() or (prob and ((nums < 0).any() or (nums > 1).any())):
                    self.fail(where, "table has a value out of range" + (" [0, 1]" if prob else ""))
                shape = [sizes[d] if d in dash_dims else 1 for d in range(len(inst))]
                v = np.broadcast_to(nums.reshape(shape), grids[0].shape)
            key = np.zeros(n, dtype=np.int64)
            for c, p in enumerate(perm):
                key += grids[p].ravel().astype(np.int64) * strides[c]
            keys.append(key)
            vals.append(np.asarray(v, dtype=float).ravel())
            seqs.append(np.full(n, seq))
        keys.append(np.array(fast_k, dtype=np.int64))
        vals.append(np.array(fast_v, dtype=float))
        seqs.append(np.array(fast_q, dtype=np.int64))
        if sum(k.size for k in keys) == 0:
            self.fail(section, "has no <Entry>")
        all_key, all_val, all_seq = np.concatenate(keys), np.concatenate(vals), np.concatenate(seqs)
        keep = all_seq >= clear[all_key // last_size]
        all_key, all_val, all_seq = all_key[keep], all_val[keep], all_seq[keep]
        order = np.lexsort((all_seq, all_key))
        all_key, all_val = all_key[order], all_val[order]
        last = np.ones(all_key.size, bool)
        last[:-1] = all_key[1:] != all_key[:-1]
        return all_key[last], all_val[last]
