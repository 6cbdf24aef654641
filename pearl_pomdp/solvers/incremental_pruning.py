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
4. **Stop** after ``horizon`` epochs, or (infinite horizon) when the *weak
   bound* between successive value functions (pomdp-solve's default stopping
   rule) is small: ``max_{α'∈Γ'} min_{α∈Γ} max_s |α'(s) − α(s)| ≤
   ε (1−γ) / (2γ)``, with ``ε`` = ``epsilon`` (pomdp-solve's ``-stop_delta``,
   default 1e-9). The returned value function is Γ' of the last epoch.

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
from typing import List, Optional, Tuple, Union

import numpy as np

from .base import AlphaVectorPolicy, SolveResult
from .prune import DEFAULT_TOL, PruneStats, PruneTimeout, prune

__all__ = ["solve_incremental_pruning", "dp_backup", "weak_bound", "STAGE_TOL"]

#: Tolerance of the intermediate prunes (projections, cross-sums): near-exact, so the
#: losses of successive stages cannot add up past ``prune_tol`` (see the module docstring).
STAGE_TOL = 1e-9


def weak_bound(new: np.ndarray, old: np.ndarray, chunk_elems: int = 8_000_000) -> float:
    """pomdp-solve's weak bound: ``max_{α'∈new} min_{α∈old} max_s |α'(s) − α(s)|``.

    It compares vectors component by component, i.e. at the corners of the
    belief simplex, which bounds the difference anywhere inside.
    """
    worst = 0.0
    S = new.shape[1]
    step = max(1, chunk_elems // max(1, old.shape[0] * S))
    for i in range(0, new.shape[0], step):
        d = np.abs(new[i:i + step, None, :] - old[None, :, :]).max(axis=2)  # [blk, M]
        worst = max(worst, float(d.min(axis=1).max()))
    return worst


class _Backup:
    """One exact DP backup of a value function, following the steps of the module docstring.

    Holds the per-(a, o) projection operators ``M[a, o] = γ T[a] ∘ O[a,:,o]``
    (``[S, S']``, element-wise product along ``s'``) and the reward share
    ``R[:, a] / |Z|``.
    """

    def __init__(self, model, tol: float, stats: PruneStats, deadline: Optional[float]) -> None:
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
        # Witness beliefs of each prune in the previous epoch, by (a, o): the
        # value functions of successive epochs differ little, so last epoch's
        # witnesses find most of this epoch's useful vectors without an LP.
        self.memory: dict = {}

    def _seeds(self, key, *fresh: np.ndarray) -> Optional[tuple]:
        """The seed points of one prune: ``fresh`` witnesses, then last epoch's of the same prune
        (a tuple of arrays: :func:`.prune` takes them in order, without stacking them)."""
        mem = self.memory.get(key)
        return fresh + (mem,) if mem is not None else fresh

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
                summed = (acc[:, None, :] + nxt[None, :, :]).reshape(-1, self.S)
                acc, acc_w = self._prune(summed, self._seeds(("sum", a, o), acc_w, nxt_w))
                self.memory[("sum", a, o)] = acc_w
            per_action.append(acc)
            per_action_witness.append(acc_w)
        # Step 3: union over actions, prune again.
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
) -> SolveResult:
    """Solve ``model`` exactly by incremental pruning (Cassandra, Littman & Zhang 1997).

    Args:
        model: a :class:`~pearl_pomdp.model.pomdp.Pomdp` (dense or sparse T;
            the solver works on ``model.T_dense()`` ``[A, S, S']``, so it is
            meant for models of up to a few hundred states).
        horizon: number of epochs (a finite-horizon solve); ``None`` runs to
            convergence (needs ``discount < 1``).
        epsilon: infinite horizon stop: after an epoch, stop when the weak
            bound (see :func:`weak_bound`) is ``≤ epsilon·(1−γ)/(2γ)``
            (pomdp-solve's default ``-stop_criteria weak -stop_delta 1e-9``).
        time_limit: seconds; when exceeded (checked between LPs and between
            epochs) the solve stops and returns the last *complete* epoch's
            value function with ``converged=False``.
        progress: a tqdm bar on stderr, one step per epoch.
        initial: starting value function, ``[K, S]`` α-vectors or an
            :class:`AlphaVectorPolicy`; default one zero vector (pomdp-solve's).
        prune_tol: a vector is kept only if it wins by ``≥ prune_tol`` at
            some belief (default: pomdp-solve's effective 5.01e-7).

    Returns:
        :class:`SolveResult` with method ``"incprune"``, ``iterations`` =
        completed epochs, ``vectors_per_epoch`` = ``|Γ_t|`` after each epoch,
        ``value_at_start`` = ``max_α α·b0``, ``converged`` (stop rule met, or
        the horizon reached), and in ``extra``: ``stop_error`` (last weak
        bound), ``stop_threshold``, ``epoch_seconds``, LP counts.

    Raises:
        ValueError: bad horizon/epsilon/time limit, or ``discount == 1``
            without a horizon.
    """
    if horizon is not None and (int(horizon) != horizon or horizon < 0):
        raise ValueError(f"horizon must be a non-negative integer or None, got {horizon!r}")
    if epsilon < 0:
        raise ValueError(f"epsilon must be >= 0, got {epsilon}")
    if time_limit is not None and time_limit <= 0:
        raise ValueError(f"time_limit must be > 0 seconds, got {time_limit}")
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

    stats = PruneStats()
    backup = _Backup(model, prune_tol, stats, deadline)
    threshold = epsilon * (1.0 - gamma) / (2.0 * gamma) if gamma < 1.0 else 0.0
    counts: List[int] = []
    epoch_seconds: List[float] = []
    witnesses: Optional[np.ndarray] = None
    converged = False
    timed_out = False
    error = float("inf")

    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=horizon, desc=f"incprune {model.name}", unit="epoch", leave=False)
    try:
        epoch = 0
        while horizon is None or epoch < horizon:
            if deadline is not None and time.perf_counter() > deadline:
                timed_out = True
                break
            t0 = time.perf_counter()
            try:
                new_alphas, new_actions, witnesses = backup(alphas, witnesses)
            except PruneTimeout:
                timed_out = True
                break
            epoch += 1
            epoch_seconds.append(time.perf_counter() - t0)
            counts.append(int(new_alphas.shape[0]))
            if horizon is None:
                error = weak_bound(new_alphas, alphas)
            alphas, actions = new_alphas, new_actions
            if bar is not None:
                bar.update(1)
                bar.set_postfix(vectors=counts[-1], **({"bound": f"{error:.3g}"} if horizon is None else {}))
            if horizon is None and error <= threshold:
                converged = True
                break
        else:
            converged = True  # the horizon was reached
    finally:
        if bar is not None:
            bar.close()

    policy = AlphaVectorPolicy(alphas, actions)
    return SolveResult(
        policy=policy,
        method="incprune",
        value_at_start=float(np.max(alphas @ np.asarray(model.b0, dtype=float))),
        upper_bound=None,
        iterations=len(counts),
        seconds=time.perf_counter() - start,
        vectors_per_epoch=counts,
        converged=converged and not timed_out,
        extra={
            "horizon": horizon,
            "stop_error": None if horizon is not None else error,
            "stop_threshold": None if horizon is not None else threshold,
            "timed_out": timed_out,
            "epoch_seconds": epoch_seconds,
            "prune": stats.as_dict(),
        },
    )


def dp_backup(model, alphas: np.ndarray, tol: float = DEFAULT_TOL) -> Tuple[np.ndarray, np.ndarray]:
    """One exact backup ``Γ → Γ'`` (steps 1–3), returning ``(alphas [K', S], actions [K'])``."""
    new_alphas, new_actions, _ = _Backup(model, tol, PruneStats(), None)(np.atleast_2d(alphas), None)
    return new_alphas, new_actions
