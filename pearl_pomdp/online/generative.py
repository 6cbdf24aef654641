"""Generative models and the bounds an online search starts from.

A :class:`GenerativeModel` steps many particles at once and is *deterministic given its
uniforms*: ``step(states, a, u)`` with ``u`` ``[N, uniforms_per_step]`` in [0, 1) always returns
the same ``(next_states, observations, rewards)``. DESPOT needs exactly this (Ye et al., JAIR
2017, §3: a scenario is a start state plus a stream of random numbers), and it lets models
with millions of states (RockSample(15,15): 7,372,800) run without any ``|S|×|S|`` array.
States, observations and actions are integers; a model names its actions.

:class:`ExplicitModel` is the adapter for the project's :class:`~pearl_pomdp.model.pomdp.Pomdp`
(``T[a][s, s']`` dense or sparse, ``O[a, s', o]``, ``R[s, a]``): inverse-CDF sampling over each
row (in C, ``_step_kernel.c``), so a Pearl domain plans online with its exact belief at the root.

Bounds (:class:`Bounds`) value a *set of particles* (equal weights): ``upper(states)`` must not be
below the optimal value of the particle belief, ``lower(states, rng)`` must be the value of some
policy that sees only the history. Which ones are used is explicit:

* :class:`AlphaBounds` — the project's offline bounds for an explicit model: the fast informed
  bound (or QMDP) ``max_a mean_s Q(s, a)`` above, the best of a set of α-vectors (blind policies,
  or a point-based solver's lower bound) below. Each α-vector is the value of a conditional plan,
  so its mean over the particles is a policy's value.
* :class:`DefaultBounds` — for a generative model without its own bounds: ``R_max/(1-γ)`` above
  (the trivial MDP bound), and below the best fixed-action rollout ("always a" for ``horizon``
  steps, then ``R_min/(1-γ)`` for the rest): each is a history-independent policy.
"""
from __future__ import annotations

from typing import Dict, List, Optional, Protocol, Sequence, Tuple, runtime_checkable

import numpy as np

from pearl_pomdp.model.pomdp import Pomdp, issparse
from pearl_pomdp.online import _step_kernel

__all__ = ["GenerativeModel", "Bounds", "ExplicitModel", "AlphaBounds", "DefaultBounds", "sample_step",
           "alpha_bounds"]


@runtime_checkable
class GenerativeModel(Protocol):
    """A POMDP given by a simulator over integer states (vectorised over particles).

    Attributes:
        name: a label for reports.
        actions: the action names (an action is its index).
        discount: γ in (0, 1).
        uniforms_per_step: how many uniforms in [0, 1) one step of one particle consumes.
    """

    name: str
    actions: List[str]
    discount: float
    uniforms_per_step: int

    def step(self, states: np.ndarray, action: int,
             uniforms: np.ndarray) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(next_states [N] int64, observations [N] int64, rewards [N] float)`` for ``states [N]``
        under ``action``, deterministic given ``uniforms [N, uniforms_per_step]``."""
        ...

    def is_terminal(self, states: np.ndarray) -> np.ndarray:
        """``[N]`` bool: the state is absorbing with zero reward from now on."""
        ...


class Bounds(Protocol):
    """Value bounds of a particle set (equal weights; none of them terminal).

    Optional, for speed (the search uses the first one offered, in this order, and builds the same
    tree): ``grouped(states, starts, rng)`` — ``(lowers, uppers)`` of the sets
    ``states[starts[g]:starts[g + 1]]`` in one call; ``many(groups, rng)`` — the same for a list of
    arrays; ``both(states, rng)`` — ``(lower, upper)`` of one set in one pass.
    """

    #: One line saying which bounds these are (reports and ``--explain`` show it).
    description: str

    def upper(self, states: np.ndarray) -> float:
        """An upper bound of the optimal value of the belief the particles represent."""
        ...

    def lower(self, states: np.ndarray, rng: np.random.Generator) -> float:
        """The value (on these particles) of a policy that sees only the history."""
        ...


def sample_step(model: GenerativeModel, state: int, action: int,
                rng: np.random.Generator) -> Tuple[int, int, float]:
    """One step of one state with fresh uniforms: ``(next_state, observation, reward)``."""
    u = rng.random((1, model.uniforms_per_step))
    s2, o, r = model.step(np.array([state], dtype=np.int64), action, u)
    return int(s2[0]), int(o[0]), float(r[0])


class ExplicitModel:
    """A :class:`~pearl_pomdp.model.pomdp.Pomdp` as a :class:`GenerativeModel`.

    ``step`` draws ``s' ~ T[a][s, :]`` with the first uniform and ``o ~ O[a, s', :]`` with the
    second, by the inverse CDF of each row, and the reward is ``R[s, a]``. The definition (one for
    both draws): the row's entries in stored order (T's CSR order) are summed left to right in
    float64, ``c_k = p_1 + … + p_k`` and the mass ``M = c_n``; the draw is the first ``k`` with
    ``c_k > u·M``, and when rounding leaves none (only a subnormal ``M`` can: ``u·M < M = c_n``
    otherwise), the last entry with ``p_k > 0`` takes the residue. An entry of zero probability is
    never drawn; the same uniforms give the same outcome.

    The draws run in the C kernel ``_step_kernel.c`` (on the ward ~20x less step time than the numpy
    version it replaced, docs/ward.md), which reads the model's own arrays in place: sparse ``T``
    stays CSR with its int32 or int64 indices, ``O`` stays float64 or float32 (a large compiled
    model's, the ward's 210 MB), so the adapter adds no ``nnz``-sized or ``[A, S, Z]``-sized array
    to the model's: only the kernel's tables of T (each row's mass and its running sums every 32
    entries: 38 MB on the ward), with which a draw scans little more than the block of its row that
    holds the drawn entry. A dense ``T`` is turned into CSR rows once here.

    Raises (``step``): ValueError for an action or a state out of range, uniforms outside [0, 1),
    or a row without positive mass (the message names the action).
    """

    uniforms_per_step = 2

    def __init__(self, model: Pomdp):
        self.model = model
        self.name = model.name
        self.actions = list(model.actions)
        self.observations = list(model.observations)
        self.states = list(model.states)
        self.discount = float(model.discount)
        self.R = np.ascontiguousarray(model.R, dtype=float)
        O = model.O   # float64, or float32 for a large compiled model: not copied
        usable = O.dtype in (np.float32, np.float64) and O.flags.c_contiguous
        self._O = O if usable else np.ascontiguousarray(O, dtype=float)
        self._rows: List[Tuple[np.ndarray, np.ndarray, np.ndarray]] = []
        for Ta in model.T:
            if issparse(Ta):
                c = Ta if Ta.format == "csr" else Ta.tocsr()
                data = c.data if c.data.dtype in (np.float32, np.float64) else np.asarray(c.data, dtype=float)
                indptr, indices = c.indptr, c.indices
            else:
                dense = np.asarray(Ta, dtype=float)
                rows, indices = np.nonzero(dense)
                data = dense[rows, indices]
                indptr = np.concatenate(([0], np.cumsum(np.bincount(rows, minlength=dense.shape[0]))))
                indices = indices.astype(np.int32 if dense.shape[0] < 2 ** 31 else np.int64)
            self._rows.append((np.ascontiguousarray(indptr), np.ascontiguousarray(indices), np.ascontiguousarray(data)))
        # Per action, the kernel's tables of T (_step_kernel.row_tables): each row's mass, summed as the
        # draw sums it, and the running sums at every BLOCK-th entry, so that a draw skips the blocks
        # of its row before the drawn entry ([S] + 2·nnz/BLOCK float64: 38 MB on the ward).
        self._tables: List[Tuple[np.ndarray, np.ndarray, np.ndarray]] = []
        for indptr, _, data in self._rows:
            blocks = data.shape[0] // _step_kernel.BLOCK + 1
            mass, ends, peaks = np.empty(indptr.shape[0] - 1), np.empty(blocks), np.empty(blocks)
            _step_kernel.row_tables(indptr, data, mass, ends, peaks)
            self._tables.append((mass, ends, peaks))

    def step(self, states, action, uniforms):
        nxt, obs, rew = self.step_actions(states, [action], uniforms)
        return nxt[0], obs[0], rew[0]

    def step_many(self, states, uniforms):
        """``step`` under every action with the same uniforms: ``[A, N]`` next states, observations, rewards."""
        return self.step_actions(states, range(len(self._rows)), uniforms)

    def step_actions(self, states, actions, uniforms):
        """``step`` under each of ``actions`` (indices, repeats allowed) with the same uniforms:
        ``[len(actions), N]`` next states, observations, rewards. The kernel writes each row in
        place (no per-action arrays to stack afterwards) and a repeated action is stepped once."""
        s = np.ascontiguousarray(states, dtype=np.int64)
        u = np.ascontiguousarray(uniforms, dtype=float)
        actions = [int(a) for a in actions]
        n = s.shape[0]
        nxt = np.empty((len(actions), n), dtype=np.int64)
        obs = np.empty((len(actions), n), dtype=np.int64)
        rew = np.empty((len(actions), n))
        first: Dict[int, int] = {}
        for row, a in enumerate(actions):
            if a in first:
                done = first[a]
                nxt[row], obs[row], rew[row] = nxt[done], obs[done], rew[done]
                continue
            if not 0 <= a < len(self._rows):
                raise ValueError(f"{self.name}: action {a!r} is not an action index (0..{len(self._rows) - 1})")
            first[a] = row
            (indptr, indices, data), (mass, ends, peaks) = self._rows[a], self._tables[a]
            try:
                _step_kernel.step(indptr, indices, data, mass, ends, peaks, self._O, self.R, a, s, u, nxt[row],
                                  obs[row], rew[row])
            except ValueError as err:
                raise ValueError(f"{self.name}: step under action {self.actions[a]!r}: {err}") from None
        return nxt, obs, rew

    def is_terminal(self, states):
        return np.zeros(np.shape(states), dtype=bool)

    def observation_likelihood(self, next_states, action: int, observation: int) -> np.ndarray:
        """``O[a, s', o]`` for each of ``next_states`` (what a particle filter weights by)."""
        return self.model.O[action, np.asarray(next_states, dtype=np.int64), observation]


class AlphaBounds:
    """Bounds from α-vectors over the explicit states.

    Args:
        upper_q: ``[S, A]`` Q-values of an upper bound (FIB or QMDP):
            ``upper(states) = max_a mean_i Q(s_i, a)``, the bound's value at the particle belief.
        lower_alphas: ``[K, S]`` vectors each the value of a policy (blind policies, or the
            lower bound of :mod:`pearl_pomdp.solvers.point_based`): ``lower = max_k mean_i α_k(s_i)``.
        description: which bounds these are.
    """

    def __init__(self, upper_q: np.ndarray, lower_alphas: np.ndarray, description: str):
        self.upper_q = np.ascontiguousarray(upper_q, dtype=float)
        self.lower_alphas_t = np.ascontiguousarray(np.atleast_2d(np.asarray(lower_alphas, dtype=float)).T)  # [S, K]
        self.description = description

    def upper(self, states):
        return float(self.upper_q[states].mean(axis=0).max())

    def lower(self, states, rng):
        return float(self.lower_alphas_t[states].mean(axis=0).max())

    def grouped(self, states: np.ndarray, starts: np.ndarray, rng) -> Tuple[np.ndarray, np.ndarray]:
        """``(lowers, uppers)`` of the particle sets ``states[starts[g]:starts[g + 1]]`` (``starts`` int64
        from 0 to ``len(states)``, no set empty), in one pass of the C kernel
        (``_step_kernel.group_max_means``: each set's column means as numpy's ``add.reduceat`` sums
        them, then the largest). What DESPOT asks for at every expansion."""
        states = np.ascontiguousarray(states, dtype=np.int64)
        starts = np.ascontiguousarray(starts, dtype=np.int64)
        lowers, uppers = np.empty(starts.shape[0] - 1), np.empty(starts.shape[0] - 1)
        _step_kernel.group_max_means(states, starts, self.upper_q, uppers)
        _step_kernel.group_max_means(states, starts, self.lower_alphas_t, lowers)
        return lowers, uppers

    def many(self, groups: Sequence[np.ndarray], rng) -> Tuple[np.ndarray, np.ndarray]:
        """``(lowers, uppers)`` of several particle sets (each set's ``lower``/``upper``) by :meth:`grouped`."""
        sizes = np.fromiter((g.shape[0] for g in groups), dtype=np.int64, count=len(groups))
        return self.grouped(np.concatenate(groups), np.concatenate(([0], np.cumsum(sizes))), rng)


def alpha_bounds(model: Pomdp, upper: str = "fib", lower: str = "blind",
                 lower_alphas: Optional[np.ndarray] = None) -> AlphaBounds:
    """The project's offline bounds for ``model``: ``upper`` ``"fib"`` (Hauskrecht 2000) or ``"qmdp"``;
    ``lower`` ``"blind"`` (one vector per action, :func:`~pearl_pomdp.solvers.mdp.blind_lower_bound`)
    unless ``lower_alphas`` (e.g. a point-based policy's ``alphas``) is given.

    Raises:
        ValueError: an unknown bound name, or vectors of the wrong length.
    """
    from pearl_pomdp.solvers.mdp import blind_lower_bound, fib_q, mdp_value_iteration

    if upper == "fib":
        Q = fib_q(model)[0]
    elif upper == "qmdp":
        Q = mdp_value_iteration(model)[1]
    else:
        raise ValueError(f"upper bound {upper!r}: expected 'fib' or 'qmdp'")
    if lower_alphas is not None:
        alphas = np.atleast_2d(np.asarray(lower_alphas, dtype=float))
        if alphas.shape[1] != model.num_states:
            raise ValueError(f"lower_alphas have {alphas.shape[1]} entries, the model has {model.num_states} states")
        what = f"{alphas.shape[0]} given α-vectors"
    elif lower == "blind":
        alphas = blind_lower_bound(model)
        what = "blind policies"
    else:
        raise ValueError(f"lower bound {lower!r}: expected 'blind' or lower_alphas")
    return AlphaBounds(Q, alphas, f"upper: {upper.upper()} Q at the particles; lower: best of {what}")


class DefaultBounds:
    """The standard bounds for a generative model with nothing better (see the module doc).

    Args:
        model: the generative model.
        reward_range: ``(R_min, R_max)`` over all states and actions.
        horizon: steps of each fixed-action rollout before the ``R_min/(1-γ)`` tail.
    """

    def __init__(self, model: GenerativeModel, reward_range: Sequence[float], horizon: int = 30):
        self.model = model
        self.r_min, self.r_max = float(reward_range[0]), float(reward_range[1])
        self.horizon = int(horizon)
        g = model.discount
        self.description = (f"upper: R_max/(1-γ) = {self.r_max / (1 - g):.4g}; lower: best fixed-action "
                            f"rollout over {self.horizon} steps, then R_min/(1-γ)")

    def upper(self, states):
        return self.r_max / (1.0 - self.model.discount)

    def lower(self, states, rng):
        g, m = self.model.discount, self.model
        best = -np.inf
        for a in range(len(m.actions)):
            s = np.asarray(states, dtype=np.int64)
            total = np.zeros(s.shape[0])
            alive = ~m.is_terminal(s)
            for t in range(self.horizon):
                s, _, r = m.step(s, a, rng.random((s.shape[0], m.uniforms_per_step)))
                total += np.where(alive, (g ** t) * r, 0.0)
                alive &= ~m.is_terminal(s)
            total += np.where(alive, (g ** self.horizon) * self.r_min / (1.0 - g), 0.0)
            best = max(best, float(total.mean()))
        return best
