"""Run the paper's Figure 4 scenario (or another) through the full ROS 2 graph.

The Pearl nodes and simulated hardware run in one process under simulated time;
prints a transcript, writes a bag, the transcript and a belief plot into --out,
and ends with a one-line outcome.

Examples:
  pearl demo --scenario config/scenarios/table4_dialog.yaml --seed 3
  pearl plan config/pearl.domain.yaml && pearl demo --policy out/policies/pearl --json
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

COMMAND = "demo"
HELP = "run a scenario through the full graph (Pearl nodes + simulated hardware) and print the transcript"


def _share(relative: str) -> str:
    """A file from the source tree, or the installed share/pearl_pomdp."""
    here = Path(__file__).resolve().parents[2] / relative
    if here.exists():
        return str(here)
    return str(Path(sys.prefix) / "share" / "pearl_pomdp" / relative)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--scenario", default=_share("config/scenarios/figure4.yaml"), help="scenario file")
    parser.add_argument("--domain", default=_share("config/pearl.domain.yaml"), help="factored domain")
    parser.add_argument("--hierarchy", default=_share("config/pearl.hierarchy.yaml"), help="action hierarchy")
    parser.add_argument("--policy", default="",
                        help="planned policy folder (`pearl plan` saves out/policies/pearl); default: plan now")
    parser.add_argument("--out", default=None, help="output folder (default: out/demo-<scenario>-<time>)")
    parser.add_argument("--seed", type=int, default=None, help="override the scenario's seed")
    parser.add_argument("--domain-id", type=int, default=None, help="ROS_DOMAIN_ID of the in-process graph")
    parser.add_argument("--json", action="store_true", help="print one JSON object instead of the transcript")


def run(args: argparse.Namespace) -> int:
    from pearl_pomdp.cli import print_json
    from pearl_sim.demo import run_demo, summary_dict

    from pearl_pomdp.cli._inputs import require_dir, require_file
    from pearl_pomdp.errors import PearlError
    from pearl_sim.scenario import load_scenarios

    # Check every input before planning or starting the graph (a typo fails at once).
    require_file(args.scenario, "scenario file (--scenario)")
    require_file(args.domain, "domain file (--domain)")
    if args.policy:
        require_dir(args.policy, "policy directory (--policy, from `pearl plan`)")
    else:
        require_file(args.hierarchy, "hierarchy file (--hierarchy)")
    load_scenarios(args.scenario)  # parse errors name the file and field
    out = Path(args.out) if args.out else Path("out") / f"demo-{Path(args.scenario).stem}-{time.strftime('%Y%m%d-%H%M%S')}"
    if (out / "bag").is_dir() and any((out / "bag").iterdir()):
        raise PearlError(f"{out / 'bag'}: already holds a bag; choose another --out folder")
    echo = None if args.json else (lambda text: print(text, flush=True))
    if not args.json:
        print(f"pearl demo: scenario {args.scenario}; planning the policy and starting the graph…", flush=True)
    result = run_demo(Path(args.scenario), out, domain_path=Path(args.domain), hierarchy_path=Path(args.hierarchy),
                      policy=args.policy, seed=args.seed, domain_id=args.domain_id, echo=echo)
    if args.json:
        print_json(summary_dict(result))
    else:
        print(f"wrote {result.transcript}, {result.plot}, {result.bag} ({result.seconds:.1f} s)")
        print(result.outcome())
    return 0 if result.metrics.get("guidances_completed") or not result.metrics.get("guidances_started") else 1
