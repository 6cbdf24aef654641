"""``pearl experiment --domain config/ward.domain.yaml``: the ward study (docs/ward.md).

Builds the compared controllers once (the hierarchy beside the domain, DESPOT online at every step,
the ward behaviour tree), runs every controller in every cell of the study file × noise levels ×
seeds through the one step loop, and reports per controller and noise level the return, task
success, requests met, medications taken, wrong actions and decision times with 95 % CIs, and the
paired differences against the tree and between the POMDP controllers. Writes ``study.json``. The
runner is the one the worlds of a study file share (:mod:`pearl_sim.world_study`); here is the ward's own.
"""
from __future__ import annotations

import argparse
from typing import List

from pearl_sim.ward import study
from pearl_sim.ward.scenario import load_ward_scenarios
from pearl_sim.world_study import NURSING_HOME_ONLY, WorldExperiment

__all__ = ["EXPERIMENT", "DEFAULT_NOISE", "DEFAULT_SEEDS"]

#: The protocol's noise levels (recogniser word error rates) and seeds per episode and level.
DEFAULT_NOISE = "0.1,0.3"
DEFAULT_SEEDS = 10


def _check_policies(policies: List[str]) -> None:
    from pearl_pomdp.errors import SpecError
    from pearl_pomdp.online.decider import online_trials

    known = {"hierarchical", "online", "behaviour_tree", "qmdp"}
    bad = [p for p in policies if p not in known and not p.startswith("online:")]
    if bad or not policies:
        raise SpecError("<command line>", "--policies", f"{bad[0] if bad else ''!r}: the ward world compares "
                        f"{', '.join(sorted(known))} and online:TRIALS")
    for p in policies:
        online_trials(p, "--policies")          # a bad online:TRIALS fails before the model is compiled


def _agents(domain, hierarchy, policies: List[str], args: argparse.Namespace, log):
    return study.ward_agents(domain, hierarchy, policies=policies, seed=args.seed, log=log)


#: What the ward brings to the frame's study runner (:func:`pearl_sim.world_study.run_world_experiment`).
EXPERIMENT = WorldExperiment(
    default_noise=DEFAULT_NOISE, default_seeds=DEFAULT_SEEDS,
    refused=NURSING_HOME_ONLY + ("--flat-trials", "--flat-time-limit"),
    refused_reason="is not for the ward study (docs/ward.md: the flat solve does not close at this size; "
                   "online and the hierarchy are compared)",
    residents_reason="the ward's residents are in its study file (--study)",
    study=study, load_scenarios=load_ward_scenarios, run_episode=study.run_ward_episode,
    check_policies=_check_policies, build_agents=_agents, chunksize=4)

