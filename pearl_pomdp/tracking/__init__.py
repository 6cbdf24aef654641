"""Belief tracking step by step: the one step loop the robot, the simulator and the study run.

The step protocol (docs/design.md §6): the policy publishes an action ``a_t``; the next
observation ``o_{t+1}`` (one input from any modality) closes the step; the belief is
updated with ``(a_t, o_{t+1})`` by eq. 5; the policy answers with ``a_{t+1}``.
:class:`BeliefTracker` is that loop without ROS, behind one closed façade:

* **in**: :meth:`~BeliefTracker.on_input` (an input message), :meth:`~BeliefTracker.on_action`
  (an action taken), :meth:`~BeliefTracker.on_tick` (the clock), :meth:`~BeliefTracker.reset`,
  :meth:`~BeliefTracker.abandon_step` (stop without an update) and
  :meth:`~BeliefTracker.set_live` (the settings that may change while running);
* **out**: every call that takes an input, an action or the clock returns one
  :class:`InputOutcome` — what it did (its :attr:`~InputOutcome.kind`), the step it closed and
  the :class:`Event` s to log; the rest is read-only state (belief, counters, deadline).

The ``belief_tracker`` node is a thin rclpy wrapper of it (subscriptions call ``on_input`` /
``on_action``, a one-shot timer at :meth:`~BeliefTracker.deadline` calls ``on_tick``), and
:class:`pearl_pomdp.executive.Executive` drives the same object for experiments with
thousands of episodes — so a change to the rules below shows up in both. Its settings are
:class:`StepSettings`, whose fields are the node's parameters (name, type, range,
description, whether it may change at run time): one source for every default.

**Inputs → observation symbols** (the one place this is done: :mod:`pearl_pomdp.tracking.readers`,
one reader class per input kind). The inputs are the domain's
channels (:attr:`FactoredDomain.inputs <pearl_pomdp.model.factored.FactoredDomain.inputs>`, one
per modality, declared in the domain file: :mod:`pearl_pomdp.channels`); the code lists none.
Each input is read by its kind:

* ``speech``: text that is exactly a symbol of the input is that symbol (a script or a
  recogniser that sends the symbol itself); other text goes through the domain's keyword
  filter (:class:`pearl_pomdp.speech.KeywordFilter`, over the input's symbols): text with no
  keyword becomes the input's ``unknown`` symbol (still an observation: the robot heard
  something it did not understand) and is counted. A recogniser may attach its confidence
  (:func:`pearl_pomdp.speech.parse_speech_message`): a keyword heard with confidence below
  ``confidence_floor`` is taken as the unknown symbol too (counter ``low_confidence``) — a
  mumbled "yes" is weaker evidence than a clear one, and the model's speech noise already
  describes how often the unknown symbol goes with each true state.
* ``symbol``: the string must be a symbol of the input's modality (blanks around it are
  ignored); anything else is *invalid*: counted per input, reported, and no observation is made.
* ``number``: the number is discretised into the symbol of its bin, with hysteresis
  (:class:`~pearl_pomdp.channels.NumberDiscretiser`); a reading outside the declared range is
  invalid. With ``report: change`` a reading that keeps the input's symbol makes no observation
  (counter ``unchanged_<input>``); one of the input's symbols given as text is taken as it is.
* A flat model (no domain) has one input, ``observation``, on which every symbol is valid.

**The cases the paper leaves open**, each counted in :meth:`BeliefTracker.counters`:

* *Nothing is heard.* With ``step_timeout > 0`` a step still open ``step_timeout`` seconds
  after its action is closed with ``timeout_observation`` (default: the domain's silence
  symbol, :attr:`FactoredDomain.silence_symbol <pearl_pomdp.model.factored.FactoredDomain.silence_symbol>`
  — the symbol an input declares as ``silence:``, else a speech input's unknown symbol:
  silence carries no more information than unrecognised speech). :meth:`BeliefTracker.deadline`
  says when; the node arms a one-shot timer for that instant, the simulator jumps its
  clock to it. Counter ``timeouts``. Actions listed in ``no_timeout_actions`` (by
  default the domain's actions of ``drive_category``, none unless it is set) are not closed
  by ``step_timeout``: a drive takes as long as it takes and navigation ends it with a landmark.
* *A drive that never arrives* (a blocked corridor, lost localisation). With
  ``drive_speed > 0`` each drive gets its own deadline from
  :class:`~pearl_pomdp.navigation.DriveTimer`: the distance from the place the robot most
  likely is (the belief's ``place_feature`` marginal when the drive starts) to the drive's
  goal, at ``drive_speed`` (``guide_speed`` for ``guide_actions``), through
  :class:`~pearl_pomdp.navigation.DriveDeadline`. When it passes without an observation
  the step closes with ``nav_failed_observation`` (a symbol of the domain whose rows say the
  robot is most likely still where it started; Pearl's ``navFailed``), counter
  ``nav_failures``, a warning; the policy decides what next (retry, ask, go home). The
  navigation's progress reports (Nav2's feedback, :meth:`BeliefTracker.on_drive_progress`)
  move that deadline to what the remaining path needs while the robot gets closer.
* *Observation before any action / several in one step.* Inputs have no header, so
  arrival order is the only order there is. An observation while no step is open is
  *queued* (FIFO, at most ``max_pending``; on overflow the oldest is dropped — counter
  ``dropped_overflow``); the next action closes its step at once with the oldest queued
  one. Counter ``queued``.
* *An input during a drive that the drive can never give.* While a drive is open (an action of
  ``no_timeout_actions``), an observation its observation table gives in no state — a word she
  says while Pearl guides her, whose step only a landmark, ``navFailed`` or ``userLost`` closes in
  Pearl's domain; a battery reading — does not close the step: closing it would end the drive
  in the belief while the robot still drives (the filter throws such an observation away, and the
  policy would act again mid-drive). It is queued as below (counter ``held``) and closes the first
  step after the drive (a later drive that cannot give it leaves it waiting too), or goes stale. Other actions' steps close with
  whatever comes first, as before: a misheard word is still the answer to the question asked.
* *Stale input.* With ``stale_after > 0`` a queued observation older than that when it
  would be used is dropped (``dropped_stale``): it answers a question no longer asked.
* *A second action while a step is open*: the newer one replaces it, because the robot
  does what it was last told (``replaced_actions``).
* *An unknown action name* is ignored (``unknown_actions``).
* *Zero-likelihood observations* are recovered by :class:`~pearl_pomdp.belief.BeliefFilter`
  (``zero_likelihood``).

Nothing is dropped silently: every case increments a counter and records an :class:`Event`
(in the :class:`InputOutcome` of the call) that the node logs and reports on ``/diagnostics``.
"""
from __future__ import annotations

import collections
import dataclasses
import secrets
from dataclasses import dataclass
from typing import Any, Deque, Dict, FrozenSet, List, Mapping, Optional, Sequence, Tuple, Union

import numpy as np

from pearl_pomdp.belief import BeliefFilter
from pearl_pomdp.channels import InputChannel, flat_channels
from pearl_pomdp.model.pomdp import Pomdp
from pearl_pomdp.navigation import DriveTimer
from pearl_pomdp.speech import KeywordFilter, Utterance
from pearl_pomdp.tracking.readers import SpeechReader, input_readers
from pearl_pomdp.tracking.settings import SettingSpec, StepSettings, drive_actions

__all__ = ["BeliefTracker", "InputOutcome", "StepResult", "StepSettings", "SettingSpec", "Event",
           "COUNTERS", "drive_actions"]

#: Names of the step rules' counters (reported on /diagnostics; :meth:`BeliefTracker.counters`
#: adds the input mapping's: ``unknown_speech``, ``low_confidence``, ``invalid_<input>`` for
#: every input and ``unchanged_<input>`` for every number input).
COUNTERS = ("updates", "timeouts", "nav_failures", "queued", "dropped_stale", "dropped_overflow",
            "replaced_actions", "unknown_actions", "zero_likelihood", "drive_progress", "deadline_moves", "held")

#: A step may close this much before its deadline (clock rounding: sim time travels in ns).
_DEADLINE_SLACK = 1e-9




@dataclass
class StepResult:
    """One closed step: the belief after ``(action, observation)``.

    Attributes:
        step: how many steps are closed, this one included (1 for the first).
        action: ``a_t``, the action that opened the step.
        observation: ``o_{t+1}``, the symbol that closed it.
        source: where the observation came from (``speech``, ``touchscreen`` …, ``timeout`` or
            ``nav_deadline``).
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


@dataclass(frozen=True)
class InputOutcome:
    """What one call of the tracker did: the one outcome of :meth:`BeliefTracker.on_input`,
    :meth:`~BeliefTracker.on_action`, :meth:`~BeliefTracker.on_tick` and
    :meth:`~BeliefTracker.abandon_step`.

    Attributes:
        kind: what happened —

            * ``"closed"``: the call closed a step (:attr:`closed` holds it): an input closed the
              open step, a queued input closed the step an action opened, or the clock passed
              a deadline;
            * ``"queued"``: an input arrived while no step was open and waits for the next action;
            * ``"invalid"``: the input maps to no observation symbol (counted, nothing observed);
            * ``"dropped"``: the input was dropped at once (``max_pending`` 0);
            * ``"opened"``: an action opened a step and nothing closed it yet;
            * ``"unknown"``: the action is not one of the model's (counted, ignored);
            * ``"abandoned"``: :meth:`~BeliefTracker.abandon_step` left the open step without an update;
            * ``"resumed"``: the action a step resumed from a journal was opened with, heard again
              (the policy's latched copy): the step goes on, nothing is reopened;
            * ``"moved"``: a drive's progress report moved its deadline
              (:meth:`~BeliefTracker.on_drive_progress`);
            * ``"idle"``: nothing happened (a tick before any deadline, nothing to abandon, a
              number input's reading that kept its symbol, a progress report that moved nothing).
        closed: the step closed by this call, or ``None``.
        symbol: the observation symbol the input was taken as (``None`` for an invalid input,
            an action or a tick).
        heard: how an input was read — ``"symbol"`` (a symbol input, or speech that was itself
            a Speech symbol), ``"keyword"`` (speech through the keyword filter),
            ``"no_keyword"`` (speech with no keyword: the unknown symbol, counted),
            ``"low_confidence"`` (a keyword below ``confidence_floor``: the unknown symbol,
            counted), ``"number"`` (a number input's reading gave a new symbol),
            ``"unchanged"`` (a number input's reading kept its symbol: kind ``"idle"``, nothing
            observed, counted), ``"invalid"``; ``""`` for actions and ticks.
        text: the input's text (speech as recognised, without its confidence).
        confidence: the recogniser's confidence (1.0 when none was given).
        events: what the call has to report, oldest first (the node logs each).
    """

    kind: str
    closed: Optional[StepResult] = None
    symbol: Optional[str] = None
    heard: str = ""
    text: str = ""
    confidence: float = 1.0
    events: Tuple[Event, ...] = ()


@dataclass
class _Pending:
    symbol: str
    source: str
    stamp: float
    text: str = ""
    confidence: float = 1.0


class _StepProtocol:
    """The step rules over a flat :class:`Pomdp`, on observation *symbols* (see the module doc).

    Args:
        model: the POMDP (``T[a][s, s']``, ``O[a, s', o]``).
        step_timeout, timeout_observation, no_timeout_actions, max_pending, stale_after:
            see :class:`StepSettings` (``no_timeout_actions`` here is a plain list).
        belief_filter: the filter to use (a new :class:`BeliefFilter` by default).

    Private: :class:`BeliefTracker` is its only user (ranges are checked by :class:`StepSettings`).

    Raises:
        ValueError: a named symbol/action is not in the model (the message names the parameter
            and the valid values).
    """

    def __init__(self, model: Pomdp, *, step_timeout: float = 0.0, timeout_observation: str = "",
                 no_timeout_actions: Sequence[str] = (), max_pending: int = 8, stale_after: float = 0.0,
                 belief_filter: Optional[BeliefFilter] = None, nav_failed_observation: Optional[str] = None):
        self.check_timeout(model, step_timeout, timeout_observation)
        if nav_failed_observation is not None and nav_failed_observation not in model.observations:
            raise ValueError(f"nav_failed_observation {nav_failed_observation!r} is not an observation of "
                             f"{model.name} (add it to a modality of the domain, or set drive_speed 0 "
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
        #: Per drive action index, ``[Z]``: whether its observation table gives ``o`` in some state
        #: (module doc, *an input during a drive*); filled at a drive's first input (a large model's
        #: table is read once per drive, not per tracker).
        self._drive_gives: Dict[int, np.ndarray] = {}
        self.counters: Dict[str, int] = {}
        self.reset()

    @staticmethod
    def check_timeout(model: Pomdp, step_timeout: float, timeout_observation: str) -> None:
        """A timeout needs its observation in the model (raises ``ValueError`` naming both)."""
        if step_timeout > 0 and not timeout_observation:
            raise ValueError(f"timeout_observation: step_timeout {step_timeout:g} s needs the symbol a silent step "
                             f"closes with; set it (valid: {', '.join(model.observations)}), declare silence: on an "
                             "input of the domain, or set step_timeout 0")
        if step_timeout > 0 and timeout_observation not in model.observations:
            raise ValueError(f"timeout_observation {timeout_observation!r} is not an observation of "
                             f"{model.name} (valid: {', '.join(model.observations)}; or step_timeout 0)")

    # ---------------------------------------------------------------- state
    def reset(self) -> None:
        """Back to ``b0`` with no open step, nothing queued and zeroed counters."""
        self.belief = np.array(self.model.b0, dtype=float)
        self.step = 0
        self.current_action: Optional[str] = None
        self.opened_at: Optional[float] = None
        #: Seconds the open drive may take (``None``: not a timed drive).
        self.drive_limit: Optional[float] = None
        #: The fewest metres the open drive's progress reports have said remain (``None``: none yet).
        self.closest_remaining: Optional[float] = None
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

    def abandon(self) -> bool:
        """Leave the open step without an update (True if one was open)."""
        was_open = self.step_open
        self.current_action = None
        self.opened_at = None
        self.drive_limit = None
        self.closest_remaining = None
        return was_open

    def take_events(self) -> List[Event]:
        """The events since the last call (for the tracker's outcome), oldest first."""
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
        self.closest_remaining = None
        kept: List[_Pending] = []   # queued inputs this action's step can never get: they wait on
        closed = None
        while self.pending:
            item = self.pending.popleft()
            if self.stale_after > 0 and now - item.stamp > self.stale_after:
                self.counters["dropped_stale"] += 1
                self.events.append(Event("warn", f"dropped stale observation {item.symbol!r} from {item.source} "
                                                 f"({now - item.stamp:.3f} s old > stale_after {self.stale_after} s)", kind="stale"))
                continue
            if not self.can_close(item.symbol):
                kept.append(item)
                continue
            closed = self._close(item.symbol, item.source, now, item.text, item.confidence)
            break
        self.pending.extendleft(reversed(kept))
        return closed

    def can_close(self, symbol: str) -> bool:
        """Whether ``symbol`` may close the open step: False only while a drive (an action of
        ``no_timeout_actions``) is open whose observation table gives ``symbol`` in no state."""
        if self.current_action is None or self.current_action not in self.no_timeout_actions:
            return True
        a = self._action_index[self.current_action]
        gives = self._drive_gives.get(a)
        if gives is None:
            gives = self._drive_gives[a] = np.asarray(self.model.O[a]).max(axis=0) > 0
        return bool(gives[self._obs_index[symbol]])

    def on_observation(self, symbol: str, source: str, now: float, text: str = "",
                       confidence: float = 1.0) -> Tuple[str, Optional[StepResult]]:
        """An observation symbol arrived from ``source`` at time ``now`` (s).

        Closes the open step, or queues the observation when no step is open or the open action
        can never give it (:meth:`can_close`). Returns ``(kind, closed step)``: kind ``"closed"``,
        ``"queued"`` or ``"dropped"`` (``max_pending`` 0).

        Raises:
            ValueError: ``symbol`` is not an observation of the model (callers validate first).
        """
        if symbol not in self._obs_index:
            raise ValueError(f"{symbol!r} is not an observation of {self.model.name}")
        if self.step_open and self.can_close(symbol):
            return "closed", self._close(symbol, source, now, text, confidence)
        held = self.step_open
        if held:
            self.counters["held"] += 1
        if self.max_pending == 0 or len(self.pending) >= self.max_pending:
            if self.pending:
                old: Optional[_Pending] = self.pending.popleft()
                assert old is not None
                what = f"dropped queued observation {old.symbol!r} from {old.source}"
            else:
                old = None
                what = f"dropped observation {symbol!r} from {source}"
            self.counters["dropped_overflow"] += 1
            self.events.append(Event("warn", f"{what}: more than max_pending={self.max_pending} "
                                             f"observations wait for an action", kind="overflow"))
            if old is None:
                return "dropped", None
        self.pending.append(_Pending(symbol, source, float(now), text, confidence))
        self.counters["queued"] += 1
        why = (f"{self.current_action!r} never gives it (its observation table), so it waits for a step that can"
               if held else "no open step")
        self.events.append(Event("info", f"queued observation {symbol!r} from {source}: {why} "
                                         f"({len(self.pending)} waiting)", kind="held" if held else "queued"))
        return "queued", None

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

    def on_drive_progress(self, action: str, path_remaining: float, allowed: float, max_seconds: float,
                          now: float) -> bool:
        """Progress of the open timed drive ``action`` at ``now``: ``path_remaining`` metres left, which
        are ``allowed`` seconds. When the robot is closer than any earlier report of this drive said,
        the deadline moves to ``now + allowed`` (at most ``max_seconds`` after the drive began); True
        if it moved. Every report is counted (``drive_progress``), each move too (``deadline_moves``)."""
        self.counters["drive_progress"] += 1
        if (self.current_action != action or self.drive_limit is None or self.opened_at is None
                or (self.closest_remaining is not None and path_remaining >= self.closest_remaining)):
            return False
        self.closest_remaining = path_remaining
        limit = min(max_seconds, max(0.0, now - self.opened_at) + allowed)
        if limit == self.drive_limit:
            return False
        self.drive_limit = limit
        self.counters["deadline_moves"] += 1
        return True

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
        self.closest_remaining = None
        return StepResult(self.step, action, symbol, source, self.belief, zero, float(now), text or symbol,
                          confidence)



class BeliefTracker:
    """The step loop on raw inputs, behind one closed façade (see the module doc).

    Args:
        model: the compiled model (beliefs are ``[S]`` over its states).
        domain: the FactoredDomain (modalities, keywords, drives, marginals), or ``None``.
        settings: the step rules (:class:`StepSettings`; its defaults when ``None``).
        keyword_filter: overrides the domain's keyword filter (for every speech input).
        channels: the inputs (:class:`~pearl_pomdp.channels.InputChannel`); default: the
            domain's (:attr:`FactoredDomain.inputs`), or a flat model's one ``observation`` input
            (a speech input when ``keyword_filter`` is given).

    Attributes:
        settings: the settings in force (:meth:`set_live` replaces them).
        timeout_observation: the symbol a timed-out step closes with (the setting, else the
            domain's silence symbol; ``""`` when there is none).
        startup_events: what construction has to report (e.g. drives left without deadlines).
        history: the last closed steps, oldest first, once :meth:`keep_history` was called.

    Raises:
        ValueError: a setting is out of range or names something the model does not have.
    """

    def __init__(self, model: Pomdp, domain=None, settings: Optional[StepSettings] = None,
                 keyword_filter: Optional[KeywordFilter] = None, channels: Optional[Sequence[InputChannel]] = None):
        self.settings = settings = settings or StepSettings()
        self.model, self.domain = model, domain
        self.timeout_observation = settings.timeout_observation or (
            (domain.silence_symbol or "") if domain is not None else "")
        if settings.no_timeout_actions is None:
            no_timeout = drive_actions(domain, settings.drive_category) if domain is not None else []
        else:
            no_timeout = [a for a in settings.no_timeout_actions if a in model.actions]
        self._drive_timer = settings.drive_timer(domain, no_timeout)
        missing_symbol = self._drive_timer is not None and settings.nav_failed_observation not in model.observations
        startup: List[Event] = []
        if missing_symbol:
            # A domain written before navFailed existed (a recorded bag's copy): drives keep no
            # deadline, as when it was recorded; said once at start.
            self._drive_timer = None
            startup.append(Event("warn", f"drives have no deadline: nav_failed_observation "
                                         f"{settings.nav_failed_observation!r} is not an observation of "
                                         f"{model.name} (add it to a modality of the domain)", kind="no_deadline"))
        self.startup_events: Tuple[Event, ...] = tuple(startup)
        self._protocol = _StepProtocol(model, step_timeout=settings.step_timeout,
                                       timeout_observation=self.timeout_observation,
                                       no_timeout_actions=no_timeout, max_pending=settings.max_pending,
                                       stale_after=settings.stale_after,
                                       nav_failed_observation=(settings.nav_failed_observation
                                                               if self._drive_timer is not None else None))
        if channels is None:
            channels = domain.inputs if domain is not None else \
                flat_channels(model.observations, "speech" if keyword_filter is not None else "symbol")
        #: Input name → its reader (:mod:`pearl_pomdp.tracking.readers`, one class per input kind).
        self._readers = input_readers(model, channels, domain.keywords if domain is not None else {},
                                      keyword_filter, settings.confidence_floor)
        self._speech = [r for r in self._readers.values() if isinstance(r, SpeechReader)]
        self.history: Optional[Deque[StepResult]] = None
        self._run = 1 + secrets.randbits(31)   # never 0: a belief with run 0 carries none
        self._resumed_action: Optional[str] = None
        #: (belief array, its journal text): a step's opening journals the belief its closing just did
        #: (the ward's base64 is ~2 ms); the belief is only ever replaced, never changed in place.
        self._encoded_belief: Tuple[Optional[np.ndarray], str] = (None, "")

    # ------------------------------------------------------------ read-only
    @property
    def belief(self) -> np.ndarray:
        """The current belief ``[S]`` (a fresh array after each update; never mutated)."""
        return self._protocol.belief

    @property
    def step(self) -> int:
        """Steps closed since :meth:`reset`."""
        return self._protocol.step

    @property
    def step_open(self) -> bool:
        """True while an action waits for its observation."""
        return self._protocol.step_open

    @property
    def open_action(self) -> Optional[str]:
        """The action of the open step, or ``None``."""
        return self._protocol.current_action

    @property
    def opened_at(self) -> Optional[float]:
        """When the open step was opened (clock seconds), or ``None``."""
        return self._protocol.opened_at

    @property
    def pending(self) -> int:
        """Observations waiting for the next action."""
        return len(self._protocol.pending)

    @property
    def last_nav_failure(self) -> str:
        """Why the last drive failed (for /diagnostics); empty until one did."""
        return self._protocol.last_nav_failure

    @property
    def drive_timer(self) -> Optional[DriveTimer]:
        """The drives' deadlines (:class:`~pearl_pomdp.navigation.DriveTimer`), or ``None``."""
        return self._drive_timer

    @property
    def no_timeout_actions(self) -> FrozenSet[str]:
        """The actions ``step_timeout`` never closes (the drives)."""
        return self._protocol.no_timeout_actions

    @property
    def keyword_filter(self) -> Optional[KeywordFilter]:
        """The first speech input's keyword filter, or ``None`` (no speech input with keywords:
        speech text must be a symbol)."""
        return next((r.keyword_filter for r in self._speech if r.keyword_filter is not None), None)

    @property
    def channels(self) -> Tuple[InputChannel, ...]:
        """The inputs, in the domain's modality order (the node subscribes to each)."""
        return tuple(r.channel for r in self._readers.values())

    def symbols(self, key: str) -> FrozenSet[str]:
        """The observation symbols input ``key`` may carry.

        Raises:
            ValueError: ``key`` is not an input (names the inputs).
        """
        return self._readers[self._check_input(key)].allowed

    def _check_input(self, key: str) -> str:
        if key not in self._readers:
            raise ValueError(f"unknown input {key!r}; inputs: {', '.join(self._readers)}")
        return key

    def input_for(self, observation: str) -> str:
        """The input that carries ``observation``: the one whose symbols have it, else the first
        speech input (recognised text for its keyword filter), else the first input."""
        stripped = observation.strip()
        for key, reader in self._readers.items():
            if stripped in reader.allowed:
                return key
        return self._speech[0].channel.name if self._speech else next(iter(self._readers))

    def deadline(self) -> Optional[float]:
        """When the open step times out (clock seconds), or ``None`` (no open step, no timeout,
        a drive without a deadline). A drive's deadline is its opening time plus its limit."""
        return self._protocol.deadline()

    def snapshot(self) -> Tuple[int, Optional[str], int]:
        """``(step, open action or None, number queued)`` — for diagnostics."""
        return self.step, self.open_action, self.pending

    def counters(self) -> Dict[str, int]:
        """Every counter of the step rules and the input mapping (all zeroed by :meth:`reset`)."""
        out = dict(self._protocol.counters)
        out["unknown_speech"] = sum(r.no_keyword for r in self._speech)
        out["low_confidence"] = sum(r.low_confidence for r in self._speech)
        for reader in self._readers.values():
            out.update(reader.counts())
        return out

    def warnings(self) -> int:
        """How many inputs were dropped, invalid or recovered, plus the drives that missed their
        deadline (the /diagnostics WARN condition)."""
        c = self.counters()
        return (c["dropped_stale"] + c["dropped_overflow"] + c["replaced_actions"] + c["unknown_actions"]
                + c["zero_likelihood"] + c["nav_failures"] + sum(r.invalid for r in self._readers.values()))

    def marginals(self, belief: Optional[np.ndarray] = None) -> Dict[str, Dict[str, float]]:
        """``{feature: {value: P}}`` of ``belief`` (default: the current one); a flat model
        reports the pseudo-feature ``"state"``."""
        b = self.belief if belief is None else belief
        if self.domain is None:
            return {"state": {s: float(pv) for s, pv in zip(self.model.states, b)}}
        marginals = self.domain.feature_marginals(b)
        return {f.name: dict(zip((str(v) for v in f.values), marginals[f.name].tolist())) for f in self.domain.features}

    def likely_place(self) -> Optional[str]:
        """The most likely value of ``place_feature`` under the current belief (``None`` without a drive timer)."""
        if self._drive_timer is None:
            return None
        marginal = self.marginals().get(self.settings.place_feature, {})
        return max(marginal, key=lambda v: marginal[v]) if marginal else None

    @property
    def run(self) -> int:
        """This run's identity: a random number drawn at construction, at every :meth:`reset` and
        :meth:`abandon_step` (the policy decides afresh) and kept by :meth:`resume`, so ``(run, step)`` names one belief of one run (the policy node
        answers each once: docs/reliability.md, "Crashes")."""
        return self._run

    def journal_state(self) -> Dict[str, Any]:
        """What a restarted tracker needs to carry on (JSON-serialisable; :meth:`resume` reads it):
        the belief, run and step, the open step (action, opening time, drive limit), the queued
        observations and the counters."""
        from pearl_pomdp.journal import encode_array

        proto = self._protocol
        if self._encoded_belief[0] is not proto.belief:
            self._encoded_belief = (proto.belief, encode_array(proto.belief))
        return {"num_states": int(self.model.num_states), "belief": self._encoded_belief[1],
                "run": self._run, "step": proto.step, "open_action": proto.current_action,
                "opened_at": proto.opened_at, "drive_limit": proto.drive_limit,
                "pending": [dataclasses.asdict(item) for item in proto.pending],
                "counters": dict(proto.counters), "last_nav_failure": proto.last_nav_failure}

    def resume(self, state: Mapping[str, Any]) -> None:
        """Carry on from a :meth:`journal_state` (the open step keeps its opening time, so its
        deadline too). Everything is checked before anything changes.

        Raises:
            ValueError: a field is missing or does not fit this model (names the field).
        """
        from pearl_pomdp.journal import decode_array

        try:
            belief = decode_array(state["belief"])
            run, step = int(state["run"]), int(state["step"])
            action = state.get("open_action")
            opened_at = None if state.get("opened_at") is None else float(state["opened_at"])
            limit = None if state.get("drive_limit") is None else float(state["drive_limit"])
            pending = [_Pending(str(p["symbol"]), str(p["source"]), float(p["stamp"]), str(p.get("text", "")),
                                float(p.get("confidence", 1.0))) for p in state.get("pending", [])]
            counters = {k: int(v) for k, v in dict(state.get("counters", {})).items() if k in COUNTERS}
        except (KeyError, TypeError, ValueError) as err:
            raise ValueError(f"journal state: missing or malformed field ({type(err).__name__}: {err})") from None
        if belief.size != self.model.num_states:
            raise ValueError(f"journal state: belief has {belief.size} states, {self.model.name} has "
                             f"{self.model.num_states}")
        if not np.isfinite(belief).all() or (belief < 0).any() or abs(belief.sum() - 1.0) > 1e-6:
            raise ValueError(f"journal state: belief is not a distribution (sum {belief.sum():.9g})")
        if step < 0:
            raise ValueError(f"journal state: step {step} < 0")
        if action is not None and (action not in self.model.actions or opened_at is None):
            raise ValueError(f"journal state: open_action {action!r} is not an action of {self.model.name} "
                             "or has no opened_at")
        unknown = sorted({p.symbol for p in pending} - set(self.model.observations))
        if unknown:
            raise ValueError(f"journal state: queued observation {unknown[0]!r} is not an observation of "
                             f"{self.model.name}")
        proto = self._protocol
        proto.belief, proto.step, self._run = belief, step, run
        proto.current_action, proto.opened_at = action, (opened_at if action is not None else None)
        proto.drive_limit = limit if action is not None else None
        proto.pending = collections.deque(pending)
        proto.counters.update(counters)
        proto.last_nav_failure = str(state.get("last_nav_failure", ""))
        #: The open step's action as resumed; the same action heard again (the policy's latched
        #: copy) is that step, not a new one (see :meth:`on_action`).
        self._resumed_action = action

    def keep_history(self, maxlen: int = 10_000) -> None:
        """Remember the last ``maxlen`` closed steps in :attr:`history` (off by default: a robot runs for days)."""
        self.history = collections.deque(maxlen=maxlen)

    # ------------------------------------------------------------ routes in
    def reset(self) -> None:
        """Back to ``b0``: no open step, nothing queued, every counter zeroed (history kept)."""
        self._protocol.reset()
        for reader in self._readers.values():
            reader.reset()
        self._run = 1 + secrets.randbits(31)   # never 0: a belief with run 0 carries none
        self._resumed_action = None

    def on_action(self, name: str, now: float) -> InputOutcome:
        """An action was taken at ``now``: opens a step (a queued input may close it at once).

        A drive gets its deadline here, from the place the robot most likely is now.
        """
        if self._resumed_action is not None:
            resumed, self._resumed_action = self._resumed_action, None
            if name == resumed and self._protocol.current_action == name:
                # The policy's latched copy of the action this resumed step was opened with.
                return self._outcome("resumed", None)
        limit = None
        if self._drive_timer is not None and name in self._drive_timer.goals:
            limit = self._drive_timer.seconds(name, self.likely_place())
        known = name in self.model.actions
        closed = self._protocol.on_action(name, now, limit)
        if closed is not None:
            return self._outcome("closed", closed)
        return self._outcome("opened" if known else "unknown", None)

    def on_tick(self, now: float) -> InputOutcome:
        """The clock reads ``now``: closes the open step when its deadline has passed."""
        closed = self._protocol.on_tick(now)
        return self._outcome("closed" if closed is not None else "idle", closed)

    def on_drive_progress(self, action: str, path_remaining: float, now: float) -> InputOutcome:
        """The navigation's progress on the drive ``action`` at ``now``: ``path_remaining`` metres left
        along its planned path (Nav2's ``NavigateToPose`` feedback, ``distance_remaining``).

        When ``action`` is the open step and a timed drive, and the robot is closer to its goal than
        any earlier report of this drive said, the drive's deadline moves to ``now`` plus the seconds
        those metres are allowed (:meth:`DriveTimer.remaining_seconds
        <pearl_pomdp.navigation.DriveTimer.remaining_seconds>`), never past ``drive_max_seconds`` after
        the drive began. So a drive that advances is timed by what is left, not by the distance guessed
        from where the robot most likely started; one that stands still or backs off gains no time
        (Nav2 ends it with an abort, or the deadline with ``nav_failed_observation``). Outcome kind
        ``"moved"`` when the deadline moved, else ``"idle"`` (a report for another action, no timed
        drive, no progress, or an invalid distance; counter ``drive_progress`` counts every report).
        """
        timer = self._drive_timer
        try:
            allowed = timer.remaining_seconds(action, float(path_remaining)) if timer is not None else None
        except ValueError:
            allowed = None
        if allowed is None:
            self._protocol.counters["drive_progress"] += 1
            return self._outcome("idle", None)
        moved = self._protocol.on_drive_progress(action, float(path_remaining), allowed,
                                                 self.settings.drive_max_seconds, now)
        return self._outcome("moved" if moved else "idle", None)

    def on_input(self, key: str, data: Union[str, float, Utterance], now: float) -> InputOutcome:
        """One input message on input ``key`` (one of :attr:`channels`' names).

        A speech input's ``data`` is an :class:`~pearl_pomdp.speech.Utterance` (the typed message:
        text, confidence and, when the recogniser mapped it, a symbol of the input, which is taken
        as heard; any other symbol is ignored and the text filtered), or recogniser text, optionally
        with its confidence (:func:`~pearl_pomdp.speech.parse_speech_message`); a symbol input's is a
        symbol; a number input's is the reading (a float, or one of its symbols as text).

        Raises:
            ValueError: ``key`` is not an input (names the inputs).
        """
        symbol, heard, text, confidence = self._readers[self._check_input(key)].read(data)
        if heard == "unchanged":   # a number input's reading that kept its symbol: nothing observed
            return self._outcome("idle", None, symbol, heard, text, confidence)
        if symbol is None:
            return self._outcome("invalid", None, None, heard, text, confidence)
        kind, closed = self._protocol.on_observation(symbol, key, now, text, confidence)
        return self._outcome(kind, closed, symbol, heard, text, confidence)

    def abandon_step(self) -> InputOutcome:
        """Leave the open step without an update (a deactivated node: the robot stops what it was
        doing, and on activation the policy decides afresh). The belief and the queue are kept; a new
        :attr:`run` begins, so the policy answers the kept belief again."""
        self._run = 1 + secrets.randbits(31)   # never 0: a belief with run 0 carries none
        self._resumed_action = None
        return self._outcome("abandoned" if self._protocol.abandon() else "idle", None)

    def set_live(self, *, step_timeout: Optional[float] = None, stale_after: Optional[float] = None,
                 confidence_floor: Optional[float] = None) -> None:
        """Change the settings that may change while running (:meth:`StepSettings.live_names`).

        Every value is checked before any is applied: out of range, or a timeout whose
        observation the model lacks, raises ``ValueError`` naming the field and changes nothing.
        The open step's deadline follows a new ``step_timeout`` at once.
        """
        new = dataclasses.replace(   # checks the ranges
            self.settings,
            step_timeout=self.settings.step_timeout if step_timeout is None else float(step_timeout),
            stale_after=self.settings.stale_after if stale_after is None else float(stale_after),
            confidence_floor=self.settings.confidence_floor if confidence_floor is None else float(confidence_floor))
        _StepProtocol.check_timeout(self.model, new.step_timeout, self.timeout_observation)
        self.settings = new
        self._protocol.step_timeout = new.step_timeout
        self._protocol.stale_after = new.stale_after
        for reader in self._speech:
            reader.confidence_floor = new.confidence_floor

    # ---------------------------------------------------------------- out
    def _outcome(self, kind: str, closed: Optional[StepResult], symbol: Optional[str] = None, heard: str = "",
                 text: str = "", confidence: float = 1.0) -> InputOutcome:
        if closed is not None and self.history is not None:
            self.history.append(closed)
        return InputOutcome(kind, closed, symbol, heard, text, confidence, tuple(self._protocol.take_events()))
