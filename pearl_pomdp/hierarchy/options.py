"""A subtask as an *option* that may stop: its abstract model with an ``Exit`` pseudo-action.

The paper solves each subtask as a POMDP over its own actions only, for ever. For the
discounted infinite horizon that is ill-posed for most subtasks: a subtask that has no
free action must keep acting after its job is done, and its values then say more about
that perpetual cost than about the job. Pearl's ``Remind`` shows it plainly: with only
the three reminders, "deliver the due reminder, then remind for nothing (−200) for ever"
is worse than "never deliver it, remind wrongly (−100) for ever", so the infinite-horizon
local policy would never deliver a reminder.

We solve every subtask but the root as an option (Sutton, Precup & Singh 1999; MAXQ's
termination, Dietterich 2000): the model gets one more action, ``Exit``, worth 0, that
moves every state to one absorbing ``done`` state (reward 0 under every action, silent:
it emits the model's first observation class). The local value is then "what reaching the
subtask's goals is worth, stopping when nothing more is to be gained": finite, and 0
where nothing is to be done. The subtask's *choice* at a belief is its best real action
(``Exit`` is never executed): the parent decides whether that action is worth taking,
seeing it truly (policy-contingent parameterisation, :mod:`pearl_pomdp.hierarchy.plan`).
"""
from __future__ import annotations

import numpy as np

from pearl_pomdp.model.pomdp import Pomdp, issparse

__all__ = ["EXIT", "DONE", "with_exit"]

#: The name of the stopping pseudo-action (the last action of an option's model).
EXIT = "Exit"
#: The name of the absorbing state it leads to (the last state).
DONE = "done"


def with_exit(model: Pomdp) -> Pomdp:
    """``model`` with one absorbing state ``done`` and one action ``Exit`` appended (last).

    ``T[a][s, s']`` is unchanged on the old states for every old action; ``done`` stays
    ``done`` under every action; ``Exit`` moves every state to ``done``. ``R`` is 0 for
    ``Exit`` and in ``done``. ``done`` emits observation 0 under every action, and so does
    every state under ``Exit`` (stopping observes nothing). ``b0`` puts no mass on ``done``.
    """
    if EXIT in model.actions or DONE in model.states:
        raise ValueError(f"model {model.name!r} already has an action {EXIT!r} or a state {DONE!r}")
    S, A, Z = model.num_states, model.num_actions, model.num_observations
    T: list = []
    if model.is_sparse or any(issparse(t) for t in model.T):
        import scipy.sparse as sp

        one = sp.csr_matrix(([1.0], ([0], [0])), shape=(1, 1))
        for t in model.T:
            T.append(sp.block_diag([sp.csr_matrix(t), one], format="csr"))
        T.append(sp.csr_matrix((np.ones(S + 1), (np.arange(S + 1), np.full(S + 1, S))), shape=(S + 1, S + 1)))
    else:
        for t in model.T:
            grown = np.zeros((S + 1, S + 1))
            grown[:S, :S] = np.asarray(t, dtype=float)
            grown[S, S] = 1.0
            T.append(grown)
        stop = np.zeros((S + 1, S + 1))
        stop[:, S] = 1.0
        T.append(stop)
    O = np.zeros((A + 1, S + 1, Z))
    O[:A, :S] = model.O
    O[:, S, 0] = 1.0
    O[A, :, 0] = 1.0
    R = np.zeros((S + 1, A + 1))
    R[:S, :A] = model.R
    b0 = np.append(np.asarray(model.b0, dtype=float), 0.0)
    return Pomdp.create(list(model.states) + [DONE], list(model.actions) + [EXIT], list(model.observations), T, O,
                        R, b0, model.discount, f"{model.name}+exit", sparse=bool(model.is_sparse))
