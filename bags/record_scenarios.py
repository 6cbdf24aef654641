#!/usr/bin/env python3
"""Regenerate the recorded scenarios in bags/ from a live run of the Pearl nodes.

For each scenario this script

1. starts the three nodes as separate processes (the console scripts ``belief_tracker``,
   ``hierarchical_policy``, ``action_executor``) on a private ``ROS_DOMAIN_ID`` under sim
   time, with the domain and planned policy kept in ``bags/pearl/`` (a snapshot, so the
   bags stay replayable when ``config/`` evolves);
2. starts ``pearl record`` (this project's recorder) as another process on the same domain,
   with ``--use-sim-time`` and the replay configuration in ``custom_data``;
3. drives the graph from this process: it publishes ``/clock`` and, after each action the
   policy publishes, the next input of a scripted user / world (below), waiting for every
   answer (no fixed sleeps);
4. stops the recorder with SIGINT (clean close: metadata.yaml), then the nodes, and writes
   ``bags/<scenario>.expected.json`` with the actions seen live.

``bags/pearl/policy`` is planned once from ``bags/pearl/domain.yaml`` and
``bags/pearl/hierarchy.yaml`` (``--replan`` redoes it; planning is time-limited, so a new
plan may choose differently and the bags must then be re-recorded).

Scenarios (in the spirit of the paper, on the Pearl domain):

* ``table4_clarification`` — Table 4: a resident's requests arrive as garbled recogniser
  text; whatever clarification questions the policy asks are answered, one silence (the
  tracker's step timeout, in sim time) included.
* ``figure4_guidance`` — Figure 4: a physiotherapy reminder, contact with the resident,
  reminding, guidance to physiotherapy (laser landmarks), then a weather question.

Run from the repository root:  .venv/bin/python bags/record_scenarios.py [--only NAME]
"""
from __future__ import annotations

import argparse
import json
import os
import random
import shutil
import sys
import tempfile
import time
from pathlib import Path
from typing import Dict, List, Optional, Tuple

REPO = Path(__file__).resolve().parents[1]
BAGS = REPO / "bags"
PEARL = BAGS / "pearl"
BIN = Path(sys.executable).parent
sys.path.insert(0, str(REPO / "test"))
# The node-process helpers the ROS tests use: environment per domain, SIGINT → SIGTERM → SIGKILL.
from ros_helpers import Proc, ros_env  # noqa: E402

#: Tracker parameters of the recording (stored in custom_data, used again by the replay).
TRACKER_PARAMS = {"step_timeout": 10.0, "timeout_observation": "unknown", "max_pending": 8, "stale_after": 30.0}
RECORD_TOPICS = ["/clock", "/pearl/speech", "/pearl/touchscreen", "/pearl/laser", "/pearl/reminder",
                 "/pearl/action", "/pearl/decision", "/pearl/belief_marginals", "/pearl/say", "/pearl/display",
                 "/goal_pose"]
INPUTS = ("speech", "touchscreen", "laser", "reminder")
SILENCE = ("silence", "")
Input = Tuple[str, str]

# ---------------------------------------------------------------------------- scenarios
#: The world's answer to an action, whatever the script says (robot motion ends at a landmark;
#: the resident answers the robot's questions).
WORLD = {
    "GotoPatientRoom": ("laser", "atRoom"),
    "GuideToPhysio": ("laser", "atPhysio"),
    "GoHome": ("laser", "atHome"),
    "RingDoorBell": ("touchscreen", "t_yes"),
    "CheckUserPresent": ("touchscreen", "t_yes"),
}

SCENARIOS: Dict[str, Dict] = {
    "table4_clarification": {
        "doc": "Table 4-style dialog: garbled requests, clarification questions answered, one silence",
        "answers": {"ConfirmWantTime": ("speech", "yes that is right"),
                    "ConfirmWantWeather": ("speech", "yes please"),
                    "VerifyInfoRequest": ("speech", "the time what time is it"),
                    "ConfirmDone": ("speech", "yes thank you"),
                    "ConfirmGoHome": ("speech", "yes")},
        "script": [("speech", "pearl hello"),
                   ("speech", "pearl what is like start meds"),
                   ("speech", "pearl what time is it for will the"),
                   SILENCE,
                   ("speech", "pearl was on abc"),
                   ("speech", "pearl what is the whether like"),
                   ("speech", "pearl go to the that pretty good what"),
                   ("touchscreen", "t_time"),
                   ("speech", "thank you that is all")],
        "max_steps": 24,
    },
    "figure4_guidance": {
        "doc": "Figure 4-style guidance: reminder, contact, remind, guide to physio, weather question",
        "answers": {"RemindPhysioAppt": ("speech", "okay let's go"),
                    "ConfirmGuideToPhysio": ("speech", "yes please take me"),
                    "ConfirmWantWeather": ("speech", "yes"),
                    "ConfirmWantTime": ("speech", "no"),
                    "VerifyInfoRequest": ("touchscreen", "t_weather"),
                    "ConfirmDone": ("touchscreen", "t_yes"),
                    "TerminateGuidance": ("speech", "what is the weather forecast for tomorrow"),
                    "ConfirmGoHome": ("touchscreen", "t_yes")},
        "script": [("reminder", "g_physio"),
                   ("speech", "yes i am here"),
                   ("touchscreen", "t_go"),
                   ("speech", "give me the weather forecast for tomorrow"),
                   ("speech", "thank you")],
        "max_steps": 24,
    },
}


# ------------------------------------------------------------------------------ helpers
def ensure_policy(replan: bool) -> None:
    """Plan bags/pearl/policy from the snapshot domain + hierarchy unless it exists."""
    if (PEARL / "policy").is_dir() and not replan:
        return
    from pearl_pomdp.hierarchy import load_hierarchy, plan
    from pearl_pomdp.model.factored import load_domain

    if not (PEARL / "domain.yaml").is_file() or replan:
        PEARL.mkdir(parents=True, exist_ok=True)
        shutil.copy(REPO / "config" / "pearl.domain.yaml", PEARL / "domain.yaml")
        shutil.copy(REPO / "config" / "pearl.hierarchy.yaml", PEARL / "hierarchy.yaml")
    domain = load_domain(PEARL / "domain.yaml")
    print("planning bags/pearl/policy (takes a while) ...", file=sys.stderr)
    policy = plan(domain, load_hierarchy(PEARL / "hierarchy.yaml", domain))
    if (PEARL / "policy").exists():
        shutil.rmtree(PEARL / "policy")
    policy.save(PEARL / "policy")


def wait_until(pred, timeout: float, spin=None, what: str = "") -> None:
    deadline = time.monotonic() + timeout
    while not pred():
        if time.monotonic() > deadline:
            raise RuntimeError(f"timed out after {timeout} s waiting for {what}")
        if spin is not None:
            spin(0.02)
        else:
            time.sleep(0.02)


# ----------------------------------------------------------------------------- recording
def record(name: str, spec: Dict, domain_id: int, log_dir: Path) -> List[str]:
    import rclpy
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
    from rosgraph_msgs.msg import Clock
    from std_msgs.msg import String

    out = BAGS / name
    if out.exists():
        shutil.rmtree(out)
    env = ros_env(domain_id, log_dir)
    os.environ.update({k: env[k] for k in ("ROS_DOMAIN_ID", "ROS_AUTOMATIC_DISCOVERY_RANGE", "ROS_LOG_DIR")})
    os.environ["FASTRTPS_DEFAULT_PROFILES_FILE"] = env["FASTRTPS_DEFAULT_PROFILES_FILE"]

    rel = os.path.relpath(PEARL, out)
    common = ["-p", f"domain:={PEARL / 'domain.yaml'}", "-p", "use_sim_time:=true"]
    tracker_args = [x for k, v in TRACKER_PARAMS.items() for x in ("-p", f"{k}:={v}")]
    params_file = REPO / "config" / "pearl_nodes.yaml"
    procs: List[Proc] = []
    rclpy.init(domain_id=domain_id)
    node = rclpy.create_node("scenario_driver")
    try:
        procs.append(Proc([str(BIN / "belief_tracker"), "--ros-args", *common, *tracker_args],
                          env, log_dir, "belief_tracker"))
        procs.append(Proc([str(BIN / "hierarchical_policy"), "--ros-args", *common,
                                                  "-p", f"policy:={PEARL / 'policy'}"], env, log_dir, "hierarchical_policy"))
        if params_file.is_file():
            procs.append(Proc([str(BIN / "action_executor"), "--ros-args", "--params-file",
                                                  str(params_file), *common], env, log_dir, "action_executor"))
        custom = [f"pearl.domain={rel}/domain.yaml", f"pearl.policy={rel}/policy",
                  f"pearl.tracker_params={json.dumps(TRACKER_PARAMS, separators=(',', ':'))}",
                  f"pearl.scenario={name}"]
        recorder = Proc([str(BIN / "pearl"), "record", str(out), "--use-sim-time", "--topics",
                                     *RECORD_TOPICS, "--custom-data", *custom], env, log_dir, "recorder")
        procs.append(recorder)

        latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
        events = QoSProfile(depth=20, reliability=ReliabilityPolicy.RELIABLE)
        actions: List[str] = []
        node.create_subscription(String, "/pearl/action", lambda m: actions.append(m.data), latched)
        # The tracker's /diagnostics tell whether it has seen the latest action (the step is
        # open): inputs are sent only then, so none waits in its queue — as in a replay.
        from pearl_pomdp.nodes import conversions as cv

        tracker_state: Dict[str, str] = {}

        def on_diag(msg) -> None:
            status = cv.msg_to_diagnostics(msg).get("pearl: belief_tracker")
            if status:
                tracker_state.clear()
                tracker_state.update(status["values"])

        node.create_subscription(cv.DiagnosticsMsg, "/diagnostics", on_diag, events)
        clock_pub = node.create_publisher(Clock, "/clock", 10)
        pubs = {k: node.create_publisher(String, f"/pearl/{k}", events) for k in INPUTS}
        spin = lambda t: rclpy.spin_once(node, timeout_sec=t)  # noqa: E731

        # Ready = the recorder subscribed to every topic and the tracker listens to every input.
        wanted = [f"subscribed {t} " for t in RECORD_TOPICS if t not in ("/pearl/say", "/pearl/display",
                                                                         "/goal_pose")]
        wait_until(lambda: all(w in recorder.stderr() for w in wanted), 60, spin, "the recorder's subscriptions")
        wait_until(lambda: all(p.get_subscription_count() >= 2 for p in pubs.values()), 30, spin,
                   "the tracker and recorder to match the inputs")
        wait_until(lambda: len(actions) >= 1, 30, spin, "the first action")

        sim_ns = 1_000_000_000
        script = list(spec["script"])

        def tick(seconds: float) -> None:
            nonlocal sim_ns
            sim_ns += int(seconds * 1e9)
            msg = Clock()
            msg.clock.sec, msg.clock.nanosec = divmod(sim_ns, 1_000_000_000)
            clock_pub.publish(msg)

        tick(0.0)
        steps = 0
        while steps < spec["max_steps"]:
            action = actions[-1]
            answer: Optional[Input] = WORLD.get(action) or spec["answers"].get(action)
            if answer is None:
                if not script:
                    break
                answer = script.pop(0)
            n = len(actions)
            if answer == SILENCE:
                # nobody answers: sim time passes 1 s at a time until the tracker's step timeout
                for _ in range(int(TRACKER_PARAMS["step_timeout"]) + 5):
                    tick(1.0)
                    try:
                        wait_until(lambda: len(actions) > n, 0.5, spin)
                        break
                    except RuntimeError:
                        continue
            else:
                # Sim time moves on 2 s (the tracker's diagnostics timer fires), then 1 s at a
                # time until the tracker reports the step of this action open.
                def step_open() -> bool:
                    return (tracker_state.get("step") == str(len(actions) - 1)
                            and tracker_state.get("open_action") == actions[-1])

                tick(2.0)
                for _ in range(5):
                    try:
                        wait_until(step_open, 2.0, spin)
                        break
                    except RuntimeError:
                        tick(1.0)
                wait_until(step_open, 5.0, spin, f"the tracker to open the step of {action}")
                topic, text = answer
                pubs[topic].publish(String(data=text))
            wait_until(lambda: len(actions) > n, 30, spin, f"an answer to {answer}")
            print(f"  {name}: {action:22s} <- {answer[0]}: {answer[1]!r:45} -> {actions[-1]}", file=sys.stderr)
            steps += 1
        # Stop the recorder only once every action is on disk: it flushes each message, so
        # the bag can be read (salvaged) while it is being written.
        from pearl_pomdp.bags.reader import BagReader
        from pearl_pomdp.nodes.bag_replay import expected_actions

        def on_disk() -> bool:
            try:
                return len(expected_actions(BagReader(out))) >= len(actions)
            except Exception:
                return False

        wait_until(on_disk, 20, spin, "the recorder to write every action")
    finally:
        for p in reversed(procs):
            p.stop(timeout=15.0)
        node.destroy_node()
        rclpy.shutdown()
    return actions


def main(argv: Optional[List[str]] = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--only", choices=sorted(SCENARIOS), help="record one scenario")
    ap.add_argument("--replan", action="store_true", help="plan bags/pearl/policy again")
    ap.add_argument("--domain-id", type=int, help="ROS domain (default: random in 60..100)")
    ap.add_argument("--log-dir", type=Path, help="keep the processes' output here (default: a temporary dir)")
    args = ap.parse_args(argv)
    ensure_policy(args.replan)
    from pearl_pomdp.bags.reader import BagReader
    from pearl_pomdp.nodes.bag_replay import expected_actions

    for name, spec in SCENARIOS.items():
        if args.only and name != args.only:
            continue
        domain_id = args.domain_id or random.randint(60, 100)
        if args.log_dir:
            (args.log_dir / name).mkdir(parents=True, exist_ok=True)
            actions = record(name, spec, domain_id, args.log_dir / name)
        else:
            with tempfile.TemporaryDirectory(prefix=f"pearl_{name}_") as tmp:
                actions = record(name, spec, domain_id, Path(tmp))
        recorded = expected_actions(BagReader(BAGS / name, salvage=False))
        if recorded != actions:
            print(f"{name}: the bag's /pearl/action ({len(recorded)}) differs from what the driver saw "
                  f"({len(actions)}): {recorded} vs {actions}", file=sys.stderr)
            return 1
        (BAGS / f"{name}.expected.json").write_text(json.dumps(
            {"scenario": name, "description": spec["doc"], "expected_actions": actions}, indent=1) + "\n")
        print(f"{name}: {len(actions)} actions recorded in bags/{name}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
