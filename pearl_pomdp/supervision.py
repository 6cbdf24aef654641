"""Keeping a graph of managed nodes up, as Nav2's lifecycle manager does (ROS-free).

:class:`Supervisor` decides; the ``lifecycle_supervisor`` node (:mod:`pearl_pomdp.nodes.supervisor`)
asks each managed node for its lifecycle state every heartbeat period (``~/get_state``) and
makes the transitions it is told to (``~/change_state``). The rules:

* **In order.** The nodes are brought up (``configure``, then ``activate``) in the order given,
  each once those before it are active (or left down): Pearl's executor, then the policy,
  then the tracker, whose first belief starts the loop. Later, one transition at a time, a
  node that was up once does not hold back the others.
* **Heartbeat.** A node that answered before and has not answered for ``heartbeat_timeout``
  seconds is *down* (its process died or hangs); one line says so. A node in a transition is
  not judged (a configure that plans a policy takes seconds and answers nothing meanwhile).
* **Restart.** A node comes back — respawned by the launcher (``respawn="true"``): it answers
  again, ``unconfigured`` — and is configured and activated again; so is a node found
  ``unconfigured`` or ``inactive`` while it should be active (it restarted faster than the
  heartbeat noticed).
* **No loop.** Each comeback and each failed transition uses one of ``max_restarts`` within
  ``restart_window`` seconds; a node that needs more is *left down*: reported, never touched
  again (the launcher stops respawning it too: ``pearl launch --respawn-max-retries``). A
  transition that fails at a node's first bring-up (a bad parameter) leaves it down at once,
  as Nav2's manager aborts a bring-up: the same parameters would fail again.

Times are seconds of a monotonic clock (the node uses the steady clock, never sim time).
"""
from __future__ import annotations

import collections
from dataclasses import dataclass, field
from typing import Deque, Dict, List, Optional, Sequence, Tuple

__all__ = ["Supervisor", "Watched", "SupervisorEvent", "UP_STATES"]

#: The lifecycle states a node is brought to, in order.
UP_STATES = ("unconfigured", "inactive", "active")
#: The transition that leaves each state towards ``active``.
NEXT = {"unconfigured": "configure", "inactive": "activate"}


@dataclass(frozen=True)
class SupervisorEvent:
    """One thing to log and report: ``level`` ``info``/``warn``/``error``, the node, the text."""

    level: str
    node: str
    text: str


@dataclass
class Watched:
    """What the supervisor knows of one node."""

    name: str
    #: The last state it reported (``unknown`` until it answers; ``down`` once its heartbeat is lost).
    state: str = "unknown"
    last_answer: Optional[float] = None
    #: The transition in flight, or ``None``.
    busy: Optional[str] = None
    #: True once it has been active: a later ``unconfigured`` is a restart.
    was_active: bool = False
    left_down: bool = False
    comebacks: int = 0
    times: Deque[float] = field(default_factory=collections.deque)


class Supervisor:
    """The decisions of a lifecycle supervisor (see the module doc).

    Args:
        names: the managed nodes, in the order they are brought up.
        heartbeat_timeout: seconds without an answer after which a node is down (> 0).
        max_restarts: comebacks and failed transitions allowed within ``restart_window`` (≥ 0).
        restart_window: seconds (> 0).

    Raises:
        ValueError: no node, a name twice, or a setting out of range (names the setting).
    """

    def __init__(self, names: Sequence[str], heartbeat_timeout: float = 3.0, max_restarts: int = 3,
                 restart_window: float = 300.0):
        names = [n for n in names if n]
        if not names:
            raise ValueError("node_names: no node to supervise")
        if len(set(names)) != len(names):
            raise ValueError(f"node_names: a node is named twice ({', '.join(names)})")
        if not heartbeat_timeout > 0:
            raise ValueError(f"heartbeat_timeout: must be > 0 s, got {heartbeat_timeout}")
        if max_restarts < 0:
            raise ValueError(f"max_restarts: must be >= 0, got {max_restarts}")
        if not restart_window > 0:
            raise ValueError(f"restart_window: must be > 0 s, got {restart_window}")
        self.nodes: Dict[str, Watched] = {n: Watched(n) for n in names}
        self.order: List[str] = list(names)
        self.heartbeat_timeout = float(heartbeat_timeout)
        self.max_restarts = int(max_restarts)
        self.restart_window = float(restart_window)

    # ------------------------------------------------------------------ inputs
    def answered(self, name: str, state: str, now: float) -> List[SupervisorEvent]:
        """``name`` reported its lifecycle ``state`` (a label: ``unconfigured``, ``active`` …)."""
        node = self.nodes[name]
        events: List[SupervisorEvent] = []
        came_back = node.state == "down" or (node.was_active and node.busy is None and state == "unconfigured")
        node.last_answer, node.state = now, state
        if came_back and not node.left_down:
            node.comebacks += 1
            events += self._use_one(node, now, f"{name} is back ({state}): bringing it up again "
                                               f"(comeback {node.comebacks})")
        if state == "active":
            node.was_active = True
        return events

    def transition_done(self, name: str, transition: str, success: Optional[bool], now: float) -> List[SupervisorEvent]:
        """The ``transition`` of ``name`` ended: ``True``/``False``, or ``None`` when its answer never
        came (the next heartbeat tells the state)."""
        node = self.nodes[name]
        node.busy = None
        if success:
            node.state = {"configure": "inactive", "activate": "active"}[transition]
            node.last_answer = now
            if node.state == "active":
                node.was_active = True
                return [SupervisorEvent("info", name, f"{name} is active")]
            return []
        node.state = "unknown" if success is None else node.state
        if success is None:
            return [SupervisorEvent("warn", name, f"{name}: no answer to {transition}; asking its state")]
        if not node.was_active:
            # Its first bring-up: the same parameters would fail the same way again (its log says why).
            node.left_down = True
            return [SupervisorEvent("error", name, f"{name}: {transition} failed at start-up (its log line says "
                                                   "why): left down")]
        return self._use_one(node, now, f"{name}: {transition} failed")

    def not_sent(self, name: str) -> None:
        """The transition :meth:`tick` asked for could not be sent yet (the service is not there):
        it is asked for again at the next tick."""
        self.nodes[name].busy = None

    def tick(self, now: float) -> Tuple[List[Tuple[str, str]], List[SupervisorEvent]]:
        """``(transitions to request as (node, transition), events)`` at time ``now``: heartbeats
        judged, then the first node (in order) that is not active gets its next transition."""
        events: List[SupervisorEvent] = []
        for node in self.nodes.values():
            if (node.busy is None and node.state not in ("down", "unknown") and node.last_answer is not None
                    and now - node.last_answer > self.heartbeat_timeout):
                node.state = "down"
                level = "info" if node.left_down else "error"
                events.append(SupervisorEvent(level, node.name, f"{node.name} is down: no heartbeat for "
                                                                f"{now - node.last_answer:.1f} s (waiting for it to "
                                                                f"be respawned)"))
        todo: List[Tuple[str, str]] = []
        for name in self.order:
            node = self.nodes[name]
            if node.left_down:
                continue
            if node.busy is not None:
                break                       # one at a time, in order
            transition = NEXT.get(node.state)
            if transition is not None:
                node.busy = transition
                todo.append((name, transition))
                break
            if node.state != "active" and not node.was_active:
                break                       # at start the later nodes wait for this one
        return todo, events

    # ----------------------------------------------------------------- reading
    def level(self, name: str) -> str:
        """``ok`` (active), ``warn`` (coming up) or ``error`` (down, left down)."""
        node = self.nodes[name]
        if node.left_down or node.state == "down":
            return "error"
        return "ok" if node.state == "active" else "warn"

    def summary(self, name: str) -> str:
        node = self.nodes[name]
        if node.left_down:
            return f"left down after {len(node.times)} comebacks/failures in {self.restart_window:g} s"
        return node.state + (f" ({node.busy})" if node.busy else "")

    def _use_one(self, node: Watched, now: float, text: str) -> List[SupervisorEvent]:
        times = node.times
        times.append(now)
        while times and now - times[0] > self.restart_window:
            times.popleft()
        if len(times) > self.max_restarts:
            node.left_down = True
            return [SupervisorEvent("error", node.name, f"{text}; {node.name} needed {len(times)} restarts or "
                                                        f"retries within {self.restart_window:g} s (max_restarts "
                                                        f"{self.max_restarts}): left down")]
        return [SupervisorEvent("warn", node.name, text)]
