"""Who may command the robot: an SROS2 access-control policy for a launch file's graph.

``pearl security policy FILE [name:=value …]`` starts the launch file's nodes as ``pearl launch``
does, on a private ROS domain (``--ros-domain-id``, localhost discovery, its own ROS_HOME: no
journal of the robot is read or written), waits until every node is up and every managed node
active, reads what each node publishes, subscribes, serves and calls from the ROS graph, stops the
graph and prints the SROS2 policy (``--out FILE`` writes it): one enclave ``/pearl/<node>`` per
node granting exactly its endpoints, and the operator's enclave ``/pearl/operator`` (node
``pearl_operator``), the only one that may publish the operator's veto and command topics and call
the operator services (named by the policy node's parameters). The topics a tracker subscribes
come from the domain's declared inputs, so a domain or launch argument that changes them changes
the policy. docs/reliability.md ("Who may command the robot") shows how a ROS 2 install with DDS
security turns it on; the shipped ``config/sros2/pearl.policy.xml`` is this command's output for
``launch/pearl.launch.xml`` (test/test_sros2_policy.py regenerates and compares). Give it the launch
arguments the robot is started with: with a planned ``policy:=`` the graph is up in seconds; without
one the policy node first plans the hierarchy, as at a robot's start-up (the same SROS2 policy
either way).

Examples:
  pearl security policy launch/pearl.launch.xml policy:=out/policies/pearl > pearl.policy.xml
  pearl security policy launch/pearl.launch.xml policy:=out/policies/pearl speech:=true --out robot.policy.xml
"""
from __future__ import annotations

import argparse
import os
import random
import signal
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import List

from pearl_pomdp.errors import PearlError

COMMAND = "security"
HELP = "SROS2 security: generate the access-control policy of a launch file's graph"

#: The executable whose node serves the operator (its parameters name the operator's endpoints).
POLICY_EXECUTABLE = "hierarchical_policy"

#: Private ROS domain ids the command picks from when none is given (away from 0, the default one).
DOMAIN_RANGE = (150, 230)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    verbs = parser.add_subparsers(dest="verb", metavar="VERB", required=True, help="policy: generate the SROS2 policy")
    policy = verbs.add_parser("policy", help="start the launch file's graph on a private domain and print its SROS2 "
                                             "policy (every node's endpoints; the operator's enclave)",
                              description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    policy.add_argument("file", help="launch file (ROS 2 XML format), e.g. launch/pearl.launch.xml")
    policy.add_argument("arguments", nargs="*", metavar="name:=value", help="launch arguments")
    policy.add_argument("--out", metavar="FILE", help="write the policy here instead of printing it")
    policy.add_argument("--ros-domain-id", type=int, metavar="N",
                        help=f"the private ROS domain to start the graph on; default: a random one in "
                             f"{DOMAIN_RANGE[0]}..{DOMAIN_RANGE[1]}")
    policy.add_argument("--timeout", type=float, default=120.0, metavar="S",
                        help="seconds to wait for the graph to be up (a policy planned at start-up takes a while); "
                             "default 120")


def _launch_command(file: str, arguments: List[str]) -> List[str]:
    """``pearl launch FILE ARGS`` in this Python; a node that dies is not respawned (the graph is read once)."""
    return [sys.executable, "-c", "import sys; from pearl_pomdp.cli import main; sys.exit(main())",
            "launch", file, *arguments, "--respawn-max-retries", "0"]


def _resolve_name(name: str, node_fqn: str) -> str:
    """A topic or service name as the node ``node_fqn`` resolves it (absolute, ``~/private``, relative)."""
    if name.startswith("/"):
        return name
    if name.startswith("~"):
        return node_fqn + name[1:]
    return f"{node_fqn.rpartition('/')[0]}/{name}"


def _environment(domain_id: int, home: Path) -> dict:
    from pearl_pomdp.launch_xml import package_share_dir

    env = dict(os.environ)
    env.pop("ROS_LOCALHOST_ONLY", None)
    env.pop("ROS_SECURITY_ENABLE", None)   # the graph is read, not secured: the pip install has no DDS security
    env.update(ROS_DOMAIN_ID=str(domain_id), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST", ROS_HOME=str(home),
               ROS_LOG_DIR=str(home / "log"), PYTHONUNBUFFERED="1")
    share = package_share_dir("pearl_pomdp")
    if "FASTRTPS_DEFAULT_PROFILES_FILE" not in env and share is not None:
        env["FASTRTPS_DEFAULT_PROFILES_FILE"] = str(share / "config" / "fastdds_profile.xml")
    return env


def generate_policy(file: str, arguments: List[str], domain_id: int, timeout: float) -> str:
    """The policy XML of ``file``'s graph started with ``arguments`` on ``domain_id`` (see the module doc).

    Raises:
        PearlError: the launch file names no node, the graph did not come up within ``timeout``
            seconds, or its nodes are already on that domain.
    """
    from pearl_pomdp.launch_xml import parse_cli_arguments, parse_launch_file
    from pearl_pomdp.nodes.graph_endpoints import GraphWatch, close_probe, probe_context
    from pearl_pomdp.sros2_policy import OPERATOR_PARAMETERS, build_policy, fold_actions, operator_endpoints

    description = parse_launch_file(file, parse_cli_arguments(arguments))
    if not description.nodes:
        raise PearlError(f"{file}: no <node> to start")
    unnamed = [n.executable for n in description.nodes if not n.name]
    if unnamed:
        raise PearlError(f"{file}: node(s) {', '.join(unnamed)} have no name=: a policy's profile needs the node's name")
    names = [str(n.fully_qualified_name) for n in description.nodes]
    with tempfile.TemporaryDirectory(prefix="pearl-security-") as tmp:
        env = _environment(domain_id, Path(tmp))
        os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"   # the probe, before its participant exists
        log = open(Path(tmp) / "launch.log", "wb")
        launch = subprocess.Popen(_launch_command(file, arguments), env=env, stdout=log, stderr=subprocess.STDOUT,
                                  stdin=subprocess.DEVNULL)
        probe = probe_context(domain_id, "_pearl_security_probe")
        try:
            watch = GraphWatch(probe[1], probe[2], names)
            bare_node = watch.own_endpoints(timeout)   # before the probe creates any client
            try:
                found = watch.wait_ready(timeout)
            except PearlError as err:
                tail = (Path(tmp) / "launch.log").read_text(errors="replace").strip().splitlines()[-5:]
                raise PearlError(f"{file}: {err}" + ("; the launch said: " + " | ".join(tail) if tail else "")) from None
            enclaves = watch.enclaves()
            operator = None
            served = [n for n in description.nodes if n.executable == POLICY_EXECUTABLE]
            if served:
                fqn = str(served[0].fully_qualified_name)
                wanted = [p for params in OPERATOR_PARAMETERS.values() for p in params]
                operator = operator_endpoints({k: _resolve_name(v, fqn) for k, v in watch.parameters(fqn, wanted).items()},
                                              bare_node)
        finally:
            close_probe(*probe)
            launch.send_signal(signal.SIGINT)
            try:
                launch.wait(timeout=20)
            except subprocess.TimeoutExpired:
                launch.kill()
                launch.wait()
            log.close()
    nodes = [fold_actions(found[n]) for n in names]
    comment = (f"SROS2 policy of {Path(file).name}'s graph: each node's profile, in the enclave the launch file\n"
               "starts it in, grants exactly the topics, services and actions the node used when started;\n"
               "the operator's enclave is the only one that may publish the operator's veto and command and\n"
               "call the operator services. Generated by `pearl security policy`; regenerate it after a\n"
               "node's topics, services or actions change. docs/reliability.md, 'Who may command the robot',\n"
               "says how to turn it on.")
    return build_policy(nodes, operator, comment=comment, enclaves=enclaves)


def run(args: argparse.Namespace) -> int:
    domain_id = args.ros_domain_id if args.ros_domain_id is not None else random.randint(*DOMAIN_RANGE)
    if not 0 <= domain_id <= 232:
        raise PearlError(f"--ros-domain-id must be 0..232, got {domain_id}")
    if not args.timeout > 0:
        raise PearlError(f"--timeout must be > 0 s, got {args.timeout}")
    text = generate_policy(args.file, args.arguments, domain_id, args.timeout)
    if args.out:
        from pearl_pomdp.atomic import atomic_write

        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        atomic_write(Path(args.out), text)
        print(f"pearl security: wrote {args.out}", file=sys.stderr)
    else:
        sys.stdout.write(text)
    return 0
