"""``pearl experiment --domain config/reception.domain.yaml``: the reception study (docs/reception.md).

Plans the compared controllers once (the hierarchy beside the domain, a flat point-based solve,
QMDP) and builds the reception behaviour tree, runs every controller in every cell of the study
file × noise levels × seeds through the one step loop, and reports per controller and noise level
the return, task success and wrong actions with 95 % CIs and the paired differences against the
behaviour tree. Writes ``study.json`` into ``--out``. The runner is the one the worlds of a study
file share (:mod:`pearl_sim.world_study`); here is what is the reception's own.
"""
from __future__ import annotations

import argparse
from typing import List

from pearl_sim.reception import study
from pearl_sim.reception.scenario import load_reception_scenarios
from pearl_sim.world_study import NURSING_HOME_ONLY, WorldExperiment

__all__ = ["EXPERIMENT", "DEFAULT_NOISE", "DEFAULT_SEEDS"]

#: The protocol's noise levels (recogniser word error rates) and seeds per episode and level.
DEFAULT_NOISE = "0,0.2,0.4"
DEFAULT_SEEDS = 20


def _check_policies(policies: List[str]) -> None:
    from pearl_pomdp.errors import SpecError
    known = set(study.DEFAULT_POLICIES) | {"most_likely_state"}
    bad = [p for p in policies if p not in known]
    if bad or not policies:
        raise SpecError("<command line>", "--policies", f"{bad[0] if bad else ''!r}: the reception world compares "
                        f"{', '.join(sorted(known))}")


def _agents(domain, hierarchy, policies: List[str], args: argparse.Namespace, log):
    return study.reception_agents(domain, hierarchy, policies=policies, seed=args.seed, flat_trials=args.flat_trials,
                                  flat_time_limit=args.flat_time_limit, log=log)


#: What the reception brings to the frame's study runner (:func:`pearl_sim.world_study.run_world_experiment`).
EXPERIMENT = WorldExperiment(
    default_noise=DEFAULT_NOISE, default_seeds=DEFAULT_SEEDS,
    refused=NURSING_HOME_ONLY,
    refused_reason="is for the nursing-home study; the reception study runs on this machine's processes "
                   "(--jobs) with word error rates",
    residents_reason="the reception world's visitors are in its study file (--study)",
    study=study, load_scenarios=load_reception_scenarios, run_episode=study.run_reception_episode,
    check_policies=_check_policies, build_agents=_agents, chunksize=8)
