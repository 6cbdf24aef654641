"""The executive: belief tracking plus a decider, one step at a time (DESIGN.md §6).

The step protocol: an action ``a_t`` is taken, the next observation ``o_{t+1}`` (one
message from any modality) closes the step, the belief is updated with
``(a_t, o_{t+1})`` (eq. 5), and the decider answers with ``a_{t+1}``::

    ex = Executive(model, decider, keyword_filter=KeywordFilter(domain.keywords))
    decision = ex.decide()                       # a_0 from b0
    ex.observe(decision.action_name, "go")       # closes step 0
    decision = ex.decide()                       # a_1 ...

This is a plain Python object (numpy only): the ROS nodes wrap it and experiments
with thousands of episodes use it directly.

A *decider* is anything with ``.execute(belief) -> Decision``: a
:class:`~pearl_pomdp.hierarchy.execute.HierarchicalPolicy`, or
:class:`FlatPolicyDecider` around a flat policy.
"""
from __future__ import annotations

import logging
import math
from typing import Optional

import numpy as np

from pearl_pomdp.belief import BeliefFilter
from pearl_pomdp.errors import BeliefError
from pearl_pomdp.hierarchy.execute import Decision, TraceStep
from pearl_pomdp.model.pomdp import Pomdp

__all__ = ["Executive", "FlatPolicyDecider", "Decision", "TraceStep"]

log = logging.getLogger(__name__)


class FlatPolicyDecider:
    """A flat policy as a decider: ``execute(b)`` → :class:`Decision` with a one-step trace.

    Args:
        policy: an :class:`~pearl_pomdp.solvers.base.AlphaVectorPolicy` (the trace value is
            ``max_k α_k·b``) or anything with ``.action(belief) -> int`` such as
            :class:`~pearl_pomdp.solvers.mdp.MostLikelyStatePolicy` (value NaN: it has none).
        model: the model whose action names the decisions carry.
        name: the trace's subtask label.
    """

    def __init__(self, policy, model: Pomdp, name: str = "flat"):
        self.policy = policy
        self.model = model
        self.name = name
        alphas = getattr(policy, "alphas", None)
        self._alphas = np.asarray(alphas, dtype=float) if isinstance(alphas, np.ndarray) else None
        self._labels = np.asarray(policy.actions) if self._alphas is not None else None

    def execute(self, belief) -> Decision:
        """The policy's action at ``belief`` ``[S]``, with the value where the policy has one."""
        b = np.asarray(belief, dtype=float)
        if self._alphas is not None:
            values = self._alphas @ b
            k = int(np.argmax(values))
            a, value = int(self._labels[k]), float(values[k])
        else:
            a, value = int(self.policy.action(b)), math.nan
        name = self.model.actions[a]
        return Decision(a, name, [TraceStep(self.name, name, value)])

    def action(self, belief) -> int:
        return self.execute(belief).action


class Executive:
    """Belief tracking (eq. 5) and decisions, one step of the step protocol at a time.

    Args:
        model: the full flat POMDP (beliefs are ``[S]`` over its states).
        decider: ``.execute(belief) -> Decision`` (hierarchical or flat policy).
        keyword_filter: a :class:`~pearl_pomdp.speech.KeywordFilter`; when given,
            :meth:`observe` also accepts recognised speech *text*, classified to a Speech
            symbol (words matching no keyword become its unknown symbol and are counted).
        domain: the FactoredDomain, for :meth:`marginals` (optional).

    Attributes:
        belief: the current belief ``[S]`` (a fresh array after each update; never mutated).
        updates: belief updates done.
        zero_likelihood: updates whose observation had zero likelihood (recovered; see
            :mod:`pearl_pomdp.belief`).
        unknown_inputs: inputs the keyword filter could not classify.
        last_decision: the most recent :class:`Decision` (``None`` before the first).
    """

    def __init__(self, model: Pomdp, decider, keyword_filter=None, domain=None):
        self.model = model
        self.decider = decider
        self.keyword_filter = keyword_filter
        self.domain = domain
        self.filter = BeliefFilter(model)
        self._obs_index = {o: i for i, o in enumerate(model.observations)}
        self._act_index = {a: i for i, a in enumerate(model.actions)}
        self.reset()

    def reset(self) -> None:
        """Back to ``b0`` with zeroed counters."""
        self.belief = self.filter.initial()
        self.updates = 0
        self.zero_likelihood = 0
        self.unknown_inputs = 0
        self.last_decision: Optional[Decision] = None
        self._unknown_base = getattr(self.keyword_filter, "unknown_count", 0)
        self._zero_base = self.filter.zero_likelihood_count

    def symbol(self, observation: str) -> str:
        """The model observation symbol for ``observation`` (a symbol, or speech text via the keyword filter).

        Raises:
            BeliefError: not a symbol of the model and no keyword filter to classify it.
        """
        if observation in self._obs_index:
            return observation
        if self.keyword_filter is None:
            shown = ", ".join(self.model.observations[:20])
            raise BeliefError(f"unknown observation {observation!r}; known: {shown} "
                              "(give a keyword_filter to accept recognised speech text)")
        symbol = self.keyword_filter.classify(observation)
        self.unknown_inputs = getattr(self.keyword_filter, "unknown_count", 0) - self._unknown_base
        if symbol not in self._obs_index:
            raise BeliefError(f"the keyword filter mapped {observation!r} to {symbol!r}, which is not an "
                              "observation of the model")
        return symbol

    def observe(self, action_name: str, observation_symbol: str) -> np.ndarray:
        """Close one step: update the belief with the action taken and the observation that followed.

        Args:
            action_name: the primitive action that was executed (``a_t``).
            observation_symbol: ``o_{t+1}``: a model observation symbol, or recognised speech
                text when a keyword filter was given.

        Returns:
            The new belief ``[S]`` (also in :attr:`belief`).

        Raises:
            BeliefError: unknown action or observation.
        """
        if action_name not in self._act_index:
            raise BeliefError(f"unknown action {action_name!r}; known: {', '.join(self.model.actions)}")
        symbol = self.symbol(observation_symbol)
        self.belief = self.filter.update(self.belief, self._act_index[action_name], self._obs_index[symbol])
        self.updates += 1
        self.zero_likelihood = self.filter.zero_likelihood_count - self._zero_base
        return self.belief

    def decide(self) -> Decision:
        """The decider's :class:`Decision` at the current belief."""
        self.last_decision = self.decider.execute(self.belief)
        return self.last_decision

    def step(self, observation_symbol: str) -> Decision:
        """Observe the outcome of the last decided action, then decide the next one."""
        if self.last_decision is None:
            raise BeliefError("step() needs a previous decide(): no action has been taken yet")
        self.observe(self.last_decision.action_name, observation_symbol)
        return self.decide()

    def marginals(self) -> dict:
        """Per state feature, its marginal under the current belief (needs ``domain``)."""
        if self.domain is None:
            raise ValueError("marginals() needs the FactoredDomain (Executive(..., domain=...))")
        return self.domain.feature_marginals(self.belief)
