"""LaserTag as a generative model, with its exact belief and its bounds.

LaserTag is Tag (Pineau, Gordon & Thrun, IJCAI 2003) with a laser for eyes (Somani, Ye, Hsu & Lee,
*DESPOT: Online POMDP Planning with Regularization*, NIPS 2013): a robot and an opponent on a 7×11
grid with 8 obstacles at random cells. The robot moves North, East, South or West (into a wall or
an obstacle: it stays), −1 a move; ``tag`` is +10 and ends the episode when both share a cell,
−10 otherwise (the episode goes on). The opponent moves away from the robot: along each axis
where they differ one cell away with 0.4, along an axis where they are level one cell either way
with 0.2 each, and stays with the remaining 0.2 (a move into a wall or an obstacle stays); its move
depends on the state before the robot's. The robot sees neither position: after every step its
laser reads the distance to the first obstacle, wall or the opponent in 8 directions (the four
axes and the four diagonals, a diagonal cell √2 long), each reading ``floor(d + ε)`` with
``ε ≤ 0`` half-normal of σ = 2.5 folded below the true distance ``d`` (``P(reading r) = 2 (Φ(min(d,
r + 1) − d) − Φ(r − d))``, ``Φ`` of N(0, 2.5²), the first bucket open below); when both share a cell it
reads the one observation "same cell". Every reading is a 7-bit field of the observation, 8 of
them: ~10⁸ observations, so the model is generative only. The start belief is uniform over every
pair of free cells (the robot does not know where it is either); γ = 0.95.

These are the dynamics and the observation model of DESPOT's own code (AdaCompNUS/despot,
``examples/cpp_models/tag/src/laser_tag/laser_tag.cpp`` and ``base/base_tag.cpp``), written here from
that description. The code draws its obstacles at random for every run (``RandomMap(7, 11, 8)``):
there is no standard map. Ours (:data:`LAYOUT`) is drawn once with ``numpy.random.default_rng(8)``;
:func:`random_lasertag` draws one as that code does, for a study over maps.

* :class:`LaserTag` — ``step`` over many particles at once, deterministic given 9 uniforms a
  step (the opponent's move, then one per beam), as the search needs
  (:mod:`pearl_pomdp.online.generative`).
* :class:`LaserTagBelief` — the exact belief over the 69² cell pairs (Bayes' rule with the
  transition and the 8 beams' likelihoods): the root's particles are drawn from it.
* :class:`LaserTagBounds` — above, each particle's value in the fully observed MDP (value
  iteration from the Manhattan chase's, which is a bound too: the opponent never comes closer, so
  no policy tags sooner; DESPOT's ``MANHATTAN``); below, the best of a few chases, policies of the history: tag when the
  laser reads "same cell", else walk the shortest path to where one of the set's most common
  particles puts the opponent, then move at random (as the rollout policy of DESPOT's code does
  once its path is walked).
"""
from __future__ import annotations

import math
from collections import defaultdict, deque
from typing import Dict, List, Sequence, Tuple

import numpy as np
import scipy.sparse as sp
from scipy import special

__all__ = ["LaserTag", "LaserTagBelief", "LaserTagBounds", "lasertag", "random_lasertag", "LAYOUT", "ROWS", "COLUMNS",
           "SAME_CELL", "NORTH", "EAST", "SOUTH", "WEST", "TAG"]

ROWS, COLUMNS, OBSTACLES = 7, 11, 8
#: The obstacles (x, y) of our fixed map: :func:`random_lasertag` with ``numpy.random.default_rng(8)``
#: (its free cells are connected). A test checks the draw.
LAYOUT: Tuple[Tuple[int, int], ...] = ((6, 6), (5, 5), (2, 1), (5, 1), (1, 2), (6, 4), (4, 4), (8, 6))
NORTH, EAST, SOUTH, WEST, TAG = range(5)
#: Moves and beams (x, y): the four axes (the actions' order), then the diagonals.
DIRECTIONS = ((0, 1), (1, 0), (0, -1), (-1, 0), (1, 1), (1, -1), (-1, -1), (-1, 1))
BITS_PER_READING = 7
#: The observation when robot and opponent share a cell: every reading 101.
SAME_CELL = sum(101 << (BITS_PER_READING * beam) for beam in range(8))
TAG_REWARD = 10.0
NOISE_SIGMA = 2.5


def _normal_cdf(x: np.ndarray) -> np.ndarray:
    """Φ of the laser's noise, N(0, σ²)."""
    return special.ndtr(np.asarray(x, dtype=float) / NOISE_SIGMA)


class LaserTag:
    """LaserTag on one map (module doc). States ``robot_cell · N + opponent_cell`` over the ``N`` free
    cells (row by row from y = 0), then one absorbing ``terminal`` state (tagged).

    Args:
        obstacles: the blocked ``(x, y)`` cells of the 11 × 7 grid.
        discount: γ.
    """

    uniforms_per_step = 1 + len(DIRECTIONS)

    def __init__(self, obstacles: Sequence[Tuple[int, int]] = LAYOUT, discount: float = 0.95):
        self.obstacles = tuple((int(x), int(y)) for x, y in obstacles)
        blocked = set(self.obstacles)
        if len(blocked) != len(self.obstacles) or any(not (0 <= x < COLUMNS and 0 <= y < ROWS) for x, y in blocked):
            raise ValueError(f"obstacles must be distinct cells of the {COLUMNS}x{ROWS} grid, got {obstacles}")
        self.name = "LaserTag" + ("" if self.obstacles == LAYOUT else f"[{len(blocked)} obstacles]")
        self.actions = ["north", "east", "south", "west", "tag"]
        self.discount = float(discount)
        self.cells: List[Tuple[int, int]] = [(x, y) for y in range(ROWS) for x in range(COLUMNS)
                                             if (x, y) not in blocked]
        self.index: Dict[Tuple[int, int], int] = {c: i for i, c in enumerate(self.cells)}
        n = self.n = len(self.cells)
        self.num_states = n * n + 1
        self.terminal = n * n
        # The robot's next cell per (cell, move); a wall or an obstacle: it stays.
        self.next_cell = np.array([[self.index.get((x + dx, y + dy), i) for dx, dy in DIRECTIONS[:4]]
                                   for i, (x, y) in enumerate(self.cells)], dtype=np.int64)
        self._build_opponent(n)
        self._build_readings(n)

    # ------------------------------------------------------------------ dynamics
    def _build_opponent(self, n: int) -> None:
        """Per (robot, opponent) pair, the opponent's next cells and their cumulative probabilities,
        in ascending cell order (the order the search's uniform is read in)."""
        width = 5
        cells = np.zeros((n * n, width), dtype=np.int64)
        cumulative = np.ones((n * n, width))
        for rob, (rx, ry) in enumerate(self.cells):
            for opp, (ox, oy) in enumerate(self.cells):
                moves: Dict[int, float] = defaultdict(float)
                steps_x = ((1, 0.2), (-1, 0.2)) if ox == rx else ((1 if ox > rx else -1, 0.4),)
                steps_y = ((1, 0.2), (-1, 0.2)) if oy == ry else ((1 if oy > ry else -1, 0.4),)
                for dx, p in steps_x:
                    moves[self.index.get((ox + dx, oy), opp)] += p
                for dy, p in steps_y:
                    moves[self.index.get((ox, oy + dy), opp)] += p
                moves[opp] += 0.2
                s = rob * n + opp
                targets = sorted(moves)
                cells[s, :len(targets)] = targets
                cells[s, len(targets):] = targets[-1]
                cumulative[s, :len(targets)] = np.cumsum([moves[c] for c in targets])
                cumulative[s, len(targets) - 1:] = 1.0
        self._opp_cells, self._opp_cumulative = cells, cumulative

    def _build_readings(self, n: int) -> None:
        """Per state and beam the reading's distribution: ``_reading_cdf [S, 8, R]`` (cumulative)
        and ``_reading_p [S, 8, R]`` (zero past the true distance)."""
        ranges = np.zeros((n * n, len(DIRECTIONS)))
        for rob, (rx, ry) in enumerate(self.cells):
            for opp, (ox, oy) in enumerate(self.cells):
                for beam, (dx, dy) in enumerate(DIRECTIONS):
                    d = 1
                    while (rx + dx * d, ry + dy * d) in self.index and (rx + dx * d, ry + dy * d) != (ox, oy):
                        d += 1
                    ranges[rob * n + opp, beam] = d * math.hypot(dx, dy)
        self.laser_range = ranges
        width = int(math.ceil(ranges.max()))
        bucket = np.arange(width)[None, None, :]
        dist = ranges[:, :, None]
        upper = _normal_cdf(np.minimum(dist, bucket + 1.0) - dist)
        lower = np.where(bucket > 0, _normal_cdf(bucket - dist), 0.0)
        p = np.where(bucket < dist, 2.0 * (upper - lower), 0.0)
        self._reading_p = p
        self._reading_cdf = np.cumsum(p, axis=2)

    def is_terminal(self, states):
        return np.asarray(states) == self.terminal

    def step(self, states, action, uniforms):
        """``(next_states, observations, rewards)`` of ``states [N]`` under ``action``, deterministic
        given ``uniforms [N, 9]`` (the opponent's move, then one per beam)."""
        nxt, rewards = self.transition(states, action, uniforms[:, 0])
        return nxt, self._observe(nxt, uniforms[:, 1:]), rewards

    def transition(self, states, action: int, uniform: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
        """``(next_states, rewards)`` of :meth:`step` without the observation (``uniform [N]``: the
        opponent's move): :meth:`transition_each` with ``action`` for every particle."""
        states = np.asarray(states, dtype=np.int64)
        return self.transition_each(states, np.full(states.shape, action, dtype=np.int64), uniform)

    def transition_each(self, states: np.ndarray, actions: np.ndarray,
                        uniform: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
        """``(next_states, rewards)`` with an action per particle (``actions [N]``; −1: no step, reward
        0): the bounds simulate many plans in one call, :meth:`transition` one action."""
        states = np.asarray(states, dtype=np.int64)
        n = self.n
        acting = actions >= 0
        live = (states != self.terminal) & acting
        s = np.where(live, states, 0)
        rob, opp = s // n, s % n
        tag = actions == TAG
        tagged = live & tag & (rob == opp)
        rewards = np.where(tag, np.where(rob == opp, TAG_REWARD, -TAG_REWARD), -1.0)
        next_rob = np.where(tag, rob, self.next_cell[rob, np.where(tag | ~acting, 0, actions)])
        pick = (uniform[:, None] > self._opp_cumulative[s]).sum(axis=1)
        next_opp = self._opp_cells[s, np.minimum(pick, self._opp_cells.shape[1] - 1)]
        nxt = np.where(tagged, self.terminal, np.where(live, next_rob * n + next_opp, states))
        return nxt, np.where(live, rewards, 0.0)

    def _observe(self, states: np.ndarray, uniforms: np.ndarray) -> np.ndarray:
        """The laser's observation of each state (``SAME_CELL`` when both share a cell or tagged)."""
        n = self.n
        live = states != self.terminal
        s = np.where(live, states, 0)
        cdf = self._reading_cdf[s]                                   # [N, 8, R]
        readings = (uniforms[:, :, None] > cdf).sum(axis=2)         # the first bucket whose cdf ≥ u
        tops = np.ceil(self.laser_range[s] - 1e-9).astype(np.int64) - 1
        readings = np.minimum(readings, np.maximum(tops, 0))        # round-off past the last bucket
        shifts = BITS_PER_READING * np.arange(len(DIRECTIONS), dtype=np.int64)
        obs = (readings.astype(np.int64) << shifts[None, :]).sum(axis=1)
        same = ~live | (s // n == s % n)
        return np.where(same, SAME_CELL, obs)

    def observation_likelihood(self, observation: int) -> np.ndarray:
        """``[S]``: P(observation | the state the step ended in), for every state."""
        like = np.zeros(self.num_states)
        n = self.n
        same = np.arange(n) * n + np.arange(n)
        if observation == SAME_CELL:
            like[same] = 1.0
            like[self.terminal] = 1.0
            return like
        readings = [(observation >> (BITS_PER_READING * beam)) & ((1 << BITS_PER_READING) - 1)
                    for beam in range(len(DIRECTIONS))]
        width = self._reading_p.shape[2]
        prod = np.ones(n * n)
        for beam, r in enumerate(readings):
            if r >= width:
                return like
            prod *= self._reading_p[:, beam, r]
        prod[same] = 0.0
        like[:n * n] = prod
        return like

    def transition_matrix(self, action: int) -> sp.csr_matrix:
        """``[S, S]`` sparse ``T[s, s']`` of ``action`` (what :class:`LaserTagBelief` predicts with)."""
        n = self.n
        s = np.arange(n * n)
        rob, opp = s // n, s % n
        probs = np.diff(np.concatenate([np.zeros((n * n, 1)), self._opp_cumulative], axis=1), axis=1)
        next_rob = rob if action == TAG else self.next_cell[rob, action]
        cols = next_rob[:, None] * n + self._opp_cells
        if action == TAG:
            cols = np.where((rob == opp)[:, None], self.terminal, cols)
        rows = np.repeat(s, probs.shape[1])
        T = sp.csr_matrix((probs.ravel(), (rows, cols.ravel())), shape=(self.num_states, self.num_states))
        T = T + sp.csr_matrix(([1.0], ([self.terminal], [self.terminal])), shape=T.shape)
        T.sum_duplicates()
        T.eliminate_zeros()
        return T

    def initial_belief(self) -> "LaserTagBelief":
        return LaserTagBelief(self)


class LaserTagBelief:
    """The exact belief over the cell pairs (and ``terminal``): uniform at the start, then Bayes'
    rule after each step — the transition, then the 8 beams' likelihood of what was read."""

    def __init__(self, model: LaserTag):
        self.model = model
        self.b = np.zeros(model.num_states)
        self.b[:model.n * model.n] = 1.0 / (model.n * model.n)
        self._T: Dict[int, sp.csr_matrix] = {}

    def sample(self, count: int, rng: np.random.Generator) -> np.ndarray:
        """``count`` states drawn from the belief."""
        cdf = np.cumsum(self.b)
        draws = np.searchsorted(cdf, rng.random(count) * cdf[-1], side="right")
        return np.minimum(draws, self.model.num_states - 1).astype(np.int64)

    def update(self, action: int, observation: int) -> None:
        """Bayes' rule after ``action`` and ``observation``.

        Raises:
            ValueError: the observation is impossible under the belief (a model mismatch)."""
        T = self._T.get(action)
        if T is None:
            T = self._T[action] = self.model.transition_matrix(action).T.tocsr()
        posterior = (T @ self.b) * self.model.observation_likelihood(observation)
        total = posterior.sum()
        if not total > 0:
            raise ValueError(f"LaserTag: observation {observation} has probability 0 after {self.model.actions[action]}")
        self.b = posterior / total


class LaserTagBounds:
    """LaserTag's bounds on a particle set (module doc): the fully observed MDP (or Manhattan) above,
    a policy of the history below.

    ``lower="walk"`` (the default): the random walk that tags when the laser reads "same cell" and
    otherwise moves at random (each move a quarter); its value :attr:`walk_values` is solved exactly
    once, and a set's bound is its particles' mean. It uses nothing a set's particles know.

    ``lower="chase"``: the best of chases: tag on "same cell", otherwise follow a shortest path to
    where one of the set's :attr:`modes` most common particles puts the opponent, then the walk. Its
    value on a particle is the plan's steps simulated (or, for a set of one state, pushed through
    exactly) and then the walk's value where the plan ended. Choosing a plan by the set's particles
    is a policy of the history in DESPOT's sense, but with ~10⁸ observations almost every node below
    the root holds one scenario, whose "most common particle" is the scenario's own state: the bound
    then chases an opponent it has been told where to find, every action looks as informed as
    every other, and the search learns nothing about looking (docs/online.md, LaserTag). Kept to
    compare.

    ``lower="target"``: the best of the walk and, per target cell, "tag on "same cell", else a
    shortest move towards the target, then the walk", simulated on the set's particles; the
    targets are the opponent's most common cells among the root's particles, which the search
    hands over first (:meth:`begin_search`), so no node heads for what its own scenarios know
    (after DESPOT's ``TagSHRPolicy``, which heads for the exact belief's mode).
    """

    def __init__(self, model: LaserTag, modes: int = 3, upper: str = "mdp", lower: str = "walk"):
        self.model = model
        g = model.discount
        if upper not in ("mdp", "manhattan"):
            raise ValueError(f"upper bound {upper!r}: expected 'mdp' or 'manhattan'")
        if lower not in ("walk", "chase", "target"):
            raise ValueError(f"lower bound {lower!r}: expected 'walk', 'chase' or 'target'")
        #: ``lower="target"``: the opponent cells the plans head for, from the belief the search
        #: plans for (:meth:`begin_search`), not from a node's own scenarios.
        self.targets: List[int] = []
        #: ``"walk"``, ``"chase"`` or ``"target"`` (class doc).
        self.lower_kind = lower
        xy = np.array(model.cells)
        dist = np.abs(xy[:, None, :] - xy[None, :, :]).sum(axis=2).reshape(-1)
        manhattan = -(1.0 - g ** dist) / (1.0 - g) + TAG_REWARD * g ** dist
        #: ``[S]``: the upper bound per state: the fully observed MDP's value (``"mdp"``: it sees
        #: both cells, so no policy of the laser does better), or the Manhattan chase (``"manhattan"``).
        self.upper_values = np.concatenate([manhattan, [0.0]])
        if upper == "mdp":
            self.upper_values = self._mdp_values(self.upper_values)
        #: How many of the most common particles each give a plan (choosing among plans by the
        #: particle set is still a policy of the history).
        self.modes = int(modes)
        self._first_move = self._shortest_moves()
        cells = np.arange(model.num_states)
        #: States where the laser reads "same cell" (the chase tags there).
        self.same = self.same_cell(cells)
        moves = [model.transition_matrix(a) for a in range(TAG)]
        tag = model.transition_matrix(TAG)
        keep = sp.diags((~self.same).astype(float))
        on_same = sp.diags(self.same.astype(float))
        #: Per move, its transition with the tag taken instead wherever the laser reads "same cell".
        self._chase_T = [(keep @ T + on_same @ tag).tocsr() for T in moves]
        live = cells != model.terminal
        self._chase_reward = np.where(self.same, TAG_REWARD, np.where(live, -1.0, 0.0))
        #: ``[S]``: the value of the random walk that tags on "same cell", (I − γM)⁻¹ r, exact.
        self.walk_values = self._walk_values()
        #: ``[S]``: each state's own chase (its plan pushed through exactly, then the walk); only
        #: ``lower="chase"`` reads it, so only that builds it.
        self.chase_values = self._chase_table() if lower == "chase" else np.full(model.num_states, np.nan)
        self.description = (("upper: each particle's value in the fully observed MDP (value iteration); " if upper == "mdp"
                             else "upper: each particle's value with the opponent standing at its Manhattan distance; ")
                            + {"walk": "lower: the random walk that tags on the same-cell reading (its exact value)",
                               "target": "lower: the best of the random walk that tags on the same-cell reading and moves towards the 3 "
                               "opponent cells most common among the root's particles, then the walk (simulated)",
                               "chase": "lower: the best of the chases 'tag on the same-cell reading, else the shortest path to "
                               "one of the 3 most common particles' opponent, then random moves' (the plan simulated, "
                               "the random walk's exact value after it; exact for a set of one state)"}[lower])

    def upper(self, states):
        return float(self.upper_values[np.asarray(states)].mean(dtype=np.float64))

    def lower(self, states, rng):
        states = np.asarray(states, dtype=np.int64)
        return float(self.grouped(states, np.array([0, states.shape[0]]), rng)[0][0])

    def grouped(self, states: np.ndarray, starts: np.ndarray, rng) -> Tuple[np.ndarray, np.ndarray]:
        """``(lowers, uppers)`` of the sets ``states[starts[g]:starts[g + 1]]`` in one call (the search's
        fast path): the walk's values averaged per set; or (``lower="chase"``) a set of one state from
        the table, the others' plans simulated together, every particle under each of its set's plans
        in one vectorised pass."""
        states = np.asarray(states, dtype=np.int64)
        first = starts[:-1]
        sizes = np.diff(starts)
        uppers = np.add.reduceat(self.upper_values[states], first) / sizes
        if self.lower_kind != "chase":
            walk = np.add.reduceat(self.walk_values[states], first) / sizes
            if self.lower_kind == "target" and self.targets:
                return np.maximum(walk, self._toward_targets(states, starts, rng)), uppers
            return walk, uppers
        single = np.minimum.reduceat(states, first) == np.maximum.reduceat(states, first)
        lowers = self.chase_values[states[first]].astype(float)
        mixed = np.flatnonzero(~single)
        if mixed.size:
            lowers[mixed] = self._simulated(states, starts, mixed, rng)
        return lowers, uppers

    def begin_search(self, root_states: np.ndarray) -> None:
        """``lower="target"``: the opponent's :attr:`modes` most common cells among the root's
        particles (the belief planned for) become the cells every node's plans head for."""
        if self.lower_kind != "target":
            return
        m = self.model
        live = np.asarray(root_states)[np.asarray(root_states) != m.terminal]
        counts = np.bincount(live % m.n, minlength=m.n) if live.size else np.zeros(m.n, dtype=np.int64)
        self.targets = [int(c) for c in np.argsort(-counts, kind="stable")[: self.modes] if counts[c] > 0]

    def _toward_targets(self, states: np.ndarray, starts: np.ndarray, rng) -> np.ndarray:
        """Per set, the best over :attr:`targets` of "tag on the same-cell reading, else a shortest
        move towards the target cell; there, the walk", simulated on every particle of the set."""
        m = self.model
        n, g = m.n, m.discount
        T = len(self.targets)
        targets = np.tile(np.asarray(self.targets, dtype=np.int64), states.shape[0])   # particle-major, as current
        current = np.repeat(states, T)
        total = np.zeros(current.shape[0])
        active = current != m.terminal
        for t in range(2 * n):
            if not active.any():
                break
            robot = np.where(active, current // n, 0)
            move = self._first_move[targets, robot]
            arrived = active & (move < 0) & ~self.same[current]
            total[arrived] += g ** t * self.walk_values[current[arrived]]
            active &= ~arrived
            actions = np.where(self.same[current], TAG, np.where(active, move, -1))
            current, rewards = m.transition_each(current, actions, rng.random(current.shape[0]))
            total += np.where(active, g ** t * rewards, 0.0)
            active &= current != m.terminal
        total[active] += g ** (2 * n) * self.walk_values[current[active]]
        per_target = np.add.reduceat(total.reshape(-1, T), starts[:-1], axis=0) / np.diff(starts)[:, None]
        return per_target.max(axis=1)

    def _simulated(self, states: np.ndarray, starts: np.ndarray, sets: np.ndarray, rng) -> np.ndarray:
        """Per set of ``sets``, the best of its modes' chases, each simulated on all its particles."""
        m = self.model
        plans: List[List[int]] = []
        owner: List[int] = []          # per plan: its position in ``sets``
        rows: List[np.ndarray] = []    # per plan: the particles it runs on
        for k, g in enumerate(sets):
            members = states[starts[g]:starts[g + 1]]
            live = members[members != m.terminal]
            counts = np.bincount(live) if live.size else np.zeros(1, dtype=np.int64)
            for mode in np.argsort(-counts, kind="stable")[: self.modes]:
                if counts[mode] == 0:
                    break
                plans.append(self._plan(int(mode)))
                owner.append(k)
                rows.append(members)
        if not plans:
            return np.zeros(sets.size)
        length = max(len(p) for p in plans)
        table = np.full((len(plans), length + 1), -1, dtype=np.int64)
        for i, plan in enumerate(plans):
            table[i, :len(plan)] = plan
        plan_of = np.repeat(np.arange(len(plans)), [r.size for r in rows])
        ends = np.array([len(p) for p in plans])[plan_of]
        current = np.concatenate(rows)
        total = np.zeros(current.shape[0])
        for t in range(length):
            actions = np.where(self.same[current], TAG, table[plan_of, t])   # −1: this plan has ended
            uniform = rng.random((current.shape[0],))
            current, rewards = m.transition_each(current, actions, uniform)
            total += m.discount ** t * rewards
        total += m.discount ** ends * self.walk_values[current]
        means = np.bincount(plan_of, weights=total) / np.bincount(plan_of)
        best = np.full(sets.size, -np.inf)
        np.maximum.at(best, np.array(owner), means)
        return np.where(np.isfinite(best), best, 0.0)

    def _plan(self, state: int) -> List[int]:
        """The moves of ``state``'s chase: its robot's shortest path to its opponent."""
        n = self.model.n
        return self._path(state // n, state % n)

    def chase_value(self, state: int) -> float:
        """The exact expected return of ``state``'s own chase (what :meth:`lower` gives a set of it alone)."""
        return float(self.chase_values[state])

    def _mdp_values(self, start: np.ndarray, tolerance: float = 1e-6, max_sweeps: int = 2000) -> np.ndarray:
        """The fully observed MDP's values by value iteration from ``start`` (an upper bound, so every
        iterate stays one: the Bellman operator is monotone and the MDP's value is its fixed point)."""
        m = self.model
        T = [m.transition_matrix(a) for a in range(len(m.actions))]
        cells = np.arange(m.num_states)
        live = cells != m.terminal
        rewards = np.where(live, -1.0, 0.0)
        tag_reward = np.where(self.same_cell(cells), TAG_REWARD, np.where(live, -TAG_REWARD, 0.0))
        values = start.copy()
        for _ in range(max_sweeps):
            q = [rewards + m.discount * (T[a] @ values) for a in range(TAG)]
            q.append(tag_reward + m.discount * (T[TAG] @ values))
            new = np.max(q, axis=0)
            new[m.terminal] = 0.0
            if np.abs(new - values).max() < tolerance:
                return new
            values = new
        return values

    def same_cell(self, states: np.ndarray) -> np.ndarray:
        """Whether robot and opponent share a cell (the laser then reads "same cell")."""
        n = self.model.n
        states = np.asarray(states)
        return (states < n * n) & (states // n == states % n)

    def _walk_values(self) -> np.ndarray:
        """The random walk's value: tag on "same cell", else each move with ¼, solved exactly."""
        from scipy.sparse.linalg import spsolve

        m = self.model
        walk = (self._chase_T[0] + self._chase_T[1] + self._chase_T[2] + self._chase_T[3]) / 4.0
        system = (sp.identity(m.num_states, format="csc") - m.discount * walk.tocsc()).tocsc()
        values = np.asarray(spsolve(system, self._chase_reward), dtype=float)
        values[m.terminal] = 0.0
        return values

    def _chase_table(self) -> np.ndarray:
        """``[S]``: every state's own chase, its expected discounted return computed exactly: the
        distribution over states pushed through the plan's moves (one sparse product per move a step,
        the states that take it at once; the tag wherever the laser reads "same cell"), then the
        random walk's value where each plan ended."""
        m = self.model
        g = m.discount
        count = m.n * m.n
        plans = [self._plan(s) for s in range(count)]
        lengths = np.array([len(p) for p in plans])
        P = sp.identity(m.num_states, format="csr")[:count]
        values = np.zeros(m.num_states)
        for t in range(int(lengths.max()) + 1):
            ended = np.flatnonzero(lengths == t)
            if ended.size:
                values[ended] += g ** t * (P[ended] @ self.walk_values)
            acts = np.array([p[t] if t < len(p) else -1 for p in plans])
            if (acts < 0).all():
                break
            moved = sp.diags((acts < 0).astype(float)) @ P
            for a in range(TAG):
                chosen = acts == a
                if chosen.any():
                    rows = sp.diags(chosen.astype(float)) @ P
                    values[:count] += g ** t * (rows @ self._chase_reward)
                    moved = moved + rows @ self._chase_T[a]
            P = moved.tocsr()
        return values

    def _shortest_moves(self) -> np.ndarray:
        """``[goal, cell]``: the first move of a shortest path from ``cell`` to ``goal`` in action order
        (−1: none, or at the goal), breadth first from every goal (the moves are reversible)."""
        m = self.model
        n = m.n
        distance = np.full((n, n), -1, dtype=np.int64)
        first = np.full((n, n), -1, dtype=np.int64)
        for goal in range(n):
            distance[goal, goal] = 0
            queue = deque([goal])
            while queue:
                cell = queue.popleft()
                for action in range(4):
                    nxt = int(m.next_cell[cell, action])
                    if distance[goal, nxt] < 0:
                        distance[goal, nxt] = distance[goal, cell] + 1
                        queue.append(nxt)
            for cell in range(n):
                if distance[goal, cell] > 0:
                    for action in range(4):
                        if distance[goal, int(m.next_cell[cell, action])] == distance[goal, cell] - 1:
                            first[goal, cell] = action
                            break
        return first

    def _path(self, start: int, goal: int) -> List[int]:
        """The moves of a shortest path from cell ``start`` to ``goal`` ([] when none or already there)."""
        moves: List[int] = []
        cell = start
        while self._first_move[goal, cell] >= 0:
            action = int(self._first_move[goal, cell])
            moves.append(action)
            cell = int(self.model.next_cell[cell, action])
        return moves


def lasertag(discount: float = 0.95) -> LaserTag:
    """LaserTag on our fixed map (:data:`LAYOUT`)."""
    return LaserTag(LAYOUT, discount)


def random_lasertag(rng: np.random.Generator, discount: float = 0.95) -> LaserTag:
    """LaserTag on a map drawn as DESPOT's code draws one: 8 distinct cells of the 77, uniformly."""
    picks = rng.choice(ROWS * COLUMNS, size=OBSTACLES, replace=False)
    return LaserTag(tuple((int(p % COLUMNS), int(p // COLUMNS)) for p in picks), discount)
