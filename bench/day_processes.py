"""A working day through the Pearl nodes, each in its own process: memory and answer time per hour; one JSON object.

``pearl launch launch/pearl_sim.launch.xml day:=true`` runs the day world (``pearl_sim_world``, which owns
``/clock``) against the belief tracker, the hierarchical policy, the action executor and the lifecycle
supervisor, each a process of its own, as on a robot. This bench watches from outside: at every hour of
simulated time it reads each node process's resident memory (Linux ``/proc/PID/statm``), and it bins the
policy's decision times (``latency_s`` of ``/pearl/decision``, the policy node's own measure from the
belief's arrival to the action's publication) by the hour of the day. It reports, per node, the memory of
the first and the last hour and the growth between them, the decisions' p50 / p99 per hour and the last
hour's p99 against the first's (issue: "each node's RSS grows ≤ 10 % from the first to the last hour;
decision p99 of the last hour within 20 % of the first"), the wall time (start-up and the day apart) and
the day's checklist as the world counted it. Each decision is also paired with the belief it answered
(``belief_step`` of ``/pearl/decision`` with ``step`` of ``/pearl/belief``) and binned by that belief's
support (the states it holds mass on): ``decisions_by_support`` gives p50 / p99 per support band and hour,
so a rise through the day that follows the belief can be told from one that follows the nodes' age.

Time runs ``--rate`` times the wall clock (ticks of ``--clock-period`` wall seconds) and stands still while
the policy decides, so the day is the day world's under the robot's rules, not bit-identical to
``pearl day`` (one process, lock-step clock).

    python bench/day_processes.py [--resident-seed 29] [--resident 1] [--seed 0] [--noise 0.25]
                                  [--until 43200] [--rate 400] [--clock-period 0.005] [--run-dir DIR]
"""
from __future__ import annotations

import argparse
import bisect
import json
import os
import re
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Dict, List, Optional

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
HOUR_S = 3600.0
#: The simulator journals its world as the launch file has it (``--no-sim-journal``: off). Its journal once
#: rewrote every call made on the world (a wait every idle tick) whole every tick, so the day took 189-195 s
#: at load 3.4-4.6 and the decisions' p50 climbed from 1.5 to 3.4 ms through the afternoon; the calls are
#: now appended to the journal's log (pearl_pomdp.journal), and the day costs what it costs without it.
#: Seconds of the day between two /diagnostics summaries of a node (see main).
DIAGNOSTICS_PERIOD = 600.0
NODES = ("belief_tracker", "hierarchical_policy", "action_executor", "lifecycle_supervisor", "pearl_sim_world")


def node_pids(log: Path) -> Dict[str, int]:
    """``{node: pid}`` from ``pearl launch``'s ``[launch] started NODE (pid N)`` and ``[launch] respawned NODE
    (pid N)`` lines (the latest per node: a respawned node's new process)."""
    pids: Dict[str, int] = {}
    for line in log.read_text(errors="replace").splitlines():
        if line.startswith(("[launch] started ", "[launch] respawned ")) and "(pid " in line:
            pids[line.split()[2]] = int(line.rsplit("(pid ", 1)[1].rstrip(")"))
    return pids


def rss_mb(pid: int) -> Optional[float]:
    """A process's resident memory in MB, or None when it is gone (an exited process reads 0)."""
    try:
        pages = int(Path(f"/proc/{pid}/statm").read_text().split()[1])
    except (OSError, IndexError, ValueError):
        return None
    return pages * os.sysconf("SC_PAGE_SIZE") / 1e6 if pages > 0 else None


#: Support bands (states with mass in the belief a decision answered), lower edges: a decision's work in the
#: policy (EXECUTE's products, the belief's conversion) follows its support.
SUPPORT_BANDS = (1, 25, 65, 129, 257)


def support_band(support: int) -> str:
    """The band of :data:`SUPPORT_BANDS` a support size falls in, as ``"lo-hi"`` (the last ``"lo+"``)."""
    i = max(bisect.bisect_right(SUPPORT_BANDS, support) - 1, 0)
    return f"{SUPPORT_BANDS[i]}-{SUPPORT_BANDS[i + 1] - 1}" if i + 1 < len(SUPPORT_BANDS) else f"{SUPPORT_BANDS[i]}+"


def latency_summary(latencies: List[float]) -> Dict[str, float]:
    """``{decisions, p50_ms, p99_ms}`` of decision times in seconds."""
    return {"decisions": len(latencies), "p50_ms": round(float(np.percentile(latencies, 50)) * 1e3, 2),
            "p99_ms": round(float(np.percentile(latencies, 99)) * 1e3, 2)}


def by_support(paired: List[tuple]) -> Dict[str, Dict[str, Dict[str, float]]]:
    """``{band: {hour: {decisions, p50_ms, p99_ms}}}`` from ``(hour, support, latency_s)`` triples, the bands
    from the smallest support up."""
    cells: Dict[str, Dict[int, List[float]]] = {support_band(b): {} for b in SUPPORT_BANDS}
    for hour, support, latency in paired:
        cells[support_band(support)].setdefault(hour, []).append(latency)
    return {band: {f"{8 + h:02d}": latency_summary(v) for h, v in sorted(hours.items())}
            for band, hours in cells.items() if hours}


def summarize(start: Dict[str, float], hourly: Dict[str, List[Optional[float]]],
              decisions: Dict[int, List[float]]) -> Dict[str, object]:
    """Per node: its memory when the clock started and at the end of each hour, and the growth from the
    end of the first hour to the end of the last (and from the start); per hour: decision p50 / p99 (ms)."""
    nodes = {}
    for name, per_hour in hourly.items():
        ends = [m for m in per_hour if m is not None]
        if len(ends) >= 2:
            nodes[name] = {"start_mb": None if start.get(name) is None else round(start[name], 1),
                           "first_hour_mb": round(ends[0], 1), "last_hour_mb": round(ends[-1], 1),
                           "growth": round(ends[-1] / ends[0] - 1.0, 4),
                           "growth_from_start": (round(ends[-1] / start[name] - 1.0, 4) if start.get(name) else None),
                           "per_hour_mb": [None if m is None else round(m, 1) for m in per_hour]}
    hours = sorted(decisions)
    per_hour = {h: latency_summary(decisions[h]) for h in hours}
    out: Dict[str, object] = {"nodes": nodes, "decisions_per_hour": {f"{8 + h:02d}": v for h, v in per_hour.items()}}
    if len(hours) >= 2:
        first, last = per_hour[hours[0]]["p99_ms"], per_hour[hours[-1]]["p99_ms"]
        out["last_vs_first_hour_p99"] = round(last / first, 3) if first else None
    if nodes:
        out["max_node_growth"] = max(n["growth"] for n in nodes.values())
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--domain", default=str(REPO / "config/pearl_day.domain.yaml"))
    ap.add_argument("--policy", default=str(REPO / "config/plans/pearl_day"), help="planned policy directory")
    ap.add_argument("--resident-seed", type=int, default=29)
    ap.add_argument("--resident", type=int, default=1)
    ap.add_argument("--seed", type=int, default=0, help="the day's seed")
    ap.add_argument("--noise", type=float, default=0.25)
    ap.add_argument("--until", type=float, default=12 * HOUR_S, help="seconds of the day to run (from 08:00)")
    ap.add_argument("--rate", type=float, default=400.0)
    ap.add_argument("--clock-period", type=float, default=0.005)
    ap.add_argument("--wall-timeout", type=float, default=3600.0)
    ap.add_argument("--domain-id", type=int, default=None, help="ROS domain id (default: one from this process's id)")
    ap.add_argument("--no-journal", action="store_true", help="journal:=false: no node journals its state")
    ap.add_argument("--no-sim-journal", action="store_true", help="sim_journal:=false: the simulator keeps no journal")
    ap.add_argument("--log-events", action="store_true", help="the simulator logs every event of its world (in the log)")
    ap.add_argument("--kill-simulator-at", type=float, default=None, metavar="S",
                    help="SIGKILL the simulator once its clock has passed S seconds of the day: the launch respawns "
                         "it and it resumes its world from its journal (reported under simulator_killed)")
    ap.add_argument("--run-dir", type=Path, default=None,
                    help="where the launch's log and the nodes' ROS_HOME go (default: a new temporary folder)")
    args = ap.parse_args()

    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from rclpy.signals import SignalHandlerOptions
    from rosgraph_msgs.msg import Clock

    from pearl_interfaces.msg import Belief, Decision
    from pearl_pomdp.nodes.common import EVENT_QOS

    domain_id = args.domain_id if args.domain_id is not None else 1 + (os.getpid() * 7) % 101
    run_dir = args.run_dir if args.run_dir is not None else Path(tempfile.mkdtemp(prefix="pearl_day_processes_"))
    run_dir.mkdir(parents=True, exist_ok=True)
    log = run_dir / "launch.log"
    # The nodes' /diagnostics every 10 minutes of the day, as `pearl day --nodes` has them: their default
    # (every second of the node's clock) is 400 summaries a wall second per node at 400x, load that a
    # robot at 1x never has.
    import yaml

    nodes_params = yaml.safe_load((REPO / "config" / "pearl_nodes.yaml").read_text(encoding="utf-8"))
    for name in ("belief_tracker", "hierarchical_policy", "action_executor"):
        nodes_params.setdefault(name, {}).setdefault("ros__parameters", {})["diagnostics_period"] = DIAGNOSTICS_PERIOD
    params_file = run_dir / "pearl_nodes.yaml"
    params_file.write_text(yaml.safe_dump(nodes_params), encoding="utf-8")
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain_id), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
               ROS_HOME=str(run_dir), ROS_LOG_DIR=str(run_dir))
    env.pop("ROS_LOCALHOST_ONLY", None)
    command = [str(Path(sys.executable).parent / "pearl"), "launch", "launch/pearl_sim.launch.xml", "day:=true",
               f"domain:={args.domain}", f"policy:={args.policy}", f"resident_seed:={args.resident_seed}",
               f"resident:={args.resident}", f"seed:={args.seed}", f"noise:={args.noise}", f"until:={args.until}",
               f"rate:={args.rate}", f"clock_period:={args.clock_period}", f"wall_timeout:={args.wall_timeout}",
               f"log_events:={'true' if args.log_events else 'false'}", f"params_file:={params_file}",
               f"sim_journal:={'false' if args.no_sim_journal or args.no_journal else 'true'}"] + \
        (["journal:=false"] if args.no_journal else [])
    started = time.monotonic()
    with open(log, "wb") as out:
        launch = subprocess.Popen(command, cwd=REPO, env=env, stdout=out, stderr=subprocess.STDOUT)
    context = Context()
    rclpy.init(context=context, domain_id=domain_id, signal_handler_options=SignalHandlerOptions.NO)
    node = rclpy.create_node("day_processes_probe", context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    clock = {"now": 0.0, "first_tick_wall": None}
    decisions: Dict[int, List[float]] = {}
    node.create_subscription(Clock, "/clock", lambda m: clock.__setitem__(
        "now", max(clock["now"], m.clock.sec + m.clock.nanosec * 1e-9)), 10)
    hours = int(np.ceil(args.until / HOUR_S))
    # A decision stamped at the day's very end (the answer to its last step) counts in the last hour.
    # A decision names its belief's step; the two are paired after the day. A step number seen twice (a
    # respawned tracker's new run; this bench kills at most the simulator) keeps the later belief's support.
    supports: Dict[int, int] = {}
    answered: List[tuple] = []          # (hour, belief_step, latency_s)

    def on_decision(m) -> None:
        hour = min(int((m.stamp.sec + m.stamp.nanosec * 1e-9) // HOUR_S), hours - 1)
        decisions.setdefault(hour, []).append(float(m.latency_s))
        answered.append((hour, int(m.belief_step), float(m.latency_s)))

    node.create_subscription(Decision, "/pearl/decision", on_decision, EVENT_QOS)
    node.create_subscription(Belief, "/pearl/belief", lambda m: supports.__setitem__(
        int(m.step), len(m.probabilities) if len(m.support) else int(np.count_nonzero(np.asarray(m.probabilities)))),
        QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE))   # every belief, none dropped
    start: Dict[str, float] = {}
    hourly: Dict[str, List[Optional[float]]] = {name: [None] * hours for name in NODES}

    killed: Dict[str, object] = {}

    def read_all() -> Dict[str, float]:
        return {name: m for name, pid in node_pids(log).items() if name in hourly and (m := rss_mb(pid)) is not None}

    try:
        while launch.poll() is None:
            executor.spin_once(timeout_sec=0.05)
            now = clock["now"]
            if now > 0.0 and clock["first_tick_wall"] is None:
                clock["first_tick_wall"] = time.monotonic()
                start.update(read_all())
            if args.kill_simulator_at is not None and not killed and now >= args.kill_simulator_at:
                pid = node_pids(log).get("pearl_sim_world")
                if pid is not None:
                    os.kill(pid, signal.SIGKILL)
                    killed.update(at_s=round(now, 1), pid=pid)
            if now > 0.0:
                # The hour the clock is in: its end-of-hour reading is the latest one taken in it (the last
                # before the processes end, for the day's last hour).
                hour = min(int(now // HOUR_S), hours - 1)
                for name, mb in read_all().items():
                    hourly[name][hour] = mb
            if time.monotonic() - started > args.wall_timeout + 60:
                raise SystemExit(f"bench/day_processes.py: the launch did not end within {args.wall_timeout + 60:g} s "
                                 f"(log: {log})")
    finally:
        if launch.poll() is None:
            launch.send_signal(signal.SIGINT)
            try:
                launch.wait(30)
            except subprocess.TimeoutExpired:
                launch.kill()
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown(context=context)
    ended = time.monotonic()
    text = log.read_text(errors="replace")
    finished = re.search(r"pearl_sim_world: finished (\S+): (\{.*\})", text)
    report: Dict[str, object] = {"bench": "day_processes", "resident_seed": args.resident_seed,
                                 "resident": args.resident, "seed": args.seed, "noise": args.noise,
                                 "until_s": args.until, "rate": args.rate, "clock_period": args.clock_period,
                                 "journals": {"nodes": not args.no_journal,
                                              "simulator": not (args.no_journal or args.no_sim_journal)},
                                 "exit_code": launch.returncode, "log": str(log),
                                 "startup_s": round((clock["first_tick_wall"] or ended) - started, 1),
                                 "day_wall_s": round(ended - (clock["first_tick_wall"] or ended), 1),
                                 "load_avg_1min": round(os.getloadavg()[0], 2), "cpus": os.cpu_count()}
    if args.kill_simulator_at is not None:
        # The respawned simulator's line "resumed at T s after N actions" (pearl_sim/nursing_home/world_node.py).
        resumed = re.search(r"resumed at ([0-9.]+) s after ([0-9]+) actions", text)
        report["simulator_killed"] = {**killed, "resumed_at_s": float(resumed.group(1)) if resumed else None,
                                      "actions_before": int(resumed.group(2)) if resumed else None}
    report.update(summarize(start, hourly, decisions))
    paired = [(hour, supports[step], latency) for hour, step, latency in answered if step in supports]
    report["decisions_paired_with_belief"] = len(paired)
    report["decisions_by_support"] = by_support(paired)
    if finished:
        world = json.loads(finished.group(2))
        report.update(day=finished.group(1), actions=world.get("actions"), day_score=world.get("day_score"),
                      checklist=world.get("checklist"))
    else:
        report["error"] = "pearl_sim_world did not finish the day (see the log)"
    print(json.dumps(report))
    return 0 if finished and launch.returncode == 0 else 1


if __name__ == "__main__":
    raise SystemExit(main())
