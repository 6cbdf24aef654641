"""Plan a hierarchical policy: PARAMETERIZE, abstract (eq. 18) and SOLVE every subtask bottom-up.

Examples:
  pearl plan config/pearl.domain.yaml --hierarchy config/pearl.hierarchy.yaml --out policies/pearl
  pearl plan config/pearl.domain.yaml --json        # uses config/pearl.hierarchy.yaml beside the domain

Without --hierarchy, DOMAIN's sibling NAME.hierarchy.yaml is used (for NAME.domain.yaml or
NAME.yaml), else the flat hierarchy (one root subtask over every primitive).
The --json object has `subtasks` (name, states_full, states_abstract, observations_full,
observations_abstract, actions, solver, alpha_vectors, seconds, ...) and `total_seconds`.
"""
from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path

from pearl_pomdp.cli._progress import add_progress_arguments, show_progress

COMMAND = "plan"
HELP = "plan a hierarchical policy (PLAN/SOLVE with abstraction) for a factored domain"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("domain", help="factored domain .yaml (or a .pomdp model: no feature abstraction)")
    parser.add_argument("--hierarchy", help="action hierarchy .yaml (default: NAME.hierarchy.yaml beside the domain)")
    parser.add_argument("--out", help="directory to save the policy in (policy.npz + hierarchy.json)")
    parser.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    parser.add_argument("--no-abstraction", action="store_true", help="solve every subtask on the full state/observation sets")
    parser.add_argument("--solver", choices=["incprune", "pointbased"], help="override every subtask's solver")
    parser.add_argument("--seed", type=int, default=0, help="seed of the point-based solver")
    parser.add_argument("--strict", action="store_true", help="fail on a local reward assumption violation")
    add_progress_arguments(parser)


def default_hierarchy(domain_path: Path):
    """``NAME.hierarchy.yaml`` beside ``NAME.domain.yaml`` / ``NAME.yaml``, or ``None``."""
    stem = domain_path.name
    for suffix in (".domain.yaml", ".domain.yml", ".yaml", ".yml", ".pomdp"):
        if stem.endswith(suffix):
            candidate = domain_path.with_name(stem[: -len(suffix)] + ".hierarchy.yaml")
            if candidate.is_file():
                return candidate
            break
    return None


def load_domain_any(path: str):
    """A FactoredDomain for .yaml, else the flat model from :func:`pearl_pomdp.model.load_model`."""
    p = Path(path)
    if not p.is_file():
        raise FileNotFoundError(2, "no such domain file", str(p))
    if p.suffix.lower() in (".yaml", ".yml"):
        from pearl_pomdp.model.factored import load_domain

        return load_domain(p)
    from pearl_pomdp.model import load_model

    return load_model(p)


def load_hierarchy_for(domain, domain_path: str, hierarchy_path):
    from pearl_pomdp.hierarchy import flat_hierarchy, load_hierarchy

    path = Path(hierarchy_path) if hierarchy_path else default_hierarchy(Path(domain_path))
    if path is None:
        return flat_hierarchy(list(domain.actions))
    return load_hierarchy(path, domain)


def run(args: argparse.Namespace) -> int:
    from pearl_pomdp.cli import print_json
    from pearl_pomdp.hierarchy import plan
    from pearl_pomdp.hierarchy.plan import horizon_text

    logging.basicConfig(level=logging.WARNING, format="pearl plan: warning: %(message)s", stream=sys.stderr)
    domain = load_domain_any(args.domain)
    hierarchy = load_hierarchy_for(domain, args.domain, args.hierarchy)
    policy = plan(domain, hierarchy, abstraction=not args.no_abstraction, solver=args.solver, seed=args.seed,
                  progress=show_progress(args), strict_local_reward=args.strict)
    report = dict(policy.report)
    if args.out:
        report["out"] = str(policy.save(args.out))
    if args.json:
        print_json(report)
        return 0
    print(f"{report['domain']} / {report['hierarchy']}: {len(report['subtasks'])} subtasks in "
          f"{report['total_seconds']:.2f} s")
    print(f"{'subtask':<12} {'states':>11} {'obs':>8} {'actions':>7} {'solver':>10} {'exact':>5} {'h':>4} {'|Γ|':>5} {'s':>7}  relevant features")
    for r in report["subtasks"]:
        print(f"{r['name']:<12} {r['states_full']:>5}→{r['states_abstract']:<5} {r['observations_full']:>3}→{r['observations_abstract']:<4}"
              f" {len(r['actions']):>7} {r['solver']:>10} {('yes' if r['exact'] else 'no'):>5} {horizon_text(r):>4} {r['alpha_vectors']:>5}"
              f" {r['seconds']:>7.2f}  {', '.join(r['relevant_features']) or '-'}")
        for w in r["warnings"]:
            print(f"  warning: {w}")
    if args.out:
        print(f"saved to {report['out']}")
    return 0
