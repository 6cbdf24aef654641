"""Fault injection on the launched graph, printed as ONE JSON object (docs/reliability.md, "Crashes").

Each trial runs the Figure 4 scenario through ``pearl launch launch/pearl_sim.launch.xml
rate:=RATE policy:=DIR`` (tracker, policy, executor, lifecycle supervisor and the simulated world
as processes over Fast DDS) and SIGKILLs one node — the tracker, the policy node, the executor or
the simulated hardware (``pearl_sim_world``: the resident, the scheduler, the base and the clock),
in turn — at a random moment (seeded) of the episode's first ``--window`` wall seconds. The
launcher respawns it; the supervisor re-activates a manager node, the simulator resumes its world
from its journal and starts its clock again. Per trial: whether the
episode still delivered the reminder, completed the walk and answered the question (the world's
scores), whether the guidance was closed (``TerminateGuidance``: "We have arrived"), the time
from the kill to the node being active again (the supervisor's line), and the
*repeated actions*: actions beyond one per belief the tracker published (each belief, named by
its run and step, is answered once; a resumed tracker's repeated belief must not be answered again). The
same is run with ``journal:=false`` (``--no-journal-trials``) to show what is lost without the
journal: reported, not asserted.

A ``pearl record`` beside each launch records every topic but /rosout. Per trial also: whether the
recorder was still running at the episode's end (it survived the kill), whether ``pearl bag-info``
reads the bag and it holds messages logged after the kill, and what ``pearl replay`` makes of it
(exit code, whether its actions match the recorded ones: reported, not asserted, since the
recorded run had a crash and the replay has none).

    .venv/bin/python bench/fault_injection.py [--trials 30] [--no-journal-trials 6] [--seed 0] [--rate 20.0]
"""
from __future__ import annotations

import argparse
import json
import os
import re
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Dict, List, Optional, Tuple

import numpy as np

REPO = Path(__file__).resolve().parents[1]
BIN = Path(sys.executable).parent
KINDS = ("belief_tracker", "hierarchical_policy", "action_executor", "pearl_sim_world")
#: The simulator is not a managed node: it is back when it starts its clock again.
BACK = {"pearl_sim_world": "the manager is up: starting the clock"}
FINISHED = re.compile(r"pearl_sim_world: finished \S+: (\{.*\})")


def _policy(tmp: Path) -> Path:
    """A planned Pearl policy (planned once, ~5 s)."""
    from pearl_pomdp.hierarchy import load_hierarchy, plan
    from pearl_pomdp.model.domain_yaml import load_domain

    domain = load_domain(REPO / "config" / "pearl.domain.yaml")
    out = tmp / "policy"
    plan(domain, load_hierarchy(REPO / "config" / "pearl.hierarchy.yaml", domain)).save(out)
    return out


class _Lines:
    """The launch's output lines with the monotonic time each arrived."""

    def __init__(self, proc: subprocess.Popen):
        self.lines: List[Tuple[float, str]] = []
        self.threads = [threading.Thread(target=self._read, args=(s,), daemon=True) for s in (proc.stdout, proc.stderr)]
        for t in self.threads:
            t.start()

    def _read(self, stream) -> None:
        for raw in iter(stream.readline, b""):
            self.lines.append((time.monotonic(), raw.decode("utf-8", errors="replace").rstrip("\n")))

    def first(self, needle: str, after: float = 0.0) -> Optional[float]:
        return next((t for t, line in list(self.lines) if t >= after and needle in line), None)

    def pid(self, name: str) -> Optional[int]:
        found = [int(m.group(1)) for _, line in list(self.lines)
                 if (m := re.search(rf"\[launch\] (?:started|respawned) {name} \(pid (\d+)\)", line))]
        return found[-1] if found else None

    def text(self) -> str:
        return "\n".join(line for _, line in list(self.lines))


def trial(index: int, kind: str, kill_after: float, rate: float, policy: Path, journal: bool, tmp: Path,
          timeout: float, domain_ids: Optional[Tuple[int, int]] = None) -> dict:
    """One episode with one SIGKILL (see the module doc); ``domain_ids``: the ROS domains of the
    launch and of the bag's replay (default: two of 102..149, from the pid and ``index``)."""
    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.signals import SignalHandlerOptions

    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

    from pearl_pomdp.nodes import conversions as cv

    # Every message, also the latched first ones (a reader that joined late gets them).
    DEEP = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)

    home = tmp / f"trial{index}_{'journal' if journal else 'nojournal'}"
    home.mkdir(parents=True)
    # 102..149: above the suite's 1..101, below the 150..229 of test_one_loop (a stranger's latched action
    # on the same domain would be taken for this graph's).
    domain_id = 102 + (os.getpid() * 7 + index * 13) % 48
    replay_domain_id = 102 + (domain_id - 102 + 24) % 48
    if domain_ids is not None:
        domain_id, replay_domain_id = domain_ids
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain_id), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
               ROS_HOME=str(home), ROS_LOG_DIR=str(home / "log"), PYTHONUNBUFFERED="1",
               FASTRTPS_DEFAULT_PROFILES_FILE=str(REPO / "config" / "fastdds_profile.xml"))
    env.pop("ROS_LOCALHOST_ONLY", None)
    context = Context()
    rclpy.init(context=context, domain_id=domain_id, signal_handler_options=SignalHandlerOptions.NO)
    node = rclpy.create_node("fault_probe", context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    keys: set = set()
    actions: List[str] = []
    node.create_subscription(cv.BeliefMsg, "/pearl/belief", lambda m: keys.add(cv.msg_to_belief_key(m)), DEEP)
    node.create_subscription(cv.ActionMsg, "/pearl/action", lambda m: actions.append(cv.msg_to_action(m)), DEEP)
    bag = home / "bag"
    recorder = subprocess.Popen([str(BIN / "pearl"), "record", str(bag), "--exclude", "/rosout", "--custom-data",
                                 f"pearl.domain={REPO / 'config' / 'pearl.domain.yaml'}", f"pearl.policy={policy}"],
                                env=env, cwd=str(REPO), stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                                stdin=subprocess.DEVNULL)
    cmd = [str(BIN / "pearl"), "launch", "launch/pearl_sim.launch.xml", f"rate:={rate}", f"policy:={policy}",
           f"journal:={'true' if journal else 'false'}"]
    proc = subprocess.Popen(cmd, env=env, cwd=str(REPO), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            stdin=subprocess.DEVNULL)
    lines = _Lines(proc)
    out: Dict = {"kind": kind, "journal": journal, "kill_after_s": round(kill_after, 3)}
    try:
        deadline = time.monotonic() + timeout
        started = None
        while started is None and proc.poll() is None and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.05)
            started = lines.first("the manager is up: starting the clock")
        if started is None:
            out["error"] = "the episode never started"
            return out
        while time.monotonic() < started + kill_after and proc.poll() is None:
            executor.spin_once(timeout_sec=0.02)
        pid = lines.pid(kind)
        killed = time.monotonic()
        if pid is None or proc.poll() is not None:
            out["error"] = "the episode ended before the kill" if proc.poll() is not None else f"no pid for {kind}"
            return out
        os.kill(pid, signal.SIGKILL)
        killed_ns = time.time_ns()
        while proc.poll() is None and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.05)
        if proc.poll() is None:
            out["error"] = f"the episode did not end within {timeout:g} s"
        active = lines.first(BACK.get(kind, f"{kind} is active"), after=killed)
        out["recover_s"] = None if active is None else round(active - killed, 3)
        scores = next((json.loads(m.group(1)) for _, line in lines.lines if (m := FINISHED.search(line))), None)
        out["scores"] = scores
        out["completed"] = bool(scores and scores["reminders_delivered"] >= 1 and scores["guidances_completed"] >= 1
                                and scores["questions_answered"] >= 1)
        # Each belief (run, step) is answered by one action: more actions than beliefs are repeats.
        # (Counted over the whole run: an action and its belief travel on two topics, in either order.)
        # The topics keep one message for a late reader, so the probe can miss a message a respawned node
        # published before the probe matched it: beliefs are counted by their numbers (steps 0..n of each
        # run), actions as the most of what the probe and the world saw.
        steps: Dict[int, int] = {}
        for run, step in filter(None, keys):
            steps[run] = max(step, steps.get(run, -1))
        world = scores["actions"] if scores else 0
        out["actions"], out["beliefs"] = max(len(actions), world), sum(n + 1 for n in steps.values())
        out["actions_seen"], out["beliefs_seen"] = len(actions), len(keys)
        out["repeated_actions"] = max(0, out["actions"] - out["beliefs"])
        out["resumed"] = (f"{kind}: resuming from journal" if kind in BACK else "resuming from journal") in lines.text()
        # What a tracker that forgot loses: the guidance's end ("We have arrived") is never said.
        out["guidance_closed"] = "TerminateGuidance" in actions + (scores or {}).get("first_actions", [])
        out.update(_bag_check(recorder, bag, killed_ns, policy, env, replay_domain_id))
        return out
    finally:
        _stop(proc)
        _stop(recorder)
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown(context=context)


def _stop(child: subprocess.Popen) -> None:
    """SIGINT a child still running; SIGKILL it after 30 s."""
    if child.poll() is None:
        child.send_signal(signal.SIGINT)
        try:
            child.wait(30)
        except subprocess.TimeoutExpired:
            child.kill()
            child.wait(10)


def _bag_check(recorder: subprocess.Popen, bag: Path, killed_ns: int, policy: Path, env: dict,
               replay_domain_id: int) -> dict:
    """The trial's bag (``pearl record`` beside the launch, all topics but /rosout): whether the
    recorder was still running when the episode ended (it survived the kill), whether ``pearl
    bag-info`` reads the bag and it holds messages logged after the kill, and what ``pearl replay``
    makes of it (its exit code: 0 same actions, 1 other actions, 2 unreadable; reported, not
    asserted: the recorded run had a crash in it, the replay has none)."""
    out: Dict = {"recorder_survived": recorder.poll() is None}
    _stop(recorder)
    info = subprocess.run([str(BIN / "pearl"), "bag-info", str(bag), "--json"], capture_output=True, text=True,
                          cwd=str(REPO), timeout=120)
    out["bag_read"] = info.returncode == 0
    if info.returncode == 0:
        summary = json.loads(info.stdout)
        out["bag_messages"] = summary["message_count"]
        out["bag_after_kill"] = summary["end_ns"] > killed_ns
    else:
        out["bag_error"] = (info.stderr.strip().splitlines() or ["?"])[-1]
        return out
    replay_env = dict(env, ROS_DOMAIN_ID=str(replay_domain_id))
    try:
        replay = subprocess.run([str(BIN / "pearl"), "replay", str(bag), "--json", "--domain-id", str(replay_domain_id)],
                                capture_output=True, text=True, cwd=str(REPO), env=replay_env, timeout=600)
    except subprocess.TimeoutExpired:
        out["replay_exit"] = None
        return out
    out["replay_exit"] = replay.returncode
    if replay.returncode in (0, 1):
        result = json.loads(replay.stdout)
        out["replay_match"] = result["match"]
        out["replay_actions"], out["recorded_actions"] = len(result["actions"]), len(result["expected_actions"])
    else:
        out["replay_error"] = (replay.stderr.strip().splitlines() or ["?"])[-1]
    return out


def _summary(results: List[dict]) -> dict:
    out = {}
    for kind in KINDS:
        rows = [r for r in results if r["kind"] == kind]
        rec = [r["recover_s"] for r in rows if r.get("recover_s") is not None]
        out[kind] = {"trials": len(rows), "completed": sum(bool(r.get("completed")) for r in rows),
                     "errors": [r["error"] for r in rows if "error" in r],
                     "recover_p50_s": round(float(np.percentile(rec, 50)), 3) if rec else None,
                     "recover_p99_s": round(float(np.percentile(rec, 99)), 3) if rec else None,
                     "guidance_closed": sum(bool(r.get("guidance_closed")) for r in rows),
                     "repeated_actions": sum(r.get("repeated_actions", 0) for r in rows),
                     "max_repeated_in_a_trial": max((r.get("repeated_actions", 0) for r in rows), default=0),
                     "recorder_survived": sum(bool(r.get("recorder_survived")) for r in rows),
                     "bags_read_with_messages_after_the_kill": sum(bool(r.get("bag_read") and r.get("bag_after_kill"))
                                                                   for r in rows),
                     "bags_replayed": sum(r.get("replay_exit") in (0, 1) for r in rows),
                     "replays_matching_the_recorded_actions": sum(bool(r.get("replay_match")) for r in rows)}
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trials", type=int, default=30, help="trials with the journal (kinds in turn)")
    ap.add_argument("--no-journal-trials", type=int, default=6, help="the same with journal:=false")
    ap.add_argument("--seed", type=int, default=0, help="seed of the kill moments")
    ap.add_argument("--rate", type=float, default=20.0, help="sim seconds per wall second")
    ap.add_argument("--window", type=float, default=12.0, help="kill within this many wall seconds of the start")
    ap.add_argument("--timeout", type=float, default=240.0, help="wall seconds a trial may take")
    ap.add_argument("--policy", type=Path, default=None, help="planned policy directory (default: plan now)")
    args = ap.parse_args()
    rng = np.random.default_rng(args.seed)
    start = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="pearl-faults-") as tmpdir:
        tmp = Path(tmpdir)
        # Absolute: the recorder writes it into the bag, and a relative one would be read against the bag.
        policy = args.policy.resolve() if args.policy else _policy(tmp)
        runs = {True: [], False: []}
        for journal, n in ((True, args.trials), (False, args.no_journal_trials)):
            for i in range(n):
                kind = KINDS[i % len(KINDS)]
                result = trial(i, kind, float(rng.uniform(0.5, args.window)), args.rate, policy, journal, tmp,
                               args.timeout)
                runs[journal].append(result)
                print(json.dumps(result), file=sys.stderr, flush=True)
    print(json.dumps({"scenario": "figure4", "rate": args.rate, "seed": args.seed, "window_s": args.window,
                      "with_journal": _summary(runs[True]), "without_journal": _summary(runs[False]),
                      "trials": runs[True] + runs[False], "seconds": round(time.perf_counter() - start, 1)}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
