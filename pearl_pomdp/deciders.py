"""A policy spec → the decider that runs it: :func:`load_decider`, the one place that reads one.

A *policy spec* is what a user writes where a policy goes (``pearl simulate MODEL POLICY``, the
policy node's ``policy`` parameter):

* ``online`` or ``online:TRIALS`` — plan online at every belief
  (:class:`~pearl_pomdp.online.decider.OnlineDecider`: DESPOT from the exact belief, ``TRIALS``
  trials per decision, :data:`~pearl_pomdp.online.decider.DEFAULT_TRIALS` without);
* a directory — a saved hierarchical policy (``pearl plan --out DIR``);
* a file — a flat policy (``.npz`` + ``.json`` from ``pearl solve --out``) as a
  :class:`~pearl_pomdp.policies.flat.FlatPolicyDecider`;
* empty — PLAN now from the domain and a ``hierarchy`` file.
"""
from __future__ import annotations

import logging
import time
from pathlib import Path
from typing import Optional, Union

from pearl_pomdp.errors import PolicyError
from pearl_pomdp.interfaces import Decider
from pearl_pomdp.model.pomdp import Pomdp

__all__ = ["load_decider"]

log = logging.getLogger(__name__)


def load_decider(policy: Union[str, Path, None], model: Pomdp, domain=None, *,
                 hierarchy: Union[str, Path, None] = None, seed: int = 0, time_guard: Optional[float] = None,
                 where: str = "policy", guard_where: str = "online time guard") -> Decider:
    """The decider ``policy`` names (module doc), for ``model`` and its ``domain``.

    Args:
        policy: the spec; a path is used as given (the caller resolves relative ones).
        model: the flat model decisions index (``domain.compile()`` for a factored domain).
        domain: the :class:`~pearl_pomdp.model.factored.FactoredDomain` a hierarchical policy was
            planned on (``None``: ``model`` itself, a flat model with a flat-featured hierarchy).
        hierarchy: the hierarchy file planned from when ``policy`` is empty.
        seed: the online search's seed (mixed with each belief).
        time_guard: online only: seconds of wall clock that stop a search early (``None`` or 0: never).
        where: how messages name the spec (``"parameter policy"``, ``"POLICY"``); ``guard_where``
            the time guard.

    Raises:
        PolicyError: a malformed ``online:`` spec or time guard, no such file or directory, or
            neither a policy nor a hierarchy (each message names ``where``); a saved policy's own
            errors (wrong model, damaged file) as :func:`~pearl_pomdp.policy_io.load_policy` and
            :func:`~pearl_pomdp.hierarchy.load_hierarchical_policy` raise them.
    """
    target = domain if domain is not None else model
    if policy is not None and str(policy).strip():
        from pearl_pomdp.online.decider import OnlineDecider, online_settings, online_trials

        trials = online_trials(str(policy), where)
        if trials is not None:
            return OnlineDecider(model, settings=online_settings(trials, time_guard, guard_where), seed=seed)
        path = Path(policy).expanduser()
        if path.is_dir():
            from pearl_pomdp.hierarchy import load_hierarchical_policy

            return load_hierarchical_policy(path, target)
        if not path.is_file():
            raise PolicyError(f"{where}: no such policy file or directory: {path}")
        from pearl_pomdp.policies.flat import FlatPolicyDecider
        from pearl_pomdp.policy_io import load_policy

        return FlatPolicyDecider(load_policy(path, model), model)
    if hierarchy is None or not str(hierarchy).strip():
        raise PolicyError(f"{where}: no policy and no hierarchy: give a planned policy (a directory from "
                          f"`pearl plan --out DIR`, a file from `pearl solve --out`, online) or a hierarchy to plan")
    from pearl_pomdp.hierarchy import load_hierarchy, plan

    start = time.perf_counter()
    decider = plan(target, load_hierarchy(hierarchy, target), seed=seed)
    log.info("planned %s in %.2f s", hierarchy, time.perf_counter() - start)
    return decider
