"""Exact POMDP value iteration by incremental pruning.

A. R. Cassandra, M. L. Littman and N. L. Zhang, "Incremental Pruning: A Simple,
Fast, Exact Method for Partially Observable Markov Decision Processes", UAI 1997
(§3, the "normal" variant that pomdp-solve runs with ``-method incprune``).

Value iteration ``V'(b) = max_a [ b·R[:,a] + γ Σ_o P(o|b,a) V(b^{a,o}) ]``
(docs/design.md §2) keeps ``V`` as a set Γ of α-vectors. One epoch, in the paper's
order:

1. **Project** every vector of Γ through each action a and observation o::

       Γ^{a,o} = { R[:,a]/|Z| + γ Σ_{s'} T[a,:,s'] O[a,s',o] α(s')  :  α ∈ Γ }

   (the immediate reward is split evenly over the |Z| sets so that one
   vector from each sums to a full backup), and **prune** each Γ^{a,o}.
2. **Cross-sum** the sets of one action pairwise, pruning after each sum::

       Γ^a = prune( … prune( prune(Γ^{a,o1} ⊕ Γ^{a,o2}) ⊕ Γ^{a,o3} ) … ⊕ Γ^{a,o|Z|} )

   where ``A ⊕ B = {α + β : α ∈ A, β ∈ B}``. Pruning after every sum is the
   whole idea: the sets stay small, instead of ``|Γ|^{|Z|}`` vectors per action.
3. **Union** over actions and prune once more: ``Γ' = prune( ∪_a Γ^a )``,
   each vector labelled with its action.
4. **Stop** after ``horizon`` epochs, or (infinite horizon) when the value
   function repeats one it had ``k ≥ 1`` epochs before, to within
   ``θ = ε (1−γ) / (2γ)`` on the vector sets (``ε`` = ``epsilon``, pomdp-solve's
   ``-stop_delta``, default 1e-9). For ``k = 1`` this is pomdp-solve's default
   test, its *weak bound* (one way): ``max_{α'∈Γ_t} min_{α∈Γ_{t−1}} max_s
   |α'(s) − α(s)| ≤ θ``. For ``k ≥ 2`` the sets must be within ``θ`` of each
   other both ways: the pruned iteration has come back to where it was ``k``
   epochs before. The returned value function is Γ_t; ``extra["last_residual"]``
   is the Bellman residual ``max_b |V_t(b) − V_{t−1}(b)|`` over the simplex
   (:func:`bellman_residual`, by LPs).

   Why ``k ≥ 2``: a vector that wins by about ``prune_tol`` is kept or dropped
   depending on its neighbours, so an epoch's result is not a continuous
   function of the previous one, and the iteration can settle into a cycle of
   value functions that differ only in such vectors. On shuttle.95 it does from
   about epoch 150 on (and by epoch ~430 every other vector has settled): two
   sets of 200 vectors alternate, differing in one vector (2.3e-2 apart component-wise, winning by 5.6e-7 in one set and
   1.8e-7 in the other), so the weak bound to the previous epoch stays at
   9.3e-3 / 2.3e-2 for ever (22,693 epochs in 300 s before issue 26) while
   ``V`` moves by 4.2e-7. Random 3-state models do it too (5 of 150 tried;
   periods 2 to 48). Exact value iteration cannot cycle (a γ-contraction has
   one fixed point), and a repeat is as good a place to stop as a fixed point:
   if each epoch's prune lowers ``V`` by at most ``τ``, ``‖V_t − V_{t−k}‖ ≤ θ``
   gives ``‖V_t − V*‖ ≤ τ/(1−γ) + γ^k θ/(1−γ^k)``, which for ``k = 1`` is the
   bound behind pomdp-solve's test (``τ/(1−γ) + ε/2``) and only smaller for
   larger ``k``. (Two pruned sets within ``θ < prune_tol`` of each other have
   as many vectors, since a prune keeps no two vectors that close; with the
   sums of the vectors this fingerprint picks the earlier epochs worth
   comparing, so the test costs next to nothing; see :class:`_CycleWatch`.)

What an epoch costs depends on the LP pruning in :mod:`.prune` (pointwise
dominance first, then one LP per remaining vector, all in a C kernel), so the work goes
into needing fewer LPs, never into changing the result:

* witness beliefs seed the prunes: a belief where α wins in A and β wins in
  B is one where α+β wins in A ⊕ B, so the operands' witnesses find useful
  sums without an LP; and each prune also gets the witnesses of the *same*
  prune (same a, o) in the previous epoch, since successive value functions
  differ little (near convergence almost every useful vector is found so);
* a cross-sum with a one-vector operand (e.g. an observation that action a
  can never produce, whose projection is the reward share alone) is a
  translation of the other set: it is already parsimonious, no prune needed.

Pruning tolerance: a vector is kept only if it wins by at least ``prune_tol``
somewhere (default 5.01e-7, pomdp-solve's effective threshold; see
:mod:`.prune`). That threshold decides only the **final** prune of step 3;
the intermediate prunes (the projections and every cross-sum of step 2) use
``STAGE_TOL`` = 1e-9 (or ``prune_tol`` if smaller). A prune with tolerance
``τ`` may lower ``V`` by up to ``τ`` somewhere, and losses of successive
stages add up: with ``prune_tol`` at every stage one epoch can lose
``(2|Z| + 1)·prune_tol``. On mcc-example1 (4 states, 3 actions, 3
observations) that dropped the best vector at a corner of the simplex by
6.8e-7 > 5.01e-7 (epoch 9 from pomdp-solve's epoch 8). With near-exact
intermediate prunes one epoch's Γ' is within ``prune_tol`` (+ a few
``STAGE_TOL``) of the exact backup of Γ at every belief. With it the per-epoch vector counts match pomdp-solve 5.5 on
tiger.95 (epochs 1–20, and the converged 9 vectors after 477 epochs), tiger.aaai,
1d, parr95, cheese and network. Where pomdp-solve's lp_solve reports unstable
LPs (shuttle.95, 4x3.95) it loses useful vectors — on shuttle.95 epoch 7 it
drops one that wins by 1.3e-3 — so counts there differ while values agree.
"""
from __future__ import annotations

import time
from collections import deque
from typing import Deque, List, Optional, Tuple, Union

import numpy as np

from ..solution import AlphaVectorPolicy, SolveResult
from .prune import DEFAULT_TOL, PruneStats, PruneTimeout, WitnessLP, prune

__all__ = ["solve_incremental_pruning", "dp_backup", "weak_bound", "bellman_residual", "STAGE_TOL",
           "MAX_CANDIDATE_BYTES", "VectorCapExceeded"]

#: Tolerance of the intermediate prunes (projections, cross-sums): near-exact, so the
#: losses of successive stages cannot add up past ``prune_tol`` (see the module docstring).
STAGE_TOL = 1e-9

#: Default cap on the largest set one epoch builds: a cross-sum (or the union over actions)
#: before its prune may hold at most this many bytes of vectors, ``max_vectors = this // (8 S)``
#: (the prune needs about twice as much again for its witnesses). Past it the solve stops
#: with ``stop_reason = "vector_cap"`` instead of exhausting the machine's memory.
MAX_CANDIDATE_BYTES = 512 * 2**20

#: LPs (per direction) the last residual may still take once a solve has hit its time limit;
#: the rest is bounded by vector distances (``last_residual_exact = False``).
RESIDUAL_LPS_PAST_DEADLINE = 16

#: Earlier value functions kept for the infinite-horizon stop's repeat test (step 4 of the module
#: docstring), newest first: repeats of value functions older than this much memory go unseen.
HISTORY_BYTES = 64 * 2**20


class VectorCapExceeded(Exception):
    """Raised inside an epoch when a set it would build has more than ``max_vectors`` vectors."""

    def __init__(self, vectors: int, cap: int, where: str) -> None:
        super().__init__(f"{where} would hold {vectors} vectors, more than max_vectors={cap}")
        self.vectors, self.cap, self.where = vectors, cap, where


def _past(deadline: Optional[float]) -> bool:
    return deadline is not None and time.perf_counter() > deadline


def _nearest_distances(new: np.ndarray, old: np.ndarray, chunk_elems: int = 8_000_000,
                       deadline: Optional[float] = None, limit: Optional[float] = None) -> np.ndarray:
    """``min_{α∈old} max_s |α'(s) − α(s)|`` for every row α' of ``new`` (max-norm distance to the
    nearest vector of ``old``). Chunked (memory stays bounded); raises :class:`PruneTimeout`
    past ``deadline``; with ``limit``, stops at the first chunk whose worst row is above it
    (the rows not reached are then ``inf``)."""
    out = np.full(new.shape[0], np.inf)
    S = new.shape[1]
    step = max(1, chunk_elems // max(1, old.shape[0] * S))
    for i in range(0, new.shape[0], step):
        if _past(deadline):
            raise PruneTimeout()
        out[i:i + step] = np.abs(new[i:i + step, None, :] - old[None, :, :]).max(axis=2).min(axis=1)
        if limit is not None and out[i:i + step].max() > limit:
            break
    return out


def weak_bound(new: np.ndarray, old: np.ndarray, chunk_elems: int = 8_000_000,
               deadline: Optional[float] = None) -> float:
    """pomdp-solve's weak bound: ``max_{α'∈new} min_{α∈old} max_s |α'(s) − α(s)|``.

    It compares vectors component by component, i.e. at the corners of the
    belief simplex, which bounds the difference anywhere inside. Raises
    :class:`PruneTimeout` past ``deadline`` (a ``time.perf_counter()`` value).
    """
    if new.shape[0] == 0:
        return 0.0
    return float(_nearest_distances(new, old, chunk_elems, deadline).max())


def _same_within(a: np.ndarray, b: np.ndarray, tol: float) -> bool:
    """Every vector of ``a`` within ``tol`` (max-norm) of one of ``b``, and every one of ``b`` of
    one of ``a``: the two sets are the same value function up to ``tol`` everywhere. Cheap when
    they are not: the corners of the simplex (each state's best value) are compared first."""
    if np.abs(a.max(axis=0) - b.max(axis=0)).max() > tol:
        return False
    return bool(_nearest_distances(a, b, limit=tol).max() <= tol
                and _nearest_distances(b, a, limit=tol).max() <= tol)


class _CycleWatch:
    """Finds the first epoch t whose Γ_t repeats an earlier Γ_{t−k} (k ≥ 2) to within ``tol``
    both ways (:func:`_same_within`), comparing few pairs of sets.

    Earlier sets are kept, newest first, up to :data:`HISTORY_BYTES` (older ones are dropped),
    each with a fingerprint: its number of vectors and the sum of its vectors. Two pruned sets
    within ``tol`` of each other both ways have the same number of vectors (a prune keeps no
    two vectors within ``tol`` of each other, so the match pairs them off) and sums within
    ``count·tol``: only the sets whose fingerprint matches are compared.
    """

    def __init__(self, tol: float) -> None:
        self.tol = tol
        self.sets: Deque[Tuple[int, np.ndarray]] = deque()
        self.counts: Deque[int] = deque()
        self.sums: Deque[np.ndarray] = deque()
        self.bytes = 0

    def period(self, t: int, alphas: np.ndarray) -> Optional[int]:
        """Record Γ_t (epochs numbered 0, 1, … in order); the period k if it repeats Γ_{t−k}."""
        count, total = alphas.shape[0], alphas.sum(axis=0)
        found = None
        if self.sets:
            # A match has |Σα − Σβ| ≤ count·tol; the sums' own rounding is below 1e-15·count·Σ|α|.
            scale = float(np.abs(alphas).max()) if alphas.size else 0.0
            slack = count * (self.tol + 1e-15 * count * scale)
            match = np.nonzero((np.asarray(self.counts) == count)
                               & (np.abs(np.asarray(self.sums) - total) <= slack).all(axis=1))[0]
            for i in match[::-1]:  # the shortest period first
                e, earlier = self.sets[int(i)]
                if t - e >= 2 and _same_within(alphas, earlier, self.tol):
                    found = t - e
                    break
        self.sets.append((t, alphas))
        self.counts.append(count)
        self.sums.append(total)
        self.bytes += alphas.nbytes
        while self.bytes > HISTORY_BYTES and len(self.sets) > 1:
            self.bytes -= self.sets.popleft()[1].nbytes
            self.counts.popleft()
            self.sums.popleft()
        return found


def _residual_one_way(new: np.ndarray, old: np.ndarray, max_lps: Optional[int],
                      dist: Optional[np.ndarray] = None) -> Tuple[float, bool]:
    """``max(0, max_b V_new(b) − V_old(b))`` over the simplex and whether it is exact (not just
    bounded). Each vector's max-norm distance to ``old`` bounds its own advantage; vectors are
    taken by decreasing distance, and only those whose bound exceeds the best found so far need
    an LP (Lark's witness LP against ``old``), so a set that moved little needs one or two.
    ``dist``: the distances, if already known (:func:`_nearest_distances` of ``new`` to ``old``)."""
    if dist is None:
        dist = _nearest_distances(new, old)
    order = np.argsort(-dist, kind="stable")
    lp: Optional[WitnessLP] = None
    best = 0.0
    for n, i in enumerate(order):
        if dist[i] <= best:
            break  # no remaining vector can beat the residual found
        if max_lps is not None and n >= max_lps:
            return max(best, float(dist[i])), False  # out of LPs: the distance bound stands
        if lp is None:
            lp = WitnessLP(old.shape[1])
            for alpha in old:
                lp.add(alpha)
        delta, _ = lp.solve(new[i])
        gain = float(dist[i]) if not np.isfinite(delta) else min(float(dist[i]), max(0.0, float(delta)))
        best = max(best, gain)
    return best, True


def bellman_residual(new: np.ndarray, old: np.ndarray, max_lps: Optional[int] = None,
                     _new_to_old: Optional[np.ndarray] = None) -> Tuple[float, bool]:
    """``max_b |V_new(b) − V_old(b)|`` over the whole belief simplex, with ``V(b) = max_α α·b``.

    Exact up to the LPs' precision (~1e-10): each direction is ``max_{α'} δ*(α')``, Lark's LP
    ``δ*(α') = max_b α'·b − V_old(b)``, solved only where a vector's distance to the other set
    could exceed the residual found so far (one or two LPs when the sets moved evenly, or
    differ in a few vectors). Returns ``(residual, exact)``: with ``max_lps`` LPs at most per
    direction, the vectors left are bounded by their distance instead (``exact = False``).
    """
    new = np.atleast_2d(np.asarray(new, dtype=float))
    old = np.atleast_2d(np.asarray(old, dtype=float))
    up, exact_up = _residual_one_way(new, old, max_lps, _new_to_old)
    down, exact_down = _residual_one_way(old, new, max_lps)
    return max(up, down), exact_up and exact_down


class _Backup:
    """One exact DP backup of a value function, following the steps of the module docstring.

    Holds the per-(a, o) projection operators ``M[a, o] = γ T[a] ∘ O[a,:,o]``
    (``[S, S']``, element-wise product along ``s'``) and the reward share
    ``R[:, a] / |Z|``.
    """

    def __init__(self, model, tol: float, stats: PruneStats, deadline: Optional[float],
                 max_vectors: Optional[int] = None) -> None:
        T = model.T_dense()  # [A, S, S']
        O = np.asarray(model.O, dtype=float)  # [A, S', Z]
        self.A, self.S, _ = T.shape
        self.Z = O.shape[2]
        self.gamma = float(model.discount)
        # Projection γ Σ_{s'} T[a, s, s'] O[a, s', o] α(s') is computed per call from T and O
        # (no precomputed M[a, o, s, s']: for a 1176-state, 14-class, 3-action subtask that
        # array alone is ~460 MB and took ~5 s to build, more than the whole solve).
        self.T = T
        self.O = O
        self.reward_share = np.asarray(model.R, dtype=float).T / self.Z  # [A, S]
        # An observation that can never follow a gives the reward share alone (pomdp-solve).
        self.possible = O.max(axis=1) > 0.0  # [A, Z]
        self.tol = tol
        self.stage_tol = min(tol, STAGE_TOL)
        self.stats = stats
        self.deadline = deadline
        self.max_vectors = max_vectors
        # Witness beliefs of each prune in the previous epoch, by (a, o): the
        # value functions of successive epochs differ little, so last epoch's
        # witnesses find most of this epoch's useful vectors without an LP.
        self.memory: dict = {}

    def _seeds(self, key, *fresh: np.ndarray) -> Optional[tuple]:
        """The seed points of one prune: ``fresh`` witnesses, then last epoch's of the same prune
        (a tuple of arrays: :func:`.prune` takes them in order, without stacking them)."""
        mem = self.memory.get(key)
        return fresh + (mem,) if mem is not None else fresh

    def _check(self, vectors: int, where: str) -> None:
        """Before building a set of ``vectors`` vectors: stop at the deadline or the vector cap
        (the numpy step itself then runs at most once past the deadline)."""
        if _past(self.deadline):
            raise PruneTimeout()
        if self.max_vectors is not None and vectors > self.max_vectors:
            raise VectorCapExceeded(vectors, self.max_vectors, where)

    def _prune(self, vectors: np.ndarray, points: Optional[tuple]) -> Tuple[np.ndarray, np.ndarray]:
        """An intermediate prune (step 1 or 2), at the near-exact ``stage_tol``."""
        kept, wit = prune(vectors, tol=self.stage_tol, points=points, return_witnesses=True,
                          stats=self.stats, deadline=self.deadline)
        return vectors[kept], wit

    def project(self, gamma_prev: np.ndarray, a: int, o: int) -> np.ndarray:
        """Γ^{a,o} as a ``[K, S]`` array (step 1, before pruning)."""
        if not self.possible[a, o]:
            return self.reward_share[a][None, :].copy()
        return self.gamma * (gamma_prev * self.O[a, :, o][None, :]) @ self.T[a].T + self.reward_share[a][None, :]

    def project_all(self, gamma_prev: np.ndarray, a: int) -> np.ndarray:
        """:meth:`project` for every observation of ``a`` at once, ``[Z, K, S]`` (one
        stacked product instead of |Z| small ones; rows of impossible observations unused)."""
        if self.Z * gamma_prev.size > 1_000_000:  # large sets: one observation at a time (memory)
            return np.stack([self.project(gamma_prev, a, o) for o in range(self.Z)])
        weighted = gamma_prev[None, :, :] * self.O[a].T[:, None, :]  # [Z, K, S']
        return self.gamma * weighted @ self.T[a].T + self.reward_share[a][None, None, :]

    def __call__(self, gamma_prev: np.ndarray, points: Optional[np.ndarray]) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Γ' from Γ: returns ``(alphas [K', S], actions [K'], witnesses [K', S])``."""
        per_action: List[np.ndarray] = []
        per_action_witness: List[np.ndarray] = []
        for a in range(self.A):
            # Step 1: project and prune each Γ^{a,o}.
            projected = []
            self._check(self.Z * len(gamma_prev), f"the projections of action {a}")
            all_o = self.project_all(gamma_prev, a)
            for o in range(self.Z):
                vecs = all_o[o] if self.possible[a, o] else self.reward_share[a][None, :].copy()
                projected.append(self._prune(vecs, self._seeds(("proj", a, o))))
                self.memory[("proj", a, o)] = projected[-1][1]
            # Step 2: cross-sum pairwise, pruning after each sum. The witnesses of
            # both operands are beliefs where some sum wins: they seed the prune.
            acc, acc_w = projected[0]
            for o in range(1, self.Z):
                nxt, nxt_w = projected[o]
                if len(nxt) == 1 or len(acc) == 1:
                    # Adding one vector translates the other set: what was useful
                    # stays useful with the same witnesses, and nothing else is.
                    acc, acc_w = (acc + nxt, acc_w) if len(nxt) == 1 else (acc + nxt, nxt_w)
                    continue
                self._check(len(acc) * len(nxt), f"the cross-sum of action {a} at observation {o}")
                summed = (acc[:, None, :] + nxt[None, :, :]).reshape(-1, self.S)
                acc, acc_w = self._prune(summed, self._seeds(("sum", a, o), acc_w, nxt_w))
                self.memory[("sum", a, o)] = acc_w
            per_action.append(acc)
            per_action_witness.append(acc_w)
        # Step 3: union over actions, prune again.
        self._check(sum(len(v) for v in per_action), "the union over actions")
        union = np.vstack(per_action)
        labels = np.concatenate([np.full(len(v), a, dtype=np.int64) for a, v in enumerate(per_action)])
        seeds = tuple(per_action_witness) + ((points,) if points is not None else ())
        kept, wit = prune(union, tol=self.tol, points=seeds, return_witnesses=True,
                          stats=self.stats, deadline=self.deadline)
        return union[kept], labels[kept], wit


def solve_incremental_pruning(
    model,
    horizon: Optional[int] = None,
    epsilon: float = 1e-9,
    time_limit: Optional[float] = None,
    progress: bool = False,
    initial: Union[None, np.ndarray, AlphaVectorPolicy] = None,
    prune_tol: float = DEFAULT_TOL,
    max_vectors: Optional[int] = None,
) -> SolveResult:
    """Solve ``model`` exactly by incremental pruning (Cassandra, Littman & Zhang 1997).

    Args:
        model: a :class:`~pearl_pomdp.model.pomdp.Pomdp` (dense or sparse T;
            the solver works on ``model.T_dense()`` ``[A, S, S']``, so it is
            meant for models of up to a few hundred states).
        horizon: number of epochs (a finite-horizon solve); ``None`` runs to
            convergence (needs ``discount < 1``).
        epsilon: infinite horizon stop (step 4 of the module docstring): after
            epoch t, stop when the weak bound between Γ_t and Γ_{t−1} (see
            :func:`weak_bound`) is ``≤ epsilon·(1−γ)/(2γ)`` (pomdp-solve's default
            ``-stop_criteria weak -stop_delta 1e-9``), or when Γ_t repeats an
            earlier Γ_{t−k} (any k ≥ 2) to that distance both ways (a cycle of
            the pruned iteration, see the module docstring).
        time_limit: seconds; the deadline is checked before every LP, about
            every millisecond inside a prune, and before each projection,
            cross-sum and union, so a solve overruns it by at most one LP or
            one numpy step. Past it the solve returns the last *complete*
            epoch's value function with ``converged=False``.
        progress: a tqdm bar on stderr, one step per epoch.
        initial: starting value function, ``[K, S]`` α-vectors or an
            :class:`AlphaVectorPolicy`; default one zero vector (pomdp-solve's).
        prune_tol: a vector is kept only if it wins by ``≥ prune_tol`` at
            some belief (default: pomdp-solve's effective 5.01e-7).
        max_vectors: the most vectors one set built within an epoch (a
            cross-sum or the union over actions, before its prune) may hold;
            default ``MAX_CANDIDATE_BYTES // (8·S)`` (512 MiB of vectors). A
            larger one stops the solve with ``stop_reason = "vector_cap"``.

    Returns:
        :class:`SolveResult` with method ``"incprune"``, ``iterations`` =
        completed epochs, ``vectors_per_epoch`` = ``|Γ_t|`` after each epoch,
        ``value_at_start`` = ``max_α α·b0``, ``converged`` (``stop_reason`` is
        ``"converged"`` or ``"horizon"``), and in ``extra``:

        * ``stop_reason``: ``"converged"`` (the stop rule above held),
          ``"horizon"`` (all ``horizon`` epochs done), ``"time_limit"`` or
          ``"vector_cap"`` (the epoch in progress was abandoned: the policy is
          the last complete epoch's);
        * ``last_residual``: the Bellman residual ``max_b |V_t(b) − V_{t−1}(b)|``
          over the belief simplex between the last two complete epochs
          (:func:`bellman_residual`; ``None`` before a second epoch), and
          ``last_residual_exact`` (False when it had to be bounded because the
          time limit had passed and it took more than
          :data:`RESIDUAL_LPS_PAST_DEADLINE` LPs);
        * ``cycle_period``: ``k`` when the stop was a cycle of period ``k``
          (``None`` otherwise); ``stop_error`` (last weak bound to Γ_{t−1}),
          ``stop_threshold``; ``timed_out``; ``vector_cap`` (the cap, and what
          exceeded it, or ``None``); ``epoch_seconds``; LP counts (``prune``).

    Raises:
        ValueError: bad horizon/epsilon/time limit/max_vectors, or
            ``discount == 1`` without a horizon.
    """
    if horizon is not None and (int(horizon) != horizon or horizon < 0):
        raise ValueError(f"horizon must be a non-negative integer or None, got {horizon!r}")
    if epsilon < 0:
        raise ValueError(f"epsilon must be >= 0, got {epsilon}")
    if time_limit is not None and not time_limit > 0:
        raise ValueError(f"time_limit must be > 0 seconds, got {time_limit}")
    if max_vectors is not None and (int(max_vectors) != max_vectors or max_vectors < 1):
        raise ValueError(f"max_vectors must be a positive integer or None, got {max_vectors!r}")
    gamma = float(model.discount)
    if horizon is None and gamma >= 1.0:
        raise ValueError("discount 1 needs a finite horizon (value iteration would not converge)")

    start = time.perf_counter()
    deadline = None if time_limit is None else start + float(time_limit)
    S = model.num_states
    if initial is None:
        alphas = np.zeros((1, S))
        actions = np.zeros(1, dtype=np.int64)
    elif isinstance(initial, AlphaVectorPolicy):
        alphas, actions = initial.alphas.copy(), initial.actions.copy()
    else:
        alphas = np.atleast_2d(np.asarray(initial, dtype=float))
        actions = np.zeros(alphas.shape[0], dtype=np.int64)
    if alphas.shape[1] != S:
        raise ValueError(f"initial value function has {alphas.shape[1]} states, the model {S}")
    cap = int(max_vectors) if max_vectors is not None else max(1, MAX_CANDIDATE_BYTES // (8 * S))

    stats = PruneStats()
    backup = _Backup(model, prune_tol, stats, deadline, cap)
    threshold = epsilon * (1.0 - gamma) / (2.0 * gamma) if gamma < 1.0 else 0.0
    counts: List[int] = []
    epoch_seconds: List[float] = []
    witnesses: Optional[np.ndarray] = None
    previous: Optional[np.ndarray] = None  # Γ_{t-1}, once epoch t is complete
    distances: Optional[np.ndarray] = None  # each vector of Γ_t to its nearest in Γ_{t-1}
    cycles = _CycleWatch(threshold)
    if horizon is None:
        cycles.period(0, alphas)
    stop_reason: Optional[str] = None
    cycle_period: Optional[int] = None
    cap_hit: Optional[dict] = None
    error = float("inf")

    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=horizon, desc=f"incprune {model.name}", unit="epoch", leave=False)
    try:
        while stop_reason is None:
            if horizon is not None and len(counts) >= horizon:
                stop_reason = "horizon"
                break
            if _past(deadline):
                stop_reason = "time_limit"
                break
            t0 = time.perf_counter()
            try:
                new_alphas, new_actions, witnesses = backup(alphas, witnesses)
            except PruneTimeout:
                stop_reason = "time_limit"
                break
            except VectorCapExceeded as err:
                stop_reason = "vector_cap"
                cap_hit = {"max_vectors": err.cap, "vectors": err.vectors, "where": err.where}
                break
            epoch_seconds.append(time.perf_counter() - t0)
            counts.append(int(new_alphas.shape[0]))
            previous, distances = alphas, None
            alphas, actions = new_alphas, new_actions  # a complete epoch: what is returned from now on
            if horizon is None:
                try:  # the weak bound (step 4), each vector's distance kept for the last residual
                    distances = _nearest_distances(alphas, previous, deadline=deadline)
                except PruneTimeout:
                    stop_reason = "time_limit"
                    break
                error = float(distances.max()) if distances.size else 0.0
                if error <= threshold:
                    stop_reason = "converged"
                else:
                    cycle_period = cycles.period(len(counts), alphas)
                    if cycle_period is not None:
                        stop_reason = "converged"
            if bar is not None:
                bar.update(1)
                bar.set_postfix(vectors=counts[-1], **({"bound": f"{error:.3g}"} if horizon is None else {}))
    finally:
        if bar is not None:
            bar.close()

    # The residual between the last two complete epochs (past the deadline: a few LPs at most).
    last_residual: Optional[float] = None
    residual_exact = True
    if previous is not None:
        last_residual, residual_exact = bellman_residual(
            alphas, previous, max_lps=RESIDUAL_LPS_PAST_DEADLINE if stop_reason == "time_limit" else None,
            _new_to_old=distances)

    policy = AlphaVectorPolicy(alphas, actions)
    timed_out = stop_reason == "time_limit"
    return SolveResult(
        policy=policy,
        method="incprune",
        value_at_start=float(np.max(alphas @ np.asarray(model.b0, dtype=float))),
        upper_bound=None,
        iterations=len(counts),
        seconds=time.perf_counter() - start,
        vectors_per_epoch=counts,
        converged=stop_reason in ("converged", "horizon"),
        extra={
            "horizon": horizon,
            "stop_reason": stop_reason,
            "last_residual": last_residual,
            "last_residual_exact": residual_exact,
            "cycle_period": cycle_period,
            "stop_error": None if horizon is not None else error,
            "stop_threshold": None if horizon is not None else threshold,
            "timed_out": timed_out,
            "time_limit": time_limit,
            "vector_cap": cap_hit,
            "epoch_seconds": epoch_seconds,
            "prune": stats.as_dict(),
        },
    )


def dp_backup(model, alphas: np.ndarray, tol: float = DEFAULT_TOL) -> Tuple[np.ndarray, np.ndarray]:
    """One exact backup ``Γ → Γ'`` (steps 1–3), returning ``(alphas [K', S], actions [K'])``."""
    new_alphas, new_actions, _ = _Backup(model, tol, PruneStats(), None)(np.atleast_2d(alphas), None)
    return new_alphas, new_actions
