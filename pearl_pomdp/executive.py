"""The executive: the step loop of :mod:`pearl_pomdp.tracking` plus a decider (docs/design.md §6).

The robot runs this loop split over two nodes — ``belief_tracker`` wraps the
:class:`~pearl_pomdp.tracking.BeliefTracker`, ``hierarchical_policy`` wraps the decider —
and the simulator and the study run it in one object, :class:`Executive`, driven by the
world's clock. Both use the same tracker, so the study measures the rules the robot
follows (timeouts, queueing, stale drops, drives that never time out, low-confidence
speech).

Timed use, the way the nodes see it::

    ex = Executive(model, decider, domain=domain)
    ex.start(now=0.0)                                   # ["GotoPatientRoom"]: a_0 from b0, step 1 open
    ex.on_input("speech", "what time is it", now=5.0)   # closes it → [a_1] ([] if nothing closed)
    ex.on_tick(now=15.0)                                # a timeout closed a step → [next action]

Each call returns the actions decided, in order: usually none or one; more when an
observation queued while no step was open closes the new step at once (the tracker node
then publishes each of them too).

Untimed use, for tests and scripted dialogs (one observation per action)::

    decision = ex.decide()                        # a_0 from b0
    ex.observe(decision.action_name, "go")        # closes step 0
    decision = ex.decide()                        # a_1 ...

A *decider* is a :class:`~pearl_pomdp.interfaces.Decider` (``execute(belief) -> Decision``):
a :class:`~pearl_pomdp.hierarchy.execute.HierarchicalPolicy`, or :class:`~pearl_pomdp.policies.flat.FlatPolicyDecider`
around a flat policy. An :class:`~pearl_pomdp.interfaces.ObservingDecider` (a behaviour
tree, a state machine) is also told every closed step.
"""
from __future__ import annotations

import logging
from typing import List, Optional

import numpy as np

from pearl_pomdp.errors import BeliefError
from pearl_pomdp.interfaces import Decider, Decision, ObservingDecider
from pearl_pomdp.model.pomdp import Pomdp
from pearl_pomdp.policies.flat import FlatPolicyDecider
from pearl_pomdp.tracking import BeliefTracker, StepResult, StepSettings

#: ``FlatPolicyDecider`` lives in :mod:`pearl_pomdp.policies`; it is named here too only while
#: ``nodes/hierarchical_policy.py`` imports it from this module.
__all__ = ["Executive", "FlatPolicyDecider"]

log = logging.getLogger(__name__)


class Executive:
    """The step loop (:class:`~pearl_pomdp.tracking.BeliefTracker`) with a decider answering each step.

    Args:
        model: the full flat POMDP (beliefs are ``[S]`` over its states).
        decider: a :class:`~pearl_pomdp.interfaces.Decider`.
        keyword_filter: overrides the domain's keyword filter; with either, :meth:`observe`
            also accepts recognised speech *text* (words matching no keyword become the
            unknown symbol and are counted).
        domain: the FactoredDomain (modalities, keywords, drives, :meth:`marginals`), optional.
        settings: the step rules (:class:`~pearl_pomdp.tracking.StepSettings`, whose defaults
            are the node's; the robot's values: :func:`pearl_pomdp.params.step_settings`). A
            model without the ``unknown`` symbol needs ``StepSettings(step_timeout=0.0)`` or
            another ``timeout_observation``.

    Attributes:
        tracker: the :class:`~pearl_pomdp.tracking.BeliefTracker` (the belief_tracker node runs the same class).
        last_decision: the most recent :class:`Decision` (``None`` before the first).
        steps: the closed :class:`~pearl_pomdp.tracking.StepResult` s since :meth:`reset`, oldest first.
    """

    def __init__(self, model: Pomdp, decider: Decider, keyword_filter=None, domain=None,
                 settings: Optional[StepSettings] = None):
        self.model = model
        self.decider = decider
        self.domain = domain
        self.tracker = BeliefTracker(model, domain, settings, keyword_filter)
        self._act_index = {a: i for i, a in enumerate(model.actions)}
        self.reset()

    # ------------------------------------------------------------------ state
    def reset(self) -> None:
        """Back to ``b0`` with zeroed counters (and the decider's memory, if it has one)."""
        self.tracker.reset()
        self.last_decision: Optional[Decision] = None
        self.steps: List[StepResult] = []
        if isinstance(self.decider, ObservingDecider):
            self.decider.reset()

    @property
    def belief(self) -> np.ndarray:
        """The current belief ``[S]`` (a fresh array after each update; never mutated)."""
        return self.tracker.belief

    @property
    def updates(self) -> int:
        """Belief updates done since :meth:`reset`."""
        return self.tracker.counters()["updates"]

    @property
    def zero_likelihood(self) -> int:
        """Updates whose observation had zero likelihood (recovered; see :mod:`pearl_pomdp.belief`)."""
        return self.tracker.counters()["zero_likelihood"]

    @property
    def unknown_inputs(self) -> int:
        """Speech texts the keyword filter could not classify (since :meth:`reset`)."""
        return self.tracker.counters()["unknown_speech"]

    # ------------------------------------------------------------- timed loop
    def decide(self) -> Decision:
        """The decider's :class:`Decision` at the current belief."""
        self.last_decision = self.decider.execute(self.belief)
        return self.last_decision

    def start(self, now: float = 0.0) -> List[str]:
        """Decide ``a_0`` at ``b0`` and open the first step at ``now``; returns the actions decided."""
        return self._answer(None, now)

    def on_input(self, key: str, data: str, now: float) -> List[str]:
        """One input message (see :meth:`BeliefTracker.on_input`); the actions decided because it closed a step."""
        outcome = self.tracker.on_input(key, data, now)
        return self._answer(outcome.closed, now) if outcome.closed is not None else []

    def on_tick(self, now: float) -> List[str]:
        """The clock reads ``now``; the actions decided because a timeout closed the step."""
        closed = self.tracker.on_tick(now).closed
        return self._answer(closed, now) if closed is not None else []

    def _answer(self, closed: Optional[StepResult], now: float) -> List[str]:
        """A step closed (or the loop starts): decide and open the next step, as the two nodes do.

        A queued observation can close the new step at once; the loop then answers again,
        exactly as the tracker node would publish the next belief at once.
        """
        actions: List[str] = []
        while True:
            if closed is not None:
                self._closed(closed)
            action = self.decide().action_name
            actions.append(action)
            closed = self.tracker.on_action(action, now).closed
            if closed is None:
                return actions

    def deadline(self) -> Optional[float]:
        """When the open step times out, or ``None``."""
        return self.tracker.deadline()

    # ----------------------------------------------------------- untimed use
    def observe(self, action_name: str, observation: str) -> np.ndarray:
        """Close one step: update the belief with the action taken and the observation that followed.

        Untimed use (a scripted dialog): the tracker's clock is the step count. The observation
        goes through the tracker as the input that carries it (:meth:`BeliefTracker.input_for`),
        so the robot's rule applies: a symbol as it is, speech text through the keyword filter.

        Args:
            action_name: the primitive action that was executed (``a_t``).
            observation: ``o_{t+1}``: a model observation symbol, or recognised speech
                text when the executive has a keyword filter.

        Returns:
            The new belief ``[S]`` (also in :attr:`belief`).

        Raises:
            BeliefError: unknown action or observation.
        """
        if action_name not in self._act_index:
            raise BeliefError(f"unknown action {action_name!r}; known: {', '.join(self.model.actions)}")
        tracker = self.tracker
        now = float(tracker.step)
        opened = False
        if tracker.open_action != action_name:
            queued = tracker.on_action(action_name, now).closed
            if queued is not None:   # an input queued by timed use closes the step at once
                self._closed(queued)
            opened = True
        outcome = tracker.on_input(tracker.input_for(observation), observation, now)
        if outcome.closed is None:
            if opened:
                tracker.abandon_step()
            if tracker.keyword_filter is None:
                shown = ", ".join(self.model.observations[:20])
                raise BeliefError(f"unknown observation {observation!r}; known: {shown} "
                                  "(give a keyword_filter to accept recognised speech text)")
            raise BeliefError(f"the keyword filter mapped {observation!r} to no observation of the model")
        self._closed(outcome.closed)
        return self.belief

    def _closed(self, closed: StepResult) -> None:
        self.steps.append(closed)
        if isinstance(self.decider, ObservingDecider):
            self.decider.observe(closed.action, closed.observation)

    def step(self, observation: str) -> Decision:
        """Observe the outcome of the last decided action, then decide the next one."""
        if self.last_decision is None:
            raise BeliefError("step() needs a previous decide(): no action has been taken yet")
        self.observe(self.last_decision.action_name, observation)
        return self.decide()

    def marginals(self) -> dict:
        """Per state feature, its marginal under the current belief (needs ``domain``)."""
        if self.domain is None:
            raise ValueError("marginals() needs the FactoredDomain (Executive(..., domain=...))")
        return self.tracker.marginals()
