"""Factored (DBN-style) POMDP domains written in YAML, compiled to a flat :class:`Pomdp`.

A domain lists state *features* (each with ordered values), *actions* whose
*effects* give, per feature, the next value's distribution conditioned on a few
parent features of the current state (default: the feature persists),
observation *symbols* grouped by *modality* with per-action tables over a few
features of the next state, additive *reward rules*, a factorised *start*
distribution and the *discount*. The full format is documented in
``docs/domain-format.md``; docs/design.md §3 explains why the structure is kept
(automatic abstraction in the hierarchy, per-feature marginals on the belief topic).

State index convention (mixed radix, first feature most significant)::

    s = Σ_f v_f · Π_{g > f} |values(g)|        state_values[s, f] = v_f

so for Pearl ``s = 0`` is ``RobotLocation=home,UserLocation=room,…`` (every
feature at its first value) and the last feature changes fastest.

Compiled arrays follow the project conventions (docs/design.md §2):
``T[a][s, s'] = Π_f P(s'_f | parents_f(s), a)``, ``O[a, s', o] = P(o | parents(s'), a)``,
``R[s, a] = Σ`` of the rewards of all rules matching ``(s, a)``,
``b0[s] = Π_f start_f(s_f)``.
"""
from __future__ import annotations

import copy

import itertools
import math
import re
from dataclasses import dataclass, field
from fractions import Fraction
from pathlib import Path
from typing import Any, Dict, Iterable, List, Optional, Sequence, Set, Tuple, Union

import numpy as np
import scipy.sparse as sp

from pearl_pomdp.channels import InputChannel, check_topics, default_channel, parse_input
from pearl_pomdp.errors import SpecError
from pearl_pomdp.model.pomdp import DENSE_LIMIT, LARGE_O_ENTRIES, Pomdp
from pearl_pomdp.yaml_lines import LineMap as _Map
from pearl_pomdp.yaml_lines import line_of as _line_of
from pearl_pomdp.yaml_lines import parse_yaml

__all__ = [
    "StateFeature",
    "FactoredDomain",
    "RewardRule",
    "load_domain",
    "parse_domain",
    "as_number",
    "KEEP",
    "ROW_TOLERANCE",
]

#: Pseudo-value in a transition row: "stay at the current value" (makes the feature its own parent).
KEEP = "keep"
#: How far a probability row may be from summing to 1.
ROW_TOLERANCE = 1e-6
#: Top-level keys a domain file may have.
TOP_KEYS = ("name", "discount", "description", "features", "start", "modalities", "keywords",
            "defaults", "actions", "observations", "rewards", "horizon", "fitted")


# ====================================================================== public data types
@dataclass(frozen=True)
class StateFeature:
    """One state variable: ``name`` and its ordered ``values`` (value index = position)."""

    name: str
    values: Tuple[str, ...]

    def index(self, value: str) -> int:
        """Position of ``value`` (raises ``KeyError`` naming the feature and its values)."""
        try:
            return self.values.index(value)
        except ValueError:
            raise KeyError(f"{self.name} has no value {value!r}; values: {', '.join(self.values)}") from None

    def __len__(self) -> int:
        return len(self.values)


@dataclass
class RewardRule:
    """``reward`` is added to ``R[s, a]`` for every action in ``actions`` and state matching ``when``.

    ``when`` maps a feature name to the set of allowed value indices; an empty
    ``when`` matches every state. ``why`` is the designer's one-line reason.
    """

    actions: Tuple[str, ...]
    when: Dict[str, Tuple[int, ...]]
    reward: float
    why: str
    where: str = ""


@dataclass
class _Cpt:
    """A conditional table ``P(child | parents)`` as an array ``[n_p1, …, n_pk, n_child]``."""

    parents: Tuple[int, ...]  # feature indices
    table: np.ndarray
    why: str = ""
    #: Where the table was written: the field path of its spec (``defaults.effects.F`` for every
    #: action that keeps the default, ``actions.A.effects.F`` for an action's own), or
    #: ``persists F`` when nothing mentions the feature. Tables of one origin are one table in
    #: the designer's model: ``pearl fit`` estimates them together (tied parameters).
    origin: str = ""


# ====================================================================== the domain
@dataclass
class FactoredDomain:
    """A validated factored POMDP domain.

    Attributes:
        name: domain name (``name:`` in the file, else the file stem).
        source: the file it came from (for messages).
        features: ordered list of :class:`StateFeature` (first = most significant digit of the state index).
        actions: action names, in file order (= action index of the compiled model).
        modalities: modality → list of its observation symbols, in file order.
        observations: all symbols, modality after modality (= observation index).
        discount: γ.
        keywords: speech symbol → list of keywords/phrases for :class:`pearl_pomdp.speech.KeywordFilter`.
        rewards: the reward rules, in file order.
        reward_shaping: always ``None`` here; shaping belongs to the hierarchy spec.
        categories: action → category string (``Communicate``, ``Move``…), when given.
        inputs: one :class:`~pearl_pomdp.channels.InputChannel` per modality, in modality order:
            how its symbols reach the tracker (``modalities.<M>.input``; generic when not declared).
    """

    name: str
    source: str
    features: List[StateFeature]
    actions: List[str]
    modalities: Dict[str, List[str]]
    discount: float
    keywords: Dict[str, List[str]]
    rewards: List[RewardRule]
    _transitions: List[List[_Cpt]]  # [action][feature]
    _observations: List[_Cpt]  # [action]; table [..., Z]
    _start: List[np.ndarray]  # per feature distribution
    horizon: Optional[int] = None
    description: str = ""
    categories: Dict[str, str] = field(default_factory=dict)
    reward_shaping: Any = None
    inputs: List[InputChannel] = field(default_factory=list)
    _start_explicit: Optional[np.ndarray] = field(default=None, repr=False)  # [S] when `start: {states: …}`
    _compiled: Optional[Pomdp] = field(default=None, repr=False)
    _state_values: Optional[np.ndarray] = field(default=None, repr=False)

    # ---------------------------------------------------------------- sizes and names
    @property
    def observations(self) -> List[str]:
        """All observation symbols, modality after modality (the compiled observation order)."""
        return [z for syms in self.modalities.values() for z in syms]

    @property
    def feature_names(self) -> List[str]:
        return [f.name for f in self.features]

    @property
    def radix(self) -> np.ndarray:
        """``[F]`` number of values of each feature."""
        return np.array([len(f) for f in self.features], dtype=np.int64)

    @property
    def strides(self) -> np.ndarray:
        """``[F]`` weight of each feature in the state index (last feature has stride 1)."""
        r = self.radix
        return np.concatenate([np.cumprod(r[::-1])[::-1][1:], [1]]).astype(np.int64)

    @property
    def num_states(self) -> int:
        return int(np.prod(self.radix))

    def feature(self, name: str) -> StateFeature:
        """The feature called ``name`` (``KeyError`` lists the known ones)."""
        for f in self.features:
            if f.name == name:
                return f
        raise KeyError(f"unknown feature {name!r}; features: {', '.join(self.feature_names)}")

    def feature_index(self, name: str) -> int:
        return self.feature_names.index(self.feature(name).name)

    def actions_in(self, category: str) -> List[str]:
        """The actions tagged ``category: <category>``, in file order."""
        return [a for a in self.actions if self.categories.get(a) == category]

    def deterministic_effect(self, action: str, feature: str) -> Optional[str]:
        """The value ``action`` always gives ``feature`` (whatever the state), or ``None``.

        E.g. a drive's destination: ``GoHome`` sets ``RobotLocation`` to ``home``.
        """
        cpt = self._transitions[self.actions.index(action)][self.feature_index(feature)]
        rows = cpt.table.reshape(-1, cpt.table.shape[-1])
        first = rows[0]
        if not np.allclose(rows, first) or not np.isclose(first.max(), 1.0):
            return None
        return self.feature(feature).values[int(first.argmax())]

    def intended_effect(self, action: str, feature: str) -> Optional[str]:
        """The value ``action`` gives ``feature`` most likely from every state (p > 0.5), or ``None``.

        A drive's destination when the drive may fail: ``GotoPatientRoom`` sets
        ``RobotLocation`` to ``room`` with 0.97 and keeps it with 0.03; the intended effect is
        ``room``. Equals :meth:`deterministic_effect` when that is not ``None``.
        """
        cpt = self._transitions[self.actions.index(action)][self.feature_index(feature)]
        rows = cpt.table.reshape(-1, cpt.table.shape[-1])
        best = rows.argmax(axis=1)
        if not np.all(best == best[0]) or not np.all(rows[:, best[0]] > 0.5):
            return None
        return self.feature(feature).values[int(best[0])]

    @property
    def state_values(self) -> np.ndarray:
        """``[S, F]`` int array: ``state_values[s, f]`` is the value index of feature ``f`` in state ``s``."""
        if self._state_values is None:
            grids = np.indices(tuple(self.radix)).reshape(len(self.features), -1).T
            self._state_values = np.ascontiguousarray(grids, dtype=np.int64)
        return self._state_values

    def state_names(self) -> List[str]:
        """``["RobotLocation=home,UserLocation=room,…", …]`` in state-index order."""
        # The states are the product of the features' values in C order (last feature fastest),
        # which is itertools.product's order: no per-state lookups (ward: 1.2 s -> 0.1 s per compile).
        parts = [[f"{f.name}={v}" for v in f.values] for f in self.features]
        return [",".join(names) for names in itertools.product(*parts)]

    def state_index(self, assignment: Dict[str, str]) -> int:
        """Index of the state with the given value of *every* feature (``{"Battery": "ok", …}``).

        Raises:
            KeyError: a feature is missing or unknown, or a value is unknown.
        """
        missing = [f.name for f in self.features if f.name not in assignment]
        if missing:
            raise KeyError(f"state_index needs every feature; missing: {', '.join(missing)}")
        extra = [k for k in assignment if k not in self.feature_names]
        if extra:
            raise KeyError(f"unknown feature(s) {', '.join(map(repr, extra))}; features: {', '.join(self.feature_names)}")
        digits = [f.index(str(assignment[f.name])) for f in self.features]
        return int(np.dot(digits, self.strides))

    def state_assignment(self, s: int) -> Dict[str, str]:
        """Inverse of :meth:`state_index`: feature → value name of state ``s``."""
        row = self.state_values[int(s)]
        return {f.name: f.values[v] for f, v in zip(self.features, row)}

    def states_matching(self, partial: Dict[str, Union[str, Sequence[str]]]) -> np.ndarray:
        """``[S]`` bool mask of the states whose features take the given value(s)."""
        mask = np.ones(self.num_states, dtype=bool)
        sv = self.state_values
        for name, value in partial.items():
            f = self.feature_index(name)
            vals = [value] if isinstance(value, str) else list(value)
            idx = [self.features[f].index(v) for v in vals]
            mask &= np.isin(sv[:, f], idx)
        return mask

    def feature_marginals(self, belief: np.ndarray) -> Dict[str, np.ndarray]:
        """Per-feature marginals of a belief ``b[S]``: feature → ``[|values|]`` (sums to ``b.sum()``)."""
        b = np.asarray(belief, dtype=float).ravel()
        if b.shape[0] != self.num_states:
            raise ValueError(f"belief has {b.shape[0]} entries, the domain has {self.num_states} states")
        # The states are the features' product in C order (last feature fastest), so the joint
        # marginal of features 0..i reshaped to [·, |values(i)|] has feature i along its columns:
        # its column sums are feature i's marginal and its row sums the joint of features 0..i-1.
        # Two matrix-vector products per feature on ever smaller arrays: ~0.25 ms on the ward's
        # 233,280 states, where a weighted bincount per feature took ~10 ms (the tracker's
        # marginals, published every step, sit on the path from an input to the robot's action).
        out: Dict[str, np.ndarray] = {}
        joint = b
        for f, size in zip(reversed(self.features), reversed(self.radix)):
            table = joint.reshape(-1, size)
            out[f.name] = np.ones(table.shape[0]) @ table
            joint = table @ np.ones(size)
        return {f.name: out[f.name] for f in self.features}

    # ---------------------------------------------------------------- structure for the hierarchy
    def _action_index(self, action: Union[str, int]) -> int:
        if isinstance(action, (int, np.integer)):
            return int(action)
        try:
            return self.actions.index(action)
        except ValueError:
            raise KeyError(f"unknown action {action!r}; actions: {', '.join(self.actions)}") from None

    def transition_parents(self, action: Union[str, int]) -> Dict[str, List[str]]:
        """Feature → the current-state features its next value depends on under ``action``.

        A feature that just persists has parents ``[itself]``; one set to a fixed value has ``[]``.
        """
        a = self._action_index(action)
        names = self.feature_names
        return {names[f]: [names[p] for p in cpt.parents] for f, cpt in enumerate(self._transitions[a])}

    def reward_features(self, action: Union[str, int]) -> Set[str]:
        """Features read by the reward rules that apply to ``action``."""
        name = self.actions[self._action_index(action)]
        return {f for rule in self.rewards if name in rule.actions for f in rule.when}

    def observation_parents(self, action: Union[str, int]) -> Set[str]:
        """Next-state features the observation table of ``action`` reads."""
        a = self._action_index(action)
        return {self.feature_names[p] for p in self._observations[a].parents}

    def input(self, name: str) -> InputChannel:
        """The input channel called ``name`` (a modality's name, lower-cased).

        Raises:
            KeyError: no such input (the message names the domain's inputs).
        """
        for channel in self.inputs:
            if channel.name == name:
                return channel
        raise KeyError(f"{self.name} has no input {name!r}; inputs: {', '.join(c.name for c in self.inputs)}")

    @property
    def silence_symbol(self) -> Optional[str]:
        """The symbol a step closes with when nothing arrives in time: the one an input declares
        as ``silence:``, else the ``unknown`` symbol of the first speech input, else ``None``."""
        for channel in self.inputs:
            if channel.silence is not None:
                return channel.silence
        return next((c.unknown for c in self.inputs if c.kind == "speech" and c.unknown is not None), None)

    def modality_of(self, symbol: str) -> str:
        """The modality a symbol belongs to (``KeyError`` for an unknown symbol)."""
        for modality, syms in self.modalities.items():
            if symbol in syms:
                return modality
        raise KeyError(f"unknown observation symbol {symbol!r}; symbols: {', '.join(self.observations)}")

    def transition_table(self, action: Union[str, int], feature: str) -> Tuple[List[str], np.ndarray]:
        """``(parents, table)`` with ``table[v_p1, …, v_pk, v'] = P(feature' = v' | parents, action)``."""
        a = self._action_index(action)
        cpt = self._transitions[a][self.feature_index(feature)]
        return [self.feature_names[p] for p in cpt.parents], cpt.table.copy()

    def observation_table(self, action: Union[str, int]) -> Tuple[List[str], np.ndarray]:
        """``(parents, table)`` with ``table[v_p1', …, v_pk', o] = P(o | next-state parents, action)``."""
        cpt = self._observations[self._action_index(action)]
        return [self.feature_names[p] for p in cpt.parents], cpt.table.copy()

    # ---------------------------------------------------------------- compile
    def feature_transition(self, action: Union[str, int], f: int) -> np.ndarray:
        """``[S, |f|]``: ``P(s'_f = v | s, action)`` for every current state ``s``."""
        cpt = self._transitions[self._action_index(action)][f]
        sv = self.state_values
        return cpt.table[tuple(sv[:, p] for p in cpt.parents)] if cpt.parents else np.broadcast_to(
            cpt.table, (self.num_states, cpt.table.shape[-1]))

    def transition_matrix(self, action: Union[str, int]) -> sp.csr_matrix:
        """``T[a]`` as CSR ``[S, S]``, built from the per-feature factors without a dense ``S×S`` product.

        Each row's support is expanded one feature at a time (only non-zero factors),
        so the cost is proportional to the number of non-zeros of ``T[a]``.
        """
        a = self._action_index(action)
        S = self.num_states
        rows = np.arange(S, dtype=np.int64)
        cols = np.zeros(S, dtype=np.int64)
        probs = np.ones(S, dtype=float)
        for f, stride in enumerate(self.strides):
            M = self.feature_transition(a, f)  # [S, n_f]
            m = M[rows]  # factor of each partial entry, [E, n_f]
            e_idx, v = np.nonzero(m > 0.0)
            probs = probs[e_idx] * m[e_idx, v]
            rows = rows[e_idx]
            cols = cols[e_idx] + v * stride
        return sp.csr_matrix((probs, (rows, cols)), shape=(S, S))

    def observation_matrix(self, action: Union[str, int]) -> np.ndarray:
        """``[S, Z]``: ``O[a, s', o]`` for one action."""
        cpt = self._observations[self._action_index(action)]
        sv = self.state_values
        if not cpt.parents:
            return np.broadcast_to(cpt.table, (self.num_states, cpt.table.shape[-1])).copy()
        return cpt.table[tuple(sv[:, p] for p in cpt.parents)]

    def reward_matrix(self) -> np.ndarray:
        """``R[s, a]``: the sum of the rewards of all rules matching ``(s, a)``."""
        S, A = self.num_states, len(self.actions)
        R = np.zeros((S, A))
        sv = self.state_values
        col = {name: i for i, name in enumerate(self.actions)}
        for rule in self.rewards:
            mask = np.ones(S, dtype=bool)
            for fname, vals in rule.when.items():
                mask &= np.isin(sv[:, self.feature_index(fname)], vals)
            for name in rule.actions:
                R[mask, col[name]] += rule.reward
        return R

    def start_belief(self) -> np.ndarray:
        """``b0[S]``: the product of the per-feature start distributions (or the explicit one)."""
        if self._start_explicit is not None:
            return self._start_explicit.copy()
        b = np.ones(1)
        for dist in self._start:
            b = np.multiply.outer(b, dist).ravel()
        return b

    def compile(self) -> Pomdp:
        """The flat :class:`Pomdp` (cached). T is dense up to ``pomdp.DENSE_LIMIT`` entries, else CSR.

        ``metadata`` records the domain name, source and features so tools can map
        state indices back to feature values.
        """
        if self._compiled is None:
            S = self.num_states
            T = [self.transition_matrix(a) for a in range(len(self.actions))]
            # O filled in place and handed over without a copy: at the ward's size (233,280 states,
            # 15 actions and symbols) each float64 [A, S, Z] copy is 420 MB; past LARGE_O_ENTRIES
            # it is float32 (210 MB).
            shape = (len(self.actions), S, len(self.observations))
            O = np.empty(shape, dtype=np.float32 if int(np.prod(shape)) > LARGE_O_ENTRIES else np.float64)
            for a in range(len(self.actions)):
                O[a] = self.observation_matrix(a)
            model = Pomdp.create(
                self.state_names(), list(self.actions), self.observations, T, O, self.reward_matrix(),
                b0=self.start_belief(), discount=self.discount, name=self.name,
                sparse=S * S > DENSE_LIMIT, tolerance=1e-6, copy=False,
            )
            model.metadata.update({
                "domain": self.name,
                "source": self.source,
                "features": {f.name: list(f.values) for f in self.features},
                "modalities": {m: list(z) for m, z in self.modalities.items()},
            })
            if self.horizon is not None:
                model.metadata["horizon"] = self.horizon
            self._compiled = model
        return self._compiled


# ====================================================================== loading and validation
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
        for key in d:
            if key not in TOP_KEYS:
                raise self.fail(str(key), f"unknown top-level key; expected one of {', '.join(TOP_KEYS)}", d, key)
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

    def apply_fitted(self, node: Any, parent: Any, transitions: List[List[_Cpt]], observations: List[_Cpt]) -> None:
        """``fitted:`` (written by ``pearl fit``): rows that replace rows of the tables above.

        ``transitions: {Action: {Feature: {"v1,v2": {value: p}}}}`` and
        ``observations: {Action: {"v1,v2": {symbol: p}}}``; a row key lists the values of the
        table's parents in their order (``"*"`` for a table without parents).
        """
        node = self.need_map(node, "fitted", parent, "fitted")
        for kind in node:
            if kind not in ("transitions", "observations"):
                raise self.fail(f"fitted.{kind}", "unknown key; expected transitions or observations", node, kind)
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

    def fitted_rows(self, cpt: _Cpt, rows: dict, where: str, values: List[str], noun: str) -> _Cpt:
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
        return _Cpt(cpt.parents, table, cpt.why, cpt.origin)

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
                for k in spec:
                    if k not in ("symbols", "input"):
                        raise self.fail(f"{where}.{k}", "unknown key; expected symbols and input", spec, k)
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
        for key in node:
            if key != "effects":
                raise self.fail(f"defaults.{key}", "unknown key; expected 'effects'", node, key)
        effects = self.need_map(node.get("effects", {}), "defaults.effects", node, "effects")
        out = {}
        for fname, spec in effects.items():
            where = f"defaults.effects.{fname}"
            f = self.feature_ref(fname, where, effects, fname)
            out[f] = (spec, where, effects, fname)
        return out

    def build_action(self, a: str, spec: Any, container: Any, defaults, categories) -> List[_Cpt]:
        where = f"actions.{a}"
        if spec is None:
            spec = {}
        spec = self.need_map(spec, where, container, a)
        for key in spec:
            if key not in ("effects", "category", "why", "description"):
                raise self.fail(f"{where}.{key}", "unknown key; expected effects, category, why or description", spec, key)
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

    def build_effect(self, f: int, spec: Any, where: str, container: Any, key: Any) -> _Cpt:
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
            for k in spec:
                if k not in ("set", "why"):
                    raise self.fail(f"{where}.{k}", "unexpected beside 'set'", spec, k)
            row = self.dist_row(spec["set"], feat.values, f"{where}.set", spec, "set", allow_keep=False,
                                noun=f"value of {feat.name}")
            return _Cpt((), row, why)
        for k in spec:
            if k not in ("parents", "table", "why"):
                raise self.fail(f"{where}.{k}", "unknown key; expected set, parents, table or why", spec, k)
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
        return _Cpt(tuple(full_parents), out, why)

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
    def build_observations(self, node: Any, parent: Any) -> List[_Cpt]:
        node = self.need_map(node, "observations", parent, "observations")
        for key in node:
            if key != "default" and key not in self.actions:
                raise self.fail(f"observations.{key}", f"unknown action {key!r} (keys are action names or 'default'); "
                                f"actions: {', '.join(self.actions)}", node, key)
        out = []
        cache: Dict[int, _Cpt] = {}
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

    def build_obs_table(self, spec: Any, where: str, container: Any, key: Any) -> _Cpt:
        spec = self.need_map(spec, where, container, key)
        if "mix" in spec:
            return self.build_obs_mixture(spec, where)
        for k in spec:
            if k not in ("parents", "table", "why"):
                raise self.fail(f"{where}.{k}", "unknown key; expected parents, table or why", spec, k)
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
        return _Cpt(tuple(parents), out, str(spec.get("why", "")))

    def build_obs_mixture(self, spec: dict, where: str) -> _Cpt:
        """``mix: [{weight: w, parents: [...], table: {...}}, …]`` → ``Σ_k w_k P_k(o | parents_k)``.

        Each component is one source of the step's single message (the scheduler, the
        user, the laser…); ``weight`` is the chance that this source speaks first.
        """
        for k in spec:
            if k not in ("mix", "why"):
                raise self.fail(f"{where}.{k}", "unexpected beside 'mix'", spec, k)
        comps = self.need_list(spec["mix"], f"{where}.mix", spec, "mix")
        if not comps:
            raise self.fail(f"{where}.mix", "an empty mixture", spec, "mix")
        parts: List[Tuple[float, _Cpt]] = []
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
        return _Cpt(tuple(union), out, str(spec.get("why", "")))

    # ------------------------------------------------------------ rewards
    def build_rewards(self, node: Any, parent: Any) -> List[RewardRule]:
        node = self.need_list(node, "rewards", parent, "rewards")
        rules = []
        for i, rule in enumerate(node):
            where = f"rewards[{i}]"
            rule = self.need_map(rule, where, node, i)
            for k in rule:
                if k not in ("action", "actions", "when", "reward", "why"):
                    raise self.fail(f"{where}.{k}", "unknown key; expected action, when, reward, why", rule, k)
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
            for k in item:
                if k not in ("state", "p", "why"):
                    raise self.fail(f"{where}.{k}", "unknown key; expected state, p, why", item, k)
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


def _persist(f: int, n: int) -> _Cpt:
    return _Cpt((f,), np.eye(n), "persists")


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
