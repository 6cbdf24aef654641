"""Replay a recorded bag through the belief tracker and hierarchical policy (one process,
simulated time) and compare the actions they publish with the /pearl/action recorded.

The bag's recorded inputs (/pearl/speech, /pearl/touchscreen, /pearl/laser, /pearl/reminder)
and /clock are published in file order, as the recorded bytes, into the real nodes; each
message is fed once the graph has reacted to the previous one, so the result does not
depend on the machine's speed. The domain and planned policy come from the bag's
metadata.yaml custom_data (pearl.domain, pearl.policy), or from --domain / --policy.

Output: text, or with --json one object with "actions" (list), "expected_actions" (as
recorded), "match" (bool), "messages", "messages_per_second" (replay loop only). Exit code
0 when the actions match, 1 when they do not, 2 on an unreadable bag.

Examples:
  pearl replay bags/table4_clarification
  pearl replay bags/figure4_guidance --json
"""
from __future__ import annotations

import argparse
import os

from pearl_pomdp.cli._progress import add_progress_arguments, show_progress

COMMAND = "replay"
HELP = "replay a bag's inputs through tracker + policy under sim time; compare with the recorded actions"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("bag", metavar="BAG", help="bag directory or .mcap file")
    parser.add_argument("--domain", help="domain file (default: the bag's custom_data pearl.domain)")
    parser.add_argument("--policy", help="planned policy directory (default: the bag's custom_data pearl.policy)")
    parser.add_argument("--domain-id", type=int, help="ROS domain of the replay (default: $ROS_DOMAIN_ID)")
    parser.add_argument("--step-timeout", type=float, default=10.0, metavar="S",
                        help="wall seconds to wait for the graph's reaction to one message (default 10)")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    add_progress_arguments(parser)


def run(args: argparse.Namespace) -> int:
    from pearl_pomdp.bags.replay import replay_bag
    from pearl_pomdp.cli import print_json

    domain_id = args.domain_id
    if domain_id is None and os.environ.get("ROS_DOMAIN_ID", "").isdigit():
        domain_id = int(os.environ["ROS_DOMAIN_ID"])
    result = replay_bag(args.bag, domain=args.domain, policy=args.policy, domain_id=domain_id,
                        step_timeout_s=args.step_timeout, progress=show_progress(args))
    if args.json:
        print_json(result.to_dict())
    else:
        print(f"bag:       {result.bag}")
        print(f"actions:   {' '.join(result.actions)}")
        print(f"expected:  {' '.join(result.expected_actions)}")
        status = "yes" if result.match else f"NO (first difference at action {result.first_mismatch})"
        print(f"match:     {status}")
        print(f"messages:  {result.messages} in {result.seconds:.3f} s ({result.messages_per_second:.0f} msg/s)")
    return 0 if result.match else 1
