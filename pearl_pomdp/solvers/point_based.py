"""Anytime point-based POMDP solver with a lower and an upper bound.

References:
    * J. Pineau, G. Gordon, S. Thrun. "Point-based value iteration: an anytime
      algorithm for POMDPs", IJCAI 2003 (PBVI: backups at a set of beliefs).
    * T. Smith, R. Simmons. "Point-based POMDP algorithms: improved analysis and
      implementation", UAI 2005 (HSVI2: bound-guided forward search, sawtooth
      upper bound, excess-uncertainty depth rule).
    * H. Kurniawati, D. Hsu, W. S. Lee. "SARSOP: efficient point-based POMDP
      planning by approximating optimally reachable belief spaces", RSS 2008.
    * M. Spaan, N. Vlassis. "Perseus: randomized point-based value iteration
      for POMDPs", JAIR 24, 2005.

Conventions (docs/design.md §2): ``T[a][s, s'] = P(s'|s,a)`` (dense or scipy CSR),
``O[a, s', o] = P(o|s',a)``, ``R[s, a]``, ``b0[s]``, discount ``γ < 1``.

The solver keeps

* a **lower bound** Γ of α-vectors (each the value of a concrete policy, so
  ``max_k Γ_k·b ≤ V*(b)``), initialised with the blind policies "always do a";
* an **upper bound**: the FIB vectors and a sawtooth point set over corner values (HSVI2),
  :class:`~pearl_pomdp.solvers.sawtooth.SawtoothUpperBound`.

Each *trial* walks forward from ``b0``: at belief ``b`` (depth ``d``) it takes
the action with the best upper bound and the observation with the largest
weighted excess uncertainty ``P(o|b,a)·(UB − LB − ε_t γ^{-(d+1)})``, and stops
when the width at ``b`` is within ``ε_t γ^{-d}``, ``ε_t = max(ε, κ·gap(b0))``
(κ ∈ {0.5, 0.2} picked per trial by a small deterministic bandit on LB gain per
backup). On the way back it backs up the lower bound at every visited belief
(one new α-vector when it improves the bound there) and lowers the upper bound
there. Visited beliefs form a graph that caches successor upper bounds (valid
because upper bounds only decrease), as SARSOP's belief tree does.

Between trials the upper bound is spread over all visited beliefs (an upper-bound
backup at each, newest first, every time the trials have done half as many backups as
there are visited beliefs: a trial lowers UB along one path only), and so is the lower
bound: as many Perseus backups as trial backups (Spaan & Vlassis 2005: randomised
backups; a belief leaves the round once a new vector reaches its old value) or, when
its products are small enough, a synchronous PBVI sweep over every visited belief on the
same schedule. A sweep or Perseus round that raised neither LB(b0) nor the LB at any
belief by more than ε (weighted by the belief's reach γ^d·P(path) from b0) makes the next
one wait 1, 2, 4, … trials (on small models the upper bound is what closes the gap).

The per-belief inner loops (successor beliefs, LB at the successors, the sawtooth with
its branch and bound, the backed-up vector) are one C kernel, ``_pointbased_kernel.c``,
used for every model size; they work on the states a belief can reach, with T read from
one CSR ``S × (A·S)`` block, so ten thousand states (RockSample[7,8]) stay cheap.
Pruning keeps the vectors that are maximal at a visited belief or at one of
its successors (vectors serving only successors matter: without them TagAvoid's
search stalls, and the greedy policy falls short of LB(b0)), at the successors under
the greedy action only when every action's would cost too much; by visited beliefs
alone when Γ grows past a memory cap. A prune waits
until the trials since the last one did about one backup per visited belief.

The search is deterministic (costs are counted in backups, not seconds, except
for the time limit itself); ``seed`` fixes the Perseus order and the order in
which exactly tied observations are considered.

``solve_point_based(engine="c")`` (the default under ``"auto"``) runs the same kind of search
in one C call, ``_search_kernel.c``: HSVI2 trials with these bounds, each distinct belief
stored once with cached successor upper bounds, upper-bound sweeps, round-robin lower-bound
backups in place of Perseus, and no per-trial Python (docs/solvers.md, "The C engine on issue
24's seven files"). Given a knob only the Python engine has it raises
:class:`EngineLacksSetting` (:data:`C_ENGINE_SETTINGS` are the ones it reads).
"""
from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass
from typing import Any, Callable, Dict, List, Optional, Tuple, cast

import numpy as np

from ..model.pomdp import Pomdp
from . import _pointbased_kernel as _kernel
from ..solution import AlphaVectorPolicy, SolveResult
from .mdp import blind_lower_bound
from .belief_set import BeliefSetBackups
from .sawtooth import SawtoothUpperBound

__all__ = ["solve_point_based", "PointBasedSolver", "PointBasedSettings", "BeliefNode", "transition_block", "ENGINES",
           "C_ENGINE_SETTINGS", "EngineLacksSetting"]


@dataclass(frozen=True)
class PointBasedSettings:
    """The tuning knobs of :class:`PointBasedSolver`, checked when built.

    None of them changes what the bounds mean (the lower bound is always the value
    of a policy, the upper bound always above the optimum); they decide where the
    work goes. The defaults are the ones the benchmarks were tuned with.

    Legend (the short names of the module docstring and of :meth:`PointBasedSolver.trial`):

    ========================== ======= ==================================================
    field                      symbol  meaning
    ========================== ======= ==================================================
    ``trial_kappa``            κ       a trial stops where the width UB − LB is within
                                       ``ε_t γ^{-d}``, ``ε_t = max(ε, κ·gap(b0))``; one
                                       arm of the bandit per value (large κ: shallow
                                       trials that refine b0; small κ: deep ones that
                                       carry distant rewards back)
    ``explore_every``          —       every ``explore_every``-th trial plays another arm
                                       than the best (by LB(b0) gain per backup)
    ``perseus_share``          —       Perseus backups over the visited beliefs per trial
                                       backup (0: none)
    ``sweep_ratio``            —       a synchronous PBVI sweep over all visited beliefs
                                       after this many trial backups per visited belief
                                       since the last sweep (0: never)
    ``sweep_max_flops``        —       ... only when a sweep's products cost at most this
                                       many multiply-adds (else Perseus is used)
    ``prune_keeps_successors`` —       pruning keeps vectors maximal at a successor of a
                                       visited belief too (TagAvoid's search stalls
                                       without them)
    ``max_gamma_entries``      K·S     above this many entries of Γ (8 bytes each) pruning
                                       keeps only vectors maximal at visited beliefs
    ``ub_sweep_ratio``         —       an upper-bound backup at every visited belief after
                                       this many trial backups per visited belief since
                                       the last (0: never): a trial lowers UB along one
                                       path, the sweep carries it to the siblings it
                                       passed by (tiger.95: 65 → 49 trials, 4x3: 128 → 46)
    ``fib_epsilon``            —       the FIB upper bound's stopping tolerance (with no
                                       ``fib_time``): every FIB iterate is an upper bound,
                                       so a looser tolerance is only a looser start (the
                                       hierarchy planner uses its target gap)
    ``spread_backoff``         —       a sweep or Perseus round that raised neither LB(b0)
                                       nor the LB at any belief by more than the target
                                       gap ε, weighted by the belief's reach γ^d·P(path)
                                       from b0, makes the next one wait 1, 2, 4, … trials,
                                       at most this many (0: spread after every trial);
                                       one that did resets the wait (on small models the
                                       upper bound is what closes the gap, and spreading
                                       is wasted work)
    ========================== ======= ==================================================

    Raises:
        ValueError: a field is out of range (the message names it and its value).
    """

    trial_kappa: Tuple[float, ...] = (0.5, 0.2)
    explore_every: int = 4
    perseus_share: float = 1.0
    sweep_ratio: float = 0.5
    sweep_max_flops: float = 4e8
    prune_keeps_successors: bool = True
    max_gamma_entries: int = 40_000_000
    spread_backoff: int = 16
    ub_sweep_ratio: float = 0.5
    fib_epsilon: float = 1e-6

    def __post_init__(self) -> None:
        kappa = tuple(float(k) for k in self.trial_kappa) if isinstance(self.trial_kappa, (tuple, list)) else None
        if not kappa or not all(0.0 < k <= 1.0 for k in kappa):
            raise ValueError(f"PointBasedSettings.trial_kappa must be a non-empty sequence of numbers in (0, 1], "
                             f"got {self.trial_kappa!r}")
        object.__setattr__(self, "trial_kappa", kappa)
        checks = [
            ("explore_every", isinstance(self.explore_every, int) and not isinstance(self.explore_every, bool)
             and self.explore_every >= 2, "an integer >= 2"),
            ("perseus_share", _finite(self.perseus_share) and self.perseus_share >= 0, "a number >= 0"),
            ("sweep_ratio", _finite(self.sweep_ratio) and self.sweep_ratio >= 0, "a number >= 0"),
            ("sweep_max_flops", _finite(self.sweep_max_flops) and self.sweep_max_flops >= 0, "a number >= 0"),
            ("prune_keeps_successors", isinstance(self.prune_keeps_successors, bool), "True or False"),
            ("ub_sweep_ratio", _finite(self.ub_sweep_ratio) and self.ub_sweep_ratio >= 0, "a number >= 0"),
            ("fib_epsilon", _finite(self.fib_epsilon) and self.fib_epsilon > 0, "a number > 0"),
            ("spread_backoff", isinstance(self.spread_backoff, int) and not isinstance(self.spread_backoff, bool)
             and self.spread_backoff >= 0, "an integer >= 0"),
            ("max_gamma_entries", isinstance(self.max_gamma_entries, int)
             and not isinstance(self.max_gamma_entries, bool) and self.max_gamma_entries >= 1, "an integer >= 1"),
        ]
        for name, ok, what in checks:
            if not ok:
                raise ValueError(f"PointBasedSettings.{name} must be {what}, got {getattr(self, name)!r}")


def _nonzeros(t) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(rows, cols, values)`` of the non-zero entries of a dense or scipy matrix, row-major
    (duplicates of a scipy matrix summed)."""
    if hasattr(t, "tocsr"):
        c = t.tocsr()
        c.sum_duplicates()
        c.eliminate_zeros()
        r = np.repeat(np.arange(c.shape[0], dtype=np.int64), np.diff(c.indptr))
        return r, c.indices.astype(np.int64), np.asarray(c.data, dtype=float)
    d = np.asarray(t, dtype=float)
    r, col = np.nonzero(d)
    return r.astype(np.int64), col.astype(np.int64), d[r, col]


def transition_block(T, coo=None) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``T`` (one ``S×S`` matrix per action, dense or scipy) as the kernel reads it: one CSR
    ``S × (A·S)`` block ``(t_ptr, t_ind, t_dat)`` whose row ``s`` holds ``T[a][s, :]`` for every
    ``a`` at columns ``a·S + s'`` (the successors of a belief are one gather over its support).
    ``coo``: the per-action ``(rows, cols, values)`` when the caller has them already."""
    S = T[0].shape[0]
    coo = [_nonzeros(t) for t in T] if coo is None else coo
    rows = np.concatenate([r for r, _, _ in coo])
    cols = np.concatenate([c + a * S for a, (_, c, _) in enumerate(coo)])
    vals = np.concatenate([v for _, _, v in coo])
    order = np.lexsort((cols, rows))
    return (_row_pointers(rows[order], S), np.ascontiguousarray(cols[order], dtype=np.int64),
            np.ascontiguousarray(vals[order], dtype=float))


def _action_rows(coo, S: int) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The per-action non-zeros ``coo`` of ``T`` as one ``(A·S) × S`` CSR ``(ptr, ind, dat)``: row
    ``a·S + s`` is ``T[a][s, :]`` (each action's non-zeros come row-major already)."""
    ptr = _row_pointers(np.concatenate([r + a * S for a, (r, _, _) in enumerate(coo)]), len(coo) * S)
    return (ptr, np.ascontiguousarray(np.concatenate([c for _, c, _ in coo]), dtype=np.int64),
            np.ascontiguousarray(np.concatenate([v for _, _, v in coo]), dtype=float))


def _row_pointers(rows: np.ndarray, n: int) -> np.ndarray:
    """CSR row pointers of sorted row indices ``rows`` over ``n`` rows."""
    return np.concatenate([[0], np.cumsum(np.bincount(rows, minlength=n))]).astype(np.int64)


def _finite(x) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)


def _setting(name: str) -> property:
    """A solver attribute that reads ``settings.<name>``; assigning it re-validates the settings."""

    def get(self):
        return getattr(self.settings, name)

    def set_(self, value):
        self.settings = dataclasses.replace(self.settings, **{name: value})
        if name == "trial_kappa" and len(self._arm_gain) != len(self.settings.trial_kappa):
            self._arm_gain = np.zeros(len(self.settings.trial_kappa))
            self._arm_cost = np.zeros(len(self.settings.trial_kappa))

    return property(get, set_, doc=f"``settings.{name}`` (see :class:`PointBasedSettings`).")

#: The immediate reward given to an action the action filter forbids at a belief.
_FORBIDDEN = -1e30

class BeliefNode:
    """A belief in the search graph, with cached upper bounds at its successors.

    Upper bounds only ever decrease, so a cached successor bound is always a
    valid (possibly loose) upper bound; it is refreshed when that successor is
    itself updated (SARSOP keeps its belief tree the same way). Lower bounds are
    recomputed at every visit because they are cheap (one product with Γ).
    """

    __slots__ = ("idx", "val", "key", "p", "Rb", "ub_c", "ub", "children", "ub_seen", "reach", "allowed")

    def __init__(self, idx, val, key):
        self.idx = idx        # support of b (state indices)
        self.val = val        # b on that support
        self.key = key
        self.p: Any = None    # [A, Z] P(o | b, a), set on first expansion (Any: None until then)
        self.Rb: Any = None   # [A] expected immediate reward
        self.ub_c: Any = None  # [A, Z] cached upper bounds at the successors
        self.ub = np.inf      # upper bound at b
        self.children = {}    # flat (a*Z + o) -> BeliefNode, created when the search goes there
        self.ub_seen: Any = None  # [A] sawtooth version ub_c[a] was last read at (-1: never)
        self.reach = 0.0      # max over the trials' paths to b of γ^d Π P(o|b,a): b's weight in V(b0)
        self.allowed = None   # [A] bool: the actions the action filter allows at b (None: all)


class PointBasedSolver:
    """The state of an anytime point-based solve (see the module docstring).

    Use :func:`solve_point_based` unless you want to continue a solve
    (``run`` may be called repeatedly with more time). The tuning knobs are a
    :class:`PointBasedSettings` (``settings``); each is also readable and
    assignable as an attribute of the same name, which re-validates them.
    """

    trial_kappa = _setting("trial_kappa")
    explore_every = _setting("explore_every")
    perseus_share = _setting("perseus_share")
    sweep_ratio = _setting("sweep_ratio")
    sweep_max_flops = _setting("sweep_max_flops")
    prune_keeps_successors = _setting("prune_keeps_successors")
    max_gamma_entries = _setting("max_gamma_entries")
    spread_backoff = _setting("spread_backoff")
    ub_sweep_ratio = _setting("ub_sweep_ratio")

    def __init__(self, model: Pomdp, seed: int = 0, fib_time: Optional[float] = 5.0,
                 settings: Optional[PointBasedSettings] = None,
                 action_filter: Optional[Callable[[np.ndarray, np.ndarray], np.ndarray]] = None,
                 starts: Optional[np.ndarray] = None) -> None:
        if settings is not None and not isinstance(settings, PointBasedSettings):
            raise TypeError(f"settings must be a PointBasedSettings, got {type(settings).__name__}")
        self.settings = settings if settings is not None else PointBasedSettings()
        #: ``(idx, val) -> [A] bool``: the actions allowed at the belief ``val`` on states ``idx``
        #: (asked once per belief; at least one must be allowed). ``None``: every action.
        self.action_filter = action_filter
        if not model.discount < 1.0:
            raise ValueError("the point-based solver needs a discount below 1 (got %g)" % model.discount)
        self.model = model
        self.S, self.A, self.Z = model.num_states, model.num_actions, model.num_observations
        self.g = float(model.discount)
        self.R = np.ascontiguousarray(model.R, dtype=float)
        self.O = np.ascontiguousarray(model.O, dtype=float)
        self.rng = np.random.default_rng(seed)
        # Observation tie-break order and the Perseus order come from the seed.
        self.z_jitter = self.rng.permutation(self.Z) * 1e-15
        S, A = self.S, self.A
        # T as one CSR S × (A·S) block: the successors of a belief under all actions are one
        # gather over the rows of its support (the C kernel's loop, for dense and sparse T alike).
        # T[a] as (rows, cols, values) of its non-zeros, row-major (no scipy for a dense model:
        # importing scipy.sparse costs more than solving a small file).
        coo = [_nonzeros(t) for t in model.T]
        self.t_ptr, self.t_ind, self.t_dat = transition_block(model.T, coo)
        # (A·S) × S: row a·S + s is T[a][s, :] (the backed-up vector's product).
        self.tv_ptr, self.tv_ind, self.tv_dat = _action_rows(coo, S)
        self._inner = np.zeros(S)
        # Scratch of the kernels (all zero / -1 between calls) and the successor output buffers.
        self._bT = np.zeros(A * S)
        self._U_buf = np.zeros(S, dtype=np.int64)
        self._C_buf = np.zeros(A * self.Z * min(S, 64))     # grown on demand
        self._p_buf = np.zeros(A * self.Z)
        self._live_buf = np.zeros(A * self.Z, dtype=np.int64)
        self.b0 = np.asarray(model.b0, dtype=float)
        self.r_span = float(self.R.max() - self.R.min())

        self.pos = np.full(S, -1, dtype=np.int64)
        #: The upper bound: FIB vectors and the sawtooth point set over corner values.
        self.bound = SawtoothUpperBound(model, self.settings.fib_epsilon, fib_time, self.pos)
        self._one_lb = np.zeros(1)
        self._one_best = np.zeros(1, dtype=np.int64)
        self._row0 = np.zeros(1, dtype=np.int64)

        # ---- lower bound: Γ stored transposed ([S, cap]) so gathering the rows of a support is contiguous.
        blind = blind_lower_bound(model)
        self.backups = 0
        self.cap = 256
        self.GT = np.zeros((S, self.cap))
        self.K = 0
        self.gact = np.zeros(self.cap, dtype=np.int64)
        self.gbirth = np.zeros(self.cap, dtype=np.int64)
        self.beliefs: Dict[bytes, Tuple[np.ndarray, np.ndarray]] = {}
        self.nodes: Dict[bytes, BeliefNode] = {}
        self.expansions = 0
        idx0 = np.flatnonzero(self.b0 > 0)
        self.root = self._node(idx0, self.b0[idx0])
        self.root.reach = 1.0
        #: The beliefs trials start from: b0 first, then ``starts`` (each row a belief over the
        #: model's states; duplicates and b0 itself are dropped). The search targets the gap at
        #: every one of them (see :meth:`run`).
        self.starts: List[BeliefNode] = [self.root]
        for row in ([] if starts is None else np.atleast_2d(np.asarray(starts, dtype=float))):
            if row.shape != (S,) or not np.all(np.isfinite(row)) or row.min() < 0 or row.sum() <= 0:
                raise ValueError(f"PointBasedSolver: a start belief must be a non-negative row of {S} numbers "
                                 f"with a positive sum")
            row = row / row.sum()
            nz = np.flatnonzero(row > 0)
            node = self._node(nz, row[nz])
            if all(node is not other for other in self.starts):
                node.reach = max(node.reach, 1.0)
                self.starts.append(node)
        # The lower bound starts from the blind policies "always do a" (each the value of a real
        # policy). With an action filter only those of the actions it allows at every start
        # belief (a policy the filter forbids somewhere is no lower bound of the restricted
        # problem), and the worst case R_min / (1 − γ) of any policy, so Γ is never empty.
        seeds: np.ndarray = np.arange(A)
        if self.action_filter is not None:
            masks = [self._allowed_at(n.idx, n.val) for n in self.starts]
            for n, mask in zip(self.starts, masks):
                n.allowed = mask
            seeds = np.flatnonzero(np.logical_and.reduce(masks))
            first = int(np.flatnonzero(masks[0])[0])
            self.add_alpha(np.full(S, float(self.R.min()) / (1.0 - self.g)), first)
        for a in seeds:
            self.add_alpha(blind[a], int(a))
        self.trials = 0
        self.prunes = 0
        self.pruned = 0
        self._last_prune_K = self.K
        self._backups_at_prune = 0
        self.seconds = 0.0
        # The knobs are in self.settings (PointBasedSettings, with their legend). Shallow
        # trials (large κ) refine the bounds near b0 (hallway2 gains most), deep ones carry
        # distant rewards back (TagAvoid's chase needs them), so κ is picked per trial by a
        # small bandit: the arm with the best recent LB(b0) gain per backup, every
        # explore_every-th trial another arm (deterministic: costs are counted in backups).
        # Perseus rounds (Spaan & Vlassis 2005) and PBVI sweeps spread lower-bound gains
        # over the visited beliefs between trials.
        self.perseus_backups = 0
        self.belief_set = BeliefSetBackups(self)
        self.sweeps = 0
        self.sweep_backups = 0
        self._trial_backups_at_sweep = 0
        # Spreading back-off (settings.spread_backoff): trials to skip after a spread that did
        # not lift LB(b0), the trials still to skip, and the Perseus backups forgiven meanwhile.
        self._spread_skip = 0
        self._spread_wait = 0
        self._perseus_forgiven = 0
        self.spreads_skipped = 0
        self.ub_sweeps = 0
        #: The largest LB gain at one belief times its reach, in the current sweep or Perseus round.
        self.spread_gain = 0.0
        self._backups_at_ub_sweep = 0
        self._arm_gain = np.zeros(len(self.trial_kappa))
        self._arm_cost = np.zeros(len(self.trial_kappa))
        #: (seconds since the solver was built, LB(b0), UB(b0)) about every 0.5 s.
        self.history: List[Tuple[float, float, float]] = []
        self.setup_seconds = 0.0
        self._clock = time.perf_counter

    # ------------------------------------------------------------ lower bound
    def add_alpha(self, alpha: np.ndarray, action: int) -> None:
        """Append ``alpha`` (the value of doing ``action`` then following Γ) to the lower bound Γ."""
        if self.K == self.cap:
            self.cap *= 2
            GT = np.zeros((self.S, self.cap))
            GT[:, : self.K] = self.GT[:, : self.K]
            self.GT = GT
            self.gact = np.resize(self.gact, self.cap)
            self.gbirth = np.resize(self.gbirth, self.cap)
        self.GT[:, self.K] = alpha
        self.gact[self.K] = action
        self.gbirth[self.K] = self.backups
        self.K += 1

    def lower(self, idx: np.ndarray, val: np.ndarray, k0: int = 0) -> float:
        """Lower bound at the belief ``val`` on states ``idx`` (over the vectors from ``k0`` on)."""
        lb = self._one_lb
        _kernel.lower_rows(val, idx.shape[0], idx, self._row0, self.GT, self.cap, k0, self.K, lb, self._one_best,
                           False)
        return float(lb[0])

    def upper(self, idx: np.ndarray, val: np.ndarray) -> float:
        """Upper bound at the belief ``val`` on states ``idx``."""
        return self.bound.value(idx, val)

    def _allowed_at(self, idx: np.ndarray, val: np.ndarray) -> np.ndarray:
        """The action filter's mask at a belief, checked (shape ``[A]``, at least one True)."""
        mask = np.asarray(self.action_filter(idx, val), dtype=bool)  # type: ignore[misc]  # set when called
        if mask.shape != (self.A,) or not mask.any():
            raise ValueError(f"PointBasedSolver: the action filter must return {self.A} booleans with at least one "
                             f"True, got shape {mask.shape} with {int(mask.sum())} True")
        return mask

    # ------------------------------------------------------------ expansion
    def successors(self, node: BeliefNode) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(U, C, live)``: states reachable in one step, successor beliefs ``[A*Z, |U|]`` on U
        (rows with ``P(o|b,a) = 0`` left unnormalised zeros) and the flat indices of the live rows.
        Fills ``node.p`` and ``node.Rb`` on the first call."""
        A, Z, S = self.A, self.Z, self.S
        idx, val = node.idx, node.val
        allowed = b""
        if self.action_filter is not None:
            if node.allowed is None:
                node.allowed = self._allowed_at(idx, val)
            # Successors of the actions not allowed here are not even computed (nor read, nor
            # backed up through): the kernel skips them.
            allowed = node.allowed.astype(np.uint8).tobytes()
        while True:
            nU, nl = _kernel.successors(idx, val, self.t_ptr, self.t_ind, self.t_dat, self.O, A, S, Z, self._bT,
                                        self.pos, self._U_buf, self._C_buf, self._p_buf, self._live_buf, allowed)
            if nl >= 0:
                break
            self._C_buf = np.zeros(2 * A * Z * nU)
        U = self._U_buf[:nU].copy()
        C = self._C_buf[: A * Z * nU].reshape(A * Z, nU).copy()
        live = self._live_buf[:nl].copy()
        if node.p is None:
            node.p = self._p_buf.reshape(A, Z).copy()
            node.Rb = val @ self.R[idx]
            if node.allowed is not None:
                # A forbidden action never wins a max: its probabilities are 0 and its reward is
                # far below any real value (finite, so products with 0 stay 0).
                node.p[~node.allowed] = 0.0
                node.Rb = np.where(node.allowed, node.Rb, _FORBIDDEN)
            # Cheap bounds first (corners and FIB vectors); the sawtooth is read lazily, only
            # for the successors of actions that become greedy (see _refresh_upper).
            ub = np.zeros(A * Z)
            ub[live] = self.bound.batch(U, C, rows=live, with_points=False)
            node.ub_c = ub.reshape(A, Z)
            node.ub_seen = np.full(A, -1, dtype=np.int64)
            self.expansions += 1
            self._refresh_upper(node, U, C, live)
        return U, C, live

    def _refresh_upper(self, node: BeliefNode, U, C, live) -> np.ndarray:
        """Re-read the sawtooth at the successors of the greedy action until the greedy action
        is one already refreshed in this call; returns ``Q^U(b, ·)`` (the kernel's loop).

        Incremental: ``node.ub_c[a]`` already holds the minimum over the points as they
        were at version ``node.ub_seen[a]``, so only the points whose value fell since are
        read (all of them, and the FIB vectors, when a corner value fell since, or on the
        first read). The result is the same as a full re-read."""
        Qu = np.empty(self.A)
        _kernel.refresh_upper(node.Rb, node.p, node.ub_c, node.ub_seen, C, U.shape[0], U, live, self.g, self.A,
                              self.Z, self.bound.ub_version, self.bound.vc_version, self.pos, *self.bound.point_set(), Qu)
        return Qu

    def lower_children(self, U, C, live) -> Tuple[np.ndarray, np.ndarray]:
        """``(lb, best)`` ``[A, Z]``: the lower bound at each live successor and its maximising vector (0 elsewhere)."""
        AZ = self.A * self.Z
        lb = np.zeros(AZ)
        best = np.zeros(AZ, dtype=np.int64)
        _kernel.lower_rows(C, U.shape[0], U, live, self.GT, self.cap, 0, self.K, lb, best, False)
        return lb.reshape(self.A, self.Z), best.reshape(self.A, self.Z)

    @staticmethod
    def _key(idx: np.ndarray, val: np.ndarray) -> bytes:
        return idx.tobytes() + np.round(val, 12).tobytes()

    def _node(self, idx: np.ndarray, val: np.ndarray) -> BeliefNode:
        key = self._key(idx, val)
        node = self.nodes.get(key)
        if node is None:
            node = BeliefNode(idx, val, key)
            self.nodes[key] = node
        return node

    def _update(self, node: BeliefNode, U, C, live, seen=None) -> Tuple[float, float]:
        """Back up the lower bound and lower the upper bound at ``node``; returns (LB, UB) there.

        ``seen = (lb [A,Z], best [A,Z], LB(b), K)`` are the lower bounds computed on the way
        down against the first ``K`` vectors; only vectors added since are read again (Γ only
        grows during a trial)."""
        g = self.g
        if seen is None:
            lb, best = self.lower_children(U, C, live)
            cur = self.lower(node.idx, node.val)
        else:
            lb, best, cur, K0 = seen
            if self.K > K0:
                lb, best = lb.copy(), best.copy()
                _kernel.lower_rows(C, U.shape[0], U, live, self.GT, self.cap, K0, self.K, lb.reshape(-1),
                                   best.reshape(-1), True)
                cur = max(cur, self.lower(node.idx, node.val, K0))
        a, ql = _kernel.qvalue(node.Rb, node.p, lb, g, self.A, self.Z)
        self.backups += 1
        if ql > cur + 1e-10 * max(1.0, abs(cur)):
            alpha = self.backed_up_alpha(a, best[a])
            self.add_alpha(alpha, a)
            cur = max(cur, float(node.val @ alpha[node.idx]))
        self.beliefs.setdefault(node.key, (node.idx, node.val))
        self._update_upper(node, U, C, live)
        return cur, node.ub

    def _update_upper(self, node: BeliefNode, U, C, live) -> None:
        """Lower the upper bound at ``node``: refresh the cached successor bounds from successors
        updated elsewhere, then re-read the sawtooth for the successors of the greedy action
        (the one that sets UB(b)) until that action stops changing; store the new value."""
        ub_c = node.ub_c.reshape(-1)
        for ao, child in node.children.items():
            if child.ub < ub_c[ao]:
                ub_c[ao] = child.ub
        Qu = self._refresh_upper(node, U, C, live)
        u = float(Qu.max())
        if u < node.ub:
            node.ub = u
            self.bound.lower_at(node.idx, node.val, u, node.key)

    def sweep_upper(self) -> None:
        """An upper-bound backup at every expanded belief, the most recently created first (deep
        beliefs tend to be created last, so improvements travel towards ``b0`` in one pass)."""
        for node in reversed([n for n in self.nodes.values() if n.p is not None]):
            U, C, live = self.successors(node)
            self._update_upper(node, U, C, live)
        self.ub_sweeps += 1

    # ------------------------------------------------------------ pruning
    def prune(self, by_usage: bool = False) -> int:
        """Drop α-vectors that are maximal neither at a backed-up belief nor at any successor of
        one; with ``by_usage`` (or when the batched successor check is too costly) every vector
        that is maximal at none of the backed-up beliefs. (A pointwise-dominated vector is
        never the maximiser, so this subsumes the pointwise test.)

        Vectors that serve only successors that were never backed up themselves still carry
        the lower bound there; dropping them slowed TagAvoid down badly (LB −9.9 instead of
        −6.3 after 120 trials).
        Returns the number of vectors removed."""
        K = self.K
        if not self.beliefs or K <= self.A:
            return 0
        used = np.zeros(K, dtype=bool)
        for ix, v in self.beliefs.values():
            self.lower(ix, v)
            used[self._one_best[0]] = True
        if by_usage or not self.prune_keeps_successors:
            keep = np.flatnonzero(used)
        else:
            # Keep what is maximal at a backed-up belief or at one of its successors (batched);
            # when that is too costly (RockSample[7,8]), at the successors under the action the
            # policy takes there.
            nodes = [n for n in self.nodes.values() if n.p is not None]
            got = self.belief_set.batched_children(nodes)
            if got is not None:
                _, best, live = got
                used[best[live]] = True
            else:
                self._mark_greedy_successors(nodes, used)
            keep = np.flatnonzero(used)
        removed = K - keep.size
        if removed:
            self.GT[:, : keep.size] = self.GT[:, keep]
            self.gact[: keep.size] = self.gact[keep]
            self.gbirth[: keep.size] = self.gbirth[keep]
            self.K = keep.size
        self.prunes += 1
        self.pruned += removed
        self._last_prune_K = self.K
        self._backups_at_prune = self.backups
        return removed

    def _mark_greedy_successors(self, nodes, used: np.ndarray) -> None:
        """Mark in ``used`` the vectors maximal at each node's successors under the action the
        policy takes there (its maximal vector's), as the C engine's prune does.

        The returned policy acts greedily on Γ: at a belief it does the maximal vector's action,
        and at the next belief it picks again. Its value reaches LB(b0) only if the vectors that
        carry the bound at those next beliefs are still in Γ; keeping the maximisers at the
        visited beliefs alone (the old fallback when every action's successors cost too much)
        dropped them — RockSample[7,8]: LB(b0) 21.12, yet 100 episodes of the policy returned
        19.13 ± 1.31. One action's successors cost ``1/A`` of the batched check."""
        Z = self.Z
        AZ = self.A * Z
        for node in nodes:
            self.lower(node.idx, node.val)
            a = int(self.gact[self._one_best[0]])
            U, C, live = self.successors(node)
            rows = live[live // Z == a]
            if rows.size == 0:
                continue
            lb = np.zeros(AZ)
            best = np.zeros(AZ, dtype=np.int64)
            _kernel.lower_rows(C, U.shape[0], U, rows, self.GT, self.cap, 0, self.K, lb, best, False)
            used[best[rows]] = True

    # ------------------------------------------------------------ search
    def bounds_at_start(self) -> Tuple[float, float]:
        """(LB, UB) at ``b0``."""
        r = self.root
        return self.lower(r.idx, r.val), min(r.ub, self.upper(r.idx, r.val))

    def _max_depth(self, eps_t: float) -> int:
        if self.r_span <= 0:
            return 1
        d = np.log(eps_t * (1 - self.g) / self.r_span) / np.log(self.g)
        return int(min(max(d, 1), 1000))

    def backed_up_alpha(self, a: int, best_a: np.ndarray) -> np.ndarray:
        """The point-based backup's new vector for action ``a``, ``best_a[o]`` the vector of Γ to follow after ``o``:
        α = R(:,a) + γ T[a] Σ_o O[a,:,o] ∘ Γ_{best_a[o]}  (the o-sum moves inside T[a])."""
        out = np.empty(self.S)
        _kernel.alpha(a, np.ascontiguousarray(best_a, dtype=np.int64), self.R, self.O, self.GT, self.cap,
                      self.tv_ptr, self.tv_ind, self.tv_dat, self.S, self.A, self.Z, self.g, self._inner, out)
        return out

    def _pick_arm(self) -> int:
        n = len(self.trial_kappa)
        untried = np.flatnonzero(self._arm_cost == 0)
        if untried.size:
            return int(untried[0])
        rate = self._arm_gain / self._arm_cost
        best = int(np.argmax(rate))
        if n > 1 and self.trials % self.explore_every == self.explore_every - 1:
            return (best + 1 + (self.trials // self.explore_every) % (n - 1)) % n
        return best

    def start_gaps(self) -> np.ndarray:
        """``UB − LB`` at every start belief (b0 first), as :meth:`run` tests them."""
        return np.array([min(n.ub, self.upper(n.idx, n.val)) - self.lower(n.idx, n.val) for n in self.starts])

    def _open_gap(self, epsilon: float) -> Optional[int]:
        """The index of the first start belief whose gap exceeds ``epsilon`` (``None``: none)."""
        if len(self.starts) == 1:
            lo, hi = self.bounds_at_start()
            return 0 if hi - lo > epsilon else None
        open_ = np.flatnonzero(self.start_gaps() > epsilon)
        return int(open_[0]) if open_.size else None

    def _next_start(self, epsilon: float) -> Tuple[Optional[BeliefNode], float]:
        """The start of the next trial and its gap: b0 on every other trial while its gap is
        open, else the start belief with the widest gap (the first on ties); ``(None, 0)`` when
        every gap is within ``epsilon``."""
        if len(self.starts) == 1:
            lo, hi = self.bounds_at_start()
            return (self.root, hi - lo) if hi - lo > epsilon else (None, 0.0)
        gaps = self.start_gaps()
        if gaps[0] > epsilon and self.trials % 2 == 0:
            return self.root, float(gaps[0])
        i = int(np.argmax(gaps))
        return (self.starts[i], float(gaps[i])) if gaps[i] > epsilon else (None, 0.0)

    def trial(self, eps_t: float, start: Optional[BeliefNode] = None) -> None:
        """One HSVI2/SARSOP trial from ``b0`` with target width ``eps_t``, then the backups on its path.

        **Down.** At belief ``b`` of depth ``d`` the trial stops when the width there,
        ``u − l``, is within ``eps_t γ^{-d}`` (or at the depth where discounting makes any
        width irrelevant, or at an impossible observation). Otherwise it takes the action
        ``a`` with the largest upper-bound Q-value and the observation ``o`` with the largest
        weighted excess uncertainty ``P(o|b,a)·(UB(b^{a,o}) − LB(b^{a,o}) − eps_t γ^{-(d+1)})``
        (ties broken by the seeded ``z_jitter``), creating the successor node on first visit.

        **Up.** Deepest first, each parent's cached successor upper bound is lowered to the
        child's, and :meth:`_update` backs up the lower bound (a new α-vector when it gains)
        and lowers the upper bound at the node.

        Legend of the local names:

        ``g`` γ; ``Z`` number of observations; ``d`` depth, ``max_d`` its cap
        (:meth:`_max_depth`); ``path`` the visited ``(node, a·Z + o or −1 at the end, U, C,
        live, seen)``; ``U`` the states reachable from ``b`` in one step; ``C`` ``[A·Z, |U|]``
        the successor beliefs ``b^{a,o}`` on ``U`` (unnormalised zero rows where
        ``P(o|b,a) = 0``); ``live`` the flat indices of the possible ``(a, o)``; ``lb``,
        ``best`` ``[A, Z]`` the lower bound at each successor and the index of its maximising
        α-vector; ``seen`` those plus ``LB(b)`` and ``|Γ|`` (``_update`` then reads only
        vectors added since); ``a``, ``qu`` the action with the largest upper-bound Q-value
        ``R_b(a) + γ Σ_o P(o|b,a) UB(b^{a,o})`` and that value (``_kernel.qvalue``); ``u``,
        ``l`` the bounds at ``b`` (``l`` the largest lower-bound Q-value: a one-step look-ahead
        of the lower bound); ``thr`` the successor's target width ``eps_t γ^{-(d+1)}``; ``o``
        the observation with the largest weighted excess uncertainty (``_kernel.excess_obs``).
        """
        g, Z = self.g, self.Z
        node = self.root if start is None else start
        path: list = []
        d = 0
        max_d = self._max_depth(eps_t)
        while True:
            U, C, live = self.successors(node)
            lb, best = self.lower_children(U, C, live)
            seen = (lb, best, self.lower(node.idx, node.val), self.K)
            a, qu = _kernel.qvalue(node.Rb, node.p, node.ub_c, g, self.A, Z)       # greedy on Q^U
            u = min(node.ub, qu)
            # One-step lookahead of the LB (≥ LB(b) for the uniformly improvable bounds kept here).
            l = _kernel.qvalue(node.Rb, node.p, lb, g, self.A, Z)[1]
            if u - l <= eps_t * g ** (-d) or d >= max_d:
                path.append((node, -1, U, C, live, seen))
                break
            thr = eps_t * g ** (-(d + 1))
            o = _kernel.excess_obs(node.p, node.ub_c, lb, self.z_jitter, a, thr, Z)       # argmax of score
            if node.p[a, o] <= 0.0:
                path.append((node, -1, U, C, live, seen))
                break
            path.append((node, a * Z + o, U, C, live, seen))
            child = node.children.get(a * Z + o)
            if child is None:
                c = C[a * Z + o]
                nz = np.flatnonzero(c > 0.0)
                child = self._node(U[nz], c[nz])
                child.ub = min(child.ub, float(node.ub_c[a, o]))
                node.children[a * Z + o] = child
            w = node.reach * g * float(node.p[a, o])
            if w > child.reach:
                child.reach = w
            node = child
            d += 1
        # Back up along the path, deepest first, refreshing each parent's cached successor bound.
        for i in range(len(path) - 1, -1, -1):
            node, ao, U, C, live, seen = path[i]
            if ao >= 0:
                child = node.children[ao]
                a, o = divmod(ao, Z)
                node.ub_c[a, o] = min(node.ub_c[a, o], child.ub)
            self._update(node, U, C, live, seen)
        self.trials += 1

    def run(self, time_limit: float = 60.0, epsilon: float = 1e-3, progress: bool = False,
            max_trials: Optional[int] = None) -> SolveResult:
        """Search until ``UB(b0) − LB(b0) ≤ epsilon`` or ``time_limit`` seconds (wall clock)."""
        t0 = self._clock()
        bar = None
        if progress:
            from tqdm import tqdm
            bar = tqdm(total=round(time_limit, 1), unit="s", desc=f"pointbased {self.model.name}", leave=False,
                       bar_format="{desc}: {n:.1f}/{total}s {postfix}")
        lo, hi = self.bounds_at_start()
        last_report = t0
        last_hist = -np.inf
        history = self.history
        offset = self.seconds + self.setup_seconds
        start, gap = self._next_start(epsilon)
        converged = start is None
        while not converged:
            now = self._clock()
            if now - t0 >= time_limit or (max_trials is not None and self.trials >= max_trials):
                break
            arm = self._pick_arm()
            eps_t = max(epsilon, self.trial_kappa[arm] * gap) if gap > 10 * epsilon else epsilon * 0.5
            b_before, lo_before = self.backups, self.lower(start.idx, start.val)  # type: ignore[union-attr]
            self.trial(eps_t, start)
            lo_start = self.lower(start.idx, start.val)  # type: ignore[union-attr]
            if self.K * self.S > self.max_gamma_entries:
                self.prune(by_usage=True)
            elif self.K > 2 * self._last_prune_K + 50 and \
                    self.backups - self._backups_at_prune >= min(len(self.nodes), 4 * self._last_prune_K + 200):
                # A prune reads Γ at every node and its successors, the work of one backup per
                # node: amortised over at least that many trial backups (while Γ stays small).
                self.prune()
            lo, hi = self.bounds_at_start()
            converged = self._open_gap(epsilon) is None
            # Discounted totals: an arm's rate follows the recent phase of the search.
            # The lower bound is what the policy is worth, so arms are rated by LB gains
            # (at the belief the trial started from).
            self._arm_gain[arm] = 0.95 * self._arm_gain[arm] + max(lo_start - lo_before, 0.0)
            self._arm_cost[arm] = 0.95 * self._arm_cost[arm] + (self.backups - b_before)
            if not converged and self.ub_sweep_ratio > 0 and \
                    self.backups - self._backups_at_ub_sweep >= self.ub_sweep_ratio * len(self.nodes):
                self.sweep_upper()
                self._backups_at_ub_sweep = self.backups
                lo, hi = self.bounds_at_start()
                converged = self._open_gap(epsilon) is None
            if not converged and self._spread_wait > 0:
                # Backing off: this trial's share of Perseus backups is forgiven, not owed.
                self._spread_wait -= 1
                self.spreads_skipped += 1
                self._perseus_forgiven = int(self.perseus_share * self.backups) - self.perseus_backups
            elif not converged:
                lo_spread = lo
                self.spread_gain = 0.0
                swept = False
                if self.sweep_ratio > 0 and \
                        self.backups - self._trial_backups_at_sweep >= self.sweep_ratio * len(self.nodes):
                    swept = self.belief_set.sweep()
                    if swept:
                        self._trial_backups_at_sweep = self.backups
                spread = swept
                if not swept and self.perseus_share > 0:
                    owed = int(self.perseus_share * self.backups) - self.perseus_backups - self._perseus_forgiven
                    if owed > 0:
                        self.belief_set.perseus(owed)
                        spread = True
                lo, hi = self.bounds_at_start()
                converged = self._open_gap(epsilon) is None
                if spread and self.spread_backoff:
                    # A spread that lifted neither LB(b0) nor the LB at any belief by more than
                    # the target gap (weighted by the belief's reach from b0) doubles the
                    # number of trials the next one waits (up to spread_backoff); one that
                    # did resets it.
                    if lo > lo_spread + 1e-12 * max(1.0, abs(lo_spread)) or \
                            self.spread_gain > epsilon:
                        self._spread_skip = 0
                    else:
                        self._spread_skip = min(self.spread_backoff, max(1, 2 * self._spread_skip))
                        self._spread_wait = self._spread_skip
            if not converged:
                start, gap = self._next_start(epsilon)
                converged = start is None
            if now - last_hist >= 0.5 or converged:
                history.append((round(offset + self._clock() - t0, 3), lo, hi))
                last_hist = now
            if bar is not None and (now - last_report > 0.25 or converged):
                bar.n = round(min(now - t0, time_limit), 1)
                bar.set_postfix_str(f"LB={lo:.6g} UB={hi:.6g} gap={hi - lo:.3g} |Γ|={self.K}")
                last_report = now
        if bar is not None:
            bar.close()
        self.prune()
        lo, hi = self.bounds_at_start()
        self.seconds += self._clock() - t0
        history.append((round(self.setup_seconds + self.seconds, 3), lo, hi))
        policy = AlphaVectorPolicy(self.GT[:, : self.K].T.copy(), self.gact[: self.K].copy())
        return SolveResult(
            policy=policy, method="pointbased", value_at_start=lo, upper_bound=hi,
            iterations=self.trials, seconds=self.seconds, converged=self._open_gap(epsilon) is None,
            extra={
                "gap": hi - lo, "backups": self.backups, "vectors": self.K, "ub_points": self.bound.pt_n,
                "beliefs": len(self.beliefs), "pruned": self.pruned, "fib_iterations": self.bound.fib_iterations, "nodes": len(self.nodes),
                "fib_seconds": self.bound.fib_seconds, "perseus_backups": self.perseus_backups,
                "sweeps": self.sweeps, "sweep_backups": self.sweep_backups, "spreads_skipped": self.spreads_skipped,
                "ub_sweeps": self.ub_sweeps,
                "starts": len(self.starts),
                "max_start_gap": float(self.start_gaps().max()),
                "history": list(history),
            },
        )


#: The values of ``solve_point_based(engine=...)``.
ENGINES = ("auto", "c", "python")
#: The :class:`PointBasedSettings` the C engine reads (of ``trial_kappa`` the first arm). Its
#: lower-bound spreading is round-robin backups from the newest visited belief,
#: ``perseus_share`` of them per trial backup, not Perseus' randomised rounds (so ``seed`` is
#: unused); the bandit over several κ, PBVI sweeps and the pruning knobs are the Python engine's.
C_ENGINE_SETTINGS = ("trial_kappa", "perseus_share", "spread_backoff", "ub_sweep_ratio", "fib_epsilon")


class EngineLacksSetting(ValueError):
    """``solve_point_based(engine="c")`` was given a :class:`PointBasedSettings` knob that only the
    Python engine has (see :data:`C_ENGINE_SETTINGS`): refused, not silently ignored."""


def _search_c(model: Pomdp, time_limit: Optional[float], epsilon: float,
              settings: PointBasedSettings, max_trials: Optional[int]) -> SolveResult:
    """``engine="c"``: the whole search in ``_search_kernel.c`` (HSVI2 with the same bounds as the
    Python engine: blind-policy α-vectors below, FIB vectors and a sawtooth point set above),
    one call, no Python per trial. Its knobs are :data:`C_ENGINE_SETTINGS`: ``trial_kappa[0]``
    (the trials' share of the gap at b0), ``ub_sweep_ratio`` (an upper-bound backup at every
    visited belief after that many trial backups per visited belief), ``perseus_share`` and
    ``spread_backoff`` (its round-robin lower-bound backups) and ``fib_epsilon`` (the start
    bounds' tolerance)."""
    from . import _search_kernel

    t0 = time.perf_counter()
    S, A, Z = model.num_states, model.num_actions, model.num_observations
    g = float(model.discount)
    t_ptr, t_ind, t_dat = _action_rows([_nonzeros(t) for t in model.T], S)
    R = np.ascontiguousarray(model.R, dtype=float)
    O = np.ascontiguousarray(model.O, dtype=float)
    b0 = np.ascontiguousarray(model.b0, dtype=float)
    # The start bounds stop where a further sweep moves no entry by more than this (fib_q's rule).
    init_tol = settings.fib_epsilon * (1.0 - g) / (2.0 * g)
    limit = math.inf if time_limit is None else max(float(time_limit) - (time.perf_counter() - t0), 1e-9)
    out = _search_kernel.search(S, A, Z, g, R, O, t_ptr, t_ind, t_dat, b0, float(epsilon),
                                float(settings.trial_kappa[0]), init_tol, limit, 100_000,
                                0 if max_trials is None else int(max_trials), float(settings.ub_sweep_ratio),
                                float(settings.perseus_share), int(settings.spread_backoff))
    K = int(out["vectors"])
    alphas = np.frombuffer(out["alphas"], dtype=float).reshape(K, S).copy()
    actions = np.frombuffer(out["actions"], dtype=np.int64).copy()
    # The policy's own value at b0 (what the vectors achieve there), the kernel's upper bound.
    lo = float(np.max(alphas @ b0))
    hi = float(out["upper"])
    seconds = time.perf_counter() - t0
    return SolveResult(
        policy=AlphaVectorPolicy(alphas, actions), method="pointbased", value_at_start=lo, upper_bound=hi,
        iterations=int(out["trials"]), seconds=seconds, converged=hi - lo <= epsilon,
        extra={
            "engine": "c", "gap": hi - lo, "kernel_lower": float(out["lower"]), "backups": int(out["backups"]), "vectors": K,
            "ub_points": int(out["ub_points"]), "fib_iterations": int(out["fib_iterations"]),
            "blind_iterations": int(out["blind_iterations"]), "setup_seconds": float(out["init_seconds"]),
            "stop": out["stop"], "perseus_backups": 0, "sweep_backups": 0, "ub_sweeps": int(out["ub_sweeps"]),
            "ub_sweep_backups": int(out["ub_sweep_backups"]), "trial_backups": int(out["trial_backups"]),
            "lb_sweep_backups": int(out["lb_sweep_backups"]), "corner_updates": int(out["corner_updates"]),
            "history": [(round(seconds, 3), lo, hi)],
        },
    )


def solve_point_based(model: Pomdp, time_limit: Optional[float] = 60.0, epsilon: float = 1e-3, seed: int = 0,
                      progress: bool = False, settings: Optional[PointBasedSettings] = None,
                      max_trials: Optional[int] = None, engine: str = "auto") -> SolveResult:
    """Anytime point-based solve with bounds (HSVI2/SARSOP style; see the module docstring).

    Args:
        model: the POMDP (``γ < 1``).
        time_limit: wall-clock seconds for the search (FIB initialisation included);
            ``None``: no clock limit (then ``max_trials`` or ``epsilon`` ends the search).
        epsilon: stop when ``UB(b0) − LB(b0) ≤ epsilon``.
        seed: fixes the Perseus order and tie-breaking among observations.
        progress: show LB/UB/gap on a tqdm line (stderr).
        settings: the tuning knobs (:class:`PointBasedSettings`); default: its defaults.
        max_trials: stop after this many trials. A budget that is not wall-clock time:
            with ``time_limit=None`` the FIB initialisation runs to convergence and the
            search to this count, so the same seed gives the same policy on a busy and a
            quiet machine (the study plans the flat policy this way).
        engine: ``"c"``: the whole search in one C call (``_search_kernel.c``: HSVI2 trials
            with both bounds backed up along each trial's path; no per-trial Python, so small
            and medium files solve in milliseconds; deterministic, ``seed`` unused; no
            progress line); ``"python"``: :class:`PointBasedSolver` (adds Perseus/PBVI
            spreading over the visited beliefs and the tuning knobs of ``settings``);
            ``"auto"`` (the default): ``"c"`` unless ``settings`` or ``progress`` asks for what
            only the Python engine has, or ``max_trials`` is given (a trial budget counts the
            Python engine's trials, which the study's protocols fix). Both return the same
            kind of result: the α-vectors of a lower bound, an upper bound, ``converged`` when
            ``UB(b0) − LB(b0) ≤ epsilon``.

    Returns:
        :class:`SolveResult` with method ``"pointbased"``: the lower-bound α-vectors as the
        policy, ``value_at_start`` = LB(b0), ``upper_bound`` = UB(b0), ``iterations`` = trials,
        ``converged`` when the gap reached ``epsilon``; ``extra`` has ``gap``, ``backups``
        (trial backups), ``perseus_backups``, ``sweeps``, ``vectors``, ``ub_points``, ``beliefs``,
        ``pruned``, ``fib_iterations``, ``setup_seconds`` and ``history`` (``[seconds, LB, UB]``
        about every 0.5 s).
    """
    if max_trials is not None and (isinstance(max_trials, bool) or not isinstance(max_trials, int) or max_trials < 1):
        raise ValueError(f"solve_point_based: max_trials must be an integer >= 1, got {max_trials!r}")
    if time_limit is None and max_trials is None and not epsilon > 0:
        raise ValueError("solve_point_based: with time_limit=None give max_trials or an epsilon > 0")
    if engine not in ENGINES:
        raise ValueError(f"solve_point_based: engine must be one of {', '.join(map(repr, ENGINES))}, got {engine!r}")
    if engine == "auto":
        # A trial budget keeps the Python engine's trials: the study's protocols fix flat
        # policies by a trial count (pearl experiment --flat-trials), and a C trial is another
        # amount of work, so the same count would plan another policy.
        engine = "python" if settings is not None or progress or max_trials is not None else "c"
    if engine == "c":
        if not model.discount < 1.0:
            raise ValueError("the point-based solver needs a discount below 1 (got %g)" % model.discount)
        if not epsilon > 0:
            raise ValueError(f"solve_point_based: engine='c' needs an epsilon > 0, got {epsilon!r}")
        if time_limit is not None and not time_limit > 0:
            raise ValueError(f"solve_point_based: time_limit must be > 0 or None, got {time_limit!r}")
        default = PointBasedSettings()
        python_only = [f"settings.{f.name}" for f in dataclasses.fields(PointBasedSettings)
                       if settings is not None and getattr(settings, f.name) != getattr(default, f.name)
                       and (f.name not in C_ENGINE_SETTINGS or f.name == "trial_kappa" and len(settings.trial_kappa) > 1)]
        if python_only:
            raise EngineLacksSetting(f"solve_point_based: engine='c' has no Perseus rounds, PBVI sweeps, κ bandit or "
                                     f"pruning knobs: {', '.join(python_only)} would be ignored (use engine='python')")
        return _search_c(model, time_limit, epsilon, settings or PointBasedSettings(), max_trials)
    t0 = time.perf_counter()
    # Without a clock limit FIB runs to its own convergence (deterministic), else it
    # gets a tenth of the budget.
    fib_time = None if time_limit is None else max(0.5, 0.1 * time_limit)
    solver = PointBasedSolver(model, seed=seed, fib_time=fib_time, settings=settings)
    setup = time.perf_counter() - t0
    solver.setup_seconds = setup
    search_time = math.inf if time_limit is None else max(0.0, time_limit - setup)
    res = solver.run(time_limit=search_time, epsilon=epsilon, progress=progress, max_trials=max_trials)
    res.seconds = time.perf_counter() - t0
    res.extra["setup_seconds"] = setup
    res.extra["engine"] = "python"
    return res
