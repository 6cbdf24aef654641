"""RockSample (Smith & Simmons, *Heuristic Search Value Iteration for POMDPs*, UAI 2004) as a
generative model, with its exact factored belief and its bounds.

The terms are those of the project's generated ``test/data/pomdp/RockSample_*.pomdp`` files
(test/data/pomdp/README.md), so the generative model and the explicit file agree state by state:

* an ``n × n`` grid (x grows East, y North), ``k`` rocks at fixed cells; a state is the rover's
  cell and the good/bad bit of each rock, ``state = (y·n + x)·2^k + bits`` (rock ``i`` is bit ``i``),
  plus one absorbing exit state ``n²·2^k``: 247,808 states for (11,11), 7,372,800 for (15,15);
* actions ``N S E W Sample Check_1 … Check_k``; observations ``good bad`` (actions other than a
  check observe ``good``); γ = 0.95;
* moving East off the grid: +10 and exit; sampling a good rock: +10 and it turns bad; a bad
  rock: −10; an illegal move (off the N, S or W edge) or ``Sample`` off a rock: −100 and exit;
* ``Check_i`` reports rock ``i`` correctly with probability ``(1 + η)/2``, ``η = 2^(−d/d₀)``,
  ``d`` the Euclidean distance from the rover to the rock;
* start: the rover at the start cell, each rock good with probability ½ independently.

Layouts (:data:`LAYOUTS`): (7,8) and (11,11) are the standard ones (HSVI/ZMDP, SARSOP and the
DESPOT code's ``Init_7_8``/``Init_11_11`` agree); (4,4) is HSVI's with ``η = e^(−d)``. DESPOT
places the rocks of (15,15) at random (its ``InitGeneral``), so there is no standard layout:
:data:`LAYOUTS` holds one drawn with ``numpy.random.default_rng(15)`` (written out so
it never changes) with the rover starting at ``(0, n//2)`` as DESPOT's does.
"""
from __future__ import annotations

import math
from typing import Dict, List, Sequence, Tuple

import numpy as np

from pearl_pomdp.online import _step_kernel

__all__ = ["RockSample", "RockBelief", "RockSampleBounds", "LAYOUTS", "rocksample", "random_rocksample"]

#: name → (n, start (x, y), rocks [(x, y), …], d₀).
LAYOUTS: Dict[str, Tuple[int, Tuple[int, int], List[Tuple[int, int]], float]] = {
    "4_4": (4, (0, 2), [(3, 1), (2, 1), (1, 3), (1, 0)], math.log(2.0)),
    "7_8": (7, (0, 3), [(2, 0), (0, 1), (3, 1), (6, 3), (2, 4), (3, 4), (5, 5), (1, 6)], 20.0),
    "11_11": (11, (0, 5), [(0, 3), (0, 7), (1, 8), (2, 4), (3, 3), (3, 8), (4, 3), (5, 8), (6, 1), (9, 3), (9, 9)],
              20.0),
    # Drawn once: cells = numpy.random.default_rng(15).choice(225, size=15, replace=False), cell c at
    # (c % 15, c // 15); written out so the instance never changes with numpy.
    "15_15": (15, (0, 7), [(13, 2), (11, 9), (2, 2), (6, 3), (11, 10), (7, 6), (8, 14), (1, 13), (9, 0), (0, 10),
                           (3, 14), (9, 11), (14, 6), (5, 8), (14, 4)], 20.0),
}

N, S, E, W, SAMPLE = 0, 1, 2, 3, 4
GOOD, BAD = 0, 1


class RockSample:
    """RockSample(n, k) as a :class:`~pearl_pomdp.online.generative.GenerativeModel` (module doc)."""

    uniforms_per_step = 1

    def __init__(self, n: int, start: Tuple[int, int], rocks: Sequence[Tuple[int, int]],
                 half_efficiency_distance: float = 20.0, discount: float = 0.95, name: str = ""):
        self.n = int(n)
        self.k = len(rocks)
        self.start = (int(start[0]), int(start[1]))
        self.rocks = [(int(x), int(y)) for x, y in rocks]
        if len(set(self.rocks)) != self.k:
            raise ValueError("rocks: two rocks share a cell")
        self.d0 = float(half_efficiency_distance)
        self.discount = float(discount)
        self.name = name or f"RockSample({self.n},{self.k})"
        self.actions = ["N", "S", "E", "W", "Sample"] + [f"Check_{i + 1}" for i in range(self.k)]
        self.observations = ["good", "bad"]
        self.num_states = self.n * self.n * (1 << self.k) + 1
        self.exit_state = self.num_states - 1
        cells = self.n * self.n
        self.rock_at = np.full(cells, -1, dtype=np.int64)
        for i, (x, y) in enumerate(self.rocks):
            self.rock_at[y * self.n + x] = i
        xs, ys = np.arange(cells) % self.n, np.arange(cells) // self.n
        rx = np.array([x for x, _ in self.rocks], dtype=float)
        ry = np.array([y for _, y in self.rocks], dtype=float)
        dist = np.hypot(xs[:, None] - rx[None, :], ys[:, None] - ry[None, :])      # [cells, k]
        #: P(check reports the truth) per cell and rock.
        self.accuracy = 0.5 * (1.0 + np.power(2.0, -dist / self.d0))
        #: Manhattan distance per cell and rock (the bounds').
        self.manhattan = (np.abs(xs[:, None] - rx[None, :]) + np.abs(ys[:, None] - ry[None, :])).astype(np.int64)

    # --------------------------------------------------------------- encoding
    def encode(self, x: int, y: int, bits: int) -> int:
        return (y * self.n + x) * (1 << self.k) + bits

    def decode(self, state: int) -> Tuple[int, int, int]:
        """``(x, y, bits)``; raises ValueError for the exit state."""
        if state == self.exit_state:
            raise ValueError("the exit state has no cell")
        cell, bits = divmod(int(state), 1 << self.k)
        return cell % self.n, cell // self.n, bits

    def is_terminal(self, states):
        return np.asarray(states) == self.exit_state

    # ------------------------------------------------------------------- step
    def step(self, states, action, uniforms):
        s = np.asarray(states, dtype=np.int64)
        k, n = self.k, self.n
        done = s == self.exit_state
        cell = np.where(done, 0, s >> k)
        bits = s & ((1 << k) - 1)
        x, y = cell % n, cell // n
        reward = np.zeros(s.shape[0])
        obs = np.full(s.shape[0], GOOD, dtype=np.int64)
        nxt = s.copy()
        exit_now = np.zeros(s.shape[0], dtype=bool)
        if action in (N, S, E, W):
            dx, dy = {N: (0, 1), S: (0, -1), E: (1, 0), W: (-1, 0)}[action]
            x2, y2 = x + dx, y + dy
            east_exit = x2 >= n
            illegal = (x2 < 0) | (y2 < 0) | (y2 >= n)
            reward = np.where(east_exit, 10.0, np.where(illegal, -100.0, 0.0))
            exit_now = east_exit | illegal
            nxt = np.where(exit_now, self.exit_state, ((y2 * n + x2) << k) + bits)
        elif action == SAMPLE:
            rock = self.rock_at[cell]
            on_rock = rock >= 0
            r_idx = np.maximum(rock, 0)
            good = ((bits >> r_idx) & 1).astype(bool) & on_rock
            reward = np.where(on_rock, np.where(good, 10.0, -10.0), -100.0)
            exit_now = ~on_rock
            cleared = bits & ~(np.int64(1) << r_idx)
            nxt = np.where(exit_now, self.exit_state, (cell << k) + np.where(on_rock, cleared, bits))
        else:
            i = action - 5
            if not 0 <= i < k:
                raise ValueError(f"action {action} is not an action of {self.name}")
            truth_good = ((bits >> i) & 1).astype(bool)
            correct = uniforms[:, 0] < self.accuracy[cell, i]
            obs = np.where(truth_good == correct, GOOD, BAD).astype(np.int64)
        nxt = np.where(done, self.exit_state, nxt)
        reward = np.where(done, 0.0, reward)
        obs = np.where(done, GOOD, obs)
        return nxt.astype(np.int64), obs, reward

    def step_many(self, states, uniforms):
        """Every action at once: ``(next states, observations, rewards)``, each ``[A, N]``, row ``a``
        equal to :meth:`step` ``(states, a, uniforms)`` (one numpy pass instead of one per action:
        the search expands a node under all of them)."""
        s = np.asarray(states, dtype=np.int64)
        k, n = self.k, self.n
        count = s.shape[0]
        done = s == self.exit_state
        cell = np.where(done, 0, s >> k)
        bits = s & ((1 << k) - 1)
        x, y = cell % n, cell // n
        A = len(self.actions)
        nxt = np.empty((A, count), dtype=np.int64)
        obs = np.full((A, count), GOOD, dtype=np.int64)
        reward = np.zeros((A, count))
        dx = np.array([0, 0, 1, -1])[:, None]           # N S E W
        dy = np.array([1, -1, 0, 0])[:, None]
        x2, y2 = x[None, :] + dx, y[None, :] + dy
        east_exit = x2 >= n
        illegal = (x2 < 0) | (y2 < 0) | (y2 >= n)
        reward[:4] = np.where(east_exit, 10.0, np.where(illegal, -100.0, 0.0))
        nxt[:4] = np.where(east_exit | illegal, self.exit_state, ((y2 * n + x2) << k) + bits[None, :])
        rock = self.rock_at[cell]
        on_rock = rock >= 0
        r_idx = np.maximum(rock, 0)
        good = ((bits >> r_idx) & 1).astype(bool) & on_rock
        reward[SAMPLE] = np.where(on_rock, np.where(good, 10.0, -10.0), -100.0)
        cleared = bits & ~(np.int64(1) << r_idx)
        nxt[SAMPLE] = np.where(~on_rock, self.exit_state, (cell << k) + np.where(on_rock, cleared, bits))
        truth_good = ((bits[None, :] >> np.arange(k)[:, None]) & 1).astype(bool)          # [k, N]
        correct = uniforms[:, 0][None, :] < self.accuracy[cell].T                          # [k, N]
        obs[5:] = np.where(truth_good == correct, GOOD, BAD)
        nxt[5:] = s[None, :]
        nxt[:, done] = self.exit_state
        reward[:, done] = 0.0
        obs[:, done] = GOOD
        return nxt, obs, reward

    def initial_belief(self) -> "RockBelief":
        return RockBelief(self)


class RockBelief:
    """RockSample's exact belief: the rover's cell (known), whether it has exited, and
    ``P(rock i good)`` per rock. Exact because the rocks are independent at the start and every
    observation informs one rock only; it cannot run out of particles.
    """

    def __init__(self, model: RockSample):
        self.model = model
        self.x, self.y = model.start
        self.exited = False
        self.p_good = np.full(model.k, 0.5)

    def sample(self, count: int, rng: np.random.Generator) -> np.ndarray:
        """``count`` states drawn from the belief."""
        m = self.model
        if self.exited:
            return np.full(count, m.exit_state, dtype=np.int64)
        good = rng.random((count, m.k)) < self.p_good[None, :]
        bits = (good.astype(np.int64) << np.arange(m.k, dtype=np.int64)[None, :]).sum(axis=1)
        return m.encode(self.x, self.y, 0) + bits

    def update(self, action: int, observation: int) -> None:
        """Bayes' rule after ``action`` and ``observation`` (moves are deterministic)."""
        m = self.model
        if self.exited:
            return
        if action in (N, S, E, W):
            dx, dy = {N: (0, 1), S: (0, -1), E: (1, 0), W: (-1, 0)}[action]
            x2, y2 = self.x + dx, self.y + dy
            if not (0 <= x2 < m.n and 0 <= y2 < m.n):
                self.exited = True
                return
            self.x, self.y = x2, y2
        elif action == SAMPLE:
            rock = int(m.rock_at[self.y * m.n + self.x])
            if rock < 0:
                self.exited = True
                return
            self.p_good[rock] = 0.0
        else:
            i = action - 5
            acc = float(m.accuracy[self.y * m.n + self.x, i])
            like_good = acc if observation == GOOD else 1.0 - acc
            like_bad = 1.0 - acc if observation == GOOD else acc
            p = self.p_good[i]
            self.p_good[i] = p * like_good / (p * like_good + (1.0 - p) * like_bad)


class RockSampleBounds:
    """RockSample's bounds on a particle set (all at the rover's one cell).

    * upper (``"mdp"``, the default): the value of the fully observed MDP (:func:`mdp_upper_values`)
      at each particle, averaged — DESPOT's default for RockSample too. ``"distance"``: every good
      rock collected at its own Manhattan distance and the exit at its own distance,
      ``Σ_{good i} 10 γ^{d_i} + 10 γ^{n−1−x}`` — no policy reaches a rock sooner; averaged.
    * lower (``"check"``, the default): the best of a few fixed policies, each valued exactly on
      every particle and averaged (the best is itself a policy: it chooses by the set, that is by
      the history):

      - driving East at once;
      - the open-loop tour: visit, nearest first, the rocks that more than half the particles call
        good, sample each, then drive East;
      - two *checking tours*: visit, nearest first, the rocks that any particle (resp. at least half
        of them) calls good; on arrival ``Check`` the rock — at distance 0 the sensor is exact
        (``η = 2⁰ = 1``) — and sample it only if it is good; a rock every particle calls good is
        sampled without a check; then drive East. A particle's sample times depend on how many good
        rocks it sampled before, so these are valued particle by particle, not from the shares.

      At RockSample(11,11)'s start (2,000 particles) the open-loop tour is worth 6.0 and the checking
      tour 19.6 (the planners' returns there are ~22): leaves valued by a policy that looks before it
      samples. ``"tour"``: East or the open-loop tour only (the bound before the checking tours).
    """

    def __init__(self, model: RockSample, upper: str = "mdp", lower: str = "check"):
        self.model = model
        if upper not in ("mdp", "distance"):
            raise ValueError(f"upper bound {upper!r}: expected 'mdp' or 'distance'")
        if lower not in ("check", "tour"):
            raise ValueError(f"lower bound {lower!r}: expected 'check' or 'tour'")
        #: The MDP value per state (``upper="mdp"``), else ``None``.
        self.mdp_values = mdp_upper_values(model).reshape(-1) if upper == "mdp" else None
        self.checking = lower == "check"
        self._rocks = np.array(model.rocks, dtype=np.int64).reshape(model.k, 2)
        #: γ^(Manhattan distance) per cell and rock.
        self._upper_discounts = model.discount ** model.manhattan
        self._shifts = np.arange(model.k, dtype=np.int64)[None, :]
        # γ^t for every step a tour can reach (travel < 2n per rock and to the exit, a check and a
        # sample per rock); the tours are valued in C (_step_kernel.rock_tours).
        self._powers = model.discount ** np.arange(2 * model.n * (model.k + 1) + 2 * model.k + 2, dtype=np.float64)
        self.description = ("upper: " + ("the fully observed MDP's value (value iteration)" if upper == "mdp" else
                                         "good rocks and the exit each at its own Manhattan distance")
                            + "; lower: " + ("the best of East, the open-loop tour and two tours that check each "
                                             "rock on arrival" if self.checking else
                                             "open-loop nearest-first tour of the rocks most particles call good, "
                                             "then East"))

    def _share(self, states) -> Tuple[int, np.ndarray]:
        """The rover's cell and, per rock, the share of particles that call it good."""
        m = self.model
        bits = states & ((1 << m.k) - 1)
        counts = np.bitwise_and(bits[:, None] >> self._shifts, 1).sum(axis=0)
        return int(states[0] >> m.k), counts / bits.shape[0]

    # Both bounds are linear in the particles' rock bits, so their mean needs only the shares.
    def upper(self, states):
        m = self.model
        if self.mdp_values is not None:
            return float(self.mdp_values[states].mean(dtype=np.float64))
        cell, share = self._share(states)
        return float(10.0 * share @ self._upper_discounts[cell] + 10.0 * m.discount ** (m.n - 1 - cell % m.n))

    def lower(self, states, rng):
        return self.both(states, rng)[0]

    def both(self, states, rng) -> Tuple[float, float]:
        """``(lower, upper)`` from one pass over the particles."""
        lowers, uppers = self.many([np.asarray(states, dtype=np.int64)], rng)
        return float(lowers[0]), float(uppers[0])

    def many(self, groups: Sequence[np.ndarray], rng) -> Tuple[np.ndarray, np.ndarray]:
        """``(lowers, uppers)`` of several particle sets (each at its own single cell) in one pass:
        the same numbers :meth:`both` gives set by set (what the search asks of a new node's
        children), without a numpy call per set."""
        m = self.model
        sizes = np.fromiter((g.shape[0] for g in groups), dtype=np.int64, count=len(groups))
        starts = np.concatenate(([0], np.cumsum(sizes)[:-1]))
        states = np.concatenate(groups)
        bits = states & ((1 << m.k) - 1)
        per_rock = np.bitwise_and(bits[:, None] >> self._shifts, 1)
        shares = np.add.reduceat(per_rock, starts, axis=0) / sizes[:, None]          # [G, k]
        cells = states[starts] >> m.k
        if self.mdp_values is not None:
            uppers = np.add.reduceat(self.mdp_values[states].astype(np.float64), starts) / sizes
        else:
            uppers = (10.0 * np.einsum("gk,gk->g", shares, self._upper_discounts[cells])
                      + 10.0 * m.discount ** (m.n - 1 - cells % m.n))
        weight = np.int64(1) << np.arange(m.k, dtype=np.int64)
        most = ((shares > 0.5) * weight).sum(axis=1)
        none = np.zeros_like(most)
        # Candidate tours per set, as (rocks visited, rocks sampled without a check): East at once,
        # the open-loop tour, and the checking tours over the rocks some / half the particles call good.
        visit, blind = [none, most], [none, most]
        if self.checking:
            certain = ((shares >= 1.0) * weight).sum(axis=1)
            visit += [((shares > 0.0) * weight).sum(axis=1), ((shares >= 0.5) * weight).sum(axis=1)]
            blind += [certain, certain]
        lowers = np.empty(len(groups))
        _step_kernel.rock_tours(states, np.append(starts, states.shape[0]), m.k, m.n, self._rocks,
                                np.ascontiguousarray(np.stack(visit, axis=1)),
                                np.ascontiguousarray(np.stack(blind, axis=1)), self._powers, lowers)
        return lowers, uppers


def mdp_upper_values(model: RockSample, max_sweeps: int = 1000, tolerance: float = 1e-4,
                     dtype=np.float32) -> np.ndarray:
    """The fully observed MDP's value ``[n², 2^k]`` (rocks known): an upper bound of the POMDP value.

    Value iteration from the distance bound of :class:`RockSampleBounds` (each good rock and the
    exit at its own Manhattan distance), which satisfies ``H U ≤ U`` (a move shortens each distance
    by at most one; sampling a good rock earns the 10 the bound counted for it), so the iterates
    decrease monotonically and *every* iterate is an upper bound: a sweep cap never makes it
    unsafe. Rounded up by ``tolerance`` at the end (float32 storage for the 7.4M states of (15,15)).
    """
    m = model
    n, k, g = m.n, m.k, m.discount
    cells, B = n * n, 1 << k
    bits = np.arange(B, dtype=np.int64)
    good = ((bits[:, None] >> np.arange(k)[None, :]) & 1).astype(dtype)          # [B, k]
    xs = np.arange(cells) % n
    V = (10.0 * (g ** m.manhattan).astype(dtype) @ good.T + (10.0 * g ** (n - 1 - xs)).astype(dtype)[:, None])
    V = V.astype(dtype)
    ys = np.arange(cells) // n
    north = np.where(ys < n - 1, np.arange(cells) + n, -1)
    south = np.where(ys > 0, np.arange(cells) - n, -1)
    west = np.where(xs > 0, np.arange(cells) - 1, -1)
    east = np.where(xs < n - 1, np.arange(cells) + 1, -1)
    rock_cells = [(int(y * n + x), i) for i, (x, y) in enumerate(m.rocks)]
    gd = dtype(g)
    for _ in range(max_sweeps):
        Vn = np.full_like(V, -100.0)
        for nb in (north, south, west):
            ok = nb >= 0
            Vn[ok] = np.maximum(Vn[ok], gd * V[nb[ok]])
        ok = east >= 0
        Vn[ok] = np.maximum(Vn[ok], gd * V[east[ok]])
        Vn[~ok] = np.maximum(Vn[~ok], dtype(10.0))
        for cell, i in rock_cells:
            has = (bits >> i) & 1
            sampled = np.where(has == 1, 10.0 + gd * V[cell, bits & ~(1 << i)], -10.0 + gd * V[cell])
            Vn[cell] = np.maximum(Vn[cell], sampled.astype(dtype))
        Vn = np.minimum(Vn, V)
        delta = float(np.max(V - Vn))
        V = Vn
        if delta <= tolerance:
            break
    return V + dtype(tolerance / (1.0 - g))


def rocksample(name: str) -> RockSample:
    """RockSample by layout name (``"7_8"``, ``"11_11"``, ``"15_15"``, ``"4_4"``)."""
    try:
        n, start, rocks, d0 = LAYOUTS[name]
    except KeyError:
        raise ValueError(f"RockSample layout {name!r}: choose one of {', '.join(LAYOUTS)}") from None
    return RockSample(n, start, rocks, d0, name=f"RockSample({name.replace('_', ',')})")


def random_rocksample(n: int, k: int, rng: np.random.Generator, half_efficiency_distance: float = 20.0) -> RockSample:
    """RockSample(n, k) with its rocks at ``k`` distinct cells drawn uniformly (x then y per rock,
    redrawn when the cell is taken) and the rover at ``(0, n//2)``: how DESPOT's code lays out a
    size it has no standard layout for (``InitGeneral``), so an average over these instances is
    comparable with its figures for such sizes."""
    rocks: List[Tuple[int, int]] = []
    while len(rocks) < k:
        cell = (int(rng.integers(n)), int(rng.integers(n)))
        if cell not in rocks:
            rocks.append(cell)
    return RockSample(n, (0, n // 2), rocks, half_efficiency_distance, name=f"RockSample({n},{k}), random layout")
