"""Policies: what acts at a belief, as :class:`~pearl_pomdp.interfaces.Policy` or
:class:`~pearl_pomdp.interfaces.Decider` (after POMDPTools' Policies).

* :class:`AlphaVectorPolicy` — a set of α-vectors with an action each (every solver's output;
  defined in :mod:`pearl_pomdp.solution`, below the interfaces).
* :class:`FlatPolicyDecider` — a flat policy as a masking decider, optionally with forward search.
* :class:`Lookahead`, :class:`OneStep`, :class:`LookaheadPolicy` — exact forward search over a
  model with α-vectors at the leaves (a subtask's ``lookahead``, the contingent EXECUTE's step).
* :class:`MostLikelyStatePolicy` — the MDP action of the most probable state.

The hierarchical policy is :class:`pearl_pomdp.hierarchy.HierarchicalPolicy`; the online one
:class:`pearl_pomdp.online.decider.OnlineDecider`.
"""
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # pragma: no cover - the names resolve on first use (below)
    from pearl_pomdp.policies.flat import FlatPolicyDecider
    from pearl_pomdp.policies.lookahead import Lookahead, LookaheadPolicy, OneStep
    from pearl_pomdp.policies.most_likely_state import MostLikelyStatePolicy
    from pearl_pomdp.solution import AlphaVectorPolicy

#: Each name's module, imported on first use: a solver importing ``policies.most_likely_state``
#: must not pay for scipy (the forward search's sparse products).
_HOMES = {"AlphaVectorPolicy": "pearl_pomdp.solution", "FlatPolicyDecider": "pearl_pomdp.policies.flat",
          "Lookahead": "pearl_pomdp.policies.lookahead", "LookaheadPolicy": "pearl_pomdp.policies.lookahead",
          "OneStep": "pearl_pomdp.policies.lookahead",
          "MostLikelyStatePolicy": "pearl_pomdp.policies.most_likely_state"}

__all__ = list(_HOMES)


def __getattr__(name: str):
    from pearl_pomdp.lazy import lazy_attribute

    return lazy_attribute(globals(), _HOMES, name)
