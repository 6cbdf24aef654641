"""Solvers by name: the one table the CLI, PLAN and the experiment look them up in.

Each entry is a :class:`~pearl_pomdp.interfaces.Solver`: ``solve(model, **options) ->
SolveResult``. The options every entry understands are ``horizon``, ``epsilon``,
``time_limit``, ``seed`` and ``progress``; ``None`` means the solver's own default, and
an option a solver has no use for must be ``None`` (a finite horizon given to the
point-based solver is an error, not silently ignored). Solver modules are imported
when first used, so ``pearl --help`` does not load them.

=============  ==============================================================
name           solver
=============  ==============================================================
``incprune``   exact incremental pruning (Cassandra, Littman & Zhang 1997)
``pointbased`` point-based lower bound with an upper bound (HSVI2/SARSOP style)
``qmdp``       QMDP (one α-vector per action; an upper bound of the optimum)
=============  ==============================================================
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Any, Dict, Optional, Tuple

from pearl_pomdp.errors import PearlError

if TYPE_CHECKING:  # pragma: no cover - typing only (interfaces imports numpy: `pearl --help` must not)
    from pearl_pomdp.interfaces import Solver
    from pearl_pomdp.model.pomdp import Pomdp
    from pearl_pomdp.solution import SolveResult

__all__ = ["SOLVERS", "solve", "solver_names"]


def _incprune(model: "Pomdp", *, horizon: Optional[int] = None, epsilon: Optional[float] = None,
              time_limit: Optional[float] = None, seed: Optional[int] = None, progress: bool = False,
              trials: Optional[int] = None) -> "SolveResult":
    if trials is not None:
        raise PearlError("a trial budget applies to pointbased only, not to incprune")
    from pearl_pomdp.solvers.incremental_pruning import solve_incremental_pruning

    kwargs: Dict[str, Any] = {"horizon": horizon, "time_limit": time_limit, "progress": progress}
    if epsilon is not None:
        kwargs["epsilon"] = epsilon
    return solve_incremental_pruning(model, **kwargs)


def _pointbased(model: "Pomdp", *, horizon: Optional[int] = None, epsilon: Optional[float] = None,
                time_limit: Optional[float] = None, seed: Optional[int] = None, progress: bool = False,
                trials: Optional[int] = None) -> "SolveResult":
    from pearl_pomdp.solvers.point_based import solve_point_based

    if horizon is not None:
        raise PearlError("a finite horizon applies to incprune only, not to pointbased")
    # A trial budget alone is deterministic (no clock); neither given: 60 s.
    default_time = None if trials is not None else 60.0
    kwargs: Dict[str, Any] = {"time_limit": default_time if time_limit is None else time_limit,
                              "seed": 0 if seed is None else seed, "progress": progress, "max_trials": trials}
    if epsilon is not None:
        kwargs["epsilon"] = epsilon
    return solve_point_based(model, **kwargs)


def _qmdp(model: "Pomdp", *, horizon: Optional[int] = None, epsilon: Optional[float] = None,
          time_limit: Optional[float] = None, seed: Optional[int] = None, progress: bool = False,
          trials: Optional[int] = None) -> "SolveResult":
    if trials is not None:
        raise PearlError("a trial budget applies to pointbased only, not to qmdp")
    from pearl_pomdp.solvers.mdp import solve_qmdp

    if horizon is not None:
        raise PearlError("a finite horizon applies to incprune only, not to qmdp")
    return solve_qmdp(model) if epsilon is None else solve_qmdp(model, epsilon=epsilon)


#: name → solver (see the module doc).
SOLVERS: Dict[str, "Solver"] = {"incprune": _incprune, "pointbased": _pointbased, "qmdp": _qmdp}


def solver_names() -> Tuple[str, ...]:
    """The registered names, in table order."""
    return tuple(SOLVERS)


def solve(model, name: str, *, horizon: Optional[int] = None, epsilon: Optional[float] = None,
          time_limit: Optional[float] = None, seed: Optional[int] = None, progress: bool = False,
          trials: Optional[int] = None, where: str = "solver") -> "SolveResult":
    """Run the solver called ``name`` on ``model``.

    Args:
        trials: pointbased only: stop after this many trials, a budget that does not
            depend on the machine's speed (with no ``time_limit``, no clock is involved).
        where: how the caller names the field in errors (``--method``, ``subtask 'Act': solver``).

    Raises:
        PearlError: unknown name, an option the solver cannot take, or a solver module that
            cannot be imported here.
    """
    try:
        solver = SOLVERS[name]
    except KeyError:
        raise PearlError(f"{where}: unknown solver {name!r}; choose one of {', '.join(SOLVERS)}") from None
    try:
        return solver(model, horizon=horizon, epsilon=epsilon, time_limit=time_limit, seed=seed, progress=progress,
                      trials=trials)
    except ImportError as err:
        raise PearlError(f"{where}: solver {name} is not available in this installation ({err})") from None
