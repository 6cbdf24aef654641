"""Explain a decision: the EXECUTE trace (root → … → primitive) with each subtask's value.

Examples (after `pearl plan config/pearl.domain.yaml`, which saves out/policies/pearl):
  pearl explain config/pearl.domain.yaml --belief 'UserPresent=yes,ReminderGoal=physio:0.7|none:0.3'
  pearl explain config/pearl.domain.yaml out/policies/pearl --belief UserLocation=physio --json

POLICY is a directory written by `pearl plan`; without it, the default one of `pearl plan
DOMAIN` (out/policies/NAME) is used. --belief gives per-feature marginals: `Feature=value`
(certain) or `Feature=v1:p1|v2:p2` (a distribution; quote it: `|` is the shell's pipe).
Features not given keep their start-belief marginal, and the belief is the product of the
marginals.
"""
from __future__ import annotations

import argparse
import math
from typing import TYPE_CHECKING

from pearl_pomdp.errors import BeliefError

if TYPE_CHECKING:  # numpy itself is imported where it is used, not when `pearl --help` loads this module
    import numpy as np

COMMAND = "explain"
HELP = "print the EXECUTE trace of a planned hierarchical policy at a belief"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("domain", help="factored domain .yaml the policy was planned for")
    parser.add_argument("policy", nargs="?", default=None,
                        help="policy directory from `pearl plan` (default: out/policies/NAME, where it saves)")
    parser.add_argument("--belief", default="", help="Feature=value or Feature=v1:p1|v2:p2, comma separated")
    parser.add_argument("--json", action="store_true", help="print one JSON object")


def belief_from_spec(domain, spec: str) -> np.ndarray:
    """The product-of-marginals belief described by ``spec`` (see the command help)."""
    import numpy as np  # here, not at module top: `pearl --help` imports every command module

    b0 = domain.compile().b0
    marginals = domain.feature_marginals(b0)
    names = [f.name for f in domain.features]
    for part in filter(None, (p.strip() for p in spec.split(","))):
        if "=" not in part:
            raise BeliefError(f"--belief: {part!r} is not Feature=value")
        feat, rhs = (x.strip() for x in part.split("=", 1))
        if feat not in names:
            raise BeliefError(f"--belief: unknown feature {feat!r}; known: {', '.join(names)}")
        values = list(domain.features[names.index(feat)].values)
        dist = np.zeros(len(values))
        for item in rhs.split("|"):
            value, _, prob = item.partition(":")
            value = value.strip()
            if value not in values:
                raise BeliefError(f"--belief: unknown value {value!r} of {feat}; expected one of: {', '.join(values)}")
            try:
                dist[values.index(value)] = float(prob) if prob else 1.0
            except ValueError:
                raise BeliefError(f"--belief: {feat}: probability {prob!r} is not a number") from None
        if dist.min() < 0 or not math.isclose(dist.sum(), 1.0, abs_tol=1e-6):
            raise BeliefError(f"--belief: {feat}: probabilities sum to {dist.sum():g}, expected 1")
        marginals[feat] = dist
    sv = np.asarray(domain.state_values)
    b = np.ones(sv.shape[0])
    for f, name in enumerate(names):
        b *= np.asarray(marginals[name])[sv[:, f]]
    return b / b.sum()


def run(args: argparse.Namespace) -> int:
    import numpy as np

    from pearl_pomdp.cli import print_json
    from pearl_pomdp.cli.plan import default_policy_dir, load_domain_any
    from pearl_pomdp.errors import PolicyError
    from pearl_pomdp.hierarchy import load_hierarchical_policy

    domain = load_domain_any(args.domain)
    from pearl_pomdp.model.factored import FactoredDomain

    if not isinstance(domain, FactoredDomain):
        raise BeliefError("explain needs a factored domain (.yaml) to read --belief")
    policy_dir = args.policy or default_policy_dir(args.domain)
    if not args.policy and not policy_dir.is_dir():
        raise PolicyError(f"{policy_dir}: no policy planned for {args.domain} here; run `pearl plan {args.domain}` "
                          f"first (it saves there), or give POLICY")
    policy = load_hierarchical_policy(policy_dir, domain)
    b = belief_from_spec(domain, args.belief)
    decision = policy.execute(b)
    if args.json:
        out = decision.as_dict()
        out["marginals"] = {k: np.asarray(v).tolist() for k, v in domain.feature_marginals(b).items()}
        print_json(out)
        return 0
    for name, m in domain.feature_marginals(b).items():
        values = domain.features[[f.name for f in domain.features].index(name)].values
        print(f"  {name:<15} " + "  ".join(f"{v}={p:.3f}" for v, p in zip(values, m)))
    for depth, step in enumerate(decision.trace):
        print(f"{'  ' * depth}{step.subtask} → {step.choice}   V={step.value:.3f}")
    print(f"action: {decision.action_name}")
    return 0
