"""Anytime DESPOT (Ye, Somani, Hsu & Lee, *DESPOT: Online POMDP Planning with Regularization*,
JAIR 58, 2017; Somani et al., NIPS 2013), over a :class:`~pearl_pomdp.online.generative.GenerativeModel`.

A decision samples ``K`` scenarios — a start state from the root belief and a stream of uniforms
per depth — and grows a sparse belief tree in which every node holds the scenarios consistent
with its action-observation history. A *trial* walks from the root down the action with the
highest upper bound and the observation child with the largest *excess uncertainty*
``E(b) = γ^d (U(b) - L(b)) - ξ |Φ_b|/K (U(b0) - L(b0))`` (Alg. 3 of the JAIR paper), expands
leaves (every action, every observation the scenarios produce), and backs the bounds up:
``L(b,a) = Σ_φ r_φ/K − λ γ^{-d} + γ Σ_o L(b')``, ``L(b) = max(L₀(b), max_a L(b,a))``,
``U(b) = min(U₀(b), max_a U(b,a))``. The decision is the root action with the best lower bound.

Node values are *totals over the root's K scenarios divided by K*, discounted from the node
(not from the root): a node holding half the scenarios with per-particle value 10 has value 5.

The budget is deterministic: ``trials`` per decision, every random number drawn from a
generator seeded per decision; ``time_limit`` is only a guard: no expansion starts that would
end past it at the pace of the slowest expansion so far (the trial under way stops and backs up).
"""
from __future__ import annotations

import gc
import time
from dataclasses import dataclass
from typing import Dict, List, Optional

import numpy as np

from pearl_pomdp.online import _step_kernel
from pearl_pomdp.online.generative import Bounds, GenerativeModel

__all__ = ["DespotSettings", "Despot", "SearchResult", "CLOCKS"]

#: ``DespotSettings.clock`` → the clock the time guard reads.
CLOCKS = {"wall": time.perf_counter, "process": time.process_time}


@dataclass(frozen=True)
class DespotSettings:
    """The search's parameters (defaults: the JAIR paper's K = 500, D = 90, ξ = 0.95, λ = 0).

    Attributes:
        scenarios: ``K``, scenarios sampled at the root.
        depth: ``D``, the deepest node a trial expands.
        xi: ``ξ`` in (0, 1]: a trial stops where the gap is below this share of the root's.
        regularization: ``λ`` ≥ 0, the price of a policy node (0: plain anytime DESPOT).
        trials: trials per decision (the deterministic budget); ``None``: until ``time_limit``.
        time_limit: seconds per decision, a guard checked before each expansion against the slowest
            expansion so far; ``None``: none.
        gap_tolerance: stop early once ``U(b0) − L(b0)`` is at most this.
        clock: what ``time_limit`` measures: ``"wall"`` (the default: what a robot waits) or
            ``"process"`` (this process's CPU seconds, as DESPOT's own code counts its budget: a
            benchmark on a shared machine gives each decision the same work whatever the load).
    """

    scenarios: int = 500
    depth: int = 90
    xi: float = 0.95
    regularization: float = 0.0
    trials: Optional[int] = 1000
    time_limit: Optional[float] = None
    gap_tolerance: float = 1e-6
    clock: str = "wall"

    def __post_init__(self):
        if self.clock not in CLOCKS:
            raise ValueError(f"clock: {self.clock!r} is not one of {', '.join(CLOCKS)}")
        if self.scenarios < 1:
            raise ValueError(f"scenarios: {self.scenarios} is not a positive count")
        if self.depth < 1:
            raise ValueError(f"depth: {self.depth} is not a positive count")
        if not 0.0 < self.xi <= 1.0:
            raise ValueError(f"xi: {self.xi} is not in (0, 1]")
        if self.regularization < 0:
            raise ValueError(f"regularization: {self.regularization} is negative")
        if self.trials is None and self.time_limit is None:
            raise ValueError("trials and time_limit are both unset: the search would never stop")
        if self.trials is not None and self.trials < 1:
            raise ValueError(f"trials: {self.trials} is not a positive count")
        if self.time_limit is not None and not self.time_limit > 0:
            raise ValueError(f"time_limit: {self.time_limit} is not a positive number of seconds")


class _Belief:
    """A DESPOT belief node: the scenarios that reach it and their states; ``expansion`` once expanded."""

    __slots__ = ("states", "scenarios", "depth", "lower", "upper", "lower0", "upper0", "expansion", "terminal")

    def __init__(self, states, scenarios, depth, lower0=0.0, upper0=0.0, terminal=False):
        self.states = states
        self.scenarios = scenarios
        self.depth = depth
        self.expansion: Optional["_Expansion"] = None
        self.lower = self.lower0 = lower0
        self.upper = self.upper0 = upper0
        self.terminal = terminal


class _Expansion:
    """An expanded node's actions and their observation children, as columns of lists.

    Per action ``a``: ``rewards[a]`` (a total over the root's scenarios / K) and its current bounds
    ``lower[a]``, ``upper[a]``; its children are positions ``cut[a] .. cut[a + 1] - 1`` of the child
    columns, in ascending observation: ``observations``, current bounds ``lowers``/``uppers``,
    scenario ``counts``, first position ``starts`` of their particles in the grouped arrays
    ``states``/``scenarios``, and ``terminal``. A child becomes a :class:`_Belief` (``kids[position]``)
    only when a trial walks into it: most never do (on the ward ~1 of an expansion's ~28 children),
    and an object per child, or per action, would cost more than the search does with them. A
    created child's bounds are copied back into ``lowers``/``uppers`` as the trial backs up, so the
    columns always hold every child's current bounds.
    """

    __slots__ = ("rewards", "lower", "upper", "cut", "observations", "lowers", "uppers", "counts", "starts", "terminal",
                 "states", "scenarios", "kids")

    def __init__(self, rewards: List[float], cut: List[int], observations: List[int], lowers: List[float],
                 uppers: List[float], counts: List[int], starts: List[int], terminal: List[bool], states: np.ndarray,
                 scenarios: np.ndarray):
        self.rewards = rewards
        self.lower: List[float] = [0.0] * len(rewards)
        self.upper: List[float] = [0.0] * len(rewards)
        self.cut = cut
        self.observations = observations
        self.lowers = lowers
        self.uppers = uppers
        self.counts = counts
        self.starts = starts
        self.terminal = terminal
        self.states = states
        self.scenarios = scenarios
        self.kids: Dict[int, _Belief] = {}

    def child(self, position: int, depth: int) -> _Belief:
        """Child ``position`` as a node (created at its first visit with its initial bounds)."""
        kid = self.kids.get(position)
        if kid is None:
            begin, end = self.starts[position], self.starts[position] + self.counts[position]
            kid = _Belief(self.states[begin:end], self.scenarios[begin:end], depth, self.lowers[position],
                          self.uppers[position], self.terminal[position])
            self.kids[position] = kid
        return kid


@dataclass
class SearchResult:
    """One decision's outcome and the size of the search behind it.

    Attributes:
        action: the chosen action index (best lower bound at the root).
        lower, upper: the root's bounds after the search (``gap = upper − lower``).
        trials: trials run; ``nodes``: belief nodes in the tree; ``expansions``: nodes expanded.
        seconds: the search's time on the settings' clock (wall-clock by default).
        stop: why it stopped: ``"trials"``, ``"time_limit"`` or ``"gap"``.
        action_bounds: per root action ``(lower, upper)``.
        top: the top of the tree (see :meth:`Despot.tree_top`).
    """

    action: int
    lower: float
    upper: float
    trials: int
    nodes: int
    expansions: int
    seconds: float
    stop: str
    action_bounds: List[tuple]
    top: dict

    @property
    def gap(self) -> float:
        return self.upper - self.lower

    def as_dict(self) -> dict:
        return {"action": self.action, "lower": self.lower, "upper": self.upper, "gap": self.gap,
                "trials": self.trials, "nodes": self.nodes, "expansions": self.expansions,
                "seconds": self.seconds, "stop": self.stop}


class Despot:
    """The anytime DESPOT search (see the module doc).

    Args:
        model: the generative model.
        bounds: the heuristics (:class:`~pearl_pomdp.online.generative.Bounds`).
        settings: :class:`DespotSettings`.
    """

    def __init__(self, model: GenerativeModel, bounds: Bounds, settings: DespotSettings = DespotSettings()):
        self.model = model
        self.bounds = bounds
        self.settings = settings
        self._powers = model.discount ** np.arange(settings.depth + 2)

    # ------------------------------------------------------------------ search
    def search(self, root_states: np.ndarray, seed: int) -> SearchResult:
        """Plan from the particles ``root_states`` (``[K]`` states: the sampled scenarios' starts).

        Everything random comes from ``numpy.random.default_rng(seed)``: the same seed and
        particles give the same tree and the same action (with ``trials`` as the budget).

        Python's cyclic garbage collector is paused during the search (and restored after). The
        tree has no cycles (nodes point only down), so reference counting frees it as the search
        returns; the thousands of nodes it allocates would otherwise start collections in the
        middle of the decision, and a full one walks every object of the process: ~30 ms on the
        ward, every ~10 decisions in bench/ward_decision.py (docs/ward.md).
        """
        paused = gc.isenabled()
        gc.disable()
        try:
            return self._search(root_states, seed)
        finally:
            if paused:
                gc.enable()

    def _search(self, root_states: np.ndarray, seed: int) -> SearchResult:
        st = self.settings
        now = self._now = CLOCKS[st.clock]
        t0 = now()
        rng = np.random.default_rng(seed)
        K = int(root_states.shape[0])
        self._K = K
        self._rng = rng
        self._uniforms = rng.random((K, st.depth + 1, self.model.uniforms_per_step))
        self._nodes = 1
        self._expansions = 0
        self._deadline = None if st.time_limit is None else t0 + st.time_limit
        self._slowest = 0.0      # the longest expansion of this search (the guard's look-ahead)
        states = np.ascontiguousarray(root_states, dtype=np.int64)
        # Bounds whose default policy depends on the belief being planned for (not on a node's own
        # scenarios) hear of it first; the others have no such method and see no change.
        begin = getattr(self.bounds, "begin_search", None)
        if begin is not None:
            begin(states)
        lowers, uppers, terminal = self._initial_bounds(states, np.array([0, K], dtype=np.int64))
        root = _Belief(states, np.arange(K, dtype=np.int64), 0, lowers[0], uppers[0], terminal[0])
        trials, stop = 0, "trials"
        while True:
            self._trial(root)
            trials += 1
            if root.upper - root.lower <= st.gap_tolerance:
                stop = "gap"
                break
            if st.trials is not None and trials >= st.trials:
                stop = "trials"
                break
            if self._deadline is not None and now() + self._slowest >= self._deadline:
                stop = "time_limit"
                break
        top = root.expansion
        assert top is not None   # the first trial expands the root
        action = int(np.argmax(top.lower))
        return SearchResult(action, root.lower, root.upper, trials, self._nodes, self._expansions,
                            now() - t0, stop, list(zip(top.lower, top.upper)), self.tree_top(root))

    def _initial_bounds(self, states: np.ndarray, starts: np.ndarray):
        """The initial bounds of the particle sets ``states[starts[g]:starts[g + 1]]`` (``starts`` from 0
        to ``len(states)``, no set empty): lists ``(lower0, upper0, terminal)``.

        A set's bounds are those of its live (non-terminal) particles, times their share of the root's
        K scenarios (node values are totals over the root's scenarios / K); a set with none alive is
        terminal, bounds 0. The bounds come in one call for every set when they offer it: ``grouped``
        (the sets as one array), else ``many`` (a list of arrays), else ``both`` or ``lower``/``upper``
        per set, in order. The search spends much of its time here: one call beats a call per node.
        """
        K = self._K
        alive = ~np.asarray(self.model.is_terminal(states), dtype=bool)
        if alive.all():
            live_states, live = states, np.diff(starts)
        else:
            live = np.add.reduceat(alive.astype(np.int64), starts[:-1])
            live_states = states[alive]
        nonempty = live > 0
        live_starts = np.concatenate(([0], np.cumsum(live[nonempty]))).astype(np.int64)
        lower = np.zeros(live.shape[0])
        upper = np.zeros(live.shape[0])
        if live_states.shape[0] > 0:
            grouped = getattr(self.bounds, "grouped", None)
            many = getattr(self.bounds, "many", None)
            if grouped is not None:
                lowers, uppers = grouped(live_states, live_starts, self._rng)
            else:
                sets = np.split(live_states, live_starts[1:-1])
                if many is not None:
                    lowers, uppers = many(sets, self._rng)
                else:
                    both = getattr(self.bounds, "both", None)   # one pass for both bounds, when the bounds offer it
                    pairs = [both(p, self._rng) if both is not None else (self.bounds.lower(p, self._rng), self.bounds.upper(p))
                             for p in sets]
                    lowers, uppers = [lo for lo, _ in pairs], [up for _, up in pairs]
            share = live[nonempty] / K
            lower[nonempty] = share * np.asarray(lowers, dtype=float)
            upper[nonempty] = np.maximum(share * np.asarray(uppers, dtype=float), lower[nonempty])
        return lower.tolist(), upper.tolist(), (~nonempty).tolist()

    def _expand(self, node: _Belief) -> None:
        self._expansions += 1
        K = self._K
        A = len(self.model.actions)
        u = self._uniforms[node.scenarios, node.depth]
        step_many = getattr(self.model, "step_many", None)   # every action in one pass, when offered
        if step_many is not None:   # ([A, N] arrays, or a sequence of A [N] arrays each)
            nxt, obs, rew = (np.asarray(x) for x in step_many(node.states, u))
        else:
            nxt, obs, rew = (np.stack(x) for x in zip(*(self.model.step(node.states, a, u) for a in range(A))))
        rewards = (rew.sum(axis=1) / K).tolist()   # (each row summed as rew[a].sum() sums it)
        # Every child of every action at once (the C kernel): the particles grouped by (action,
        # observation), in action order, then ascending observation, each child's particles in the
        # node's order; the children's particles are slices of the grouped arrays.
        N = node.states.shape[0]
        states = np.empty(A * N, dtype=np.int64)
        scenarios = np.empty(A * N, dtype=np.int64)
        g_action = np.empty(A * N, dtype=np.int64)
        g_obs = np.empty(A * N, dtype=np.int64)
        g_start = np.empty(A * N + 1, dtype=np.int64)
        G = _step_kernel.group_outcomes(np.ascontiguousarray(nxt, dtype=np.int64), np.ascontiguousarray(obs, dtype=np.int64),
                                        node.scenarios, states, scenarios, g_action, g_obs, g_start)
        starts = g_start[:G + 1]
        lowers, uppers, terminal = self._initial_bounds(states, starts)
        self._nodes += G
        counts = np.diff(starts).tolist()
        firsts = starts[:-1].tolist()
        observations = g_obs[:G].tolist()
        cut = np.searchsorted(g_action[:G], np.arange(A + 1)).tolist()   # action a's children: cut[a]..cut[a+1]-1
        ex = node.expansion = _Expansion(rewards, cut, observations, lowers, uppers, counts, firsts, terminal, states,
                                         scenarios)
        for a in range(A):
            self._backup_action(ex, a, node.depth)
        self._backup_belief(node)

    def _backup_action(self, ex: _Expansion, a: int, depth: int) -> None:
        g = self.model.discount
        penalty = self.settings.regularization / self._powers[min(depth, len(self._powers) - 1)]
        i, j = ex.cut[a], ex.cut[a + 1]
        ex.lower[a] = ex.rewards[a] - penalty + g * sum(ex.lowers[i:j])
        ex.upper[a] = ex.rewards[a] - penalty + g * sum(ex.uppers[i:j])

    def _backup_belief(self, node: _Belief) -> None:
        ex = node.expansion
        assert ex is not None
        node.lower = max(node.lower0, max(ex.lower))
        node.upper = max(min(node.upper0, max(ex.upper)), node.lower)

    def _excess(self, node: _Belief, root_gap: float) -> float:
        return (self._powers[node.depth] * (node.upper - node.lower)
                - self.settings.xi * node.scenarios.shape[0] / self._K * root_gap)

    def _best_child(self, ex: _Expansion, a: int, depth: int, root_gap: float):
        """``(position, excess)`` of the child of action ``a`` of ``ex`` (at ``depth``) with the largest
        excess uncertainty (the first of equals), computed as :meth:`_excess` computes a node's."""
        weight, xi, K = self._powers[depth], self.settings.xi, self._K
        i, j = ex.cut[a], ex.cut[a + 1]
        lowers, uppers, counts = ex.lowers, ex.uppers, ex.counts
        excess = [weight * (uppers[c] - lowers[c]) - xi * counts[c] / K * root_gap for c in range(i, j)]
        best = max(range(j - i), key=excess.__getitem__)
        return i + best, excess[best]

    def _trial(self, root: _Belief) -> None:
        path = [root]
        taken: List[int] = []   # per node of the path: the action the trial went down (-1: none)
        went: List[int] = []    # ... and the child it went to
        node = root
        root_gap = root.upper - root.lower
        while node.depth < self.settings.depth and not node.terminal:
            if node.expansion is None:
                if (node is not root and self._deadline is not None
                        and self._now() + self._slowest >= self._deadline):
                    break   # the wall-clock guard: back up what this trial found, then stop
                started = self._now()
                self._expand(node)
                self._slowest = max(self._slowest, self._now() - started)
            elif node is not root and self._excess(node, root_gap) <= 0:
                break
            ex = node.expansion
            assert ex is not None
            best = max(range(len(ex.upper)), key=ex.upper.__getitem__)     # the first of equals
            position, excess = self._best_child(ex, best, node.depth + 1, root_gap)
            if excess <= 0:
                break
            taken.append(best)
            went.append(position)
            node = ex.child(position, node.depth + 1)
            path.append(node)
        taken.append(-1)
        went.append(-1)
        # Only the nodes of the path changed, so at each only the action the trial took needs its
        # bounds backed up again, after its child's new bounds are copied into the columns (the other
        # children are as they were at their last backup: the same sums); then the node's own bounds
        # over all its actions.
        for n, a, position in zip(reversed(path), reversed(taken), reversed(went)):
            ex = n.expansion
            if ex is not None:
                if a >= 0:
                    kid = ex.kids[position]
                    ex.lowers[position], ex.uppers[position] = kid.lower, kid.upper
                    self._backup_action(ex, a, n.depth)
                self._backup_belief(n)

    # ------------------------------------------------------------------ report
    def tree_top(self, root: _Belief, width: int = 3) -> dict:
        """The root and, for its best few actions, their observation children (bounds, scenarios)."""
        K = self._K
        out: dict = {"lower": root.lower, "upper": root.upper, "scenarios": int(root.scenarios.shape[0]),
                     "actions": []}
        ex = root.expansion
        if ex is None:
            return out
        ranked = sorted(range(len(ex.lower)), key=lambda a: -ex.lower[a])
        for a in ranked[:width]:
            out["actions"].append({
                "action": self.model.actions[a], "lower": ex.lower[a], "upper": ex.upper[a], "reward": ex.rewards[a],
                "children": [{"observation": int(ex.observations[c]), "share": ex.counts[c] / K, "lower": ex.lowers[c],
                              "upper": ex.uppers[c], "expanded": c in ex.kids and ex.kids[c].expansion is not None}
                             for c in range(ex.cut[a], ex.cut[a + 1])]})
        return out
