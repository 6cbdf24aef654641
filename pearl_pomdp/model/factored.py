"""Factored (DBN-style) POMDP domains, compiled to a flat :class:`Pomdp`; read from YAML by
:mod:`pearl_pomdp.model.domain_yaml`.

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

import itertools
from dataclasses import dataclass, field
from typing import Any, Dict, List, Optional, Sequence, Set, Tuple, Union

import numpy as np
import scipy.sparse as sp

from pearl_pomdp.channels import InputChannel
from pearl_pomdp.model.pomdp import DENSE_LIMIT, LARGE_O_ENTRIES, Pomdp

__all__ = ["StateFeature", "FactoredDomain", "RewardRule", "Cpt"]


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
class Cpt:
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
    _transitions: List[List[Cpt]]  # [action][feature]
    _observations: List[Cpt]  # [action]; table [..., Z]
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

    def intended_effect(self, action: str, feature: str) -> Optional[str]:
        """The value ``action`` gives ``feature`` most likely from every state (p > 0.5), or ``None``.

        A drive's destination when the drive may fail: ``GotoPatientRoom`` sets
        ``RobotLocation`` to ``room`` with 0.97 and keeps it with 0.03; the intended effect is
        ``room``; a drive that never fails sets it with 1.
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

    # ---------------------------------------------------------------- compile
    def feature_transition(self, action: Union[str, int], f: int) -> np.ndarray:
        """``[S, |f|]``: ``P(s'_f = v | s, action)`` for every current state ``s``."""
        cpt = self._transitions[self._action_index(action)][f]
        sv = self.state_values
        return cpt.table[tuple(sv[:, p] for p in cpt.parents)] if cpt.parents else np.broadcast_to(
            cpt.table, (self.num_states, cpt.table.shape[-1]))

    def transition_matrix(self, action: Union[str, int], factors: Optional[dict] = None) -> sp.csr_matrix:
        """``T[a]`` as CSR ``[S, S]``, built from the per-feature factors without a dense ``S×S`` product.

        Each row holds the products of its state's non-zero factors, one of every feature, in C
        (``_step_kernel.product_rows``: the entries, their order and their products are those of
        the numpy expansion feature by feature it replaced, bit for bit, at ~1/20 of its time),
        so the cost is proportional to the number of non-zeros of ``T[a]``. ``factors``: a dict
        the calls of one compilation share, so that a feature's table that several actions have
        (the ward: 21 distinct of 150) is read over the states once.
        """
        from pearl_pomdp.online import _step_kernel

        a = self._action_index(action)
        S = self.num_states
        found = [self._state_factors(a, f, factors) for f in range(len(self.features))]
        sizes = np.ones(S, dtype=np.int64)
        for ptr, _, _ in found:
            sizes *= np.diff(ptr)
        indptr = np.zeros(S + 1, dtype=np.int64)
        np.cumsum(sizes, out=indptr[1:])
        nnz = int(indptr[-1])
        offsets = np.cumsum([0] + [len(values) for _, values, _ in found[:-1]])
        ptrs = np.stack([ptr + offset for (ptr, _, _), offset in zip(found, offsets)]) if found else \
            np.zeros((0, S + 1), dtype=np.int64)
        values = np.concatenate([v for _, v, _ in found]) if found else np.zeros(0, dtype=np.int64)
        probs = np.concatenate([p for _, _, p in found]).astype(np.float64, copy=False) if found else np.zeros(0)
        # int32 indices where they fit, as scipy chooses them
        index = np.int32 if max(S, nnz) <= np.iinfo(np.int32).max else np.int64
        indices, data = np.empty(nnz, dtype=index), np.empty(nnz, dtype=np.float64)
        _step_kernel.product_rows(ptrs, values.astype(np.int64, copy=False), probs,
                                  np.asarray(self.strides, dtype=np.int64), indptr, indices, data)
        return sp.csr_matrix((data, indices, indptr.astype(index, copy=False)), shape=(S, S))

    def _state_factors(self, a: int, f: int, cache: Optional[dict]) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(ptr [S+1], v, p)``: the non-zero ``P(s'_f = v | s, a) = p`` of every state ``s`` at
        ``ptr[s]..ptr[s+1]``, values ascending; shared through ``cache`` by equal tables."""
        cpt = self._transitions[a][f]
        key = (tuple(cpt.parents), cpt.table.shape, cpt.table.tobytes())
        if cache is not None and key in cache:
            return cache[key]
        M = self.feature_transition(a, f)  # [S, n_f]
        s_idx, v_all = np.nonzero(M > 0.0)
        ptr = np.zeros(self.num_states + 1, dtype=np.int64)
        np.cumsum(np.bincount(s_idx, minlength=self.num_states), out=ptr[1:])
        found = (ptr, v_all, M[s_idx, v_all])
        if cache is not None:
            cache[key] = found
        return found

    def observation_matrix(self, action: Union[str, int], out: Optional[np.ndarray] = None) -> np.ndarray:
        """``[S, Z]``: ``O[a, s', o]`` for one action, written into ``out`` when given (``[S, Z]``,
        float64 or float32: the table is cast first, which rounds each number as casting the
        result would) and returned. compile() fills its ``[A, S, Z]`` array this way, without a
        float64 ``[S, Z]`` per action in between (the ward: 28 MB each)."""
        cpt = self._observations[self._action_index(action)]
        if out is None:
            out = np.empty((self.num_states, cpt.table.shape[-1]))
        table = cpt.table.reshape(-1, cpt.table.shape[-1]).astype(out.dtype, copy=False)
        if not cpt.parents:
            out[:] = table[0]
            return out
        sv = self.state_values
        rows = np.ravel_multi_index(tuple(sv[:, p] for p in cpt.parents), cpt.table.shape[:-1])
        return np.take(table, rows, axis=0, out=out)

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
            factors: dict = {}
            T = [self.transition_matrix(a, factors) for a in range(len(self.actions))]
            del factors
            # O filled in place and handed over without a copy: at the ward's size (233,280 states,
            # 15 actions and symbols) each float64 [A, S, Z] copy is 420 MB; past LARGE_O_ENTRIES
            # it is float32 (210 MB).
            shape = (len(self.actions), S, len(self.observations))
            O = np.empty(shape, dtype=np.float32 if int(np.prod(shape)) > LARGE_O_ENTRIES else np.float64)
            for a in range(len(self.actions)):
                self.observation_matrix(a, out=O[a])
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
