"""Plan a hierarchical policy: PARAMETERIZE, abstract (eq. 18) and SOLVE every subtask bottom-up.

Examples:
  pearl plan config/pearl.domain.yaml            # saves out/policies/pearl (explain/hierarchy find it)
  pearl plan config/reception.domain.yaml --hierarchy config/reception.hierarchy.yaml --out my-policies/reception
  pearl plan config/pearl.domain.yaml --json --no-save

Hierarchy: --hierarchy FILE, else DOMAIN's sibling NAME.hierarchy.yaml (for NAME.domain.yaml
or NAME.yaml). When there is none, the domain is planned flat (one root subtask over every
primitive, the point-based solver with its default trial budget) with a warning naming the
file that was looked for; --flat plans flat on purpose (no warning).

Budgets: each subtask's solver stops at its own budget (the hierarchy file's `trials`, a count
that does not depend on the machine, so the same files give the same policy anywhere).
--time-limit S is a guard over the whole plan: a subtask gets at most what is left of S, and
the report says which were cut short. A subtask asked to be solved exactly (`solver:
incprune`) that does not converge within its budget is planned point-based instead, and says
so. Every subtask reports the bounds it reached at b0 (LB, UB and their gap).

The policy is saved to --out DIR, by default out/policies/NAME under the current directory,
where `pearl explain DOMAIN` and `pearl hierarchy DOMAIN` look for it; --no-save keeps nothing.
The --json object has `subtasks` (name, states_full, states_abstract, observations_full,
observations_abstract, actions, solver, alpha_vectors, seconds, ...), `total_seconds`,
`hierarchy_file` (null when flat) and `out` (the saved directory, null with --no-save).
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
    group = parser.add_mutually_exclusive_group()
    group.add_argument("--hierarchy", help="action hierarchy .yaml (default: NAME.hierarchy.yaml beside the domain)")
    group.add_argument("--flat", action="store_true",
                       help="plan flat (one root subtask over every primitive) without looking for a hierarchy")
    save = parser.add_mutually_exclusive_group()
    save.add_argument("--out", help="directory to save the policy in (policy.npz + hierarchy.json); "
                                    "default out/policies/NAME")
    save.add_argument("--no-save", action="store_true", help="do not save the policy")
    parser.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    parser.add_argument("--no-abstraction", action="store_true", help="solve every subtask on the full state/observation sets")
    parser.add_argument("--solver", choices=["incprune", "pointbased"], help="override every subtask's solver")
    parser.add_argument("--seed", type=int, default=0, help="seed of the point-based solver")
    parser.add_argument("--time-limit", type=float, metavar="S",
                        help="seconds for the whole plan: a guard over the subtasks' own budgets (default: none)")
    parser.add_argument("--strict", action="store_true", help="fail on a local reward assumption violation")
    add_progress_arguments(parser)


#: Where `pearl plan` saves a domain's policy when --out is not given (relative to the current
#: directory, like the demo's out/demo-…), and where `explain` and `hierarchy` look for it.
DEFAULT_POLICY_ROOT = Path("out") / "policies"

_DOMAIN_SUFFIXES = (".domain.yaml", ".domain.yml", ".yaml", ".yml", ".pomdp", ".pomdpx")


def domain_name(domain_path: Path) -> str:
    """``pearl`` for ``pearl.domain.yaml`` / ``pearl.yaml`` / ``pearl.pomdp``: the NAME of the doc."""
    name = Path(domain_path).name
    for suffix in _DOMAIN_SUFFIXES:
        if name.lower().endswith(suffix):
            return name[: -len(suffix)]
    return Path(domain_path).stem


def hierarchy_candidate(domain_path: Path) -> Path:
    """The hierarchy file looked for beside ``domain_path``: ``NAME.hierarchy.yaml``."""
    return Path(domain_path).with_name(domain_name(domain_path) + ".hierarchy.yaml")


def declared_name(domain_path: Path):
    """The ``name:`` a YAML domain declares at its top level (read line by line, no parsing), or ``None``."""
    import re

    if Path(domain_path).suffix.lower() not in (".yaml", ".yml"):
        return None
    try:
        with open(domain_path, encoding="utf-8") as fh:
            for line in fh:
                found = re.match(r"name:\s*['\"]?([A-Za-z0-9_.-]+)", line)
                if found:
                    return found.group(1)
    except OSError:
        return None
    return None


def default_hierarchy(domain_path: Path):
    """``NAME.hierarchy.yaml`` beside ``NAME.domain.yaml`` / ``NAME.yaml``; else the hierarchy of the
    domain's declared ``name:`` beside it (``pearl_day.domain.yaml``, a refit of ``name: pearl``,
    plans with ``pearl.hierarchy.yaml``); else ``None``."""
    candidate = hierarchy_candidate(domain_path)
    if candidate.is_file():
        return candidate
    declared = declared_name(Path(domain_path))
    if declared and declared != domain_name(Path(domain_path)):
        by_name = Path(domain_path).with_name(declared + ".hierarchy.yaml")
        if by_name.is_file():
            return by_name
    return None


def default_policy_dir(domain_path) -> Path:
    """``out/policies/NAME``: where `pearl plan DOMAIN` saves without --out."""
    return DEFAULT_POLICY_ROOT / domain_name(Path(domain_path))


def load_domain_any(path: str):
    """A FactoredDomain for .yaml, else the flat model (:func:`pearl_pomdp.model.load_domain_or_model`)."""
    from pearl_pomdp.cli._inputs import require_file
    from pearl_pomdp.model import load_domain_or_model

    return load_domain_or_model(require_file(path, "domain file"))


def resolve_hierarchy_path(domain_path: str, hierarchy_path, flat: bool = False, warn=None):
    """The hierarchy file to plan with, or ``None`` for the flat hierarchy.

    ``hierarchy_path`` if given; else ``NAME.hierarchy.yaml`` beside the domain; else ``None``,
    calling ``warn`` (e.g. a print to stderr) with a line that names the file looked for —
    unless ``flat`` asked for the flat hierarchy.
    """
    if flat:
        return None
    if hierarchy_path:
        from pearl_pomdp.cli._inputs import require_file

        return require_file(hierarchy_path, "hierarchy file (--hierarchy)")
    found = default_hierarchy(Path(domain_path))
    if found is None and warn is not None:
        warn(f"no --hierarchy given and no {hierarchy_candidate(Path(domain_path))} beside the domain: "
             f"planning flat (one root subtask over every primitive; slow and inexact for a large domain). "
             f"Give --hierarchy FILE, or --flat to plan flat without this warning.")
    return found


def load_hierarchy_for(domain, domain_path: str, hierarchy_path, flat: bool = False, warn=None):
    """The Hierarchy for :func:`resolve_hierarchy_path`'s file, or the flat hierarchy."""
    from pearl_pomdp.hierarchy import flat_hierarchy, load_hierarchy

    path = resolve_hierarchy_path(domain_path, hierarchy_path, flat=flat, warn=warn)
    if path is None:
        return flat_hierarchy(list(domain.actions))
    return load_hierarchy(path, domain)


def warn_on_stderr(command: str):
    """A ``warn`` callable printing ``pearl COMMAND: warning: …`` on stderr."""
    return lambda text: print(f"pearl {command}: warning: {text}", file=sys.stderr, flush=True)


def run(args: argparse.Namespace) -> int:
    from pearl_pomdp.cli import print_json
    from pearl_pomdp.hierarchy import plan
    from pearl_pomdp.hierarchy.plan import horizon_text

    logging.basicConfig(level=logging.WARNING, format="pearl plan: warning: %(message)s", stream=sys.stderr)
    if args.time_limit is not None and not args.time_limit > 0:
        from pearl_pomdp.errors import PearlError

        raise PearlError(f"--time-limit must be a positive number of seconds, got {args.time_limit}")
    domain = load_domain_any(args.domain)
    hierarchy_file = resolve_hierarchy_path(args.domain, args.hierarchy, flat=args.flat, warn=warn_on_stderr("plan"))
    hierarchy = load_hierarchy_for(domain, args.domain, hierarchy_file, flat=hierarchy_file is None)
    policy = plan(domain, hierarchy, abstraction=not args.no_abstraction, solver=args.solver, seed=args.seed,
                  progress=show_progress(args), strict_local_reward=args.strict, time_limit=args.time_limit)
    policy.report["hierarchy_file"] = None if hierarchy_file is None else str(hierarchy_file)
    report = dict(policy.report)
    report["out"] = None if args.no_save else str(policy.save(args.out or default_policy_dir(args.domain)))
    if args.json:
        print_json(report)
        return 0
    print(f"{report['domain']} / {report['hierarchy']}: {len(report['subtasks'])} subtasks in "
          f"{report['total_seconds']:.2f} s")
    print(f"{'subtask':<12} {'states':>11} {'obs':>8} {'actions':>7} {'solver':>10} {'stop':>9} {'h':>4} {'LB':>9} "
          f"{'UB':>9} {'gap':>8} {'|Γ|':>5} {'s':>7}  relevant features")
    for r in report["subtasks"]:
        ub = r.get("upper_bound")
        stop = r.get("stop_reason") or ("exact" if r["exact"] else "-")
        ub_text = "-" if ub is None else f"{ub:.3f}"
        gap_text = "-" if ub is None else f"{ub - r['value_at_start']:.3g}"
        print(f"{r['name']:<12} {r['states_full']:>5}→{r['states_abstract']:<5} {r['observations_full']:>3}→{r['observations_abstract']:<4}"
              f" {len(r['actions']):>7} {r['solver']:>10} {stop:>9} {horizon_text(r):>4} {r['value_at_start']:>9.3f}"
              f" {ub_text:>9} {gap_text:>8} {r['alpha_vectors']:>5} {r['seconds']:>7.2f}"
              f"  {', '.join(r['relevant_features']) or '-'}")
        for w in r["warnings"]:
            print(f"  warning: {w}")
    if report["out"]:
        print(f"saved to {report['out']}")
    return 0
