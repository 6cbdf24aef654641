"""Belief tracking step by step: the one step loop the robot, the simulator and the study run.

The step protocol (docs/design.md §6): the policy publishes an action ``a_t``; the next
observation ``o_{t+1}`` (one input from any modality) closes the step; the belief is
updated with ``(a_t, o_{t+1})`` by eq. 5; the policy answers with ``a_{t+1}``.
:class:`BeliefTracker` is that loop without ROS. The ``belief_tracker`` node is a thin
rclpy wrapper of it (subscriptions call :meth:`BeliefTracker.on_input` /
:meth:`~BeliefTracker.on_action`, a timer calls :meth:`~BeliefTracker.on_tick`), and
:class:`pearl_pomdp.executive.Executive` drives the same object directly for experiments
with thousands of episodes — so a change to the rules below shows up in both.

**Inputs → observation symbols** (:class:`ObservationMapper`, the only place this is done):

* Speech text goes through the domain's keyword filter (:class:`pearl_pomdp.speech.KeywordFilter`);
  text with no keyword becomes the ``unknown`` symbol (still an observation: the robot heard
  something it did not understand) and is counted. A recogniser may attach its confidence
  (:func:`pearl_pomdp.speech.parse_speech_message`): a keyword heard with confidence below
  ``confidence_floor`` is taken as ``unknown`` too (counter ``low_confidence``) — a mumbled
  "yes" is weaker evidence than a clear one, and the model's speech noise already
  describes how often ``unknown`` goes with each true state.
* Touchscreen / laser / reminder strings must be symbols of their modality (``t_yes``,
  ``atRoom``, ``g_physio`` …; blanks around them are ignored); anything else is *invalid*:
  counted per input, reported, and no observation is made.
* For a flat model without modalities every symbol is valid on every input, and speech
  text must itself be a symbol (there are no keywords).

**The cases the paper leaves open**, each counted in :attr:`StepProtocol.counters`:

* *Nothing is heard.* With ``step_timeout > 0`` a step still open ``step_timeout`` seconds
  after its action is closed with ``timeout_observation`` (default ``unknown``: silence
  carries no more information than unrecognised speech). :meth:`StepProtocol.deadline`
  says when; the node arms a one-shot timer for that instant, the simulator jumps its
  clock to it. Counter ``timeouts``. Actions listed in ``no_timeout_actions`` (by
  default the domain's ``category: Move`` actions) are not closed by ``step_timeout``:
  a drive takes as long as it takes and navigation ends it with a landmark.
* *A drive that never arrives* (a blocked corridor, lost localisation). With
  ``drive_speed > 0`` each drive gets its own deadline from
  :class:`~pearl_pomdp.navigation.DriveTimer`: the distance from the place the robot most
  likely is (the belief's ``place_feature`` marginal when the drive starts) to the drive's
  goal, at ``drive_speed`` (``guide_speed`` for ``guide_actions``), through
  :class:`~pearl_pomdp.navigation.DriveDeadline`. When it passes without an observation
  the step closes with ``nav_failed_observation`` (``navFailed``, a Laser symbol of the
  domain whose rows say the robot is most likely still where it started), counter
  ``nav_failures``, a warning; the policy decides what next (retry, ask, go home).
* *Observation before any action / several in one step.* Inputs have no header, so
  arrival order is the only order there is. An observation while no step is open is
  *queued* (FIFO, at most ``max_pending``; on overflow the oldest is dropped — counter
  ``dropped_overflow``); the next action closes its step at once with the oldest queued
  one. Counter ``queued``.
* *Stale input.* With ``stale_after > 0`` a queued observation older than that when it
  would be used is dropped (``dropped_stale``): it answers a question no longer asked.
* *A second action while a step is open*: the newer one replaces it, because the robot
  does what it was last told (``replaced_actions``).
* *An unknown action name* is ignored (``unknown_actions``).
* *Zero-likelihood observations* are recovered by :class:`~pearl_pomdp.belief.BeliefFilter`
  (``zero_likelihood``).

Nothing is dropped silently: every case increments a counter and records an :class:`Event`
(:meth:`StepProtocol.take_events`) that the node logs and reports on ``/diagnostics``.
"""
from __future__ import annotations

import collections
from dataclasses import dataclass
from typing import Any, Deque, Dict, FrozenSet, List, Optional, Sequence, Tuple

import numpy as np

from pearl_pomdp.belief import BeliefFilter
from pearl_pomdp.model.pomdp import Pomdp
from pearl_pomdp.speech import KeywordFilter, parse_speech_message

__all__ = ["BeliefTracker", "ObservationMapper", "StepProtocol", "StepResult", "StepSettings", "Event",
           "COUNTERS", "SYMBOL_INPUTS", "drive_actions"]

#: Names of the counters of :class:`StepProtocol` (reported on /diagnostics).
COUNTERS = ("updates", "timeouts", "nav_failures", "queued", "dropped_stale", "dropped_overflow",
            "replaced_actions", "unknown_actions", "zero_likelihood")

#: Symbol inputs: input name → the domain modality (lower-cased) whose symbols it carries.
SYMBOL_INPUTS = {"touchscreen": "touchscreen", "laser": "laser", "reminder": "reminder"}

#: Every input of the tracker: speech text plus the symbol inputs.
INPUTS = ("speech", *SYMBOL_INPUTS)

#: A step may close this much before its deadline (clock rounding: sim time travels in ns).
_DEADLINE_SLACK = 1e-9


def drive_actions(domain) -> List[str]:
    """The actions of ``domain`` tagged ``category: Move`` (drives: never timed out)."""
    return domain.actions_in("Move")


@dataclass(frozen=True)
class StepSettings:
    """The step protocol's parameters (one source: ``config/pearl_nodes.yaml``'s belief_tracker section).

    Attributes:
        step_timeout: seconds after which an open step is closed with ``timeout_observation``;
            ``0`` disables the timeout.
        timeout_observation: the symbol used on timeout.
        no_timeout_actions: actions never timed out; ``None`` = the domain's drives
            (``category: Move``), or none for a flat model.
        max_pending: observations that may wait for the next action.
        stale_after: seconds after which a waiting observation is dropped; ``0`` never.
        confidence_floor: speech recognised with a lower confidence counts as ``unknown``.
        drive_speed: m/s a drive is timed at (:class:`~pearl_pomdp.navigation.DriveDeadline`);
            ``0`` gives drives no deadline (only an observation closes them).
        guide_speed: m/s a guidance (``guide_actions``) is timed at: the slowest pace, rests
            included, of a resident the robot still guides.
        guide_actions: drives that walk the resident along.
        drive_path_factor, drive_slack, drive_margin, drive_max_seconds: the other fields of
            :class:`~pearl_pomdp.navigation.DriveDeadline`.
        nav_failed_observation: the symbol that closes a drive at its deadline.
        place_feature: the state feature whose values are the places (the drives set it).
        places: ``(name, x, y)`` of each place, metres in the map frame (the params file's
            ``location_names`` / ``locations.<name>``).
    """

    step_timeout: float = 10.0
    timeout_observation: str = "unknown"
    no_timeout_actions: Optional[Tuple[str, ...]] = None
    max_pending: int = 8
    stale_after: float = 0.0
    confidence_floor: float = 0.0
    drive_speed: float = 0.0
    guide_speed: float = 0.03
    guide_actions: Tuple[str, ...] = ()
    drive_path_factor: float = 1.4
    drive_slack: float = 1.5
    drive_margin: float = 10.0
    drive_max_seconds: float = 1800.0
    nav_failed_observation: str = "navFailed"
    place_feature: str = "RobotLocation"
    places: Tuple[Tuple[str, float, float], ...] = ()

    @classmethod
    def from_params(cls, params: Dict[str, Any]) -> "StepSettings":
        """From a parameter table (the node's, or the params file's belief_tracker section)."""
        names = {f for f in cls.__dataclass_fields__}
        kwargs = {k: v for k, v in params.items() if k in names}
        if "no_timeout_actions" in kwargs:
            given = kwargs["no_timeout_actions"]
            # An empty list in a params file means "not given" (ROS cannot express None).
            kwargs["no_timeout_actions"] = tuple(given) if given else None
        if "guide_actions" in kwargs:
            kwargs["guide_actions"] = tuple(a for a in kwargs["guide_actions"] if a)
        names_given = [n for n in params.get("location_names", ()) if n]
        if names_given and "places" not in params:
            places = []
            for name in names_given:
                pose = params.get(f"locations.{name}")
                if pose is None or len(pose) < 2:
                    raise ValueError(f"locations.{name}: expected [x, y, yaw] for location {name!r}, got {pose!r}")
                places.append((name, float(pose[0]), float(pose[1])))
            kwargs["places"] = tuple(places)
        return cls(**kwargs)

    def drive_timer(self, domain, drives: Sequence[str]):
        """The :class:`~pearl_pomdp.navigation.DriveTimer` of these settings, or ``None`` (off,
        no domain, or no drive with a place goal).

        Raises:
            ValueError: a field is out of range or a drive's goal has no pose (names the parameter).
        """
        if self.drive_speed <= 0 or domain is None:
            return None
        from pearl_pomdp.navigation import DriveDeadline, DriveTimer, Place

        deadline = DriveDeadline(speed=self.drive_speed, path_factor=self.drive_path_factor, slack=self.drive_slack,
                                 margin=self.drive_margin, max_seconds=self.drive_max_seconds)
        places = {name: Place(name, x, y) for name, x, y in self.places}
        if not places:
            raise ValueError("location_names: drive deadlines (drive_speed > 0) need the places' poses "
                             "(location_names and locations.<name>)")
        return DriveTimer.for_domain(domain, drives, places, deadline, self.place_feature, self.guide_actions,
                                     self.guide_speed)


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
        time: when the step closed (the clock given with the closing input or tick).
        text: the input text that closed it (speech text as recognised; the symbol otherwise).
        confidence: the recogniser's confidence for speech (1.0 when none was given).
    """

    step: int
    action: str
    observation: str
    source: str
    belief: np.ndarray
    zero_likelihood: bool = False
    time: float = 0.0
    text: str = ""
    confidence: float = 1.0


@dataclass
class Event:
    """Something a node must log (``level`` is ``"info"`` or ``"warn"``).

    ``kind`` names the sort of event (``"nav_failed"``, ``"zero_likelihood"``, …): a node logs
    every event, but throttles a flood of one kind (see the belief tracker node).
    """

    level: str
    text: str
    kind: str = ""


@dataclass
class _Pending:
    symbol: str
    source: str
    stamp: float
    text: str = ""
    confidence: float = 1.0


class StepProtocol:
    """The step rules over a flat :class:`Pomdp`, on observation *symbols* (see the module doc).

    Args:
        model: the POMDP (``T[a][s, s']``, ``O[a, s', o]``).
        step_timeout, timeout_observation, no_timeout_actions, max_pending, stale_after:
            see :class:`StepSettings` (``no_timeout_actions`` here is a plain list).
        belief_filter: the filter to use (a new :class:`BeliefFilter` by default).

    Raises:
        ValueError: a parameter is out of range, or a named symbol/action is not in the
            model (the message names the parameter and the valid values).
    """

    def __init__(self, model: Pomdp, *, step_timeout: float = 0.0, timeout_observation: str = "unknown",
                 no_timeout_actions: Sequence[str] = (), max_pending: int = 8, stale_after: float = 0.0,
                 belief_filter: Optional[BeliefFilter] = None, nav_failed_observation: Optional[str] = None):
        if step_timeout < 0:
            raise ValueError(f"step_timeout must be >= 0 s, got {step_timeout}")
        if stale_after < 0:
            raise ValueError(f"stale_after must be >= 0 s, got {stale_after}")
        if max_pending < 0:
            raise ValueError(f"max_pending must be >= 0, got {max_pending}")
        if step_timeout > 0 and timeout_observation not in model.observations:
            raise ValueError(f"timeout_observation {timeout_observation!r} is not an observation of "
                             f"{model.name} (valid: {', '.join(model.observations)})")
        if nav_failed_observation is not None and nav_failed_observation not in model.observations:
            raise ValueError(f"nav_failed_observation {nav_failed_observation!r} is not an observation of "
                             f"{model.name} (add it to the domain's Laser modality, or set drive_speed 0 "
                             f"to give drives no deadline)")
        #: The symbol a drive is closed with at its deadline (``None``: drives have none).
        self.nav_failed_observation = nav_failed_observation
        unknown = sorted(set(no_timeout_actions) - set(model.actions))
        if unknown:
            raise ValueError(f"no_timeout_actions names {unknown[0]!r}, which is not an action of {model.name}")
        self.model = model
        # The protocol reports each recovery as an Event (the node logs it once); the filter stays quiet.
        self.filter = belief_filter or BeliefFilter(model, log_recoveries=False)
        self.step_timeout = float(step_timeout)
        self.no_timeout_actions: FrozenSet[str] = frozenset(no_timeout_actions)
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
        #: Seconds the open drive may take (``None``: not a timed drive).
        self.drive_limit: Optional[float] = None
        #: Why the last drive failed (for /diagnostics); empty until one did.
        self.last_nav_failure = ""
        self.pending: Deque[_Pending] = collections.deque()
        self.counters = {name: 0 for name in COUNTERS}
        self.events: List[Event] = []

    @property
    def step_open(self) -> bool:
        """True while an action waits for its observation."""
        return self.current_action is not None

    def deadline(self) -> Optional[float]:
        """When the open step times out (clock seconds), or ``None`` (no open step, no timeout,
        a drive without a deadline). A drive's deadline is ``opened_at + drive_limit``."""
        if not self.step_open or self.opened_at is None:
            return None
        if self.current_action in self.no_timeout_actions:
            if self.drive_limit is None or self.nav_failed_observation is None:
                return None
            return self.opened_at + self.drive_limit
        if self.step_timeout <= 0:
            return None
        return self.opened_at + self.step_timeout

    def take_events(self) -> List[Event]:
        """The events since the last call (for the node to log), oldest first."""
        events, self.events = self.events, []
        return events

    # --------------------------------------------------------------- inputs
    def on_action(self, name: str, now: float, drive_limit: Optional[float] = None) -> Optional[StepResult]:
        """An action was published at time ``now`` (s): open a step.

        ``drive_limit``: seconds a drive (an action of ``no_timeout_actions``) may take before
        it is closed with ``nav_failed_observation``; ``None``: no deadline.
        Returns the closed step when a queued observation closes it at once.
        """
        if name not in self._action_index:
            self.counters["unknown_actions"] += 1
            self.events.append(Event("warn", f"ignored action {name!r}: not an action of {self.model.name}",
                                     kind="ignored_action"))
            return None
        if self.step_open:
            self.counters["replaced_actions"] += 1
            self.events.append(Event("warn", f"action {name!r} replaces {self.current_action!r}, "
                                             f"which no observation closed", kind="replaced_action"))
        self.current_action = name
        self.opened_at = float(now)
        self.drive_limit = None if drive_limit is None else float(drive_limit)
        while self.pending:
            item = self.pending.popleft()
            if self.stale_after > 0 and now - item.stamp > self.stale_after:
                self.counters["dropped_stale"] += 1
                self.events.append(Event("warn", f"dropped stale observation {item.symbol!r} from {item.source} "
                                                 f"({now - item.stamp:.3f} s old > stale_after {self.stale_after} s)", kind="stale"))
                continue
            return self._close(item.symbol, item.source, now, item.text, item.confidence)
        return None

    def on_observation(self, symbol: str, source: str, now: float, text: str = "",
                       confidence: float = 1.0) -> Optional[StepResult]:
        """An observation symbol arrived from ``source`` at time ``now`` (s).

        Closes the open step, or queues the observation when no step is open.

        Raises:
            ValueError: ``symbol`` is not an observation of the model (callers validate first).
        """
        if symbol not in self._obs_index:
            raise ValueError(f"{symbol!r} is not an observation of {self.model.name}")
        if self.step_open:
            return self._close(symbol, source, now, text, confidence)
        if self.max_pending == 0 or len(self.pending) >= self.max_pending:
            if self.pending:
                old: Optional[_Pending] = self.pending.popleft()
                what = f"dropped queued observation {old.symbol!r} from {old.source}"
            else:
                old = None
                what = f"dropped observation {symbol!r} from {source}"
            self.counters["dropped_overflow"] += 1
            self.events.append(Event("warn", f"{what}: more than max_pending={self.max_pending} "
                                             f"observations wait for an action", kind="overflow"))
            if old is None:
                return None
        self.pending.append(_Pending(symbol, source, float(now), text, confidence))
        self.counters["queued"] += 1
        self.events.append(Event("info", f"queued observation {symbol!r} from {source}: no open step "
                                         f"({len(self.pending)} waiting)", kind="queued"))
        return None

    def on_tick(self, now: float) -> Optional[StepResult]:
        """Check the step timeout at time ``now`` (s); closes the step with the timeout observation."""
        deadline = self.deadline()
        if deadline is not None and now >= deadline - _DEADLINE_SLACK:
            assert self.opened_at is not None  # deadline() is None otherwise
            if self.current_action in self.no_timeout_actions:
                assert self.nav_failed_observation is not None  # a drive has a deadline only then
                self.counters["nav_failures"] += 1
                self.last_nav_failure = (f"{self.current_action} did not arrive within its deadline of "
                                         f"{self.drive_limit:.1f} s (opened at {self.opened_at:.3f} s)")
                self.events.append(Event("warn", f"{self.last_nav_failure}: closing the step with "
                                                 f"{self.nav_failed_observation!r}", kind="nav_failed"))
                return self._close(self.nav_failed_observation, "nav_deadline", now)
            self.counters["timeouts"] += 1
            self.events.append(Event("info", f"nothing heard {now - self.opened_at:.3f} s after "
                                             f"{self.current_action!r}: closing the step with "
                                             f"{self.timeout_observation!r}", kind="timeout"))
            return self._close(self.timeout_observation, "timeout", now)
        return None

    # --------------------------------------------------------------- update
    def _close(self, symbol: str, source: str, now: float, text: str = "", confidence: float = 1.0) -> StepResult:
        action = self.current_action
        assert action is not None  # internal invariant: only called with an open step
        before = self.filter.zero_likelihood_count
        self.belief = self.filter.update(self.belief, self._action_index[action], self._obs_index[symbol])
        zero = self.filter.zero_likelihood_count > before
        if zero:
            self.counters["zero_likelihood"] += 1
            self.events.append(Event("warn", f"observation {symbol!r} has zero likelihood after {action!r}: "
                                             f"belief recovered with a uniform floor", kind="zero_likelihood"))
        self.counters["updates"] += 1
        self.step += 1
        self.current_action = None
        self.opened_at = None
        self.drive_limit = None
        return StepResult(self.step, action, symbol, source, self.belief, zero, float(now), text or symbol,
                          confidence)

    def snapshot(self) -> Tuple[int, Optional[str], int]:
        """``(step, open action or None, number queued)`` — for diagnostics."""
        return self.step, self.current_action, len(self.pending)


class ObservationMapper:
    """Turns input strings into observation symbols of the model (see the module doc).

    Args:
        model: the compiled :class:`~pearl_pomdp.model.pomdp.Pomdp`.
        domain: the :class:`FactoredDomain` (modalities, keywords), or ``None``.
        keyword_filter: a ready keyword filter (default: built from ``domain.keywords``).
        confidence_floor: speech below this recogniser confidence counts as the unknown symbol.
    """

    def __init__(self, model: Pomdp, domain=None, keyword_filter: Optional[KeywordFilter] = None,
                 confidence_floor: float = 0.0):
        if not 0.0 <= confidence_floor <= 1.0:
            raise ValueError(f"confidence_floor must be in [0, 1], got {confidence_floor}")
        self.model = model
        symbols = set(model.observations)
        self.allowed: Dict[str, FrozenSet[str]] = {}
        modalities = {m.lower(): list(v) for m, v in (domain.modalities if domain is not None else {}).items()}
        for key, modality in SYMBOL_INPUTS.items():
            self.allowed[key] = frozenset(modalities.get(modality, symbols))
        self.invalid: Dict[str, int] = {key: 0 for key in INPUTS}
        self.keyword_filter = keyword_filter
        if keyword_filter is None and domain is not None and domain.keywords:
            self.keyword_filter = KeywordFilter.from_domain(domain)
        self.speech_symbols = frozenset(modalities.get("speech", symbols))
        self.confidence_floor = float(confidence_floor)
        self.low_confidence = 0

    @property
    def unknown_speech(self) -> int:
        """Speech texts with no keyword, classified as the unknown symbol (0 without a filter)."""
        return self.keyword_filter.unknown_count if self.keyword_filter is not None else 0

    def speech(self, text: str, confidence: float = 1.0) -> Optional[str]:
        """The symbol of recognised text, or ``None`` (counted) when it maps to no symbol."""
        if self.keyword_filter is not None:
            symbol = self.keyword_filter.classify(text)
            if confidence < self.confidence_floor and symbol != self.keyword_filter.unknown_symbol:
                self.low_confidence += 1
                symbol = self.keyword_filter.unknown_symbol
        else:
            symbol = text.strip()
        if symbol not in self.speech_symbols or symbol not in self.model.observations:
            self.invalid["speech"] += 1
            return None
        return symbol

    def symbol(self, key: str, text: str) -> Optional[str]:
        """The symbol of a touchscreen/laser/reminder string, or ``None`` (counted) if invalid."""
        symbol = text.strip()
        if symbol not in self.allowed[key]:
            self.invalid[key] += 1
            return None
        return symbol


@dataclass
class InputOutcome:
    """What one input did: its symbol (``None``: invalid, counted) and the step it closed, if any."""

    symbol: Optional[str]
    closed: Optional[StepResult] = None
    text: str = ""
    confidence: float = 1.0


class BeliefTracker:
    """The step loop on raw inputs: :class:`ObservationMapper` + :class:`StepProtocol`.

    Args:
        model: the compiled model (beliefs are ``[S]`` over its states).
        domain: the FactoredDomain (modalities, keywords, drives, marginals), or ``None``.
        settings: the step rules (:class:`StepSettings`; defaults when ``None``).
        keyword_filter: overrides the domain's keyword filter.

    Raises:
        ValueError: a setting is out of range or names something the model does not have.
    """

    def __init__(self, model: Pomdp, domain=None, settings: Optional[StepSettings] = None,
                 keyword_filter: Optional[KeywordFilter] = None):
        self.settings = settings = settings or StepSettings()
        self.model, self.domain = model, domain
        if settings.no_timeout_actions is None:
            no_timeout = drive_actions(domain) if domain is not None else []
        else:
            no_timeout = [a for a in settings.no_timeout_actions if a in model.actions]
        #: Deadlines of the drives (:class:`~pearl_pomdp.navigation.DriveTimer`), or ``None``.
        self.drive_timer = settings.drive_timer(domain, no_timeout)
        missing_symbol = self.drive_timer is not None and settings.nav_failed_observation not in model.observations
        if missing_symbol:
            # A domain written before navFailed existed (a recorded bag's copy): drives keep no
            # deadline, as when it was recorded; said once at start.
            self.drive_timer = None
        self.protocol = StepProtocol(model, step_timeout=settings.step_timeout,
                                     timeout_observation=settings.timeout_observation,
                                     no_timeout_actions=no_timeout, max_pending=settings.max_pending,
                                     stale_after=settings.stale_after,
                                     nav_failed_observation=(settings.nav_failed_observation
                                                             if self.drive_timer is not None else None))
        if missing_symbol:
            self.protocol.events.append(Event("warn", f"drives have no deadline: nav_failed_observation "
                                                      f"{settings.nav_failed_observation!r} is not an observation of "
                                                      f"{model.name} (add it to the domain's Laser modality)", kind="no_deadline"))
        self.mapper = ObservationMapper(model, domain, keyword_filter, settings.confidence_floor)
        self._marginal_index: Optional[list] = None
        #: The last closed steps, oldest first, when :meth:`keep_history` was called (replay --explain).
        self.history: Optional[Deque[StepResult]] = None

    def keep_history(self, maxlen: int = 10_000) -> None:
        """Remember the last ``maxlen`` closed steps in :attr:`history` (off by default: a robot runs for days)."""
        self.history = collections.deque(maxlen=maxlen)

    def _closed(self, result: Optional[StepResult]) -> Optional[StepResult]:
        if result is not None and self.history is not None:
            self.history.append(result)
        return result

    # The protocol's state, for callers that only hold the tracker.
    @property
    def belief(self) -> np.ndarray:
        return self.protocol.belief

    @property
    def step_open(self) -> bool:
        return self.protocol.step_open

    def deadline(self) -> Optional[float]:
        """When the open step times out, or ``None`` (see :meth:`StepProtocol.deadline`)."""
        return self.protocol.deadline()

    def reset(self) -> None:
        """Back to ``b0``: no open step, nothing queued, counters zeroed."""
        self.protocol.reset()

    def on_action(self, name: str, now: float) -> Optional[StepResult]:
        """An action was taken at ``now``: opens a step (a queued input may close it at once).

        A drive gets its deadline here, from the place the robot most likely is now.
        """
        limit = None
        if self.drive_timer is not None and name in self.drive_timer.goals:
            limit = self.drive_timer.seconds(name, self.likely_place())
        return self._closed(self.protocol.on_action(name, now, limit))

    def likely_place(self) -> Optional[str]:
        """The most likely value of ``place_feature`` under the current belief (``None`` without a drive timer)."""
        if self.drive_timer is None:
            return None
        marginal = self.marginals().get(self.settings.place_feature, {})
        return max(marginal, key=lambda v: marginal[v]) if marginal else None

    def on_tick(self, now: float) -> Optional[StepResult]:
        """The clock reads ``now``: closes the step on its timeout."""
        return self._closed(self.protocol.on_tick(now))

    def on_input(self, key: str, data: str, now: float) -> InputOutcome:
        """One input message: ``key`` is ``speech``, ``touchscreen``, ``laser`` or ``reminder``.

        Speech ``data`` is recogniser text, optionally with its confidence
        (:func:`~pearl_pomdp.speech.parse_speech_message`); the others carry a symbol.
        """
        if key == "speech":
            text, confidence = parse_speech_message(data)
            symbol = self.mapper.speech(text, confidence)
        elif key in SYMBOL_INPUTS:
            text, confidence = data, 1.0
            symbol = self.mapper.symbol(key, data)
        else:
            raise ValueError(f"unknown input {key!r}; inputs: {', '.join(INPUTS)}")
        if symbol is None:
            return InputOutcome(None, None, text, confidence)
        closed = self._closed(self.protocol.on_observation(symbol, key, now, text, confidence))
        return InputOutcome(symbol, closed, text, confidence)

    def take_events(self) -> List[Event]:
        return self.protocol.take_events()

    def counters(self) -> Dict[str, int]:
        """Every counter of the step rules and the input mapping."""
        out = dict(self.protocol.counters)
        out["unknown_speech"] = self.mapper.unknown_speech
        out["low_confidence"] = self.mapper.low_confidence
        for key, n in self.mapper.invalid.items():
            out[f"invalid_{key}"] = n
        return out

    def warnings(self) -> int:
        """How many inputs were dropped, invalid or recovered, plus the drives that missed their
        deadline (the /diagnostics WARN condition)."""
        c = self.counters()
        return (c["dropped_stale"] + c["dropped_overflow"] + c["replaced_actions"] + c["unknown_actions"]
                + c["zero_likelihood"] + c["nav_failures"] + sum(c[f"invalid_{k}"] for k in INPUTS))

    def marginals(self, belief: Optional[np.ndarray] = None) -> Dict[str, Dict[str, float]]:
        """``{feature: {value: P}}`` of ``belief`` (default: the current one); a flat model
        reports the pseudo-feature ``"state"``."""
        b = self.belief if belief is None else belief
        if self.domain is None:
            return {"state": {s: float(pv) for s, pv in zip(self.model.states, b)}}
        if self._marginal_index is None:
            # state_values[s, f] = value index of feature f in state s: a marginal is one bincount.
            values = np.asarray(self.domain.state_values)
            self._marginal_index = [(f.name, [str(v) for v in f.values], values[:, i])
                                    for i, f in enumerate(self.domain.features)]
        return {name: dict(zip(names, np.bincount(col, weights=b, minlength=len(names)).tolist()))
                for name, names, col in self._marginal_index}

