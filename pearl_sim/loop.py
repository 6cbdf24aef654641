"""The episode loop: the simulated world against the robot's step loop, on the world's clock.

One loop for the fast study and for the demo through the ROS graph. The world carries out
each action and produces timestamped messages (:meth:`~pearl_sim.nursing_home.world.World.act`); the
*backend* — the robot's loop — takes each message at its time and answers with the next
action when the message closed a step. When an action produced no message the world idles
(:meth:`~pearl_sim.nursing_home.world.World.wait`) until the scheduler speaks or until the backend's
step deadline, and the backend is then told the time (the tracker's timeout closes the step).
The world never decides when a step closes.

Backends (both run the same :class:`~pearl_pomdp.tracking.BeliefTracker` rules):

* :class:`ExecutiveBackend` — the core :class:`~pearl_pomdp.executive.Executive` in this
  process (thousands of episodes a minute: the study).
* :class:`pearl_sim.nodes.GraphBackend` — the real nodes over DDS under ``/clock``
  (``pearl demo``). :func:`run_episode` gives identical actions and beliefs with either
  (``test/test_one_loop.py``).

Clock: message and deadline times are taken to whole nanoseconds (:func:`clock_ns`) as
``/clock`` carries them, and read back as ``ns * 1e-9`` as the nodes read their clock, so
both backends see bit-identical times.
"""
from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field
from typing import Callable, Deque, List, Optional, Protocol

import numpy as np

from pearl_pomdp.errors import PearlError
from pearl_sim.messages import Message, StepResult

__all__ = ["Backend", "World", "ExecutiveBackend", "EpisodeTrace", "run_episode", "clock_ns", "IDLE_LIMIT"]

#: Longest the world idles for a step with no deadline (a drive is closed by its landmark;
#: a step with no timeout and nothing to hear is a configuration fault, reported).
IDLE_LIMIT = 3600.0


def clock_ns(t: float) -> int:
    """World seconds as a ``/clock`` time in whole nanoseconds."""
    return int(round(t * 1e9))


def clock_s(ns: int) -> float:
    """A ``/clock`` time back in seconds, computed as the nodes compute it."""
    return ns * 1e-9


class EpisodeSpec(Protocol):
    """What the loop reads of a world's scenario: its name (for errors) and its step budget."""

    @property
    def name(self) -> str: ...

    @property
    def max_steps(self) -> int: ...


class World(Protocol):
    """The simulated world's side of the loop (:class:`pearl_sim.nursing_home.world.World`, the nursing home;
    :class:`pearl_sim.reception.world.ReceptionWorld`, the reception hall). The loop knows
    nothing else of a world: no domain names, no places."""

    @property
    def scenario(self) -> EpisodeSpec:
        """The episode: its name and step budget."""
        ...

    @property
    def time(self) -> float:
        """The world's clock (seconds)."""
        ...

    def act(self, action: str) -> StepResult:
        """Carry out ``action``; every message it produced, timestamped."""
        ...

    def wait(self, until: float) -> StepResult:
        """Let time pass with the robot idle until a message is produced or ``until``."""
        ...


class Backend(Protocol):
    """The robot's side of the loop."""

    def start(self) -> List[str]:
        """The first action(s), from ``b0`` at time 0."""
        ...

    def deliver(self, message: Message) -> List[str]:
        """One message at its time; the actions decided because it closed a step (often none or one)."""
        ...

    def tick(self, t_ns: int) -> List[str]:
        """The clock reads ``t_ns``; the actions decided because a timeout closed a step."""
        ...

    def deadline(self) -> Optional[float]:
        """When the open step times out (seconds), or ``None``."""
        ...


class ExecutiveBackend:
    """The core :class:`~pearl_pomdp.executive.Executive` as the robot (no DDS)."""

    def __init__(self, executive):
        self.executive = executive

    def start(self) -> List[str]:
        self.executive.reset()
        return self.executive.start(clock_s(0))

    def deliver(self, message: Message) -> List[str]:
        return self.executive.on_input(message.modality.lower(), message.text, clock_s(clock_ns(message.time)))

    def tick(self, t_ns: int) -> List[str]:
        return self.executive.on_tick(clock_s(t_ns))

    def deadline(self) -> Optional[float]:
        return self.executive.deadline()

    def beliefs(self) -> List[np.ndarray]:
        """``b0`` and the belief after every closed step, as the tracker node publishes them."""
        return [np.asarray(self.executive.model.b0, dtype=float)] + [s.belief for s in self.executive.steps]


@dataclass
class EpisodeTrace:
    """What happened in one episode: each world action in order, and the waits between."""

    actions: List[str] = field(default_factory=list)
    results: List[StepResult] = field(default_factory=list)
    waits: List[StepResult] = field(default_factory=list)


def run_episode(world: World, backend: Backend, max_steps: Optional[int] = None,
                on_action: Optional[Callable[[StepResult, List[StepResult]], None]] = None,
                before_action: Optional[Callable[[str], None]] = None,
                stop_when: Optional[Callable[[], bool]] = None) -> EpisodeTrace:
    """Run ``world`` against ``backend`` until ``max_steps`` actions (default: the scenario's)
    or, when given, until ``stop_when()`` is true before an action (a working day ends at 20:00).

    Args:
        before_action: called with each action before the world carries it out (the
            world's state is still the one the action starts in: for scoring).
        on_action: called after each action with its :class:`~pearl_sim.nursing_home.world.StepResult`
            and the waits that followed it (before the next action).

    Raises:
        PearlError: a step could never close (no deadline and nothing heard for
            :data:`IDLE_LIMIT` seconds).
    """
    budget = world.scenario.max_steps if max_steps is None else int(max_steps)
    trace = EpisodeTrace()
    queue: Deque[str] = deque(backend.start())
    while queue and len(trace.actions) < budget and not (stop_when is not None and stop_when()):
        action = queue.popleft()
        if before_action is not None:
            before_action(action)
        result = world.act(action)
        trace.actions.append(action)
        trace.results.append(result)
        answered: List[str] = []
        for message in result.messages:
            # The robot's clock passes an open step's deadline before a later message arrives
            # (a drive's deadline before a slow arrival): tell the backend first, as /clock would.
            deadline = backend.deadline()
            if deadline is not None and clock_ns(message.time) > clock_ns(deadline):
                answered += backend.tick(clock_ns(deadline))
            answered += backend.deliver(message)
        waits: List[StepResult] = []
        while not answered and not queue:
            # Nothing closed the step: the robot waits; the world lives on until the
            # scheduler speaks or the step's deadline passes.
            deadline = backend.deadline()
            until = deadline if deadline is not None else world.time + IDLE_LIMIT
            waited = world.wait(until)
            waits.append(waited)
            for message in waited.messages:
                answered += backend.deliver(message)
            if answered or waited.messages:
                continue
            if deadline is None:
                raise PearlError(f"{world.scenario.name}: after {action!r} nothing closed the step for "
                                 f"{IDLE_LIMIT:.0f} s and the step has no timeout (step_timeout 0?)")
            answered += backend.tick(clock_ns(deadline))
        trace.waits.extend(waits)
        queue.extend(answered)
        if on_action is not None:
            on_action(result, waits)
    return trace
