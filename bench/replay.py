#!/usr/bin/env python3
"""Replay throughput (messages/s) of `pearl replay`, printed as one JSON object.

Two workloads:

* ``scenarios``: every recorded bag in ``bags/`` (small: tens of messages each, so start-up
  of the DDS entities weighs in);
* ``long``: a synthetic bag built from the inputs of ``bags/table4_clarification`` repeated
  ``--steps`` times, one input every 2 s of sim time with ``/clock`` at ``--clock-hz``
  between them (a simulator publishes /clock far more often than a resident speaks). It is
  replayed twice; the second replay's rate is the headline number and both replays must
  produce the same actions (lock-step replay is deterministic).

``messages`` counts every bag message the replay handles (inputs and /clock fed to the
graph, recorded outputs compared); ``seconds`` is the replay loop only (graph start-up and
policy loading excluded). The machine is shared: compare runs made together.

Usage: .venv/bin/python bench/replay.py [--steps 100] [--clock-hz 20] [--domain-id 97]
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))


def build_long_bag(src: Path, out: Path, steps: int, clock_hz: float) -> int:
    """Write the synthetic bag; returns its message count."""
    from pearl_pomdp.bags import well_known as wk
    from pearl_pomdp.bags.reader import BagReader
    from pearl_pomdp.bags.writer import BagWriter
    from pearl_pomdp.model.domain_yaml import load_domain
    from rclpy.serialization import serialize_message
    from rosgraph_msgs.msg import Clock

    reader = BagReader(src, salvage=False)
    custom = dict((reader.metadata or {}).get("custom_data") or {})
    input_topics = {c.topic for c in load_domain(src / custom["pearl.domain"]).inputs}   # the domain's inputs
    inputs = [m for m in reader.messages if m.topic in input_topics]
    for key in ("pearl.domain", "pearl.policy"):  # paths stay valid from the new location
        custom[key] = str((src / custom[key]).resolve())
    with BagWriter(out, custom_data=custom) as bag:
        for name, info in reader.topics.items():
            bag.add_topic(name, info.type, qos=info.offered_qos_profiles)
        t = 1_000_000_000
        period = int(1e9 / clock_hz)
        for i in range(steps):
            for _ in range(int(2.0 * clock_hz)):
                t += period
                msg = Clock()
                msg.clock.sec, msg.clock.nanosec = divmod(t, 1_000_000_000)
                bag.write(wk.CLOCK_TOPIC, serialize_message(msg), t)
            m = inputs[i % len(inputs)]
            bag.write(m.topic, m.data, t)
        return bag.message_count


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--steps", type=int, default=100)
    ap.add_argument("--clock-hz", type=float, default=20.0)
    ap.add_argument("--domain-id", type=int, default=int(os.environ.get("ROS_DOMAIN_ID", "97") or 97))
    args = ap.parse_args()
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    from pearl_pomdp.nodes.bag_replay import replay_bag

    result = {"benchmark": "replay", "unit": "messages/s", "scenarios": {}, "long": {}}
    for bag in sorted(p for p in (REPO / "bags").iterdir() if (p / "metadata.yaml").is_file()):
        r = replay_bag(bag, domain_id=args.domain_id)
        result["scenarios"][bag.name] = {"match": r.match, "messages": r.messages, "fed": r.fed,
                                         "seconds": round(r.seconds, 4),
                                         "messages_per_second": round(r.messages_per_second, 1)}
    with tempfile.TemporaryDirectory() as tmp:
        long_bag = Path(tmp) / "long"
        n = build_long_bag(REPO / "bags" / "table4_clarification", long_bag, args.steps, args.clock_hz)
        runs = [replay_bag(long_bag, domain_id=args.domain_id) for _ in range(2)]
    result["long"] = {"steps": args.steps, "clock_hz": args.clock_hz, "messages": n,
                      "actions": len(runs[1].actions), "deterministic": runs[0].actions == runs[1].actions,
                      "seconds": [round(r.seconds, 4) for r in runs],
                      "messages_per_second": [round(r.messages_per_second, 1) for r in runs]}
    result["messages_per_second"] = result["long"]["messages_per_second"][1]
    result["target_messages_per_second"] = 5000
    result["load_average"] = os.getloadavg()[0]
    print(json.dumps(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
