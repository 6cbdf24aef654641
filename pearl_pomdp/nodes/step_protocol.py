"""The step protocol of the belief tracker (DESIGN.md §6), free of ROS.

One step: the policy publishes an action ``a_t``; the next observation ``o_{t+1}`` (one
message from any modality) closes the step; the tracker updates the belief with
``(a_t, o_{t+1})`` by eq. 5 and publishes it; the policy answers with ``a_{t+1}``.

The cases the paper leaves open are decided here, and each is counted:

* **Nothing is heard.** With ``step_timeout > 0``, a step still open ``step_timeout``
  seconds (node clock, so sim time in replay) after its action arrived is closed with the
  observation ``timeout_observation`` (default ``unknown``, the Pearl speech symbol for
  "nothing understood": silence carries no more information than unrecognised speech).
  Counter ``timeouts``. ``step_timeout = 0`` waits forever. Actions listed in
  ``no_timeout_actions`` (by default the Pearl domain's motions ``GotoPatientRoom``,
  ``GuideToPhysio``, ``GoHome``) are never timed out: a drive takes as long as it takes
  (a slow resident makes a guidance last minutes) and navigation always ends it with a
  landmark on the laser topic, so silence during a drive is not an observation.
* **Observation before any action / more than one observation in a step.** The inputs
  are ``std_msgs/String`` without a header, so arrival order is the only order there is.
  An observation that arrives while no step is open (before the first action, or after
  this step's observation and before the next action) is *queued* (FIFO, at most
  ``max_pending``; on overflow the oldest is dropped — counter ``dropped_overflow``). The
  next action then immediately closes its step with the oldest queued observation.
  Counter ``queued``.
* **Stale input.** With ``stale_after > 0``, a queued observation older than
  ``stale_after`` seconds when it would be used is dropped (counter ``dropped_stale``):
  it answers a question the robot no longer asks.
* **A second action while a step is open** (the policy re-published, or another node
  commands): the newer action replaces the open one, because the robot does what it was
  last told (counter ``replaced_actions``).
* **An action name the model does not know** is ignored (counter ``unknown_actions``).
* **Zero-likelihood observations** are recovered by :class:`~pearl_pomdp.belief.BeliefFilter`
  (counter ``zero_likelihood``).

Nothing is dropped silently: every case above increments a counter in :attr:`counters`
and returns an :class:`Event` the node logs and reports on ``/diagnostics``.
"""
from __future__ import annotations

import collections
from dataclasses import dataclass
from typing import Deque, Dict, List, Optional, Sequence, Tuple

import numpy as np

from pearl_pomdp.belief import BeliefFilter
from pearl_pomdp.model.pomdp import Pomdp

__all__ = ["StepProtocol", "StepResult", "Event", "COUNTERS"]

#: Names of the counters of :class:`StepProtocol` (reported on /diagnostics).
COUNTERS = ("updates", "timeouts", "queued", "dropped_stale", "dropped_overflow",
            "replaced_actions", "unknown_actions", "zero_likelihood")


@dataclass
class StepResult:
    """One closed step: the belief after ``(action, observation)``.

    Attributes:
        step: how many steps are closed, this one included (1 for the first).
        action: ``a_t``, the action that opened the step.
        observation: ``o_{t+1}``, the symbol that closed it.
        source: where the observation came from (``speech``, ``touchscreen`` …, or ``timeout``).
        belief: ``[S]`` belief after the update.
        zero_likelihood: True when the filter had to recover (see ``pearl_pomdp.belief``).
    """

    step: int
    action: str
    observation: str
    source: str
    belief: np.ndarray
    zero_likelihood: bool = False


@dataclass
class Event:
    """Something a node must log (``level`` is ``"info"`` or ``"warn"``)."""

    level: str
    text: str


@dataclass
class _Pending:
    symbol: str
    source: str
    stamp: float


class StepProtocol:
    """Belief tracking step by step over a flat :class:`Pomdp` (see the module doc).

    Args:
        model: the POMDP (``T[a][s, s']``, ``O[a, s', o]``).
        step_timeout: seconds after which an open step is closed with
            ``timeout_observation``; ``0`` disables the timeout.
        timeout_observation: observation symbol used on timeout (must be in the model when
            the timeout is enabled).
        max_pending: how many observations may wait for the next action.
        stale_after: seconds after which a waiting observation is dropped; ``0`` never.
        belief_filter: the filter to use (a new :class:`BeliefFilter` by default).

    Raises:
        ValueError: a parameter is out of range or the timeout observation is not a symbol
            of the model (the message names the parameter and the valid symbols).
    """

    def __init__(self, model: Pomdp, *, step_timeout: float = 0.0, timeout_observation: str = "unknown",
                 no_timeout_actions: Sequence[str] = (),
                 max_pending: int = 8, stale_after: float = 0.0, belief_filter: Optional[BeliefFilter] = None):
        if step_timeout < 0:
            raise ValueError(f"step_timeout must be >= 0 s, got {step_timeout}")
        if stale_after < 0:
            raise ValueError(f"stale_after must be >= 0 s, got {stale_after}")
        if max_pending < 0:
            raise ValueError(f"max_pending must be >= 0, got {max_pending}")
        if step_timeout > 0 and timeout_observation not in model.observations:
            raise ValueError(f"timeout_observation {timeout_observation!r} is not an observation of "
                             f"{model.name} (valid: {', '.join(model.observations)})")
        self.model = model
        self.filter = belief_filter or BeliefFilter(model)
        self.step_timeout = float(step_timeout)
        unknown = sorted(set(no_timeout_actions) - set(model.actions))
        if unknown:
            raise ValueError(f"no_timeout_actions names {unknown[0]!r}, which is not an action of {model.name}")
        self.no_timeout_actions = frozenset(no_timeout_actions)
        self.timeout_observation = timeout_observation
        self.max_pending = int(max_pending)
        self.stale_after = float(stale_after)
        self._action_index = {name: i for i, name in enumerate(model.actions)}
        self._obs_index = {name: i for i, name in enumerate(model.observations)}
        self.counters: Dict[str, int] = {}
        self.reset()

    # ---------------------------------------------------------------- state
    def reset(self) -> None:
        """Back to ``b0`` with no open step, nothing queued and zeroed counters."""
        self.belief = np.array(self.model.b0, dtype=float)
        self.step = 0
        self.current_action: Optional[str] = None
        self.opened_at: Optional[float] = None
        self.pending: Deque[_Pending] = collections.deque()
        self.counters = {name: 0 for name in COUNTERS}
        self.events: List[Event] = []

    @property
    def step_open(self) -> bool:
        """True while an action waits for its observation."""
        return self.current_action is not None

    def take_events(self) -> List[Event]:
        """The events since the last call (for the node to log), oldest first."""
        events, self.events = self.events, []
        return events

    # --------------------------------------------------------------- inputs
    def on_action(self, name: str, now: float) -> Optional[StepResult]:
        """An action was published at time ``now`` (s): open a step.

        Returns the closed step when a queued observation closes it at once.
        """
        if name not in self._action_index:
            self.counters["unknown_actions"] += 1
            self.events.append(Event("warn", f"ignored action {name!r}: not an action of {self.model.name}"))
            return None
        if self.step_open:
            self.counters["replaced_actions"] += 1
            self.events.append(Event("warn", f"action {name!r} replaces {self.current_action!r}, "
                                             f"which no observation closed"))
        self.current_action = name
        self.opened_at = float(now)
        while self.pending:
            item = self.pending.popleft()
            if self.stale_after > 0 and now - item.stamp > self.stale_after:
                self.counters["dropped_stale"] += 1
                self.events.append(Event("warn", f"dropped stale observation {item.symbol!r} from {item.source} "
                                                 f"({now - item.stamp:.3f} s old > stale_after {self.stale_after} s)"))
                continue
            return self._close(item.symbol, item.source)
        return None

    def on_observation(self, symbol: str, source: str, now: float) -> Optional[StepResult]:
        """An observation symbol arrived from ``source`` at time ``now`` (s).

        Closes the open step, or queues the observation when no step is open.

        Raises:
            ValueError: ``symbol`` is not an observation of the model (callers validate first).
        """
        if symbol not in self._obs_index:
            raise ValueError(f"{symbol!r} is not an observation of {self.model.name}")
        if self.step_open:
            return self._close(symbol, source)
        if self.max_pending == 0 or len(self.pending) >= self.max_pending:
            if self.pending:
                old = self.pending.popleft()
                what = f"dropped queued observation {old.symbol!r} from {old.source}"
            else:
                old = None
                what = f"dropped observation {symbol!r} from {source}"
            self.counters["dropped_overflow"] += 1
            self.events.append(Event("warn", f"{what}: more than max_pending={self.max_pending} "
                                             f"observations wait for an action"))
            if old is None:
                return None
        self.pending.append(_Pending(symbol, source, float(now)))
        self.counters["queued"] += 1
        self.events.append(Event("info", f"queued observation {symbol!r} from {source}: no open step "
                                         f"({len(self.pending)} waiting)"))
        return None

    def on_tick(self, now: float) -> Optional[StepResult]:
        """Check the step timeout at time ``now`` (s); closes the step with the timeout observation."""
        if (self.step_open and self.step_timeout > 0 and self.opened_at is not None
                and self.current_action not in self.no_timeout_actions
                and now - self.opened_at >= self.step_timeout):
            self.counters["timeouts"] += 1
            self.events.append(Event("info", f"nothing heard {now - self.opened_at:.3f} s after "
                                             f"{self.current_action!r}: closing the step with "
                                             f"{self.timeout_observation!r}"))
            return self._close(self.timeout_observation, "timeout")
        return None

    # --------------------------------------------------------------- update
    def _close(self, symbol: str, source: str) -> StepResult:
        action = self.current_action
        assert action is not None  # internal invariant: only called with an open step
        before = self.filter.zero_likelihood_count
        self.belief = self.filter.update(self.belief, self._action_index[action], self._obs_index[symbol])
        zero = self.filter.zero_likelihood_count > before
        if zero:
            self.counters["zero_likelihood"] += 1
            self.events.append(Event("warn", f"observation {symbol!r} has zero likelihood after {action!r}: "
                                             f"belief recovered with a uniform floor"))
        self.counters["updates"] += 1
        self.step += 1
        self.current_action = None
        self.opened_at = None
        return StepResult(self.step, action, symbol, source, self.belief, zero)

    def snapshot(self) -> Tuple[int, Optional[str], int]:
        """``(step, open action or None, number queued)`` — for diagnostics."""
        return self.step, self.current_action, len(self.pending)
