"""The domain YAML reader: :func:`load_domain` / :func:`parse_domain` validate a domain file and
build its :class:`~pearl_pomdp.model.factored.FactoredDomain` (one builder method per section).

The format is documented in ``docs/domain-format.md``. Every error is a
:class:`~pearl_pomdp.errors.SpecError` naming the file, the line when known and the field path.
"""
from __future__ import annotations

import copy
import itertools
import math
import re
from fractions import Fraction
from pathlib import Path
from typing import Any, Dict, Iterable, List, Optional, Sequence, Tuple, Union

import numpy as np

from pearl_pomdp.channels import InputChannel, check_topics, default_channel, parse_input
from pearl_pomdp.errors import SpecError
from pearl_pomdp.model.factored import Cpt, FactoredDomain, RewardRule, StateFeature
from pearl_pomdp.yaml_lines import LineMap as _Map
from pearl_pomdp.yaml_lines import line_of as _line_of
from pearl_pomdp.yaml_lines import parse_yaml

__all__ = ["load_domain", "parse_domain", "as_number", "KEEP", "ROW_TOLERANCE"]

#: Pseudo-value in a transition row: "stay at the current value" (makes the feature its own parent).
KEEP = "keep"
#: How far a probability row may be from summing to 1.
ROW_TOLERANCE = 1e-6
#: Top-level keys a domain file may have.
TOP_KEYS = ("name", "discount", "description", "features", "start", "modalities", "keywords",
            "defaults", "actions", "observations", "rewards", "horizon", "fitted")


def load_domain(path: Union[str, Path], fitted: bool = True) -> FactoredDomain:
    """Read and validate a domain YAML file.

    Args:
        fitted: apply the file's ``fitted:`` section (rows ``pearl fit`` estimated from
            episodes); ``False`` gives the designer's tables alone (the section is still
            validated). The shipped Pearl domain has one (issue 21).

    Raises:
        SpecError: the file is not valid; the message names the file, the line when
            known, the field path (``actions.GuideToPhysio.effects.UserLocation[room]``)
            and what is wrong.
        FileNotFoundError: no such file.
    """
    path = Path(path)
    text = path.read_text(encoding="utf-8")
    return parse_domain(text, source=str(path), default_name=path.name.split(".")[0], fitted=fitted)


def parse_domain(text: str, source: str = "<string>", default_name: str = "domain",
                 fitted: bool = True) -> FactoredDomain:
    """Parse and validate a domain from YAML text (see :func:`load_domain`)."""
    data = parse_yaml(text, source)
    return _Builder(source, data, default_name, fitted).build()


class _Builder:
    """Validates the parsed YAML and builds the :class:`FactoredDomain` (one method per section)."""

    def __init__(self, source: str, data: Any, default_name: str, fitted: bool = True):
        self.source = source
        self.data = data
        self.default_name = default_name
        self.use_fitted = fitted

    # ------------------------------------------------------------ error helpers
    def fail(self, where: str, problem: str, container: Any = None, key: Any = None) -> SpecError:
        return SpecError(self.source, where, problem, line=_line_of(container, key) if container is not None else None)

    def only_keys(self, spec: dict, where: str, allowed: Sequence[str], problem: str) -> None:
        """Fail on the first key of ``spec`` not in ``allowed``: ``where.key``, ``problem``."""
        for k in spec:
            if k not in allowed:
                raise self.fail(f"{where}.{k}" if where else str(k), problem, spec, k)

    def need_map(self, value: Any, where: str, container: Any, key: Any) -> dict:
        if not isinstance(value, dict):
            raise self.fail(where, f"expected a mapping, got {_kind(value)}", container, key)
        return value

    def need_list(self, value: Any, where: str, container: Any, key: Any) -> list:
        if not isinstance(value, list):
            raise self.fail(where, f"expected a list, got {_kind(value)}", container, key)
        return value

    def prob(self, value: Any, where: str, container: Any, key: Any) -> float:
        p = as_number(value)
        if p is None:
            raise self.fail(where, f"probability {value!r} is not a number (write 0.25 or 1/4)", container, key)
        if not (0.0 <= p <= 1.0 + ROW_TOLERANCE) or math.isnan(p):
            raise self.fail(where, f"probability {p:g} is outside [0, 1]", container, key)
        return p

    # ------------------------------------------------------------ top level
    def build(self) -> FactoredDomain:
        d = self.data
        if not isinstance(d, dict):
            raise self.fail("", f"a domain file is a mapping with features, actions, …; got {_kind(d)}")
        self.only_keys(d, "", TOP_KEYS, f"unknown top-level key; expected one of {', '.join(TOP_KEYS)}")
        for key in ("features", "actions", "modalities", "observations", "rewards", "discount"):
            if key not in d:
                raise self.fail(key, "missing (required)", d)
        name = d.get("name", self.default_name)
        if not isinstance(name, str) or not name:
            raise self.fail("name", "expected a non-empty string", d, "name")
        discount = as_number(d["discount"])
        if discount is None or not 0.0 < discount <= 1.0:
            raise self.fail("discount", f"{d['discount']!r} is not a number in (0, 1]", d, "discount")
        horizon = d.get("horizon")
        if horizon is not None and (not isinstance(horizon, int) or isinstance(horizon, bool) or horizon < 1):
            raise self.fail("horizon", f"{horizon!r} is not a positive integer", d, "horizon")
        if discount == 1.0 and horizon is None:
            raise self.fail("discount", "discount 1 needs a finite 'horizon'", d, "discount")

        self.features = self.build_features(d["features"])
        self.fnames = [f.name for f in self.features]
        self.modalities = self.build_modalities(d["modalities"])
        self.symbols = [z for zs in self.modalities.values() for z in zs]
        actions_node = self.need_map(d["actions"], "actions", d, "actions")
        if not actions_node:
            raise self.fail("actions", "no actions", d, "actions")
        self.actions = [str(a) for a in actions_node]
        for a in actions_node:
            if not isinstance(a, str) or not _NAME.match(a):
                raise self.fail(f"actions.{a}", "action names are identifiers (letters, digits, _ - .)", actions_node, a)
        categories: Dict[str, str] = {}
        default_effects = self.build_defaults(d.get("defaults"), d)
        transitions = []
        for a in self.actions:
            spec = actions_node[a]
            transitions.append(self.build_action(a, spec, actions_node, default_effects, categories))
        observations = self.build_observations(d["observations"], d)
        if d.get("fitted") is not None:
            if self.use_fitted:
                self.apply_fitted(d["fitted"], d, transitions, observations)
            else:   # still checked: a broken section is an error either way
                self.apply_fitted(d["fitted"], d, copy.deepcopy(transitions), copy.deepcopy(observations))
        rewards = self.build_rewards(d["rewards"], d)
        start = self.build_start(d.get("start"), d)
        explicit = self.build_explicit_start(d.get("start"), d)
        keywords = self.build_keywords(d.get("keywords"), d)
        inputs = self.build_inputs(keywords)
        description = d.get("description", "")
        return FactoredDomain(
            name=name, source=self.source, features=self.features, actions=self.actions,
            modalities=self.modalities, discount=float(discount), keywords=keywords, rewards=rewards,
            _transitions=transitions, _observations=observations, _start=start, _start_explicit=explicit, horizon=horizon,
            description=str(description or ""), categories=categories, inputs=inputs,
        )

    def apply_fitted(self, node: Any, parent: Any, transitions: List[List[Cpt]], observations: List[Cpt]) -> None:
        """``fitted:`` (written by ``pearl fit``): rows that replace rows of the tables above.

        ``transitions: {Action: {Feature: {"v1,v2": {value: p}}}}`` and
        ``observations: {Action: {"v1,v2": {symbol: p}}}``; a row key lists the values of the
        table's parents in their order (``"*"`` for a table without parents).
        """
        node = self.need_map(node, "fitted", parent, "fitted")
        self.only_keys(node, "fitted", ("transitions", "observations"), "unknown key; expected transitions or observations")
        for kind, tables in node.items():
            tables = self.need_map(tables, f"fitted.{kind}", node, kind)
            for action, spec in tables.items():
                where = f"fitted.{kind}.{action}"
                if action not in self.actions:
                    raise self.fail(where, f"unknown action {action!r}", tables, action)
                a = self.actions.index(action)
                spec = self.need_map(spec, where, tables, action)
                if kind == "observations":
                    observations[a] = self.fitted_rows(observations[a], spec, where, self.symbols, "observation symbol")
                    continue
                for feature, rows in spec.items():
                    if feature not in self.fnames:
                        raise self.fail(f"{where}.{feature}", f"unknown feature {feature!r}", spec, feature)
                    f = self.fnames.index(feature)
                    rows = self.need_map(rows, f"{where}.{feature}", spec, feature)
                    transitions[a] = list(transitions[a])
                    transitions[a][f] = self.fitted_rows(transitions[a][f], rows, f"{where}.{feature}",
                                                         list(self.features[f].values), "value")

    def fitted_rows(self, cpt: Cpt, rows: dict, where: str, values: List[str], noun: str) -> Cpt:
        table = np.array(cpt.table, dtype=float)   # a copy: tables may be shared between actions
        for key, dist in rows.items():
            rwhere = f"{where}[{key}]"
            parts = [] if str(key) == "*" else [p.strip() for p in str(key).split(",")]
            if len(parts) != len(cpt.parents):
                names = ", ".join(self.fnames[p] for p in cpt.parents) or "none (write \"*\")"
                raise self.fail(rwhere, f"a row key lists one value per parent; parents: {names}", rows, key)
            combo = []
            for p, v in zip(cpt.parents, parts):
                if v not in self.features[p].values:
                    raise self.fail(rwhere, f"unknown value {v!r} of parent {self.fnames[p]}", rows, key)
                combo.append(self.features[p].values.index(v))
            table[tuple(combo)] = self.dist_row(dist, values, rwhere, rows, key, allow_keep=False, noun=noun)
        return Cpt(cpt.parents, table, cpt.why, cpt.origin)

    def build_features(self, node: Any) -> List[StateFeature]:
        node = self.need_map(node, "features", self.data, "features")
        if not node:
            raise self.fail("features", "no features", self.data, "features")
        out = []
        for name, values in node.items():
            where = f"features.{name}"
            if not isinstance(name, str) or not _NAME.match(name):
                raise self.fail(where, "feature names are identifiers (letters, digits, _ - .)", node, name)
            values = self.need_list(values, where, node, name)
            vals = [str(v) if isinstance(v, (int, float)) and not isinstance(v, bool) else v for v in values]
            for i, v in enumerate(vals):
                if not isinstance(v, str) or not _NAME.match(v):
                    raise self.fail(f"{where}[{i}]", f"value {v!r} is not a name (letters, digits, _ - .)", values, i)
                if v == KEEP or v == "*":
                    raise self.fail(f"{where}[{i}]", f"{v!r} is reserved", values, i)
            if len(vals) < 1:
                raise self.fail(where, "a feature needs at least one value", node, name)
            if len(set(vals)) != len(vals):
                dup = next(v for v in vals if vals.count(v) > 1)
                raise self.fail(where, f"value {dup!r} listed twice", node, name)
            out.append(StateFeature(name, tuple(vals)))
        return out

    def build_modalities(self, node: Any) -> Dict[str, List[str]]:
        """``modalities:``: each a list of symbols, or ``{symbols: [...], input: {...}}`` (the
        ``input:`` is parsed by :meth:`build_inputs` once the keywords are known)."""
        node = self.need_map(node, "modalities", self.data, "modalities")
        if not node:
            raise self.fail("modalities", "no modalities (a POMDP needs at least one observation symbol)", self.data, "modalities")
        out: Dict[str, List[str]] = {}
        seen: Dict[str, str] = {}
        names: Dict[str, str] = {}
        #: modality → (its input: mapping, where, container, key) for build_inputs.
        self.input_nodes: Dict[str, Tuple[Any, str, Any, Any]] = {}
        for modality, spec in node.items():
            where = f"modalities.{modality}"
            if not isinstance(modality, str) or not _NAME.match(modality):
                raise self.fail(where, "modality names are identifiers (letters, digits, _ - .)", node, modality)
            if modality.lower() in names:
                raise self.fail(where, f"modality names must differ in more than case ({names[modality.lower()]} "
                                       "names the same input)", node, modality)
            names[modality.lower()] = modality
            syms, swhere, scontainer, skey = spec, where, node, modality
            if isinstance(spec, dict):
                self.only_keys(spec, where, ("symbols", "input"), "unknown key; expected symbols and input")
                if "symbols" not in spec:
                    raise self.fail(f"{where}.symbols", "missing (required): the modality's observation symbols",
                                    node, modality)
                syms, swhere, scontainer, skey = spec["symbols"], f"{where}.symbols", spec, "symbols"
                if "input" in spec:
                    self.input_nodes[modality] = (spec["input"], f"{where}.input", spec, "input")
            syms = self.need_list(syms, swhere, scontainer, skey)
            if not syms:
                raise self.fail(swhere, "a modality needs at least one symbol", scontainer, skey)
            for i, z in enumerate(syms):
                if not isinstance(z, str) or not _NAME.match(z):
                    raise self.fail(f"{swhere}[{i}]", f"symbol {z!r} is not a name", syms, i)
                if z in seen:
                    raise self.fail(f"{swhere}[{i}]", f"symbol {z!r} already belongs to modality {seen[z]} "
                                    "(symbols are unique across modalities)", syms, i)
                seen[z] = str(modality)
            out[str(modality)] = [str(z) for z in syms]
        return out

    def build_inputs(self, keywords: Dict[str, List[str]]) -> List[InputChannel]:
        """One input channel per modality (declared, or generic: :mod:`pearl_pomdp.channels`),
        checked as a whole: every topic its own, one silence symbol, keywords on speech inputs."""
        out: List[InputChannel] = []
        for modality, syms in self.modalities.items():
            if modality in self.input_nodes:
                spec, where, container, key = self.input_nodes[modality]
                out.append(parse_input(modality, syms, spec, keywords, where, self.fail, container, key))
            else:
                out.append(default_channel(modality, syms, keywords))
        modalities = self.data["modalities"]

        def where_of(channel: InputChannel, field: str) -> Tuple[str, Any, Any]:
            if channel.modality in self.input_nodes:
                spec = self.input_nodes[channel.modality][0]
                return f"modalities.{channel.modality}.input.{field}", spec, field if field in spec else None
            return f"modalities.{channel.modality}", modalities, channel.modality

        clash = check_topics(out)
        if clash is not None:
            first, second = clash
            where, container, key = where_of(second, "topic")
            raise self.fail(where, f"topic {second.topic} is declared twice (also by modality {first.modality}); "
                                   "each input needs its own topic", container, key)
        silent = [c for c in out if c.silence is not None]
        if len(silent) > 1:
            where, container, key = where_of(silent[1], "silence")
            raise self.fail(where, f"a second silence symbol ({silent[0].modality} declares {silent[0].silence!r}); "
                                   "a step that times out closes with one symbol", container, key)
        for channel in out:
            spoken = [z for z in channel.symbols if z in keywords]
            if spoken and channel.kind != "speech":
                raise self.fail(f"keywords.{spoken[0]}", f"{spoken[0]!r} is a symbol of the {channel.kind} input "
                                                         f"{channel.modality}; keywords belong to speech inputs",
                                self.data.get("keywords"), spoken[0])
        return out

    # ------------------------------------------------------------ transitions
    def build_defaults(self, node: Any, parent: Any) -> Dict[int, Tuple[Any, str, Any, Any]]:
        """Effects applied to every action for the features the action does not mention."""
        if node is None:
            return {}
        node = self.need_map(node, "defaults", parent, "defaults")
        self.only_keys(node, "defaults", ("effects",), "unknown key; expected 'effects'")
        effects = self.need_map(node.get("effects", {}), "defaults.effects", node, "effects")
        out = {}
        for fname, spec in effects.items():
            where = f"defaults.effects.{fname}"
            f = self.feature_ref(fname, where, effects, fname)
            out[f] = (spec, where, effects, fname)
        return out

    def build_action(self, a: str, spec: Any, container: Any, defaults, categories) -> List[Cpt]:
        where = f"actions.{a}"
        if spec is None:
            spec = {}
        spec = self.need_map(spec, where, container, a)
        self.only_keys(spec, where, ("effects", "category", "why", "description"),
                       "unknown key; expected effects, category, why or description")
        if "category" in spec:
            categories[a] = str(spec["category"])
        effects = spec.get("effects") or {}
        effects = self.need_map(effects, f"{where}.effects", spec, "effects")
        given: Dict[int, Tuple[Any, str, Any, Any]] = dict(defaults)
        for fname, fspec in effects.items():
            fwhere = f"{where}.effects.{fname}"
            f = self.feature_ref(fname, fwhere, effects, fname)
            given[f] = (fspec, fwhere, effects, fname)
        cpts = []
        for f in range(len(self.features)):
            if f in given:
                fspec, fwhere, cont, key = given[f]
                cpt = self.build_effect(f, fspec, fwhere, cont, key)
                cpt.origin = fwhere
                cpts.append(cpt)
            else:
                cpt = _persist(f, len(self.features[f]))
                cpt.origin = f"persists {self.fnames[f]}"
                cpts.append(cpt)
        return cpts

    def feature_ref(self, name: Any, where: str, container: Any, key: Any) -> int:
        if name not in self.fnames:
            raise self.fail(where, f"unknown feature {name!r}; features: {', '.join(self.fnames)}", container, key)
        return self.fnames.index(name)

    def parent_refs(self, spec: dict, where: str) -> List[int]:
        """Feature indices of ``spec['parents']`` (a name or a list; each at most once)."""
        parents_node = spec.get("parents", [])
        if isinstance(parents_node, str):
            parents_node = [parents_node]
        parents_node = self.need_list(parents_node, f"{where}.parents", spec, "parents")
        parents: List[int] = []
        for i, p in enumerate(parents_node):
            pi = self.feature_ref(p, f"{where}.parents[{i}]", parents_node, i)
            if pi in parents:
                raise self.fail(f"{where}.parents[{i}]", f"parent {p!r} listed twice", parents_node, i)
            parents.append(pi)
        return parents

    def build_effect(self, f: int, spec: Any, where: str, container: Any, key: Any) -> Cpt:
        feat = self.features[f]
        n = len(feat)
        if spec in ("persist", KEEP):
            return _persist(f, n)
        if isinstance(spec, str):
            raise self.fail(where, f"unknown shorthand {spec!r}; use 'persist', {{set: VALUE}} or "
                            "{parents: [...], table: {...}}", container, key)
        spec = self.need_map(spec, where, container, key)
        why = str(spec.get("why", ""))
        if "set" in spec:
            self.only_keys(spec, where, ("set", "why"), "unexpected beside 'set'")
            row = self.dist_row(spec["set"], feat.values, f"{where}.set", spec, "set", allow_keep=False,
                                noun=f"value of {feat.name}")
            return Cpt((), row, why)
        self.only_keys(spec, where, ("parents", "table", "why"), "unknown key; expected set, parents, table or why")
        if "table" not in spec:
            raise self.fail(where, "missing 'table' (or use 'set: VALUE' / 'persist')", container, key)
        parents = self.parent_refs(spec, where)
        table = self.need_map(spec["table"], f"{where}.table", spec, "table")
        uses_keep = any(isinstance(r, dict) and KEEP in r or r == KEEP for r in table.values())
        implicit_self = uses_keep and f not in parents
        full_parents = parents + ([f] if implicit_self else [])
        shape = tuple(len(self.features[p]) for p in full_parents) + (n,)
        out = np.full(shape, np.nan)

        # combo (value indices of `parents`) -> (row node, its field path, container, key)
        assigned = self.fill_rows(table, parents, where, spec, "table")
        for combo, (row_node, rwhere, cont, rkey) in assigned.items():
            if implicit_self:
                for v in range(n):
                    out[combo + (v,)] = self.dist_row(row_node, feat.values, rwhere, cont, rkey, allow_keep=True,
                                                      current=v, noun=f"value of {feat.name}")
            else:
                cur = combo[parents.index(f)] if f in parents else None
                out[combo] = self.dist_row(row_node, feat.values, rwhere, cont, rkey, allow_keep=cur is not None,
                                           current=cur, noun=f"value of {feat.name}")
        return Cpt(tuple(full_parents), out, why)

    def fill_rows(self, table: dict, parents: List[int], where: str, container: Any, key: Any) -> Dict[tuple, tuple]:
        """Match table rows (first match wins) to every parent-value combination; check coverage."""
        pvals = [self.features[p].values for p in parents]
        combos = {}
        used = {}
        for rkey, row_node in table.items():
            rwhere = f"{where}[{rkey}]"
            patterns = self.row_pattern(rkey, parents, rwhere, table)
            count = 0
            for combo in _product(patterns):
                if combo not in combos:
                    combos[combo] = (row_node, rwhere, table, rkey)
                    count += 1
            used[rkey] = count
        for rkey, count in used.items():
            if count == 0:
                raise self.fail(f"{where}[{rkey}]", "row is never used: earlier rows already cover all its parent "
                                "combinations (rows match in order, first match wins)", table, rkey)
        total = int(np.prod([len(v) for v in pvals])) if pvals else 1
        if len(combos) < total:
            for combo in _product([range(len(v)) for v in pvals]):
                if combo not in combos:
                    desc = ",".join(v[i] for v, i in zip(pvals, combo)) or "(no parents)"
                    names = ",".join(self.fnames[p] for p in parents)
                    raise self.fail(where, f"no row for {names}={desc}; tables have no implicit default — add that row "
                                    "or a '*' row (rows match in order, first match wins)", container, key)
        return combos

    def row_pattern(self, rkey: Any, parents: List[int], where: str, table: Any) -> List[List[int]]:
        """Parse a row key ``"room,*"`` / ``"physio|vitamin,yes"`` / ``"*"`` / ``default`` into value-index lists."""
        if isinstance(rkey, bool) or rkey is None:
            raise self.fail(where, f"row key {rkey!r} is not a parent-value combination", table, rkey)
        text = str(rkey).strip()
        k = len(parents)
        if text in ("*", "default"):
            return [list(range(len(self.features[p]))) for p in parents]
        parts = [t.strip() for t in text.split(",")] if text else []
        if k == 0:
            raise self.fail(where, "this table has no parents: use a single '*' row", table, rkey)
        if len(parts) != k:
            names = ",".join(self.fnames[p] for p in parents)
            raise self.fail(where, f"row key has {len(parts)} value(s), expected {k} (one per parent: {names})", table, rkey)
        out = []
        for part, p in zip(parts, parents):
            feat = self.features[p]
            if part == "*":
                out.append(list(range(len(feat))))
                continue
            idx = []
            for alt in part.split("|"):
                alt = alt.strip()
                if alt not in feat.values:
                    raise self.fail(where, f"unknown value {alt!r} of parent {feat.name}; values: {', '.join(feat.values)}",
                                    table, rkey)
                idx.append(feat.values.index(alt))
            out.append(idx)
        return out

    def dist_row(self, node: Any, values: Sequence[str], where: str, container: Any, key: Any, allow_keep: bool,
                 current: Optional[int] = None, noun: str = "value") -> np.ndarray:
        """A distribution over ``values`` from ``{v: p, …}`` (missing = 0) or a single value name (p = 1)."""
        n = len(values)
        row = np.zeros(n)
        if isinstance(node, (int, float)) and not isinstance(node, bool):
            node = str(node)
        if isinstance(node, str):
            if node == KEEP:
                if not allow_keep:
                    raise self.fail(where, f"'{KEEP}' is only allowed in transition rows", container, key)
                row[current] = 1.0
                return row
            if node not in values:
                raise self.fail(where, f"unknown {noun} {node!r}; expected one of {', '.join(values)}", container, key)
            row[values.index(node)] = 1.0
            return row
        if not isinstance(node, dict):
            raise self.fail(where, f"expected a distribution {{value: probability}} or a value name, got {_kind(node)}",
                            container, key)
        for v, p in node.items():
            v_s = str(v) if isinstance(v, (int, float)) and not isinstance(v, bool) else v
            if v_s == "why":
                continue
            pr = self.prob(p, f"{where}.{v_s}", node, v)
            if v_s == KEEP:
                if not allow_keep:
                    raise self.fail(f"{where}.{v_s}", f"'{KEEP}' is only allowed in transition rows", node, v)
                row[current] += pr
                continue
            if v_s not in values:
                raise self.fail(f"{where}.{v_s}", f"unknown {noun} {v_s!r}; expected one of {', '.join(values)}", node, v)
            row[values.index(v_s)] += pr
        total = row.sum()
        if abs(total - 1.0) > ROW_TOLERANCE:
            raise self.fail(where, f"row sums to {total:.6g}, expected 1", container, key)
        return row / total

    # ------------------------------------------------------------ observations
    def build_observations(self, node: Any, parent: Any) -> List[Cpt]:
        node = self.need_map(node, "observations", parent, "observations")
        for key in node:
            if key != "default" and key not in self.actions:
                raise self.fail(f"observations.{key}", f"unknown action {key!r} (keys are action names or 'default'); "
                                f"actions: {', '.join(self.actions)}", node, key)
        out = []
        cache: Dict[int, Cpt] = {}
        for a in self.actions:
            key = a if a in node else "default"
            if key not in node:
                raise self.fail("observations", f"no observation table for action {a} and no 'default' table", parent,
                                "observations")
            spec = node[key]
            if id(spec) in cache and key == "default":
                out.append(cache[id(spec)])
                continue
            cpt = self.build_obs_table(spec, f"observations.{key}", node, key)
            cache[id(spec)] = cpt
            out.append(cpt)
        return out

    def build_obs_table(self, spec: Any, where: str, container: Any, key: Any) -> Cpt:
        spec = self.need_map(spec, where, container, key)
        if "mix" in spec:
            return self.build_obs_mixture(spec, where)
        self.only_keys(spec, where, ("parents", "table", "why"), "unknown key; expected parents, table or why")
        if "table" not in spec:
            raise self.fail(where, "missing 'table'", container, key)
        parents = self.parent_refs(spec, where)
        table = self.need_map(spec["table"], f"{where}.table", spec, "table")
        Z = len(self.symbols)
        shape = tuple(len(self.features[p]) for p in parents) + (Z,)
        out = np.full(shape, np.nan)
        assigned = self.fill_rows(table, parents, where, spec, "table")
        rows_cache: Dict[int, np.ndarray] = {}
        for combo, (row_node, rwhere, cont, rkey) in assigned.items():
            if id(row_node) not in rows_cache:
                rows_cache[id(row_node)] = self.dist_row(row_node, self.symbols, rwhere, cont, rkey, allow_keep=False,
                                                         noun="observation symbol")
            out[combo] = rows_cache[id(row_node)]
        return Cpt(tuple(parents), out, str(spec.get("why", "")))

    def build_obs_mixture(self, spec: dict, where: str) -> Cpt:
        """``mix: [{weight: w, parents: [...], table: {...}}, …]`` → ``Σ_k w_k P_k(o | parents_k)``.

        Each component is one source of the step's single message (the scheduler, the
        user, the laser…); ``weight`` is the chance that this source speaks first.
        """
        self.only_keys(spec, where, ("mix", "why"), "unexpected beside 'mix'")
        comps = self.need_list(spec["mix"], f"{where}.mix", spec, "mix")
        if not comps:
            raise self.fail(f"{where}.mix", "an empty mixture", spec, "mix")
        parts: List[Tuple[float, Cpt]] = []
        for i, comp in enumerate(comps):
            cwhere = f"{where}.mix[{i}]"
            comp = self.need_map(comp, cwhere, comps, i)
            if "weight" not in comp:
                raise self.fail(cwhere, "missing 'weight' (the chance that this source closes the step)", comps, i)
            w = self.prob(comp["weight"], f"{cwhere}.weight", comp, "weight")
            rest = _Map({k: v for k, v in comp.items() if k != "weight"})
            rest.lines = {k: v for k, v in comp.lines.items() if k != "weight"} if isinstance(comp, _Map) else {}
            rest.line = _line_of(comp)
            if "mix" in rest:
                raise self.fail(cwhere, "mixtures do not nest", comps, i)
            parts.append((w, self.build_obs_table(rest, cwhere, comps, i)))
        total = sum(w for w, _ in parts)
        if abs(total - 1.0) > ROW_TOLERANCE:
            raise self.fail(f"{where}.mix", f"weights sum to {total:.6g}, expected 1", spec, "mix")
        union: List[int] = []
        for _, cpt in parts:
            union.extend(p for p in cpt.parents if p not in union)
        shape = tuple(len(self.features[p]) for p in union)
        grid = np.indices(shape) if union else np.zeros((0,), dtype=np.int64)
        out = np.zeros(shape + (len(self.symbols),))
        for w, cpt in parts:
            if cpt.parents:
                out += w * cpt.table[tuple(grid[union.index(p)] for p in cpt.parents)]
            else:
                out += w * cpt.table
        return Cpt(tuple(union), out, str(spec.get("why", "")))

    # ------------------------------------------------------------ rewards
    def build_rewards(self, node: Any, parent: Any) -> List[RewardRule]:
        node = self.need_list(node, "rewards", parent, "rewards")
        rules = []
        for i, rule in enumerate(node):
            where = f"rewards[{i}]"
            rule = self.need_map(rule, where, node, i)
            self.only_keys(rule, where, ("action", "actions", "when", "reward", "why"),
                           "unknown key; expected action, when, reward, why")
            act = rule.get("action", rule.get("actions"))
            if act is None:
                raise self.fail(where, "missing 'action' (an action name, a list of names, or '*')", node, i)
            if act == "*":
                acts = list(self.actions)
            else:
                names = [act] if isinstance(act, str) else act
                if not isinstance(names, list):
                    raise self.fail(f"{where}.action", f"expected an action name or a list, got {_kind(act)}", rule, "action")
                for a in names:
                    if a not in self.actions:
                        raise self.fail(f"{where}.action", f"unknown action {a!r}; actions: {', '.join(self.actions)}",
                                        rule, "action" if "action" in rule else "actions")
                acts = list(names)
            if "reward" not in rule:
                raise self.fail(where, "missing 'reward'", node, i)
            r = as_number(rule["reward"])
            if r is None or not math.isfinite(r):
                raise self.fail(f"{where}.reward", f"{rule['reward']!r} is not a finite number", rule, "reward")
            why = rule.get("why")
            if not isinstance(why, str) or not why.strip():
                raise self.fail(where, "missing 'why': every reward number carries a one-line reason", node, i)
            when_node = rule.get("when") or {}
            when_node = self.need_map(when_node, f"{where}.when", rule, "when")
            when: Dict[str, Tuple[int, ...]] = {}
            for fname, vals in when_node.items():
                wwhere = f"{where}.when.{fname}"
                f = self.feature_ref(fname, wwhere, when_node, fname)
                vals_list = vals if isinstance(vals, list) else [vals]
                idx = []
                for v in vals_list:
                    v_s = str(v) if isinstance(v, (int, float)) and not isinstance(v, bool) else v
                    if v_s not in self.features[f].values:
                        raise self.fail(wwhere, f"unknown value {v_s!r} of {fname}; values: {', '.join(self.features[f].values)}",
                                        when_node, fname)
                    idx.append(self.features[f].values.index(v_s))
                when[str(fname)] = tuple(sorted(set(idx)))
            rules.append(RewardRule(tuple(acts), when, float(r), why.strip(), where))
        return rules

    # ------------------------------------------------------------ start, keywords
    def build_start(self, node: Any, parent: Any) -> List[np.ndarray]:
        dists = [np.full(len(f), 1.0 / len(f)) for f in self.features]
        if node is None:
            return dists
        node = self.need_map(node, "start", parent, "start")
        if "states" in node:
            return dists  # explicit start: see build_explicit_start
        for fname, spec in node.items():
            where = f"start.{fname}"
            f = self.feature_ref(fname, where, node, fname)
            if spec == "uniform":
                continue
            dists[f] = self.dist_row(spec, self.features[f].values, where, node, fname, allow_keep=False,
                                     noun=f"value of {fname}")
        return dists

    def build_explicit_start(self, node: Any, parent: Any) -> Optional[np.ndarray]:
        """``start: {states: [{state: {F: v, …every feature…}, p: prob}, …]}`` → ``b0[S]``."""
        if not isinstance(node, dict) or "states" not in node:
            return None
        for key in node:
            if key != "states":
                raise self.fail(f"start.{key}", "an explicit start ('states') cannot be mixed with per-feature entries",
                                node, key)
        items = self.need_list(node["states"], "start.states", node, "states")
        radix = [len(f) for f in self.features]
        strides = np.concatenate([np.cumprod(radix[::-1])[::-1][1:], [1]]).astype(np.int64)
        b0 = np.zeros(int(np.prod(radix)))
        seen: Dict[int, int] = {}
        for i, item in enumerate(items):
            where = f"start.states[{i}]"
            item = self.need_map(item, where, items, i)
            self.only_keys(item, where, ("state", "p", "why"), "unknown key; expected state, p, why")
            if "state" not in item or "p" not in item:
                raise self.fail(where, "needs 'state' (a value for every feature) and 'p'", items, i)
            assign = self.need_map(item["state"], f"{where}.state", item, "state")
            digits = []
            for f, feat in enumerate(self.features):
                if feat.name not in assign:
                    raise self.fail(f"{where}.state", f"missing feature {feat.name} (an explicit state names every "
                                    "feature)", item, "state")
                v = assign[feat.name]
                v = str(v) if isinstance(v, (int, float)) and not isinstance(v, bool) else v
                if v not in feat.values:
                    raise self.fail(f"{where}.state.{feat.name}", f"unknown value {v!r} of {feat.name}; values: "
                                    f"{', '.join(feat.values)}", assign, feat.name)
                digits.append(feat.values.index(v))
            for k in assign:
                if k not in self.fnames:
                    self.feature_ref(k, f"{where}.state.{k}", assign, k)
            s = int(np.dot(digits, strides))
            if s in seen:
                raise self.fail(where, f"the same state as start.states[{seen[s]}]", items, i)
            seen[s] = i
            b0[s] = self.prob(item["p"], f"{where}.p", item, "p")
        if abs(b0.sum() - 1.0) > ROW_TOLERANCE:
            raise self.fail("start.states", f"probabilities sum to {b0.sum():.6g}, expected 1", node, "states")
        return b0 / b0.sum()

    def build_keywords(self, node: Any, parent: Any) -> Dict[str, List[str]]:
        if node is None:
            return {}
        node = self.need_map(node, "keywords", parent, "keywords")
        out = {}
        for sym, words in node.items():
            where = f"keywords.{sym}"
            if sym not in self.symbols:
                raise self.fail(where, f"unknown observation symbol {sym!r}; symbols: {', '.join(self.symbols)}", node, sym)
            words = self.need_list(words, where, node, sym)
            clean = []
            for i, w in enumerate(words):
                if not isinstance(w, str) or not w.strip():
                    raise self.fail(f"{where}[{i}]", f"keyword {w!r} is not a non-empty string", words, i)
                clean.append(w.strip().lower())
            out[str(sym)] = clean
        return out


# ====================================================================== helpers
_NAME = re.compile(r"^[A-Za-z0-9_][A-Za-z0-9_.\-]*$")


def _persist(f: int, n: int) -> Cpt:
    return Cpt((f,), np.eye(n), "persists")


def _product(lists: Sequence[Iterable[int]]) -> Iterable[tuple]:
    return itertools.product(*lists)


def _kind(value: Any) -> str:
    if value is None:
        return "nothing"
    if isinstance(value, dict):
        return "a mapping"
    if isinstance(value, list):
        return "a list"
    if isinstance(value, bool):
        return f"the boolean {value}"
    if isinstance(value, str):
        return f"the string {value!r}"
    return f"{type(value).__name__} {value!r}"


def as_number(value: Any) -> Optional[float]:
    """A float from a number or a string such as ``"0.25"`` / ``"1/3"`` (None if not a number)."""
    if isinstance(value, bool) or value is None:
        return None
    if isinstance(value, (int, float)):
        return float(value)
    if isinstance(value, str):
        text = value.strip()
        try:
            return float(Fraction(text)) if "/" in text else float(text)
        except (ValueError, ZeroDivisionError):
            return None
    return None
