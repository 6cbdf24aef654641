"""The most-likely-state policy: act as if the most probable state were the true one.

Built with the MDP-optimal action per state by :func:`pearl_pomdp.solvers.mdp.most_likely_state_policy`.
"""
from __future__ import annotations

import numpy as np

__all__ = ["MostLikelyStatePolicy"]


class MostLikelyStatePolicy:
    """Act as if the most probable state were the true one.

    Attributes:
        state_actions: ``[S]`` int array, the action for each state (usually the
            MDP-optimal one).
    """

    def __init__(self, state_actions) -> None:
        self.state_actions = np.asarray(state_actions, dtype=np.int64).ravel()

    def action(self, belief: np.ndarray) -> int:
        """``state_actions[argmax_s belief[s]]`` (ties: the lowest state index)."""
        b = np.asarray(belief, dtype=float).ravel()
        if b.shape[0] != self.state_actions.shape[0]:
            raise ValueError(f"belief has {b.shape[0]} entries, the policy has {self.state_actions.shape[0]} states")
        return int(self.state_actions[int(np.argmax(b))])

    def actions_batch(self, beliefs: np.ndarray) -> np.ndarray:
        """:meth:`action` for every row of ``beliefs`` ``[N, S]`` (ties: the lowest state index)."""
        return self.state_actions[np.argmax(np.asarray(beliefs, dtype=float), axis=1)]
