"""State and observation abstraction of a subtask (Pineau & Thrun, eq. 18).

For subtask ``h`` with actions ``A_h`` (primitive and abstract), split the state
features into relevant ``X+`` and irrelevant ``X-`` such that, for every ``a ∈ A_h``::

    R(X+, X-, a)              = R(X+, a)                       (1) reward
    P(X+' | X+, X-, a)        = P(X+' | X+, a)                 (2) transition
    P(Z+ | X+', X-', a)       = P(Z+ | X+', a)                 (3) observation

Then ``X-`` and the irrelevant observations cannot change h's value function and are
dropped. What this module does, per subtask:

1. **Seed X+ from the factored spec**: the reward features of the primitives the
   subtask's actions execute (for an abstract action, every primitive its policy
   ``π_j`` picks), plus the features ``π_j`` itself reads (the child's X+), closed under
   transition parents.
2. **Check the conditions on the compiled arrays**, exactly. With ``L`` the lumping of
   states onto X+ values, the *observation kernel*
   ``K_{a,o}(s, x+') = Σ_{s' ∈ x+'} T_h(s,a,s') P(o | s,a,s')`` must depend on ``s``
   only through ``x+(s)`` — this is (2) when summed over ``o`` and (3) per ``o``
   (including the state-pair observation model of abstract actions), and ``R_h(s,a)``
   must depend only on ``x+(s)`` — (1). Any feature a condition still reads (found by
   comparing each state with its copy differing in that one feature) joins X+; repeat
   to a fixpoint. The result is *exact*: the X+ marginal of any full belief evolves
   autonomously, so the abstract value function equals the full one at every belief.
3. **Observations**: symbols that give the same posterior under every action of ``h``
   (kernels proportional action by action) are merged into one — in particular all
   symbols that carry no information about X+ under ``h``'s actions become one
   ``other`` symbol (Z-). Merging symbols with identical posteriors is exact.
4. **Standard form**: the abstract model is written with the engine's
   ``O[a, s', o]`` arrays. Abstract actions have the state-pair observation model
   ``P(o | s, â, s') = O(s', π(s), o)``, which in general is *not* a function of
   ``(â, s')``. We keep it exact by **augmenting only the states that need it**: for
   each next abstract state ``x'`` and action ``a``, the distinct observation rows over
   the predecessors of ``x'`` are numbered ``j = 0, 1, …``; the model gets one state
   ``(x', j)`` per number (most ``x'`` keep a single copy), ``T(x, a, (x', j))`` puts the
   transition mass on the copy whose row the predecessor ``x`` induces, and
   ``O(a, (x', j), ·)`` is that row. The copy index never influences reward or
   transitions, so every α-vector takes equal values on all copies of an ``x'``, and a
   full belief projects onto the abstract model by its X+ marginal placed on copy 0.
   The joint ``P(x', o | x, a)`` of the subtask is reproduced exactly, and so is the
   belief update.

Array conventions as everywhere: ``T[a][s, s']``, ``O[a, s', o]``, ``R[s, a]``.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Dict, List, Optional, Sequence, Set

import numpy as np
import scipy.sparse as sp

from pearl_pomdp.hierarchy.parameterize import StateFactors, SubtaskModel
from pearl_pomdp.errors import PearlError
from pearl_pomdp.model.pomdp import Pomdp
from pearl_pomdp.model.factored import FactoredDomain

__all__ = ["AbstractSubtask", "abstract_subtask", "KernelBuilder", "AbstractionTooLarge", "MAX_PAIRS",
           "SeparableTerms", "separable_reward_terms"]

#: Two probabilities (or rewards) closer than this are equal for the condition checks.
TOL = 1e-10
#: Most abstract state pairs ``X·X'`` a subtask's kernels may index (scipy's int32 row indices, and
#: the dense ``[X, X']`` per action of the standard form, stop well before).
MAX_PAIRS = 2 ** 31 - 1


class AbstractionTooLarge(PearlError):
    """A subtask's abstraction keeps too many states to build (the message names the subtask and why)."""


def _check_size(sub, factors: "StateFactors", keep, X: int) -> None:
    if X * X > MAX_PAIRS:
        names = [factors.names[f] for f in sorted(keep)]
        raise AbstractionTooLarge(
            f"subtask {sub.name}: its abstraction keeps {X:,} states ({len(names)} features: {', '.join(names)}), "
            f"{float(X) * X:.3g} state pairs > 2^31: a feature its actions' rewards, effects or observations read "
            f"(rules for every action '*' read every feature) cannot be dropped; the subtask cannot be planned")


@dataclass
class AbstractSubtask:
    """The abstract model of a subtask and how the full model maps onto it.

    Attributes:
        name: the subtask.
        model: the standard-form POMDP that SOLVE gets (states ``X+`` values, augmented where
            the state-pair observation model needs it; observations = merged classes).
        relevant: X+ feature names (domain order).
        irrelevant: X- feature names.
        seeded: the X+ the factored spec gave (step 1).
        added_by_check: features the exact check added beyond the seed (step 2).
        state_to_model: ``[S]`` int: full state → abstract model state (copy 0 of its X+ value).
        obs_to_model: ``[Z]`` int: full observation → merged class.
        informative: per model observation, False for the class that carries no information (Z-).
        lumped_states: number of X+ values (model states before augmentation).
        checks: which eq. 18 conditions were checked and held (all True after the fixpoint).
    """

    name: str
    model: Pomdp
    relevant: List[str]
    irrelevant: List[str]
    seeded: List[str]
    added_by_check: List[str]
    state_to_model: np.ndarray
    obs_to_model: np.ndarray
    informative: List[bool]
    lumped_states: int
    checks: Dict[str, bool] = field(default_factory=dict)
    #: feature → the eq. 18 conditions ("reward", "transition", "observation") that made the check add it.
    added_reasons: Dict[str, List[str]] = field(default_factory=dict)

    @property
    def augmented_states(self) -> int:
        """States added by the state-pair observation augmentation."""
        return self.model.num_states - self.lumped_states

    def project(self, belief: np.ndarray) -> np.ndarray:
        """A full belief ``[S]`` → the abstract model's belief (X+ marginal on copy 0)."""
        return np.bincount(self.state_to_model, weights=np.asarray(belief, dtype=float),
                           minlength=self.model.num_states)

    def summary(self) -> dict:
        """JSON-ready description (feature lists, sizes, observation classes)."""
        return {
            "relevant_features": self.relevant,
            "irrelevant_features": self.irrelevant,
            "seeded_features": self.seeded,
            "added_by_check": self.added_by_check,
            "added_reasons": self.added_reasons,
            "lumped_states": self.lumped_states,
            "augmented_states": self.augmented_states,
            "observation_classes": self.model.observations,
            "informative": self.informative,
            "checks": self.checks,
        }


class KernelBuilder:
    """Observation kernels ``K_{a,o}(s, x')`` of a subtask for a given lumping of next states.

    Shared sparse copies of the model's ``T`` are cached across subtasks.
    """

    def __init__(self, model: Pomdp):
        self.model = model
        self._Tcsr: Dict[int, sp.csr_matrix] = {}

    def T(self, p: int) -> sp.csr_matrix:
        if p not in self._Tcsr:
            self._Tcsr[p] = sp.csr_matrix(self.model.T[p], dtype=float)
        return self._Tcsr[p]

    def kernels(self, source: np.ndarray, xmap: np.ndarray, X: int) -> List[sp.csr_matrix]:
        """Per action ``k``: CSR ``[S, X·Z]`` with entry ``(s, x'·Z + o) = Σ_{s'∈x'} T(s,π,s') O(s',π,o)``,
        ``π = source[k, s]`` (eq. 12–13 for primitives, 15–16 for abstract actions)."""
        model = self.model
        S, Z = model.num_states, model.num_observations
        cols = (xmap[:, None] * Z + np.arange(Z)[None, :]).ravel()
        rows = np.repeat(np.arange(S), Z)
        per_prim: Dict[int, sp.csr_matrix] = {}
        for p in np.unique(source):
            p = int(p)
            G = sp.csr_matrix((model.O[p].ravel(), (rows, cols)), shape=(S, X * Z))
            per_prim[p] = (self.T(p) @ G).tocsr()
        out = []
        for src in source:
            prims = np.unique(src)
            if prims.size == 1:
                out.append(per_prim[int(prims[0])])
                continue
            K = None
            for p in prims:
                part = sp.diags((src == p).astype(float)) @ per_prim[int(p)]
                K = part if K is None else K + part
            out.append(sp.csr_matrix(K))
        return out


def _full_strides(radices: Sequence[int]) -> np.ndarray:
    strides = np.ones(len(radices), dtype=np.int64)
    for i in range(len(radices) - 2, -1, -1):
        strides[i] = strides[i + 1] * radices[i + 1]
    return strides


def _partners(factors: StateFactors) -> List[np.ndarray]:
    """Per feature ``f``: ``[S]`` index of the state equal to ``s`` except feature ``f`` at value 0."""
    sv = factors.state_values
    S = sv.shape[0]
    strides = _full_strides(factors.radices)
    idx = sv @ strides
    if np.array_equal(idx, np.arange(S)):
        return [np.arange(S) - sv[:, f] * strides[f] for f in range(len(factors.names))]
    lookup = {tuple(row): i for i, row in enumerate(sv.tolist())}
    out = []
    for f in range(len(factors.names)):
        z = sv.copy()
        z[:, f] = 0
        out.append(np.array([lookup[tuple(r)] for r in z.tolist()], dtype=np.int64))
    return out


def _differs(M, partner: np.ndarray, tol: float) -> bool:
    """True when some row of ``M`` differs from its partner row by more than ``tol``."""
    if sp.issparse(M):
        D = (M[partner] - M).tocsr()
        return D.nnz > 0 and float(np.abs(D.data).max()) > tol
    return bool(np.abs(M[partner] - M).max(initial=0.0) > tol)


def _lumping(factors: StateFactors, keep: Sequence[int]):
    radices = [factors.radices[f] for f in keep]
    X = int(np.prod(radices)) if keep else 1
    if not keep:
        return np.zeros(factors.state_values.shape[0], dtype=np.int64), X
    strides = _full_strides(radices)
    return factors.state_values[:, list(keep)] @ strides, X


def _seed(sub: SubtaskModel, factors: StateFactors, domain, child_relevant: Sequence[str],
          dropped: Sequence[int] = ()) -> List[int]:
    """Step 1: reward features of the executed primitives (+ children's X+), closed under transition parents.

    ``dropped``: indices into ``domain.rewards`` of the separable terms taken out of the subtask's
    reward (:func:`separable_reward_terms`): their features are not seeded."""
    names = factors.names
    seed = set(n for n in child_relevant if n in names)
    prims = [sub.model.actions[int(p)] for p in np.unique(sub.source)]
    if isinstance(domain, FactoredDomain):
        skip = set(dropped)
        for p in prims:
            seed |= {f for i, rule in enumerate(domain.rewards) if i not in skip and p in rule.actions
                     for f in rule.when}
        grew = True
        parents = {p: domain.transition_parents(p) for p in prims}
        while grew:
            grew = False
            for f in list(seed):
                for p in prims:
                    for q in parents[p].get(f, [f]):
                        if q not in seed:
                            seed.add(q)
                            grew = True
    return sorted(names.index(n) for n in seed if n in names)


def abstract_subtask(sub: SubtaskModel, factors: StateFactors, domain=None, child_relevant: Sequence[str] = (),
                     enabled: bool = True, builder: Optional[KernelBuilder] = None, tol: float = TOL,
                     dropped: Sequence[int] = ()) -> AbstractSubtask:
    """Compute X+ / Z+ for subtask ``sub`` and build its abstract, standard-form model.

    Args:
        sub: the parameterized subtask (full state space).
        factors: the model's state features.
        domain: the FactoredDomain (for the seed from ``reward_features`` /
            ``transition_parents``), or ``None``.
        child_relevant: X+ features of the subtask's abstract children (π_j reads them).
        enabled: ``False`` keeps every feature and observation (only the standard-form
            conversion of the state-pair observation model is done).
        builder: a shared :class:`KernelBuilder` (caches sparse T).
        tol: equality tolerance of the checks.
        dropped: indices into ``domain.rewards`` of separable reward terms already taken out
            of ``sub.R`` (:func:`separable_reward_terms`); their features are not seeded.

    Returns:
        The :class:`AbstractSubtask`.

    Raises:
        AbstractionTooLarge: X+ keeps more than ``MAX_PAIRS`` state pairs (checked before any
            kernel is built: one line naming the subtask, its size and the features kept).
    """
    model = sub.model
    builder = builder or KernelBuilder(model)
    F = len(factors.names)
    Z = model.num_observations
    partners = _partners(factors)
    if enabled:
        seed = _seed(sub, factors, domain, child_relevant, dropped)
        keep = set(seed)
        # (1) reward: features R_h reads.
        keep |= {f for f in range(F) if _differs(sub.R, partners[f], 1e-9)}
    else:
        seed = list(range(F))
        keep = set(range(F))
    reasons: Dict[str, List[str]] = {}
    while True:
        order = sorted(keep)
        xmap, X = _lumping(factors, order)
        _check_size(sub, factors, keep, X)
        K = builder.kernels(sub.source, xmap, X)
        found = _violations(sub, K, X, Z, partners, keep, tol)
        added = set().union(*found.values())
        if not added:
            break
        for cond, feats in found.items():
            for f in feats:
                reasons.setdefault(factors.names[f], []).append(cond)
        keep |= added
        if isinstance(domain, FactoredDomain):
            keep |= set(_seed_closure(sub, factors, domain, keep))
    # The fixpoint: no condition reads a feature outside X+ (recorded for the report).
    checks = {cond: not feats for cond, feats in found.items()}
    order = sorted(keep)
    xmap, X = _lumping(factors, order)
    _, rep = np.unique(xmap, return_index=True)
    R_abs = sub.R[rep]
    # Per action, the kernel with rows (x, x') and one column per observation: [X·X', Z] (sparse).
    cols = [_by_observation(Kk[rep], X, Z) for Kk in K]

    # Step 3: merge observations whose posteriors coincide under every action.
    classes = _merge_observations(cols, tol) if enabled else [[o] for o in range(Z)]
    obs_to_model = np.empty(Z, dtype=np.int64)
    for c, members in enumerate(classes):
        obs_to_model[members] = c
    C = len(classes)
    merge = sp.csr_matrix((np.ones(Z), (np.arange(Z), obs_to_model)), shape=(Z, C))
    cols_c = [(M @ merge).tocsr() for M in cols]  # [X·X', C]
    T_flat = [np.asarray(M.sum(axis=1)).ravel() for M in cols_c]  # [X·X'] = T_abs(x, a, x')
    T_cols = [_as_column(T) for T in T_flat]
    informative = [_informative([M[:, c] for M in cols_c], T_cols, tol) for c in range(C)]
    class_names = [_class_name([model.observations[o] for o in members], informative[c])
                   for c, members in enumerate(classes)]

    pomdp, offset = _standard_form(sub, factors, order, X, xmap, cols_c, T_flat, R_abs, class_names, tol)
    seeded_names = [factors.names[f] for f in seed]
    return AbstractSubtask(
        name=sub.name, model=pomdp,
        relevant=[factors.names[f] for f in order],
        irrelevant=[factors.names[f] for f in range(F) if f not in keep],
        seeded=seeded_names if enabled else [],
        added_by_check=[factors.names[f] for f in order if f not in seed] if enabled else [],
        state_to_model=offset[xmap], obs_to_model=obs_to_model, informative=informative,
        lumped_states=X, checks=checks, added_reasons=reasons,
    )


def _violations(sub, K, X, Z, partners, keep, tol) -> Dict[str, set]:
    """Features outside ``keep`` that eq. 18's conditions (1), (2), (3) still read."""
    summer = sp.csr_matrix((np.ones(X * Z), (np.arange(X * Z), np.repeat(np.arange(X), Z))), shape=(X * Z, X))
    marginals = [(Kk @ summer).tocsr() for Kk in K]
    out: Dict[str, Set[int]] = {"reward": set(), "transition": set(), "observation": set()}
    for f in range(len(partners)):
        if f in keep:
            continue
        if _differs(sub.R, partners[f], 1e-9):
            out["reward"].add(f)
        if any(_differs(M, partners[f], tol) for M in marginals):
            out["transition"].add(f)
        elif any(_differs(Kk, partners[f], tol) for Kk in K):
            out["observation"].add(f)
    return out


def _seed_closure(sub: SubtaskModel, factors: StateFactors, domain, keep) -> List[int]:
    prims = [sub.model.actions[int(p)] for p in np.unique(sub.source)]
    cur = {factors.names[f] for f in keep}
    grew = True
    while grew:
        grew = False
        for p in prims:
            parents = domain.transition_parents(p)
            for f in list(cur):
                for q in parents.get(f, [f]):
                    if q not in cur and q in factors.names:
                        cur.add(q)
                        grew = True
    return [factors.names.index(n) for n in cur]


def _by_observation(Kx: sp.csr_matrix, X: int, Z: int) -> sp.csc_matrix:
    """``[X, X'·Z]`` kernel rows → ``[X·X', Z]`` (one column per observation)."""
    coo = Kx.tocoo()
    return sp.csc_matrix((coo.data, (coo.row * X + coo.col // Z, coo.col % Z)), shape=(X * X, Z))


def _as_column(v) -> sp.csc_matrix:
    return v if sp.issparse(v) else sp.csc_matrix(np.asarray(v, dtype=float).reshape(-1, 1))


def _proportional(u, v, tol: float) -> bool:
    """True when two non-negative vectors (sparse columns or dense) are proportional (a zero one is
    proportional to anything: merging it changes no posterior)."""
    u, v = _as_column(u), _as_column(v)
    su, sv = float(u.sum()), float(v.sum())
    if su <= TOL or sv <= TOL:
        return True
    d = (u * (1.0 / su) - v * (1.0 / sv)).tocsc()
    return d.nnz == 0 or bool(np.abs(d.data).max() <= tol * 100)


def _merge_observations(cols: List[sp.csc_matrix], tol: float) -> List[List[int]]:
    """Greedy classes of observations whose kernels are proportional action by action.

    Candidates are found by a random projection of each normalised column (proportional
    columns project equally), then confirmed exactly before merging.
    """
    A = len(cols)
    n, Z = cols[0].shape
    rng = np.random.default_rng(12345)
    r = rng.random(n)
    rows = []  # [A] per observation: projection of the normalised column, NaN when zero
    for M in cols:
        total = np.asarray(M.sum(axis=0)).ravel()
        proj = np.asarray(M.T @ r).ravel()
        rows.append(np.where(total > TOL, proj / np.where(total > TOL, total, 1.0), np.nan))
    sigs = np.array(rows).T  # [Z, A]
    classes: List[List[int]] = []
    class_sig: List[np.ndarray] = []
    for o in range(Z):
        for c, cs in enumerate(class_sig):
            both = ~np.isnan(cs) & ~np.isnan(sigs[o])
            if np.all(np.abs(cs[both] - sigs[o][both]) <= 1e-9 * (1.0 + np.abs(cs[both]))):
                if all(_proportional(cols[a][:, o], _class_column(cols[a], classes[c]), tol) for a in range(A)):
                    classes[c].append(o)
                    class_sig[c] = np.where(np.isnan(cs), sigs[o], cs)
                    break
        else:
            classes.append([o])
            class_sig.append(sigs[o].copy())
    return classes


def _class_column(M: sp.csc_matrix, members: List[int]):
    return M[:, members].sum(axis=1)


def _informative(class_cols, T_flat: List[np.ndarray], tol: float) -> bool:
    """False when the class's kernel is proportional to the transition under every action (no information)."""
    return not all(_proportional(col, T, tol) for col, T in zip(class_cols, T_flat))


def _class_name(members: List[str], informative: bool) -> str:
    if len(members) == 1:
        return members[0]
    label = "|".join(members) if len(members) <= 3 else f"{members[0]}|{members[1]}|…(+{len(members) - 2})"
    return label if informative else f"other({label})"


def _standard_form(sub, factors, order, X, xmap, cols_c, T_flat, R_abs, class_names, tol):
    """Step 4: the augmented standard-form POMDP (module doc) and the offsets of copy 0.

    ``cols_c[a]`` is the merged kernel ``[X·X', C]`` of action ``a``, ``T_flat[a]`` its row sums.
    """
    A, C = len(cols_c), len(class_names)
    moves = []  # per action: (x, x', T, copy label)
    rows_of: List[List[List[np.ndarray]]] = []
    counts = np.zeros((A, X), dtype=np.int64)
    for a in range(A):
        pairs = np.flatnonzero(T_flat[a] > tol)
        xs, x2s = pairs // X, pairs % X
        tv = T_flat[a][pairs]
        rows = cols_c[a][pairs].toarray() / tv[:, None]
        # Group equal observation rows per x' (equal to ~1e-9; a split only costs a spare copy).
        keys = np.column_stack([x2s.astype(float), np.round(rows * 1e9)])
        uniq, first, inv = np.unique(keys, axis=0, return_index=True, return_inverse=True)
        inv = inv.ravel()
        ux2 = uniq[:, 0].astype(np.int64)
        start = np.searchsorted(ux2, np.arange(X))
        moves.append((xs, x2s, tv, inv - start[x2s]))
        counts[a] = np.bincount(ux2, minlength=X)
        per: List[List[np.ndarray]] = [[] for _ in range(X)]
        for u in range(uniq.shape[0]):
            per[ux2[u]].append(rows[first[u]])
        rows_of.append(per)
    copies = np.maximum(1, counts.max(axis=0))
    offset = np.concatenate([[0], np.cumsum(copies)[:-1]]).astype(np.int64)
    N = int(copies.sum())
    aug_to_x = np.repeat(np.arange(X), copies)
    T = []
    O = np.empty((A, N, C))
    for a in range(A):
        xs, x2s, tv, labels = moves[a]
        M = sp.csr_matrix((tv, (xs, offset[x2s] + labels)), shape=(X, N)).toarray()
        # Renormalise away rounding from the lumping sums.
        M /= M.sum(axis=1, keepdims=True)
        T.append(M[aug_to_x])
        for x2 in range(X):
            distinct = rows_of[a][x2]
            for j in range(copies[x2]):
                # A copy that action a never lands on gets any valid row (a never reads it).
                row = distinct[j] if j < len(distinct) else (distinct[0] if distinct else np.full(C, 1.0 / C))
                O[a, offset[x2] + j] = row / row.sum()
    names = _state_names(factors, order, X)
    states = [names[x] if j == 0 else f"{names[x]}#{j}" for x in range(X) for j in range(copies[x])]
    b0_x = np.bincount(xmap, weights=sub.b0, minlength=X)
    b0 = np.zeros(N)
    b0[offset] = b0_x
    pomdp = Pomdp.create(states, list(sub.actions), class_names, T, O, R_abs[aug_to_x], b0=b0 / b0.sum(),
                         discount=sub.discount, name=f"{sub.model.name}/{sub.name}")
    return pomdp, offset


def _state_names(factors: StateFactors, order, X) -> List[str]:
    if not order:
        return ["*"]
    names = [""] * X
    radices = [factors.radices[f] for f in order]
    strides = _full_strides(radices)
    for x in range(X):
        parts = []
        for i, f in enumerate(order):
            v = (x // strides[i]) % radices[i]
            value = factors.values[f][v]
            parts.append(value if factors.names == ["state"] else f"{factors.names[f]}={value}")
        names[x] = ",".join(parts)
    return names


# ------------------------------------------------------------------ separable reward terms
@dataclass
class SeparableTerms:
    """The reward rules a subtask may leave out of its local reward (:func:`separable_reward_terms`).

    Attributes:
        rules: indices into ``domain.rewards``.
        term: ``[S]`` the sum of those rules' rewards in each state (subtracted from every action's
            reward of the subtask).
        described: per rule, ``"<where>: <why>"`` for the plan report.
    """

    rules: List[int]
    term: np.ndarray
    described: List[str]

    def apply(self, R: np.ndarray) -> np.ndarray:
        """``R [S, A_h]`` without the separable terms (every column minus :attr:`term`)."""
        return R - self.term[:, None] if self.rules else R


def _autonomous(domain: FactoredDomain, features: Sequence[str], primitives: Sequence[str]) -> bool:
    """True when the features, closed under transition parents, move the same way under every primitive:
    each feature of the closure has the same parents and the same table under all of ``primitives``."""
    closure = set(features)
    frontier = list(features)
    while frontier:
        f = frontier.pop()
        tables = [domain.transition_table(p, f) for p in primitives]
        parents0, table0 = tables[0]
        for parents, table in tables[1:]:
            if parents != parents0 or table.shape != table0.shape or not np.array_equal(table, table0):
                return False
        for q in parents0:
            if q not in closure:
                closure.add(q)
                frontier.append(q)
    return True


def separable_reward_terms(domain, primitives: Sequence[str], charged_under: Sequence[str]) -> SeparableTerms:
    """The reward rules whose value no action of a subtask can change, so its choice does not depend on them.

    A rule is separable from a subtask whose actions execute ``primitives`` when

    1. it reads at least one feature (a rule without ``when`` buys no abstraction: it is kept);
    2. it is charged under every action of ``charged_under`` — the subtask's primitives, and for an
       option (a subtask that may stop, :mod:`~pearl_pomdp.hierarchy.options`) every primitive of
       the domain, since stopping hands the step to the parent, which pays the rule too; and
    3. its features are *autonomous* under the subtask: closed under the transition parents, each
       of them has the same parents and table under every one of ``primitives`` — so no action of
       the subtask (nor anything its actions change) moves them.

    Then the rule adds ``E[Σ_t γ^t c(x_t) | b]`` to the value of every policy of the subtask alike
    (the law of an autonomous chain does not depend on the actions taken), and to every action's
    Q-value alike: leaving it out changes no choice (docs/hierarchy.md, "Separable reward terms").

    Args:
        domain: the FactoredDomain (a flat model has no rules: nothing is separable).
        primitives: the primitives below the subtask.
        charged_under: the actions the rule must be charged under (see 2.).

    Returns:
        :class:`SeparableTerms` (empty when nothing qualifies).
    """
    if not isinstance(domain, FactoredDomain) or not primitives:
        return SeparableTerms([], np.zeros(0), [])
    S = domain.num_states
    term = np.zeros(S)
    rules, described = [], []
    need = set(charged_under) | set(primitives)
    sv = domain.state_values
    for i, rule in enumerate(domain.rewards):
        if not rule.when or not need <= set(rule.actions):
            continue
        if not _autonomous(domain, list(rule.when), list(primitives)):
            continue
        mask = np.ones(S, dtype=bool)
        for fname, vals in rule.when.items():
            mask &= np.isin(sv[:, domain.feature_index(fname)], vals)
        term[mask] += rule.reward
        rules.append(i)
        described.append(f"{rule.where or f'rewards[{i}]'}: {rule.why}".strip())
    return SeparableTerms(rules, term, described)
