"""Decision times of the ward robot through the nodes: ``pearl launch`` online or hierarchical; one JSON object.

Starts ``pearl launch launch/pearl.launch.xml domain:=config/ward.domain.yaml policy:=online:TRIALS
params_file:=config/ward_nodes.yaml navigation:=false step_timeout:=0.0`` (three node processes
over DDS on a private domain, localhost discovery), waits for the first action (start-up: compile
and bounds, reported), then plays a robot for ``--steps`` steps: a drive is answered with its
arrival, any other action with a call button or a spoken need in turn. Reports per step the
publish → action wall time (tracker update + belief + decision + action over DDS) and the policy
node's own decision latency (``latency_s`` of ``/pearl/decision``): p50/p99/max in ms, the
belief messages' vectors on the wire (``probabilities`` and ``support``, bytes) and their support
(states with b > 0, as a fraction of the states), and the machine's load. Issue 24 part 2's target: decision p99 ≤ 100 ms. ``--policy hierarchical`` launches
with ``policy:=`` empty instead, so the policy node plans ``config/ward.hierarchy.yaml`` at start-up
(its online root, 20 DESPOT trials a decision, and the residents' subtasks) and answers with it.

    python bench/ward_launch.py [--trials 5] [--steps 100]
    python bench/ward_launch.py --policy hierarchical --steps 100
    python bench/ward_launch.py --trials 20 --shm-segment 8388608     # the belief over shared memory
"""
from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
PLACES = {"GoToStation": "station", "GoToRoomAnn": "room_ann", "GoToRoomBob": "room_bob", "GoToRoomCleo": "room_cleo",
          "GoToLounge": "lounge"}
INPUTS = [("/ward/call_button", "call_bob"), ("/ward/speech", "could i have some water"),
          ("/ward/call_button", "call_ann"), ("/ward/speech", "help me up please"), ("/ward/speech", "no")]


def _stats(values):
    import numpy as np

    v = np.asarray(values) * 1000.0
    return {"p50": round(float(np.percentile(v, 50)), 1), "p99": round(float(np.percentile(v, 99)), 1),
            "max": round(float(v.max()), 1), "n": int(v.size)}


def _spread(values, scale, digits=0):
    """p50/p90/max of ``values`` × ``scale`` (``None`` when there are none)."""
    import numpy as np

    if not values:
        return None
    v = np.asarray(values, dtype=float) * scale
    return {"p50": round(float(np.percentile(v, 50)), digits), "p90": round(float(np.percentile(v, 90)), digits),
            "max": round(float(v.max()), digits), "n": int(v.size)}


def _with_shared_memory(profile: Path, segment: int, out: Path) -> Path:
    """``profile`` with a shared-memory transport of ``segment`` bytes and UDPv4 as its participant's only
    transports (Fast DDS: ``userTransports``, ``useBuiltinTransports`` false), written to ``out``."""
    text = profile.read_text()
    opening = '<profiles xmlns="http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles">'
    if opening not in text or "<rtps>" not in text:
        raise SystemExit(f"--shm-segment: {profile} has no <profiles> element or no <rtps> to add transports to")
    text = text.replace(opening, opening + f"""
  <transport_descriptors>
    <transport_descriptor><transport_id>bench_shm</transport_id><type>SHM</type>
      <segment_size>{int(segment)}</segment_size></transport_descriptor>
    <transport_descriptor><transport_id>bench_udp</transport_id><type>UDPv4</type></transport_descriptor>
  </transport_descriptors>""", 1)
    text = text.replace("<rtps>", """<rtps>
      <userTransports><transport_id>bench_shm</transport_id><transport_id>bench_udp</transport_id></userTransports>
      <useBuiltinTransports>false</useBuiltinTransports>""", 1)
    out.write_text(text)
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--policy", choices=("online", "hierarchical"), default="online",
                    help="online: policy:=online:TRIALS; hierarchical: plan the ward's hierarchy at start-up")
    ap.add_argument("--trials", type=int, default=5, help="trials per decision of --policy online")
    ap.add_argument("--steps", type=int, default=100)
    ap.add_argument("--startup-timeout", type=float, default=900.0)
    ap.add_argument("--fastdds-profile", type=Path, default=REPO / "config" / "fastdds_profile.xml",
                    help="Fast DDS profile of every process (default: the one pearl launch gives its nodes)")
    ap.add_argument("--shm-segment", type=int, default=None, metavar="BYTES",
                    help="run under --fastdds-profile with a shared-memory transport of this segment size added "
                         "(and UDP), written to the run's log directory: big enough for the 1.87 MB belief, the belief "
                         "goes through shared memory instead of UDP")
    args = ap.parse_args()

    import numpy as np
    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.signals import SignalHandlerOptions

    from pearl_pomdp.nodes import conversions as cv
    from pearl_pomdp.nodes.common import EVENT_QOS, INPUT_QOS, LATCHED_QOS

    domain_id = 1 + (os.getpid() * 7) % 101
    log_dir = Path(tempfile.mkdtemp(prefix="pearl_ward_launch_"))
    if args.shm_segment is not None:
        args.fastdds_profile = _with_shared_memory(args.fastdds_profile, args.shm_segment, log_dir / "fastdds_shm.xml")
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain_id), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
               FASTRTPS_DEFAULT_PROFILES_FILE=str(args.fastdds_profile.resolve()), ROS_LOG_DIR=str(log_dir))
    os.environ["FASTRTPS_DEFAULT_PROFILES_FILE"] = env["FASTRTPS_DEFAULT_PROFILES_FILE"]   # this process's robot too
    env.pop("ROS_LOCALHOST_ONLY", None)
    err = open(log_dir / "launch.err", "wb")
    policy_arg = f"policy:=online:{args.trials}" if args.policy == "online" else "policy:="
    t_start = time.perf_counter()
    launch = subprocess.Popen([str(Path(sys.executable).parent / "pearl"), "launch", "launch/pearl.launch.xml",
                               f"domain:={REPO / 'config' / 'ward.domain.yaml'}", policy_arg,
                               f"hierarchy:={REPO / 'config' / 'ward.hierarchy.yaml'}",
                               f"params_file:={REPO / 'config' / 'ward_nodes.yaml'}", "navigation:=false",
                               "step_timeout:=0.0"], cwd=REPO, env=env, stdout=subprocess.DEVNULL, stderr=err)
    context = Context()
    rclpy.init(context=context, domain_id=domain_id, signal_handler_options=SignalHandlerOptions.NO)
    node = rclpy.create_node("ward_latency_probe", context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    actions, decisions, marginals, carried = [], [], [], []
    node.create_subscription(cv.ActionMsg, "/pearl/action", lambda m: actions.append((time.perf_counter(), m)), LATCHED_QOS)
    # The belief's arrival here splits a step's time into publish_to_marginals_ms (the tracker's
    # update of the belief and its publication, marginals included: one pearl_interfaces/Belief) and
    # marginals_to_action_ms (the policy node's decision, the action back). The names are kept from
    # before the typed interfaces, when the marginals were a second, small message after the belief.
    def on_belief(m):
        marginals.append(time.perf_counter())
        # What the message carried: its vectors' bytes, and the belief's support (b > 0): a message
        # without ``support`` carries the complete belief (its support is counted); one with it lists
        # the support, or, with ``outside_support`` above 0, every state is in it.
        support = getattr(m, "support", ())
        states = getattr(m, "num_states", 0) or len(m.probabilities)
        if not len(support):
            counted = int(np.count_nonzero(np.frombuffer(m.probabilities, dtype=float)))
        else:
            counted = len(support) if m.outside_support == 0.0 else states
        carried.append((8 * len(m.probabilities) + 4 * len(support), counted / states))

    node.create_subscription(cv.BeliefMsg, "/pearl/belief", on_belief, LATCHED_QOS)
    node.create_subscription(cv.DecisionMsg, "/pearl/decision", lambda m: decisions.append(m), EVENT_QOS)
    pubs = {t: node.create_publisher(cv.RecognisedSpeechMsg if t == "/ward/speech" else cv.TextMsg, t, INPUT_QOS)
            for t in ("/ward/arrived", "/ward/call_button", "/ward/speech")}

    def spin_until(pred, timeout):
        end = time.perf_counter() + timeout
        while time.perf_counter() < end:
            executor.spin_once(timeout_sec=0.01)
            if pred():
                return True
        return False

    wall, tracker, rest, report = [], [], [], {}
    try:
        ok = spin_until(lambda: actions and all(p.get_subscription_count() >= 1 for p in pubs.values()),
                        args.startup_timeout)
        if not ok:
            raise SystemExit(f"bench/ward_launch.py: the graph did not start within {args.startup_timeout} s "
                             f"(log: {log_dir / 'launch.err'})")
        startup = time.perf_counter() - t_start
        k = 0
        for _ in range(args.steps):
            action = cv.msg_to_action(actions[-1][1])
            n = len(actions)
            if action in PLACES:
                topic, text = "/ward/arrived", f"at_{PLACES[action]}"
            else:
                topic, text = INPUTS[k % len(INPUTS)]
                k += 1
            m = len(marginals)
            t0 = time.perf_counter()
            pubs[topic].publish(cv.speech_to_msg(text) if topic == "/ward/speech" else cv.text_to_msg(text))
            if not spin_until(lambda: len(actions) > n, 120.0):
                raise SystemExit(f"bench/ward_launch.py: no action after {text!r} (log: {log_dir / 'launch.err'})")
            wall.append(actions[-1][0] - t0)
            if len(marginals) > m and marginals[m] <= actions[-1][0]:
                tracker.append(marginals[m] - t0)
                rest.append(actions[-1][0] - marginals[m])
        spin_until(lambda: len(decisions) >= len(actions), 5.0)
        node_latency = [d.latency_s for d in decisions[1:]]
        report = {"bench": "ward_launch", "policy": f"online:{args.trials}" if args.policy == "online" else "hierarchical", "steps": len(wall),
                  "startup_s": round(startup, 1), "observation_to_action_ms": _stats(wall),
                  "policy_node_decision_ms": _stats([x for x in node_latency if x is not None]),
                  "publish_to_marginals_ms": _stats(tracker) if tracker else None,
                  "marginals_to_action_ms": _stats(rest) if rest else None,
                  "belief_vector_bytes": _spread([c[0] for c in carried], 1),
                  "belief_support_fraction": _spread([c[1] for c in carried], 1.0, 4),
                  "target_p99_ms": 100.0, "load_avg_1min": os.getloadavg()[0], "cpus": os.cpu_count(),
                  "fastdds_profile": str(args.fastdds_profile), "shm_segment_bytes": args.shm_segment}
        report["meets_target"] = report["observation_to_action_ms"]["p99"] <= 100.0
    finally:
        launch.send_signal(signal.SIGINT)
        try:
            launch.wait(30)
        except subprocess.TimeoutExpired:
            launch.kill()
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown(context=context)
        err.close()
    print(json.dumps(report, indent=1 if sys.stdout.isatty() else None))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
