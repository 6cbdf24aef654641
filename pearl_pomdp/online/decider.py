"""The online search as a :class:`~pearl_pomdp.interfaces.Decider` for the project's explicit models.

``OnlineDecider(model).execute(belief)`` draws the DESPOT scenarios from the tracker's exact
belief (so the root never starves), searches with the offline bounds the project already
computes (FIB above, blind policies or a point-based solver's α-vectors below; nobody writes
bounds) under a deterministic trial budget, and returns a :class:`~pearl_pomdp.interfaces.Decision`
whose ``search`` field records the search's size, the bounds and gap at the root, its seconds
and the top of the tree — what ``/pearl/decision`` carries and ``pearl replay --explain`` shows.

The seed of each decision is derived from the decider's seed and the belief's bytes, so the same
belief always gets the same action (a replayed bag reproduces the robot's choices), whatever
came before.
"""
from __future__ import annotations

import zlib
from typing import Collection, Optional

import numpy as np

from pearl_pomdp.errors import PolicyError
from pearl_pomdp.interfaces import Decision, TraceStep, forbidden_indices
from pearl_pomdp.model.pomdp import Pomdp
from pearl_pomdp.online.beliefs import sample_belief
from pearl_pomdp.online.despot import Despot, DespotSettings, SearchResult
from pearl_pomdp.online.generative import Bounds, ExplicitModel, alpha_bounds

__all__ = ["OnlineDecider", "DEFAULT_TRIALS", "DEFAULT_TIME_GUARD", "ONLINE_POLICY", "online_trials", "online_settings",
           "default_bounds", "FIB_LIMIT"]

#: The policy name that asks for online planning instead of a saved policy (node parameter
#: ``policy:=online`` or ``online:TRIALS``; ``pearl simulate MODEL online:TRIALS``).
ONLINE_POLICY = "online"

#: Trials per decision when nothing else is asked (one source for the CLI and the node).
DEFAULT_TRIALS = 200

#: Wall-clock seconds a decision of the policy node may take before its search stops at the
#: next expansion: a guard only (the budget is the trials, and a decision the guard cut says
#: ``stop: "time_limit"`` in /pearl/decision). Half the shipped configs' 10 s step timeout, so a
#: decision that would come too late to matter is cut well before the step gives up.
DEFAULT_TIME_GUARD = 5.0

#: Largest ``S·A·Z`` for which the default upper bound is the fast informed bound; past it QMDP
#: (FIB's backups cost a pass over ``T`` per action and observation: minutes and gigabytes on the
#: ward's 233,280 states × 15 × 15 = 52M, where QMDP takes seconds).
FIB_LIMIT = 5_000_000


def default_upper(model: Pomdp) -> str:
    """The default upper bound's name for ``model``: ``"fib"``, or ``"qmdp"`` past :data:`FIB_LIMIT`."""
    size = model.num_states * model.num_actions * model.num_observations
    return "fib" if size <= FIB_LIMIT else "qmdp"


def default_bounds(model: Pomdp) -> Bounds:
    """:func:`~pearl_pomdp.online.generative.alpha_bounds` with FIB above, or QMDP past :data:`FIB_LIMIT`."""
    return alpha_bounds(model, upper=default_upper(model))


def decision_seed(belief: np.ndarray, seed: int) -> int:
    """The seed of an online decision at ``belief``: the belief rounded to 12 digits, hashed, mixed with
    ``seed`` — the same belief always gets the same search (a replayed bag reproduces the choices)."""
    data = np.round(np.asarray(belief, dtype=float), 12).tobytes()
    return (zlib.crc32(data) ^ (int(seed) * 0x9E3779B1)) & 0xFFFFFFFF


def online_trials(policy: str, where: str = "policy") -> Optional[int]:
    """The trial budget ``policy`` asks for when it names online planning, else ``None``.

    ``"online"`` → :data:`DEFAULT_TRIALS`; ``"online:N"`` → ``N``; anything else → ``None`` (a path).

    Raises:
        PolicyError: ``online:`` followed by something that is not a positive integer (names ``where``).
    """
    text = str(policy).strip()
    if text == ONLINE_POLICY:
        return DEFAULT_TRIALS
    if not text.startswith(ONLINE_POLICY + ":"):
        return None
    tail = text[len(ONLINE_POLICY) + 1:]
    if not tail.isdigit() or int(tail) < 1:
        raise PolicyError(f"{where}: {text!r}: expected online or online:TRIALS with TRIALS a positive integer")
    return int(tail)


def online_settings(trials: int, time_guard: Optional[float] = None, where: str = "time guard") -> DespotSettings:
    """The search settings of ``online:TRIALS`` with an optional wall-clock guard.

    ``time_guard`` ``None`` or 0: no guard (every decision is the deterministic ``trials`` budget).

    Raises:
        PolicyError: a negative or non-finite ``time_guard`` (names ``where``).
    """
    if time_guard is None or time_guard == 0:
        return DespotSettings(trials=trials)
    guard = float(time_guard)
    if not (guard > 0 and np.isfinite(guard)):
        raise PolicyError(f"{where}: {time_guard!r}: expected a positive number of seconds, or 0 for no guard")
    return DespotSettings(trials=trials, time_limit=guard)


class OnlineDecider:
    """DESPOT at every decision over an explicit :class:`~pearl_pomdp.model.pomdp.Pomdp`.

    Args:
        model: the flat model (beliefs are ``[S]`` over its states).
        bounds: the heuristics; default :func:`default_bounds` (FIB upper, or QMDP past
            :data:`FIB_LIMIT`; blind-policy lower), computed once here.
        settings: the search's :class:`~pearl_pomdp.online.despot.DespotSettings`
            (default: ``DEFAULT_TRIALS`` trials, K = 500, D = 90).
        seed: combined with each belief's bytes into the decision's seed.
        name: the trace's subtask label.
    """

    def __init__(self, model: Pomdp, bounds: Optional[Bounds] = None, settings: Optional[DespotSettings] = None,
                 seed: int = 0, name: str = "online"):
        self.model = model
        self.generative = ExplicitModel(model)
        self.bounds = bounds if bounds is not None else default_bounds(model)
        self.settings = settings if settings is not None else DespotSettings(trials=DEFAULT_TRIALS)
        self.search_engine = Despot(self.generative, self.bounds, self.settings)
        self.seed = int(seed)
        self.name = name
        self.last_search: Optional[SearchResult] = None

    def decision_seed(self, belief: np.ndarray) -> int:
        """The seed of the decision at ``belief`` (:func:`decision_seed` with this decider's seed)."""
        return decision_seed(belief, self.seed)

    def search(self, belief) -> SearchResult:
        """The DESPOT search at ``belief`` ``[S]`` (scenarios drawn from it)."""
        b = np.asarray(belief, dtype=float)
        seed = self.decision_seed(b)
        roots = sample_belief(b, self.settings.scenarios, np.random.default_rng([seed, 1]))
        self.last_search = self.search_engine.search(roots, seed)
        return self.last_search

    def _decision(self, result: SearchResult, action: int) -> Decision:
        name = self.model.actions[action]
        record = result.as_dict()
        record.update(bounds=self.bounds.description, top=result.top, action_bounds=[
            {"action": self.model.actions[a], "lower": lo, "upper": up} for a, (lo, up) in enumerate(result.action_bounds)])
        return Decision(action, name, [TraceStep(self.name, name, float(result.action_bounds[action][0]))],
                        expansions=result.expansions, search=record)

    def execute(self, belief) -> Decision:
        """The action with the best lower bound at the root after the search."""
        result = self.search(belief)
        return self._decision(result, result.action)

    def execute_without(self, belief, forbidden: Collection[str]) -> Decision:
        """The best allowed action by the search's root lower bounds (an operator's veto).

        Raises:
            PolicyError: every action is forbidden, or a name is not an action of the model.
        """
        banned = forbidden_indices(self.model.actions, forbidden)
        result = self.search(belief)
        lows = [lo if a not in banned else -np.inf for a, (lo, _) in enumerate(result.action_bounds)]
        return self._decision(result, int(np.argmax(lows)))

    def action(self, belief) -> int:
        return self.execute(belief).action
