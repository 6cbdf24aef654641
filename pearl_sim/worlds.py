"""Which simulated world a domain runs in, by the domain's ``name:``.

``pearl demo --domain D`` and ``pearl experiment --domain D`` look the domain up here: each world
brings its own scenarios, study file, node parameters and runners. A domain with no world is a
one-line error naming the domain file and the worlds there are (no import of any world: cheap).
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Dict, Union

__all__ = ["SimWorld", "WORLDS", "world_for", "domain_name_of"]


@dataclass(frozen=True)
class SimWorld:
    """A simulated world: where its files are (relative to the source tree / share dir) and its runners.

    Attributes:
        name: the domain ``name:`` it simulates.
        demo_scenario: the scenario ``pearl demo`` runs by default.
        study: the study file ``pearl experiment`` runs by default.
        params_file: the node parameters its robot runs with.
        demo, experiment: ``module:function`` of its ``pearl demo`` / ``pearl experiment`` runner
            (``None``: the command's own, nursing-home code path).
    """

    name: str
    description: str
    demo_scenario: str
    study: str
    params_file: str
    demo: Union[str, None] = None
    experiment: Union[str, None] = None


WORLDS: Dict[str, SimWorld] = {
    "pearl": SimWorld("pearl", "the nursing home: a resident, reminders, guidance to physiotherapy",
                      "config/scenarios/figure4.yaml", "config/scenarios/study.yaml", "config/pearl_nodes.yaml"),
    "reception": SimWorld("reception", "the reception hall: visitors greeted, asked and escorted to the gallery or office",
                          "config/scenarios/reception/one_visitor.yaml", "config/scenarios/reception/study.yaml",
                          "config/reception_nodes.yaml", demo="pearl_sim.reception.demo:run_cli",
                          experiment="pearl_sim.reception.experiment:run_cli"),
    "ward": SimWorld("ward", "the ward: one robot, three residents with medication reminders and requests",
                     "config/scenarios/ward/study.yaml", "config/scenarios/ward/study.yaml", "config/ward_nodes.yaml",
                     demo="pearl_sim.ward.experiment:run_demo_cli", experiment="pearl_sim.ward.experiment:run_cli"),
}


def domain_name_of(domain_path: Union[str, Path]) -> str:
    """The ``name:`` of a domain file (as :func:`pearl_pomdp.model.domain_yaml.load_domain` reads it)."""
    from pearl_pomdp.model.domain_yaml import load_domain

    return load_domain(domain_path).name


def world_for(domain_path: Union[str, Path]) -> SimWorld:
    """The simulated world of the domain in ``domain_path``.

    Raises:
        SpecError: no world simulates that domain (names the file, its name and the worlds there are).
    """
    from pearl_pomdp.errors import SpecError

    name = domain_name_of(domain_path)
    if name not in WORLDS:
        raise SpecError(domain_path, "name", f"no simulated world for domain {name!r} (worlds: "
                        + ", ".join(f"{w.name}: {w.description}" for w in WORLDS.values()) + ")")
    return WORLDS[name]


def runner(spec: str):
    """The function named by ``module:function``."""
    import importlib

    module, _, function = spec.partition(":")
    return getattr(importlib.import_module(module), function)
