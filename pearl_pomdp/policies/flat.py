"""A flat policy as a :class:`~pearl_pomdp.interfaces.MaskingDecider`: :class:`FlatPolicyDecider`."""
from __future__ import annotations

import math
from typing import Collection, Optional, Union

import numpy as np

from pearl_pomdp.errors import PolicyError
from pearl_pomdp.interfaces import BatchPolicy, Decision, Policy, TraceStep, forbidden_indices
from pearl_pomdp.model.pomdp import Pomdp
from pearl_pomdp.policies.lookahead import Lookahead, OneStep
from pearl_pomdp.solution import AlphaVectorPolicy

__all__ = ["FlatPolicyDecider"]


class FlatPolicyDecider:
    """A flat policy as a decider: ``execute(b)`` → :class:`Decision` with a one-step trace.

    Args:
        policy: an :class:`~pearl_pomdp.solution.AlphaVectorPolicy` (the trace value is
            ``max_k α_k·b``) or any :class:`~pearl_pomdp.interfaces.Policy` such as
            :class:`~pearl_pomdp.policies.most_likely_state.MostLikelyStatePolicy` (value NaN: it has none).
        model: the model whose action names the decisions carry.
        name: the trace's subtask label.
        lookahead: steps of exact forward search over ``model`` with the α-vectors at the
            leaves (0: act greedily on the vectors). One step is what the hierarchy's root
            does at execution: a point-based lower bound that is not converged covers the
            beliefs its trials rarely reached poorly, and one Bellman step over the true
            model repairs its choice there (e.g. guide now rather than confirm again).
    """

    def __init__(self, policy: Policy, model: Pomdp, name: str = "flat", lookahead: int = 0):
        self.policy = policy
        self.model = model
        self.name = name
        self._alphas: Optional[np.ndarray] = None
        self._labels: Optional[np.ndarray] = None
        self._search: Optional[Union[OneStep, Lookahead]] = None
        if isinstance(policy, AlphaVectorPolicy):
            self._alphas, self._labels = policy.alphas, policy.actions
        if lookahead:
            if self._alphas is None:
                raise ValueError("lookahead needs an α-vector policy")
            # One step (the study's setting) runs through the point-based solver's C kernel, which
            # visits only the belief's support: ~1 ms a decision on Pearl's 576-state day model
            # where the dense numpy search took ~0.4 s (a day has ~5,400 decisions). Deeper
            # searches recurse in numpy.
            if int(lookahead) == 1:
                self._search = OneStep(model.T, model.O, model.R, model.discount, self._alphas)
            else:
                self._search = Lookahead(model.T, model.O, model.R, model.discount, self._alphas, int(lookahead))

    def execute(self, belief) -> Decision:
        """The policy's action at ``belief`` ``[S]``, with the value where the policy has one."""
        b = np.asarray(belief, dtype=float)
        if self._search is not None:
            q = self._q(b)
            a = int(np.argmax(q))
            name = self.model.actions[a]
            rest = np.where(np.arange(q.shape[0]) == a, -np.inf, q)
            r = int(np.argmax(rest))
            rival = (self.model.actions[r], float(rest[r])) if np.isfinite(rest[r]) else ("", math.nan)
            return Decision(a, name, [TraceStep(self.name, name, float(q[a]), *rival)])
        rival = ("", math.nan)
        if self._alphas is not None and self._labels is not None:
            values = self._alphas @ b
            k = int(np.argmax(values))
            a, value = int(self._labels[k]), float(values[k])
            others = np.where(self._labels != a, values, -np.inf)
            r = int(np.argmax(others))
            if np.isfinite(others[r]):
                rival = (self.model.actions[int(self._labels[r])], float(others[r]))
        else:
            a, value = int(self.policy.action(b)), math.nan
        name = self.model.actions[a]
        return Decision(a, name, [TraceStep(self.name, name, value, *rival)])

    def execute_without(self, belief, forbidden: Collection[str]) -> Decision:
        """The best action at ``belief`` among those not in ``forbidden`` (names), by the policy's values.

        * With the forward search: the largest of the search's Q-values over the allowed actions.
        * With α-vectors: the label of the largest ``α_k·b`` among the vectors whose action is
          allowed. When no vector carries an allowed action, the one-step search over the model
          with the vectors at the leaves values every allowed action
          (``Q(b, a) = b·R_a + γ Σ_o max_k α_k·(b T_a diag O_{a,o})``), so an action the policy
          never chose still gets the policy's own value.
        * A policy without values (:class:`~pearl_pomdp.policies.most_likely_state.MostLikelyStatePolicy`)
          can only be masked when its choice is allowed.

        Raises:
            PolicyError: every action is forbidden, a name is not an action of the model, or the
                policy has no values to choose another action by.
        """
        banned = forbidden_indices(self.model.actions, forbidden)
        if not banned:
            return self.execute(belief)
        b = np.asarray(belief, dtype=float)
        allowed = np.array([a not in banned for a in range(len(self.model.actions))])
        q: Optional[np.ndarray] = None
        if self._search is not None:
            q = self._q(b)
        elif self._alphas is not None and self._labels is not None:
            keep = allowed[self._labels]
            if keep.any():
                values = np.where(keep, self._alphas @ b, -np.inf)
                k = int(np.argmax(values))
                a, value = int(self._labels[k]), float(values[k])
                return Decision(a, self.model.actions[a], [TraceStep(self.name, self.model.actions[a], value)])
            m = self.model
            q = Lookahead(m.T, m.O, m.R, m.discount, self._alphas, 1).q_values(b)[0]
        else:
            decision = self.execute(b)
            if decision.action in banned:
                raise PolicyError(f"policy {type(self.policy).__name__} has no values to choose another action "
                                  f"than {decision.action_name!r} by")
            return decision
        masked = np.where(allowed, q, -np.inf)
        a = int(np.argmax(masked))
        return Decision(a, self.model.actions[a], [TraceStep(self.name, self.model.actions[a], float(masked[a]))])

    def _q(self, b: np.ndarray) -> np.ndarray:
        """``[A]`` look-ahead Q-values at ``b``."""
        if isinstance(self._search, OneStep):
            return self._search.q(b)
        assert self._search is not None
        return self._search.q_values(b)[0]

    def action(self, belief) -> int:
        return self.execute(belief).action

    def actions_batch(self, beliefs: np.ndarray) -> np.ndarray:
        """:meth:`action` for every row of ``beliefs [N, S]``: the policy's own batch when it decides
        alone (a simulation then runs exactly as on the bare policy), else row by row."""
        if self._search is None and isinstance(self.policy, BatchPolicy):
            return np.asarray(self.policy.actions_batch(beliefs), dtype=np.int64)
        B = np.atleast_2d(np.asarray(beliefs, dtype=float))
        return np.fromiter((self.execute(b).action for b in B), dtype=np.int64, count=B.shape[0])
