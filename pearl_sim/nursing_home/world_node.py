"""The simulated nursing home as one ROS node, for ``launch/pearl_sim.launch.xml``.

``pearl_sim_world`` runs a scenario's :class:`~pearl_sim.nursing_home.world.World` (the resident, the
scheduler, the robot base) against the Pearl nodes running as *separate processes*, the way
a simulator runs against a robot's stack: it owns the clock (``/clock``, the manager nodes
run with ``use_sim_time:=true``), carries out every action the policy publishes on
``/pearl/action`` and publishes what the world produces — speech, touchscreen, Laser
landmarks, reminders — when the clock reaches each message's time. When the world is idle it
lets time pass (:meth:`World.wait`), so the belief tracker's own timers close silent steps
and drives that never arrive (``navFailed``). When the scenario's ``max_steps`` actions are
done it prints one line ``pearl_sim_world: finished SCENARIO: …`` with the world's scores (JSON)
and exits 0, which ends the launch.

Time runs ``rate`` times faster than the wall clock, in ``/clock`` ticks every
``clock_period`` wall seconds (a message or a deadline lands on the first tick at or after
its time). Unlike ``pearl demo`` (one process, lock-step ``/clock``) the run is therefore not
bit-identical to the fast path, only the same scenario under the same rules.

Parameters: ``scenario`` (str, a scenario file; relative paths also in the package share
directory), ``seed`` (int, −1: the scenario's), ``rate`` (double, 1–1000, default 10),
``clock_period`` (double, 0.005–1 s, default 0.02), ``start_timeout`` (double, s, default 120:
the manager must publish its first action within this, or the node exits 1),
``answer_timeout`` (double, s, default 30: while the clock stands still for the policy, a step the
tracker closed (``/pearl/belief``) must get its action on ``/pearl/action`` within this many wall
seconds, or the node exits 1 with one line naming the step),
``wall_timeout`` (double, s, default 600: the episode must end within this, else exit 1),
``journal`` (str, ``auto``: ``$ROS_HOME/pearl/journal/domain<ID>/pearl_sim_world.json``; ``''``: none)
and ``journal_max_age`` (double, s, default 120), ``log_events`` (bool, false: log every event of the world —
what the resident did, a wrong action, a question answered — with its simulated time).

A working day instead of a scenario (``day`` true; docs/day.md): the day world of ``pearl day`` for the
resident generator's ``resident`` (int, 1-based, default 1) at ``resident_seed`` (int, default 29), the
day's ``seed`` (−1: 0) and the recogniser's word error rate ``noise`` (double, default 0.25), in the
domain ``day_domain`` (str, default ``config/pearl_day.domain.yaml``: the one the manager's nodes run, whose
battery reading this node then publishes too; not ``domain``, which a params file's ``/**`` gives every node); it ends after ``until`` (double, s, default 43,200: the
whole day from 08:00) and prints the nurse's checklist and the day score. ``bench/day_processes.py``
runs it under the launch file and reads each node process's memory per hour.

A simulator that dies loses nothing (docs/reliability.md, "Crashes"): the node journals what it did
to the world — every ``act`` and ``wait`` call in order, the clock, how many of the actions' messages
are still due, the last action's stamp — after every tick that changed any of it (atomic against its
own death; no fsync, since a restart of the simulator, not a power loss, is what it survives). The
world is seeded, so a node started again within ``journal_max_age`` on the same scenario and seed
replays those calls on a fresh world and has the very state that died (the resident, the scheduler,
the base, every random stream; nothing is unpickled — plain JSON; the calls and actions are appended
to the journal's log, so a tick's write costs the same at 19:00 as at 08:00); once it has heard the
tracker's latched belief and the policy's latched action (so it knows which steps are closed, and no
action can be published before its subscription matched) its clock goes on one tick after
the journal's, the latched last action is not carried out twice, and the manager's nodes see only a
pause. The journal is removed when the episode ends or the node is stopped cleanly, so a new launch
starts afresh.

Publishers: ``/clock`` (rosgraph_msgs/Clock) and the nursing home's simulated hardware, the frame's
(:class:`pearl_sim.nodes.SimulatedHardware`, as ``pearl demo`` has it, here publishing from this node):
``/pearl/speech`` (pearl_interfaces/RecognisedSpeech, as Pearl's domain declares it),
``/pearl/touchscreen``, ``/pearl/laser``, ``/pearl/reminder`` (std_msgs/String), ``/pearl/sim/said``
(std_msgs/String: what the resident actually said), ``/pearl/sim/truth`` (pearl_interfaces/WorldTruth,
the true state at the start and end of every action), all reliable, and with each true state
``/pearl/pose`` (geometry_msgs/PoseStamped, the robot's place in the scenario's map).
Subscribers: ``/pearl/action`` (pearl_interfaces/Action, TRANSIENT_LOCAL like the policy's publisher, but
keeping up to :data:`ACTIONS_KEPT` actions not yet taken: every action is carried out, also two that
come back to back), and ``/pearl/belief`` (pearl_interfaces/Belief: the steps the tracker closed).

Why every action must arrive: the world tells "the policy is deciding" (hold the clock) from "the
step is running" by counting, the tracker's closed steps against the actions it carried out. Had it
missed one action, then once it carried out the next its count would equal the tracker's closed
steps: it would hold the clock for an answer while the tracker's open step waits for an
observation or a deadline under that very clock, and nothing would move. The policy's publisher
keeps only its latest action (depth 1, for late joiners); a reader of depth 1 keeps only the second
of two actions that arrive before its executor takes the first. Two come that close whenever the
tracker closes a step the moment an action opens it (an observation was queued: the reminder heard
while no step was open) and the policy answers at once — well within a millisecond, so on a loaded
machine often before the world's process runs again. ``answer_timeout`` bounds whatever else leaves
a closed step unanswered (a policy that died and was not brought back, an operator who never
confirms).
"""
from __future__ import annotations

import json
import sys
import time
from collections import deque
from pathlib import Path
from typing import Deque, List, Optional

__all__ = ["SimWorldNode", "main", "ACTIONS_KEPT"]

#: Actions the world's ``/pearl/action`` reader keeps until it takes them (see the module doc); far
#: more than a policy answering one step at a time ever has in flight.
ACTIONS_KEPT = 100


def _make_node_class():
    from rclpy.node import Node

    from pearl_pomdp.nodes.common import LATCHED_QOS

    class SimWorldNode(Node):
        """See the module doc."""

        def __init__(self, **kwargs):
            super().__init__("pearl_sim_world", **kwargs)
            from rosgraph_msgs.msg import Clock

            from pearl_pomdp.nodes.common import resolve_path
            from pearl_sim.nodes import SimulatedHardware
            from pearl_sim.nursing_home.scenario import load_scenarios
            from pearl_sim.nursing_home.world import World

            declare = self.declare_parameter
            scenario_path = declare("scenario", "config/scenarios/figure4.yaml").value
            seed = int(declare("seed", -1).value)
            self.rate = float(declare("rate", 10.0).value)
            self.clock_period = float(declare("clock_period", 0.02).value)
            self.start_timeout = float(declare("start_timeout", 120.0).value)
            self.answer_timeout = float(declare("answer_timeout", 30.0).value)
            self.wall_timeout = float(declare("wall_timeout", 600.0).value)
            journal_path = str(declare("journal", "auto").value).strip()
            journal_max_age = float(declare("journal_max_age", 120.0).value)
            for name, value, lo, hi in (("rate", self.rate, 1.0, 1000.0), ("clock_period", self.clock_period, 0.005, 1.0),
                                        ("start_timeout", self.start_timeout, 1.0, 86400.0),
                                        ("answer_timeout", self.answer_timeout, 1.0, 86400.0),
                                        ("wall_timeout", self.wall_timeout, 1.0, 86400.0)):
                if not lo <= value <= hi:
                    raise ValueError(f"parameter {name}: {value} is outside [{lo}, {hi}]")
            # A working day instead of an episode (docs/day.md): her routine from the resident generator.
            self.day = bool(declare("day", False).value)
            day_params = {"resident_seed": int(declare("resident_seed", 29).value),
                          "resident": int(declare("resident", 1).value),
                          "noise": float(declare("noise", 0.25).value),
                          "domain": str(declare("day_domain", "config/pearl_day.domain.yaml").value)}
            self.until = float(declare("until", 12 * 3600.0).value)
            #: Log every world event (what the resident did, a wrong action, a question answered) as it happens.
            self.log_events = bool(declare("log_events", False).value)
            domain = None
            if self.day:
                path, ident, domain = self._day_world(seed, day_params)
            else:
                path = resolve_path(scenario_path, "scenario")
                self.scenario = load_scenarios(path)[0]
                self.world = World(self.scenario, seed=None if seed < 0 else seed)
                ident = Path(path).read_bytes()
            self.journal = None
            if journal_path:
                import os

                from pearl_pomdp.journal import Journal, default_path, domain_hash

                where = (default_path("pearl_sim_world", int(os.environ.get("ROS_DOMAIN_ID", "0") or 0))
                         if journal_path == "auto" else Path(journal_path))
                # Tied to the scenario (file bytes, or the day's parameters) and the seed: another run's journal is refused.
                ident += f"\nseed={self.world.seed}".encode()
                self.journal = Journal(where, "pearl_sim_world", str(path), domain_hash(ident),
                                       max_age=journal_max_age, sync="none")
            self._Clock = Clock
            self.clock_pub = self.create_publisher(Clock, "/clock", 10)
            # The world's inputs, said text, true state and pose go out as pearl demo's do: one hardware for both.
            self.hardware = SimulatedHardware(self.context, self.world, domain, node=self)
            self.truth_pub = self.hardware.truth   # what pearl fit counts from when /pearl/sim/truth is recorded
            from rclpy.qos import QoSProfile

            from pearl_interfaces.msg import Action

            every_action = QoSProfile(depth=ACTIONS_KEPT, history=LATCHED_QOS.history,
                                      reliability=LATCHED_QOS.reliability, durability=LATCHED_QOS.durability)
            self.create_subscription(Action, "/pearl/action", self._on_action, every_action)
            # The tracker's step count: a step it closed is answered by the policy; while that
            # answer is in flight the clock stands still (as the lock-step driver of pearl demo
            # does), so no time passes that the fast path would not have.
            from pearl_interfaces.msg import Belief

            self.create_subscription(Belief, "/pearl/belief", self._on_belief, LATCHED_QOS)
            self.closed_steps = 0
            self.actions: Deque = deque()    # (stamp, name) as published
            self.pending: Deque = deque()    # world messages not yet due
            self.taken: List[str] = []
            self.calls: List[list] = []       # every act/wait call on the world, in order (the journal)
            self.last_taken_stamp: Optional[List[int]] = None
            self.now = 0.0
            self.held_since: Optional[float] = None   # wall clock when the clock last stopped for the policy
            self.started = False
            self.resumed = False
            # What a resumed node must hear before its clock runs (see _ready): the latched belief (the
            # tracker's closed steps) and an action (the latched one proves the action topic matched).
            self.belief_heard = False
            self.action_heard = False
            self.finished = False
            self.failed: Optional[str] = None
            self.t0 = time.monotonic()
            if self.journal is not None:
                state = self.journal.load()
                self.get_logger().info(f"pearl_sim_world: {state.reason}")
                if state.state is not None:
                    self._restore(state.state)
            self.create_timer(self.clock_period, self._tick)
            self.get_logger().info(f"simulating {self.scenario.name} (seed {self.world.seed}) at {self.rate:g}x; "
                                   + (f"resumed at {self.now:.1f} s after {len(self.taken)} actions"
                                      if self.resumed else "waiting for the manager's first action"))

        def _day_world(self, seed: int, params: dict):
            """The day world of ``pearl day`` (its resident, day seed and noise): (domain path, journal
            identity, domain). Raises ``ValueError`` naming the parameter that is out of range."""
            from pearl_pomdp.model.domain_yaml import load_domain
            from pearl_pomdp.nodes.common import resolve_path
            from pearl_sim.nursing_home.day import DAY_SECONDS
            from pearl_sim.nursing_home.day_study import day_world, generated_case
            from pearl_sim.nursing_home.residents import MAX_GENERATED

            if not 1 <= params["resident"] <= MAX_GENERATED:
                raise ValueError(f"parameter resident: {params['resident']} is outside [1, {MAX_GENERATED}]")
            if not 0.0 <= params["noise"] <= 1.0:
                raise ValueError(f"parameter noise: {params['noise']} is outside [0, 1] (a word error rate)")
            if not 0.0 < self.until <= DAY_SECONDS:
                raise ValueError(f"parameter until: {self.until} is outside (0, {DAY_SECONDS:g}] s of the day")
            day_seed = max(seed, 0)
            path = resolve_path(params["domain"], "day_domain")
            domain = load_domain(path)
            self.world = day_world(generated_case(params["resident_seed"], params["resident"], day_seed), domain,
                                   params["noise"])
            self.scenario = self.world.scenario
            ident = json.dumps({**params, "day_seed": day_seed, "until": self.until}, sort_keys=True).encode()
            return path, ident, domain

        # -------------------------------------------------------------- journal
        def _save(self) -> None:
            """The world's state, for a restart (see the module doc); a failed write is logged, never fatal."""
            if self.journal is None:
                return
            state = {"pending": len(self.pending), "last_taken_stamp": self.last_taken_stamp, "now": self.now}
            try:
                # The calls and the actions only grow: appended to the journal's log, not rewritten
                # (a day has tens of thousands of calls; pearl_pomdp.journal's module doc).
                self.journal.write(state, growing={"calls": self.calls, "taken": self.taken})
            except OSError as err:
                self.get_logger().warning(f"journal {self.journal.path}: {err}", once=True)

        def _restore(self, state: dict) -> None:
            """Replay the journal's calls on the fresh world (seeded: the same draws, the same state)."""
            produced: List = []
            for call, arg in state["calls"]:
                if call == "act":
                    produced.extend(self.world.act(str(arg)).messages)
                else:
                    self.world.wait(float(arg))      # its messages went out when it ran
            self.calls = [list(c) for c in state["calls"]]
            due = int(state["pending"])
            self.pending = deque(produced[len(produced) - due:] if due else [])
            self.taken = list(state["taken"])
            self.last_taken_stamp = state["last_taken_stamp"]
            # One tick on: the clock never goes back (the last tick may have been published unjournaled).
            self.now = float(state["now"]) + self.rate * self.clock_period
            self.resumed = True

        def _drop_journal(self) -> None:
            if self.journal is not None:
                try:
                    self.journal.remove()
                except OSError:
                    pass

        # --------------------------------------------------------------- inputs
        def _on_action(self, msg) -> None:
            first, self.action_heard = not self.action_heard, True
            stamp = [int(msg.stamp.sec), int(msg.stamp.nanosec)]
            if self.resumed and first and stamp == self.last_taken_stamp:
                # The latched action this world carried out before it was restarted: only the first
                # action a resumed node hears can be that one. A later action may carry the same stamp
                # (decided while the clock stood still) and is new; dropping it stopped a resumed day
                # 960 actions later, waiting for an answer it had thrown away.
                return
            self.actions.append((stamp, msg.name.strip()))

        def _on_belief(self, msg) -> None:
            self.belief_heard = True
            self.closed_steps = max(self.closed_steps, int(msg.step))

        def _publish(self, message) -> None:
            # As pearl demo's GraphBackend delivers one: what was said first, then the input.
            if message.said:
                self.hardware.publish_said(message.said)
            publisher, msg = self.hardware.outgoing(message)
            publisher.publish(msg)

        def _publish_clock(self) -> None:
            from pearl_pomdp.nodes.conversions import seconds_to_time

            self.clock_pub.publish(self._Clock(clock=seconds_to_time(self.now)))

        # ----------------------------------------------------------------- loop
        def _ready(self) -> bool:
            """The manager answered b0 (or, resumed, is still there) and our inputs reach its tracker."""
            return not self._waiting_for() and all(p.get_subscription_count() > 0
                                                   for p in self.hardware.publishers.values())

        def _waiting_for(self) -> List[str]:
            """What the node has not heard from the manager yet and needs before its clock runs.

            A fresh node waits for the answer to b0. A resumed one waits for the tracker's latched belief
            and for an action (the latched last one, which proves the action topic matched): until the
            belief comes it cannot know whether the step it last carried out is closed (its count starts
            at 0, so the clock would run on past the robot's unanswered steps), and actions published
            before the topic matched would be lost (a day once stopped at step 695 with 692 actions
            carried out, its clock having run on for 40 s without them)."""
            if not self.resumed:
                return [] if self.actions else ["the answer to b0 on /pearl/action"]
            return ([] if self.belief_heard else ["the tracker's latched /pearl/belief"]) + \
                ([] if self.action_heard else ["the policy's latched /pearl/action"])

        def _tick(self) -> None:
            if self.finished:
                return
            wall = time.monotonic() - self.t0
            if not self.started:
                if self._ready():
                    self.started = True
                    self.t0 = time.monotonic()
                    self.get_logger().info("the manager is up: starting the clock")
                elif wall > self.start_timeout:
                    missing = self._waiting_for()
                    if not missing:
                        what = "the manager's tracker did not subscribe to the simulated inputs"
                    elif self.resumed:
                        what = f"resumed, but {' and '.join(missing)} did not come"
                    else:
                        what = "no first action on /pearl/action came"
                    self._finish(f"{what} within {self.start_timeout:g} s")
                else:
                    self._publish_clock()   # time 0 (or the journal's) until the manager is up
                return
            if wall > self.wall_timeout:
                self._finish(f"the episode did not end within {self.wall_timeout:g} wall seconds")
                return
            before = (self.now, len(self.calls), len(self.pending))
            self._advance()
            if not self.finished and (self.now, len(self.calls), len(self.pending)) != before:
                self._save()

        def _advance(self) -> None:
            """One tick of the running world: the next action, or the messages due and then the clock.

            The order is the fast path's (``pearl_sim.loop.run_episode``), as far as ticks allow:
            an answer that came while the clock stood still is carried out at once, at the time it
            was decided; what the world produced for a time inside the tick (an action's messages,
            what she said or the scheduler announced while the robot waited) goes out before the
            clock passes that time, so a step's deadline inside the tick never overtakes it; and an
            answer waiting for the last of its action's messages is carried out when the world got
            there, not a tick later. Otherwise what she said between the decision and the action
            reached the tracker after the action had opened its step, and closed it — a walk's
            step closed by a word of hers, then a silent step every 8 s for the rest of the walk
            (docs/day.md)."""
            answered = self.closed_steps >= len(self.taken)   # every step taken is closed
            if answered and (self.now >= self.until if self.day else len(self.taken) >= self.scenario.max_steps):
                self._finish(None)
                return
            if answered and self.actions and not self.pending:
                self.held_since = None
                if self.world.time > self.now:    # the last action ran on past its last message
                    self.now = self.world.time
                    self._publish_clock()
                self._take(*self.actions.popleft())
                return
            if answered and not self.actions:
                self._hold()   # the policy is deciding: hold the clock until its action arrives
                return
            self.held_since = None
            target = self.now + self.rate * self.clock_period
            # Messages that fall due in this tick: the world produced them for these times.
            while self.pending and self.pending[0].time <= target + 1e-9:
                self._publish(self.pending.popleft())
            if not self.pending and self.actions and answered:
                target = max(self.now, self.world.time)   # the answer is carried out where the world got to
            elif not self.pending and self.world.time < target:
                self._idle(target)
            self.now = target
            self._publish_clock()
            if not self.pending and self.actions and answered:
                self._take(*self.actions.popleft())

        def _take(self, stamp, action: str) -> None:
            """Carry out ``action`` at the clock's time (the world first lives up to it, if behind)."""
            self.last_taken_stamp = stamp
            if self.world.time < self.now:
                self._idle(self.now)
            self.hardware.publish_truth(self.now, "start", action)
            try:
                result = self.world.act(action)
                self.calls.append(["act", action])
                self._log_events(action, result)
            except ValueError as err:
                self._finish(f"/pearl/action {action!r}: {err}")
                return
            self.hardware.publish_truth(self.now, "end", action, result)
            self.taken.append(action)
            self.pending.extend(result.messages)
            while self.pending and self.pending[0].time <= self.now + 1e-9:
                self._publish(self.pending.popleft())

        def _hold(self) -> None:
            """The clock stands still for the policy's answer: at most ``answer_timeout`` wall seconds."""
            if self.held_since is None:
                self.held_since = time.monotonic()
            elif time.monotonic() - self.held_since > self.answer_timeout:
                last = f", the last {self.taken[-1]!r}" if self.taken else ""
                self._finish(f"no action on /pearl/action answered step {self.closed_steps} (closed on /pearl/belief) "
                             f"within answer_timeout {self.answer_timeout:g} wall seconds; the world carried out "
                             f"{len(self.taken)} action(s){last}")

        def _idle(self, until: float) -> None:
            """The robot waits: the world lives on (the scheduler may speak) until ``until``."""
            waited = self.world.wait(until)
            self.calls.append(["wait", until])
            self._log_events("", waited)
            for message in waited.messages:
                self._publish(message)

        def _log_events(self, action: str, result) -> None:
            if self.log_events and (result.events or result.wrong):
                what = "; ".join(result.events + ([f"wrong: {result.wrong}"] if result.wrong else []))
                self.get_logger().info(f"world {result.start:.1f}-{result.end:.1f} s {action or '(waiting)'}: {what}")

        def _finish(self, failure: Optional[str]) -> None:
            self.finished = True
            self.failed = failure
            self._drop_journal()   # the episode is over: a new launch starts afresh

        def summary(self) -> dict:
            if self.day:   # the nurse's checklist of the day (so far, with until)
                from pearl_sim.nursing_home.day import DayWorld, day_score

                assert isinstance(self.world, DayWorld)
                checklist = self.world.checklist()
                return {"scenario": self.scenario.name, "seed": self.world.seed, "actions": len(self.taken),
                        "sim_seconds": round(self.now, 3), "day_score": round(day_score(checklist), 2),
                        "checklist": checklist}
            m = self.world.metrics
            return {"scenario": self.scenario.name, "seed": self.world.seed, "actions": len(self.taken),
                    "sim_seconds": round(self.now, 3), "guidances_started": m.guidances_started,
                    "guidances_completed": m.guidances_completed, "residents_lost": m.residents_lost,
                    "blocked_drives": m.blocked_drives, "reminders_delivered": m.reminders_delivered,
                    "questions_answered": m.questions_answered,
                    "wrong_actions": m.wrong_actions, "first_actions": self.taken[:12]}

    return SimWorldNode


def main(args: Optional[List[str]] = None) -> int:
    """Console script ``pearl_sim_world``: 0 when the episode ended, 1 on a timeout, 2 on a bad parameter."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor

    from pearl_pomdp.errors import PearlError
    from pearl_pomdp.nodes.common import NodeSetupError, one_line_error

    rclpy.init(args=args if args is not None else sys.argv)
    node = None
    executor = SingleThreadedExecutor()
    try:
        try:
            node = _make_node_class()()
        except (ValueError, PearlError, NodeSetupError, OSError, rclpy.exceptions.ParameterException) as err:
            print(f"pearl_sim_world: error: {one_line_error(err)}", file=sys.stderr, flush=True)
            return 2
        executor.add_node(node)
        while rclpy.ok() and not node.finished:
            executor.spin_once(timeout_sec=0.1)
        if node.failed:
            print(f"pearl_sim_world: error: {node.failed}", file=sys.stderr, flush=True)
            return 1
        print(f"pearl_sim_world: finished {node.scenario.name}: {json.dumps(node.summary())}", flush=True)
        return 0
    except KeyboardInterrupt:
        if node is not None:
            node._drop_journal()   # stopped on purpose: nothing to resume
        return 0
    finally:
        executor.shutdown()
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()


if __name__ == "__main__":
    sys.exit(main())
