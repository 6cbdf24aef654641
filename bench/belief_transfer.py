"""The ward's beliefs across DDS, complete and by the states they list: one JSON object.

Keeps the tracker's beliefs along episodes of the ward's study (``config/ward.domain.yaml``,
233,280 states; the hierarchy of ``config/ward.hierarchy.yaml`` decides, as in
``bench/ward_belief_support.py``), then starts an echo process on a private ROS domain (localhost,
the Fast DDS profile ``pearl launch`` gives its nodes: UDP on localhost) that reads each
``/pearl/belief`` as the policy node does (``conversions.msg_to_belief`` with the model's number of
states) and answers with a one-word ``pearl_interfaces/Action``. For every belief this process
publishes it twice, as the tracker does today (``belief_to_msg``: by the states that differ from
one value when that is smaller) and complete (every state), in turn, and times publish → answer
(wall, ``time.perf_counter``): conversion, serialisation, the transfer, deserialisation and the
reading on the other side — a belief's whole way from the tracker to the policy's decider. A
one-state belief's round trip is the floor (the answer's way back and the executors). Reports
p50 / p99 / max in ms per form, the serialised bytes, and the machine's load.

    OMP_NUM_THREADS=1 .venv/bin/python bench/belief_transfer.py [--episodes quiet_morning,busy_ward] [--noise 0.1]
"""
from __future__ import annotations

import argparse
import array
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "bench"))

#: The echo process: argv = number of states. Answers each belief with its step once it has read it.
_ECHO = r'''
import sys
import rclpy
from rclpy.qos import QoSProfile, ReliabilityPolicy, DurabilityPolicy
from pearl_pomdp.nodes import conversions as cv
states = int(sys.argv[1])
rclpy.init()
node = rclpy.create_node("belief_echo")
qos = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE)
answer = node.create_publisher(cv.ActionMsg, "/bench/answer", qos)
def on_belief(msg):
    b = cv.msg_to_belief(msg, states)
    answer.publish(cv.action_to_msg(f"{msg.step} {b.size}"))
node.create_subscription(cv.BeliefMsg, "/pearl/belief", on_belief, qos)
print("ready", flush=True)
try:
    rclpy.spin(node)
except Exception:
    pass
'''


def _stats(values):
    import numpy as np

    v = np.asarray(values, dtype=float) * 1000.0
    return {"p50": round(float(np.percentile(v, 50)), 2), "p99": round(float(np.percentile(v, 99)), 2),
            "max": round(float(v.max()), 2), "n": int(v.size)}


def main() -> int:
    from ward_belief_support import add_study_arguments, study_beliefs

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_study_arguments(ap, episodes="quiet_morning,busy_ward")
    ap.add_argument("--fastdds-profile", type=Path, default=REPO / "config" / "fastdds_profile.xml")
    args = ap.parse_args()

    import numpy as np

    beliefs: list = []
    walk = study_beliefs(ap, args, lambda name, b: beliefs.append(np.array(b)))
    S = walk["states"]
    wanted = list(walk["steps"])

    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
    from rclpy.serialization import serialize_message
    from rclpy.signals import SignalHandlerOptions

    from pearl_pomdp.nodes import conversions as cv

    domain_id = 1 + (os.getpid() * 11) % 101
    log_dir = Path(tempfile.mkdtemp(prefix="pearl_belief_transfer_"))
    os.environ["FASTRTPS_DEFAULT_PROFILES_FILE"] = str(args.fastdds_profile.resolve())
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain_id), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
               ROS_LOG_DIR=str(log_dir))
    env.pop("ROS_LOCALHOST_ONLY", None)
    echo = subprocess.Popen([sys.executable, "-c", _ECHO, str(S)], env=env, cwd=REPO, stdout=subprocess.PIPE,
                            stderr=open(log_dir / "echo.err", "wb"), text=True)
    context = Context()
    rclpy.init(context=context, domain_id=domain_id, signal_handler_options=SignalHandlerOptions.NO)
    node = rclpy.create_node("belief_transfer", context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    qos = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE)
    pub = node.create_publisher(cv.BeliefMsg, "/pearl/belief", qos)
    answers = []
    node.create_subscription(cv.ActionMsg, "/bench/answer", lambda m: answers.append((time.perf_counter(), m.name)), qos)

    def spin_until(pred, timeout):
        end = time.perf_counter() + timeout
        while time.perf_counter() < end:
            executor.spin_once(timeout_sec=0.005)
            if pred():
                return True
        return False

    def complete(b, step):
        msg = cv.belief_to_msg(b, step=step)
        msg.support, msg.probabilities, msg.outside_support = [], array.array("d", b.tobytes()), 0.0
        return msg

    times = {"listed": [], "complete": [], "one_state": []}
    sizes = {"listed": [], "complete": []}
    load_start = os.getloadavg()
    try:
        if not spin_until(lambda: pub.get_subscription_count() >= 1 and node.count_publishers("/bench/answer") >= 1,
                          60.0):
            raise SystemExit(f"bench/belief_transfer.py: the echo process did not match (log {log_dir})")
        one = np.zeros(S)
        one[0] = 1.0
        step = 0
        for b in beliefs:
            for form, build in (("listed", lambda b, k: cv.belief_to_msg(b, step=k)), ("complete", complete),
                                ("one_state", lambda b, k: cv.belief_to_msg(one, step=k))):
                step += 1
                n = len(answers)
                t0 = time.perf_counter()
                msg = build(b, step)
                pub.publish(msg)
                if not spin_until(lambda: len(answers) > n, 30.0):
                    raise SystemExit(f"bench/belief_transfer.py: no answer to step {step} (log {log_dir})")
                times[form].append(answers[-1][0] - t0)
                assert answers[-1][1] == f"{step} {S}", answers[-1]
                if form in sizes:
                    sizes[form].append(len(serialize_message(msg)))
    finally:
        echo.terminate()
        echo.wait(10)
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown(context=context)
    print(json.dumps({
        "bench": "belief_transfer", "states": S, "beliefs": len(beliefs), "episodes": wanted,
        "round_trip_ms": {form: _stats(v) for form, v in times.items()},
        "serialised_bytes": {form: {"p50": int(np.percentile(v, 50)), "p99": int(np.percentile(v, 99)),
                                    "max": int(max(v))} for form, v in sizes.items()},
        "fastdds_profile": str(args.fastdds_profile), "omp_num_threads": os.environ.get("OMP_NUM_THREADS"),
        "load": {"start": [round(x, 2) for x in load_start], "end": [round(x, 2) for x in os.getloadavg()]},
    }, indent=1 if sys.stdout.isatty() else None))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
