"""Solve a POMDP and optionally save the policy.

    pearl solve MODEL [--method incprune|pointbased|qmdp] [--horizon N] [--epsilon E]
                      [--time-limit S] [--out POLICY] [--json]

MODEL is a Cassandra ``.pomdp`` file or a factored domain ``.yaml``.

Methods:
  incprune    exact incremental pruning (Cassandra, Littman & Zhang 1997); finite horizon
              with --horizon, else infinite horizon until the epsilon stop.
  pointbased  point-based α-vector lower bound with an upper bound (the gap is reported);
              anytime, stops at --time-limit (default 60 s) or when the gap at b0 ≤ --epsilon.
  qmdp        the QMDP approximation (one α-vector per action; an upper bound of the optimum).

Default method: incprune when --horizon is given or the model is tiny
(|S|·|A|·|Z| ≤ 32, e.g. tiger: 12, 1d: 16), else pointbased.

--json prints one object: states, actions, observations, method, value_at_start (the
policy's value at b0; a lower bound for pointbased), upper_bound (null if none),
alpha_vectors, iterations, seconds, converged, stop_reason (why it stopped: converged,
horizon, time_limit, vector_cap, or trials for pointbased), and for incprune
vectors_per_epoch, last_residual (the Bellman residual max_b |V_t(b) − V_t−1(b)| between
its last two epochs) and cycle_period (set when the value functions came back to an
earlier epoch's; see docs/solvers.md).
Examples:
  pearl solve config/table4.domain.yaml --time-limit 5 --out table4.npz
  pearl solve config/table4.domain.yaml --method qmdp --json

Progress (tqdm) goes to stderr when it is a terminal and --json is not given; --progress
forces it, --quiet turns it off.
"""
from __future__ import annotations

import argparse
import math
import sys

from pearl_pomdp.cli._progress import add_progress_arguments, show_progress
from pearl_pomdp.errors import PearlError
from pearl_pomdp.solvers.registry import solver_names

COMMAND = "solve"
HELP = "solve a .pomdp or domain .yaml model (incremental pruning, point-based, QMDP)"

METHODS = solver_names()
#: Models with |S|·|A|·|Z| up to this are solved exactly by default.
TINY_MODEL = 32


def _positive_int(text: str) -> int:
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be ≥ 1, got {value}")
    return value


def _positive_float(text: str) -> float:
    value = float(text)
    if not value > 0 or not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"must be a positive number, got {text}")
    return value


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("model", metavar="MODEL", help="a .pomdp file or a factored domain .yaml")
    parser.add_argument("--method", choices=METHODS, default=None,
                        help="solver (default: incprune for tiny models or with --horizon, else pointbased)")
    parser.add_argument("--horizon", type=_positive_int, default=None,
                        help="incprune: number of epochs (default: infinite horizon, stop at --epsilon)")
    parser.add_argument("--epsilon", type=_positive_float, default=None,
                        help="incprune: pruning/stop tolerance (default 1e-9); pointbased: target gap at b0 (default 1e-3)")
    parser.add_argument("--time-limit", type=_positive_float, default=None, metavar="S",
                        help="stop after S seconds (pointbased default 60; incprune default none)")
    parser.add_argument("--trials", type=_positive_int, default=None, metavar="N",
                        help="pointbased: stop after N trials, a budget that does not depend on the machine's "
                             "speed (alone: no time limit; the same seed gives the same policy anywhere)")
    parser.add_argument("--seed", type=int, default=0, help="pointbased: random seed (default 0)")
    parser.add_argument("--out", metavar="POLICY", default=None,
                        help="save the policy: POLICY (.npz) plus its JSON header beside it")
    parser.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    add_progress_arguments(parser)


def default_method(model, horizon=None) -> str:
    """The method used when --method is not given (see the module doc)."""
    if horizon is not None:
        return "incprune"
    size = model.num_states * model.num_actions * model.num_observations
    return "incprune" if size <= TINY_MODEL else "pointbased"


def solve(model, method: str, horizon=None, epsilon=None, time_limit=None, seed=0, progress=False, trials=None):
    """Run ``method`` on ``model`` (looked up in :mod:`pearl_pomdp.solvers.registry`)."""
    from pearl_pomdp.solvers.registry import solve as registry_solve

    if horizon is not None and method != "incprune":
        raise PearlError(f"--horizon applies to incprune only, not to {method}")
    if trials is not None and method != "pointbased":
        raise PearlError(f"--trials applies to pointbased only, not to {method}")
    return registry_solve(model, method, horizon=horizon, epsilon=epsilon, time_limit=time_limit, seed=seed,
                          progress=progress, trials=trials, where="--method")


def stop_reason(result, trials=None) -> str:
    """Why a solve stopped: the solver's own ``extra["stop_reason"]`` (incprune), else
    ``converged``, ``trials`` (pointbased's trial budget) or ``time_limit``."""
    reason = result.extra.get("stop_reason")
    if reason:
        return str(reason)
    if result.converged:
        return "converged"
    if trials is not None and result.iterations >= trials:
        return "trials"
    return "time_limit"


def summary(model, result, trials=None) -> dict:
    """The --json object for a :class:`~pearl_pomdp.solution.SolveResult`."""
    out = {
        "model": model.name,
        "states": model.num_states,
        "actions": model.num_actions,
        "observations": model.num_observations,
        "discount": model.discount,
        "method": result.method,
        "value_at_start": float(result.value_at_start),
        "upper_bound": None if result.upper_bound is None else float(result.upper_bound),
        "gap": None if result.upper_bound is None else float(result.upper_bound - result.value_at_start),
        "alpha_vectors": int(result.policy.alphas.shape[0]),
        "iterations": int(result.iterations),
        "seconds": float(result.seconds),
        "converged": bool(result.converged),
        "stop_reason": stop_reason(result, trials),
    }
    if result.method == "incprune":
        out["vectors_per_epoch"] = [int(v) for v in result.vectors_per_epoch]
        residual = result.extra.get("last_residual")
        out["last_residual"] = None if residual is None else float(residual)
        out["cycle_period"] = result.extra.get("cycle_period")
    return out


def run(args: argparse.Namespace) -> int:
    from pearl_pomdp.cli import print_json
    from pearl_pomdp.model import load_model

    from pearl_pomdp.cli._inputs import require_file

    model = load_model(require_file(args.model, "model file (.pomdp, .pomdpx or domain .yaml)"))
    method = args.method or default_method(model, args.horizon)
    result = solve(model, method, horizon=args.horizon, epsilon=args.epsilon, time_limit=args.time_limit,
                   seed=args.seed, progress=show_progress(args), trials=args.trials)
    info = summary(model, result, args.trials)
    if args.horizon is not None:
        info["horizon"] = args.horizon
    if args.out:
        from pearl_pomdp.policy_io import header_path, save_policy

        meta = {k: info[k] for k in ("method", "value_at_start", "upper_bound", "seconds", "iterations", "converged",
                                     "stop_reason")}
        meta.update({"horizon": args.horizon, "epsilon": args.epsilon, "time_limit": args.time_limit,
                     "trials": args.trials, "source": str(args.model)})
        if "vectors_per_epoch" in info:
            meta["vectors_per_epoch"] = info["vectors_per_epoch"]
        path = save_policy(args.out, result.policy, model, meta)
        info["policy"] = str(path)
        info["policy_header"] = str(header_path(path))
    if args.json:
        print_json(info)
        return 0
    gamma = f"γ = {model.discount:g}"
    print(f"{model.name}: {model.num_states} states, {model.num_actions} actions, "
          f"{model.num_observations} observations ({gamma})")
    reason = info["stop_reason"]
    if reason == "horizon":
        stop = f"horizon {args.horizon} reached"
    elif reason == "converged":
        stop = "converged"
        if info.get("cycle_period"):
            stop += f": the value function repeats the one {info['cycle_period']} epochs before"
    elif reason == "trials":
        stop = f"stopped after {args.trials} trials before converging"
    elif reason == "vector_cap":
        cap = result.extra.get("vector_cap") or {}
        stop = (f"stopped before converging: {cap.get('where', 'a set')} would hold {cap.get('vectors')} vectors, "
                f"more than the cap of {cap.get('max_vectors')}")
    elif reason == "time_limit":
        stop = "stopped by the time limit before converging"
    else:
        stop = "not converged"
    what = "epochs" if result.method == "incprune" else "iterations"
    print(f"{result.method}: {info['alpha_vectors']} α-vectors after {info['iterations']} {what} "
          f"in {info['seconds']:.3f} s ({stop})")
    line = f"V(b0) = {info['value_at_start']:.10g}"
    if info["upper_bound"] is not None:
        line += f"   upper bound {info['upper_bound']:.10g}   gap {info['gap']:.4g}"
    if info.get("last_residual") is not None:
        line += f"   last residual {info['last_residual']:.3g}"
    print(line)
    if result.method == "incprune" and info["vectors_per_epoch"] and len(info["vectors_per_epoch"]) <= 30:
        print("vectors per epoch: " + " ".join(map(str, info["vectors_per_epoch"])))
    if args.out:
        print(f"policy written to {info['policy']} (header {info['policy_header']})")
    sys.stdout.flush()
    return 0
