"""Estimate a policy's mean discounted return by simulation.

    pearl simulate MODEL POLICY [--episodes N] [--steps T] [--seed K] [--json]

MODEL is the model the policy was solved for (``.pomdp`` or domain ``.yaml``); POLICY is a
policy spec (:func:`pearl_pomdp.deciders.load_decider`): a file written by ``pearl solve --out``
(its header must carry MODEL's fingerprint), a directory written by ``pearl plan --out``, or
``online`` / ``online:TRIALS``: DESPOT at every step (docs/online.md).
Episodes start from b0, track the belief with eq. 5 and sum ``γ^t R[s_t, a_t]``.

--json prints one object: mean, ci95 (half width of the 95 % confidence interval of the
mean, 1.96·s/√N), episodes, steps, seed, std, min, max, interval ([mean − ci95, mean + ci95]),
seconds. Default --steps: until γ^T < 1e-3 (135 for γ = 0.95).

Examples:
  pearl solve config/table4.domain.yaml --time-limit 5 --out table4.npz
  pearl simulate config/table4.domain.yaml table4.npz --episodes 200 --json
"""
from __future__ import annotations

import argparse

from pearl_pomdp.cli._progress import add_progress_arguments, show_progress

COMMAND = "simulate"
HELP = "mean discounted return of a saved policy, with a 95% confidence interval"


def _positive_int(text: str) -> int:
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be ≥ 1, got {value}")
    return value


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("model", metavar="MODEL", help="the .pomdp file or domain .yaml the policy was solved for")
    parser.add_argument("policy", metavar="POLICY", help="policy .npz written by `pearl solve --out`, a "
                        "directory from `pearl plan --out`, or online[:TRIALS] to plan online (DESPOT)")
    parser.add_argument("--episodes", type=_positive_int, default=1000, help="number of episodes (default 1000)")
    parser.add_argument("--steps", type=_positive_int, default=None,
                        help="steps per episode (default: until γ^T < 1e-3)")
    parser.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    parser.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    add_progress_arguments(parser)


def run(args: argparse.Namespace) -> int:
    from pearl_pomdp.cli import print_json
    from pearl_pomdp.cli._inputs import require_file
    from pearl_pomdp.deciders import load_decider
    from pearl_pomdp.model import load_model
    from pearl_pomdp.simulate import simulate

    model = load_model(require_file(args.model, "model file (.pomdp, .pomdpx or domain .yaml)"))
    policy = load_decider(args.policy, model, seed=args.seed, where="POLICY")
    result = simulate(model, policy, episodes=args.episodes, steps=args.steps, seed=args.seed,
                      progress=show_progress(args))
    result.pop("returns")
    result = {"model": model.name, "policy": str(args.policy), **result}
    if args.json:
        print_json(result)
        return 0
    print(f"{model.name}, policy {args.policy}: mean discounted return {result['mean']:.6g} ± {result['ci95']:.3g} "
          f"(95% CI; {result['episodes']} episodes × {result['steps']} steps, seed {result['seed']}; "
          f"std {result['std']:.4g}, min {result['min']:.4g}, max {result['max']:.4g})")
    if result["zero_likelihood"]:
        print(f"warning: {result['zero_likelihood']} zero-likelihood belief updates were recovered")
    return 0
