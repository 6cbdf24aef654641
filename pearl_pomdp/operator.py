"""A person in the loop: autonomy levels, confirmation, veto and command (ROS-free).

:class:`OperatorGate` stands between the decider and the action output. The policy node runs
one (``nodes/hierarchical_policy.py``); every call returns a :class:`GateOutput` saying what
to publish, so the node only wires topics to it.

* **Autonomy levels.** ``full``: the policy's action is published at once. ``confirm``: an
  action of a confirmed category (every action when no category is named) waits for the
  operator's yes/no; yes publishes it, no or ``confirm_timeout`` seconds without an answer
  publish nothing. ``off``: the action is only proposed. An action that is not published
  opens no step in the belief tracker, so the belief stays where it is: no action was taken,
  and inputs heard meanwhile wait in the tracker's queue (``max_pending``, ``stale_after``)
  for the next action. Changing the level re-offers a step's decision that was not acted
  (``full`` publishes it now, ``confirm`` asks again, ``off`` proposes it).
* **Veto.** The vetoed action is masked for the rest of this step (until the next belief);
  when it is the step's current choice the policy decides again at once without it
  (:meth:`~pearl_pomdp.interfaces.MaskingDecider.execute_without`) and the new choice goes
  through the level's rule (under ``full`` it replaces the vetoed one the robot was doing).
* **Command.** The operator's action is published as the robot's action whatever the level;
  the belief tracker then opens its step with it, so the belief follows what the robot did.
  A waiting proposal is withdrawn.

Operator input naming no action of the model, a veto with nothing decided, an answer with
nothing waiting: the output's ``error`` says so and nothing is acted.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Collection, Dict, List, Mapping, Optional, Sequence

import numpy as np

from pearl_pomdp.errors import PolicyError
from pearl_pomdp.interfaces import Decider, Decision, MaskingDecider

__all__ = ["AUTONOMY_LEVELS", "BY_SERVICE", "OperatorEvent", "GateOutput", "OperatorGate"]

#: The autonomy levels, most autonomous first.
AUTONOMY_LEVELS = ("full", "confirm", "off")

#: How the detail of a ``vetoed`` / ``commanded`` event ends when the operator used the policy node's
#: service (not its topic): a replay has no record of the call and does it again from the event.
BY_SERVICE = "by service"


@dataclass(frozen=True)
class OperatorEvent:
    """One thing the gate did, for the record (the node publishes each on the events topic).

    ``kind``: ``acted`` (published by the policy's rule), ``waiting`` (for a yes/no),
    ``proposed`` (level off), ``confirmed``, ``declined``, ``timeout``, ``vetoed``,
    ``commanded``, ``withdrawn`` (a waiting proposal superseded), ``autonomy`` (level changed),
    ``rejected`` (bad operator input; ``detail`` says why).
    """

    kind: str
    action: str
    step: int
    stamp: float
    autonomy: str
    detail: str = ""
    #: ``autonomy`` events: the new settings (``autonomy``, ``confirm_categories``, ``confirm_timeout``),
    #: so a replay can set them again.
    settings: Optional[dict] = None

    def as_dict(self) -> dict:
        """JSON-ready form (``settings`` only when there are some)."""
        out = {"event": self.kind, "action": self.action, "step": self.step, "stamp": self.stamp,
               "autonomy": self.autonomy, "detail": self.detail}
        if self.settings is not None:
            out["settings"] = dict(self.settings)
        return out


@dataclass
class GateOutput:
    """What a gate call asks the node to do.

    Attributes:
        publish: actions to publish as the robot's, in order.
        decisions: the policy's decisions made by this call (a veto's re-decision among them).
        events: what happened, for the record.
        error: why the operator's input was refused (``None``: it was not).
        proposal_changed: the :meth:`OperatorGate.proposal` changed (publish it again).
    """

    publish: List[str] = field(default_factory=list)
    decisions: List[Decision] = field(default_factory=list)
    events: List[OperatorEvent] = field(default_factory=list)
    error: Optional[str] = None
    proposal_changed: bool = False


class OperatorGate:
    """Autonomy levels, confirmation, veto and command around a decider.

    Args:
        decider: the policy (:class:`~pearl_pomdp.interfaces.Decider`; a veto needs a
            :class:`~pearl_pomdp.interfaces.MaskingDecider`).
        actions: the model's primitive action names.
        categories: action → category (the domain's ``category:`` tags; empty for a flat model).
        autonomy, confirm_categories, confirm_timeout: see :meth:`set_level`.

    Raises:
        ValueError: a setting is invalid (the message names it).
    """

    def __init__(self, decider: Decider, actions: Sequence[str], categories: Optional[Mapping[str, str]] = None, *,
                 autonomy: str = "full", confirm_categories: Collection[str] = (), confirm_timeout: float = 30.0):
        self.decider = decider
        self.actions = list(actions)
        self.categories = dict(categories or {})
        self.autonomy = "full"
        self.confirm_categories: tuple = ()
        self.confirm_timeout = 30.0
        self._check_level(autonomy, confirm_categories, confirm_timeout)
        self.autonomy, self.confirm_categories = autonomy, tuple(confirm_categories)
        self.confirm_timeout = float(confirm_timeout)
        self.step = -1                       # beliefs answered - 1
        self.belief: Optional[np.ndarray] = None
        self.current: Optional[str] = None   # the step's current action (policy's or operator's)
        self.source = ""                     # "policy" or "operator"
        self.status = "idle"                 # acted | waiting | proposed | declined | timeout | commanded
        self.vetoed: set = set()
        self.waiting_since: Optional[float] = None
        self.counts: Dict[str, int] = {}

    # ------------------------------------------------------------ settings
    def _check_level(self, autonomy: str, confirm_categories: Collection[str], confirm_timeout: float) -> None:
        if autonomy not in AUTONOMY_LEVELS:
            raise ValueError(f"autonomy: {autonomy!r} is not a level; expected one of {', '.join(AUTONOMY_LEVELS)}")
        known = set(self.categories.values())
        unknown = sorted(set(confirm_categories) - known)
        if unknown:
            shown = ", ".join(sorted(known)) if known else "none: the model tags no action with a category"
            raise ValueError(f"confirm_categories: {', '.join(map(repr, unknown))} is not a category of the "
                             f"model's actions (categories: {shown})")
        if not float(confirm_timeout) > 0:
            raise ValueError(f"confirm_timeout: must be > 0 s, got {confirm_timeout}")

    def needs_confirmation(self, action: str) -> bool:
        """Whether ``action`` waits for a yes under ``confirm`` (every action when no category is named)."""
        return not self.confirm_categories or self.categories.get(action) in self.confirm_categories

    def set_level(self, now: float, autonomy: Optional[str] = None,
                  confirm_categories: Optional[Collection[str]] = None,
                  confirm_timeout: Optional[float] = None) -> GateOutput:
        """Change the autonomy level and its settings (``None``: unchanged), all checked first.

        A step whose decision was not acted (proposed, waiting, declined, timed out) is offered
        again under the new rule.

        Raises:
            ValueError: an invalid value (names the setting); nothing is changed.
        """
        level = self.autonomy if autonomy is None else autonomy
        cats = self.confirm_categories if confirm_categories is None else tuple(confirm_categories)
        timeout = self.confirm_timeout if confirm_timeout is None else float(confirm_timeout)
        self._check_level(level, cats, timeout)
        changed = (level, cats, timeout) != (self.autonomy, self.confirm_categories, self.confirm_timeout)
        self.autonomy, self.confirm_categories, self.confirm_timeout = level, cats, timeout
        out = GateOutput()
        if not changed:
            return out
        detail = f"level {level}" + (f", confirm {', '.join(cats) or 'every action'} within {timeout:g} s"
                                     if level == "confirm" else "")
        self._event(out, "autonomy", self.current or "", now, detail,
                    settings={"autonomy": level, "confirm_categories": list(cats), "confirm_timeout": timeout})
        if self.current is not None and self.source == "policy" and self.status in ("proposed", "waiting", "declined",
                                                                                   "timeout"):
            self._offer(out, self.current, now)
        return out

    # ------------------------------------------------------------- inputs
    def on_belief(self, belief: np.ndarray, now: float) -> GateOutput:
        """A new belief (a new step): the vetoes of the last step end; decide and offer."""
        out = GateOutput()
        if self.status == "waiting" and self.current is not None:
            self._event(out, "withdrawn", self.current, now, "a new belief arrived before the answer")
        self.step += 1
        self.belief = np.asarray(belief, dtype=float)
        self.vetoed = set()
        decision = self.decider.execute(self.belief)
        out.decisions.append(decision)
        self.source = "policy"
        self._offer(out, decision.action_name, now)
        return out

    def veto(self, action: str, now: float) -> GateOutput:
        """The operator vetoes ``action`` for this step; the policy re-decides when it was the choice."""
        out = GateOutput()
        if self._reject_unknown(out, "veto", action, now):
            return out
        if self.belief is None:
            return self._refuse(out, "veto", action, now, "nothing has been decided yet")
        if not isinstance(self.decider, MaskingDecider):
            return self._refuse(out, "veto", action, now,
                                f"the policy ({type(self.decider).__name__}) cannot decide with actions forbidden")
        self.vetoed.add(action)
        if action != self.current or self.source != "policy":
            self._event(out, "vetoed", action, now, "not the current choice: masked for the rest of this step")
            return out
        try:
            decision = self.decider.execute_without(self.belief, sorted(self.vetoed))
        except PolicyError as err:
            self.vetoed.discard(action)
            return self._refuse(out, "veto", action, now, str(err))
        self._event(out, "vetoed", action, now, f"re-decided without {', '.join(sorted(self.vetoed))}: "
                                                f"{decision.action_name}")
        out.decisions.append(decision)
        self._offer(out, decision.action_name, now)
        return out

    def answer(self, yes: bool, now: float) -> GateOutput:
        """The operator's yes/no to the waiting action (an error when nothing is waiting)."""
        out = GateOutput()
        if self.status != "waiting" or self.current is None:
            out.error = "nothing is waiting for a confirmation" + (f" (autonomy {self.autonomy})"
                                                                   if self.autonomy != "confirm" else "")
            return out
        if yes:
            out.publish.append(self.current)
            self._set(out, "acted")
            self._event(out, "confirmed", self.current, now)
        else:
            self._set(out, "declined")
            self._event(out, "declined", self.current, now, "not acted")
        return out

    def command(self, action: str, now: float) -> GateOutput:
        """The operator commands ``action``: published as the robot's action at any level."""
        out = GateOutput()
        if self._reject_unknown(out, "command", action, now):
            return out
        if self.status == "waiting" and self.current is not None:
            self._event(out, "withdrawn", self.current, now, f"the operator commanded {action}")
        self.current, self.source = action, "operator"
        out.publish.append(action)
        self._set(out, "commanded")
        self._event(out, "commanded", action, now)
        return out

    def on_tick(self, now: float) -> GateOutput:
        """The clock reads ``now``: a waiting action whose time is up is not acted."""
        out = GateOutput()
        deadline = self.deadline()
        if deadline is not None and now >= deadline and self.current is not None:
            self._set(out, "timeout")
            self._event(out, "timeout", self.current, now, f"no answer within {self.confirm_timeout:g} s: not acted")
        return out

    def deadline(self) -> Optional[float]:
        """When the waiting action times out, or ``None``."""
        if self.status != "waiting" or self.waiting_since is None:
            return None
        return self.waiting_since + self.confirm_timeout

    def proposal(self) -> dict:
        """The step's current action and what became of it (the node's latched proposal topic)."""
        return {"step": self.step, "action": self.current or "", "source": self.source, "status": self.status,
                "autonomy": self.autonomy, "vetoed": sorted(self.vetoed), "deadline": self.deadline()}

    # ------------------------------------------------------------ helpers
    def _offer(self, out: GateOutput, action: str, now: float) -> None:
        self.current = action
        if self.autonomy == "off":
            self._set(out, "proposed")
            self._event(out, "proposed", action, now)
        elif self.autonomy == "confirm" and self.needs_confirmation(action):
            self._set(out, "waiting")
            self.waiting_since = float(now)
            self._event(out, "waiting", action, now, f"until {now + self.confirm_timeout:.3f} s")
        else:
            out.publish.append(action)
            self._set(out, "acted")
            self._event(out, "acted", action, now)

    def _set(self, out: GateOutput, status: str) -> None:
        self.status = status
        if status != "waiting":
            self.waiting_since = None
        out.proposal_changed = True

    def _event(self, out: GateOutput, kind: str, action: str, now: float, detail: str = "",
               settings: Optional[dict] = None) -> None:
        self.counts[kind] = self.counts.get(kind, 0) + 1
        out.events.append(OperatorEvent(kind, action, self.step, float(now), self.autonomy, detail, settings))

    def _reject_unknown(self, out: GateOutput, what: str, action: str, now: float) -> bool:
        if action in self.actions:
            return False
        shown = ", ".join(self.actions[:20]) + (" …" if len(self.actions) > 20 else "")
        name = action if len(action) <= 60 else action[:57] + "…"   # a flood of text stays one line
        self._refuse(out, what, name, now, f"{name!r} is not an action of the model (actions: {shown})")
        return True

    def _refuse(self, out: GateOutput, what: str, action: str, now: float, why: str) -> GateOutput:
        out.error = f"{what} refused: {why}"
        self._event(out, "rejected", action, now, out.error)
        return out
