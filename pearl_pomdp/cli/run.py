"""Run one Pearl node in this process, as ``ros2 run pearl_pomdp NODE`` would.

Everything after NODE is passed to the node (``--ros-args -p domain:=… --params-file …``).
Exit code: 0 after SIGINT/SIGTERM, 2 when the node cannot start (one line on stderr).

Examples (each runs until Ctrl-C; `pearl plan config/pearl.domain.yaml` saves out/policies/pearl)::

    pearl run belief_tracker --ros-args --params-file config/pearl_nodes.yaml
    pearl run hierarchical_policy --ros-args -p policy:=out/policies/pearl -p use_sim_time:=true
"""
from __future__ import annotations

import argparse
import importlib

COMMAND = "run"
HELP = ("run one node (belief_tracker, hierarchical_policy, action_executor, landmark_detector, guide_pace, "
        "lifecycle_supervisor) with --ros-args")

#: Node executables of this package → module holding their ``main``.
NODES = {
    "belief_tracker": "pearl_pomdp.nodes.belief_tracker",
    "hierarchical_policy": "pearl_pomdp.nodes.hierarchical_policy",
    "action_executor": "pearl_pomdp.nodes.action_executor",
    "landmark_detector": "pearl_pomdp.nodes.landmark_detector",
    "guide_pace": "pearl_pomdp.nodes.guide_pace",
    "lifecycle_supervisor": "pearl_pomdp.nodes.supervisor",
}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("node", choices=sorted(NODES), help="the node to run")
    parser.add_argument("node_args", nargs=argparse.REMAINDER, metavar="--ros-args ...",
                        help="arguments for the node (ROS 2 syntax)")


def run(args: argparse.Namespace) -> int:
    module = importlib.import_module(NODES[args.node])
    return int(module.main([args.node, *args.node_args]))
