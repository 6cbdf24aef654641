"""Run the paper's Figure 4 scenario (or another) through the full ROS 2 graph.

The Pearl nodes and simulated hardware run in one process under simulated time;
prints a transcript, writes a bag, the transcript and a belief plot into --out,
and ends with a one-line outcome. The episode runs until Pearl has left for its station or
30 minutes of simulated time (Figure 4(f)); the default domain is Pearl's as fitted on working
days, whose plan ships with it (config/plans/pearl_day). The policy is the one `pearl plan` saved in
out/policies/NAME when it fits the domain (else the demo plans; --replan forces it); a copy
goes beside the bag so that `pearl replay` needs nothing else. With --foxglove the demo
serves a live view (belief marginals, actions, EXECUTE traces, transcript, robot pose) on
ws://127.0.0.1:8765 for Foxglove (layout: config/foxglove/pearl.layout.json) and waits up to
--foxglove-wait s for a client to subscribe before the episode starts.

Examples:
  pearl demo --scenario config/scenarios/table4_dialog.yaml --domain config/pearl.domain.yaml --seed 3  # the episode domain: it stays and answers
  pearl demo --json                                              # uses out/policies/pearl, saved by `pearl plan`
  pearl demo --scenario config/scenarios/figure4_recogniser.yaml # real speech: espeak-ng, noise, pocketsphinx
  pearl demo --domain config/reception.domain.yaml               # the reception robot (docs/reception.md)
"""
from __future__ import annotations

import argparse
import sys

from pearl_sim.worlds import share_path

COMMAND = "demo"
HELP = "run a scenario through the full graph (Pearl nodes + simulated hardware) and print the transcript"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--scenario", default=None,
                        help="scenario file (default: the domain's world's, config/scenarios/figure4.yaml for Pearl)")
    parser.add_argument("--domain", default=share_path("config/pearl_day.domain.yaml"),
                        help="factored domain; its name chooses the simulated world (pearl_sim/worlds.py: pearl, "
                             "reception, ward; default: Pearl's domain fitted on working days, whose plan ships "
                             "in config/plans/pearl_day)")
    parser.add_argument("--hierarchy", default=None, help="action hierarchy (default: NAME.hierarchy.yaml beside the domain)")
    parser.add_argument("--policy", default="",
                        help="planned policy folder (default: the one `pearl plan` saved in out/policies/NAME "
                             "if it fits the domain, else plan now)")
    parser.add_argument("--replan", action="store_true",
                        help="plan the policy now even when `pearl plan` saved one in out/policies/NAME")
    parser.add_argument("--out", default=None, help="output folder (default: out/demo-<scenario>-<time>)")
    parser.add_argument("--seed", type=int, default=None, help="override the scenario's seed")
    parser.add_argument("--domain-id", type=int, default=None, help="ROS_DOMAIN_ID of the in-process graph")
    parser.add_argument("--json", action="store_true", help="print one JSON object instead of the transcript")
    parser.add_argument("--foxglove", action="store_true",
                        help="serve a live view over the Foxglove WebSocket protocol (belief marginals, actions, "
                             "EXECUTE traces, transcript, robot pose; layout config/foxglove/pearl.layout.json)")
    parser.add_argument("--foxglove-port", type=int, default=8765, help="port of the live view (default 8765; 0: any)")
    parser.add_argument("--foxglove-wait", type=float, default=30.0,
                        help="seconds to wait for a Foxglove client to subscribe before the episode starts "
                             "(default 30; 0: start at once)")
    parser.add_argument("--foxglove-linger", type=float, default=0.0,
                        help="seconds the live view stays up after the episode (default 0)")


def _saved_policy(args: argparse.Namespace) -> str:
    """The policy to run when --policy is not given: the one `pearl plan DOMAIN` saved
    (out/policies/NAME) when it fits the domain; else the shipped day plan when the domain is the
    shipped day domain (:func:`pearl_sim.cli.day.shipped_day_plan`); else '' (the demo plans).
    --replan: always ''."""
    if getattr(args, "replan", False):
        return ""
    from pearl_pomdp.cli.plan import DEFAULT_POLICY_ROOT, resolve_hierarchy_path
    from pearl_pomdp.errors import PolicyError
    from pearl_pomdp.hierarchy import load_hierarchical_policy
    from pearl_pomdp.model.domain_yaml import load_domain
    from pearl_sim.cli.day import shipped_day_plan

    def say(line: str) -> None:
        if not args.json:
            print(f"pearl demo: {line}", flush=True)

    domain = load_domain(args.domain)
    candidate = DEFAULT_POLICY_ROOT / domain.name
    if (candidate / "hierarchy.json").is_file():
        try:
            load_hierarchical_policy(candidate, domain)
        except PolicyError as err:
            say(f"{candidate} does not fit {args.domain} ({err})")
        else:
            say(f"using the policy `pearl plan` saved in {candidate} (--replan to plan anew)")
            return str(candidate)
    hierarchy = resolve_hierarchy_path(args.domain, args.hierarchy)
    shipped = shipped_day_plan(args.domain, hierarchy, domain) if hierarchy is not None else None
    if shipped is not None:
        say(f"using the plan shipped with the domain, {shipped} (--replan to plan anew)")
        return str(shipped)
    return ""


def run(args: argparse.Namespace) -> int:
    from pearl_pomdp.cli._inputs import require_file
    from pearl_pomdp.errors import SpecError
    from pearl_sim.world_demo import WorldDemo, run_demo_cli
    from pearl_sim.worlds import load_attribute, world_for

    # Check every input before planning or starting the graph (a typo fails at once).
    require_file(args.domain, "domain file (--domain)")
    world = world_for(args.domain)
    if world.demo is None:
        raise SpecError(args.domain, "name", f"the {world.name} world has no `pearl demo`: run "
                                             f"`pearl experiment --domain {args.domain}`")
    target = load_attribute(world.demo)
    if isinstance(target, WorldDemo):
        run_demo_cli(args, world, target)
        return 0
    return int(target(args))


def run_nursing_home(args: argparse.Namespace) -> int:
    """``pearl demo`` in the nursing home: the frame's, with Pearl's hooks (:mod:`pearl_sim.nursing_home.demo`),
    the shipped node params and the Foxglove live view; exit status 1 when a guidance was started and
    not completed."""
    from pearl_sim.nursing_home import WORLD
    from pearl_sim.nursing_home.demo import DEMO, LiveViewWatcher
    from pearl_sim.world_demo import run_demo_cli

    result = run_demo_cli(args, WORLD, DEMO, shipped_params=True,
                          watch=lambda: LiveViewWatcher(_start_live_view(args), linger=args.foxglove_linger))
    return 0 if result.metrics.get("guidances_completed") or not result.metrics.get("guidances_started") else 1


def _start_live_view(args: argparse.Namespace):
    """The Foxglove server, up before planning so a viewer can connect; waits for one (--foxglove-wait)."""
    from pearl_pomdp.errors import PearlError

    if not 0 <= args.foxglove_port <= 65535:
        raise PearlError(f"--foxglove-port {args.foxglove_port}: not a TCP port (0-65535)")
    try:
        from pearl_pomdp.live_view import LiveView
    except ImportError as err:
        raise PearlError(f"--foxglove: {err}") from None
    try:
        view = LiveView(port=args.foxglove_port)
    except Exception as err:   # the SDK raises its own error type when the port is taken
        raise PearlError(f"--foxglove-port {args.foxglove_port}: cannot serve the live view: {err}") from None
    # On stderr: with --json, stdout holds only the JSON object.
    print(f"pearl demo: live view on {view.url} (Foxglove: Open connection → Foxglove WebSocket; "
          f"layout config/foxglove/pearl.layout.json)", file=sys.stderr, flush=True)
    if args.foxglove_wait > 0:
        wanted = ("/pearl/belief_marginals", "/pearl/action")
        if view.wait_for_subscribers(wanted, args.foxglove_wait):
            print("pearl demo: a Foxglove client subscribed; starting", file=sys.stderr, flush=True)
        else:
            print(f"pearl demo: no Foxglove client subscribed within {args.foxglove_wait:g} s; starting anyway",
                  file=sys.stderr, flush=True)
    return view
