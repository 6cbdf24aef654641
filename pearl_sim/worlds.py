"""Which simulated world a domain runs in, by the domain's ``name:``: the worlds are plug-ins.

A world registers a :class:`SimWorld` under the entry-point group ``pearl.worlds`` (the name is the
domain ``name:`` it simulates), the same way inside this repository (``setup.py``) and outside it::

    entry_points={"pearl.worlds": ["lab = my_lab.world:WORLD"]}

``pearl demo --domain D`` and ``pearl experiment --domain D`` look the domain up here. A world's
``demo`` and ``experiment`` name (``module:attr``) either a :class:`pearl_sim.world_demo.WorldDemo` /
:class:`pearl_sim.world_study.WorldExperiment`, which the frame runs (the graph, the hardware, the
bag, the study's cells, statistics and report are the frame's), or a function of the command's
arguments for a world that brings its own runner (the nursing home's: its study, and its demo, which
adds the live view to the frame's). A domain with no world is a
one-line error naming the domain file and the worlds there are. Looking a world up imports only
the module that defines its :class:`SimWorld` (each world keeps that module light).
"""
from __future__ import annotations

import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Dict, Optional, Union

__all__ = ["SimWorld", "ENTRY_POINT_GROUP", "worlds", "world_for", "domain_name_of", "load_attribute", "share_path"]

#: The entry-point group a world registers under.
ENTRY_POINT_GROUP = "pearl.worlds"


def share_path(relative: str) -> str:
    """A file of this project: from the source tree, or the installed ``share/pearl_pomdp``."""
    here = Path(__file__).resolve().parents[1] / relative
    if here.exists():
        return str(here)
    return str(Path(sys.prefix) / "share" / "pearl_pomdp" / relative)


@dataclass(frozen=True)
class SimWorld:
    """A simulated world: its files and what its ``pearl demo`` / ``pearl experiment`` run.

    Attributes:
        name: the domain ``name:`` it simulates (and the name it registers under).
        description: one line for listings and errors.
        demo_scenario: the scenario ``pearl demo`` runs by default.
        study: the study file ``pearl experiment`` runs by default.
        params_file: the node parameters its robot runs with.
        demo, experiment: ``module:attr`` of a ``WorldDemo`` / ``WorldExperiment`` the frame runs, or
            of a function ``(args) -> exit code`` (the world's own runner); ``None``: the world has
            none (the command says so).
        root: the folder the relative file names above are in; ``None``: this project's source
            tree (or its installed share folder). A world outside the repository gives its own.
    """

    name: str
    description: str
    demo_scenario: str
    study: str
    params_file: str
    demo: Optional[str] = None
    experiment: Optional[str] = None
    root: Optional[str] = None

    def path(self, relative: Union[str, Path]) -> str:
        """``relative`` (one of the world's files) as a path to open."""
        if Path(relative).is_absolute():
            return str(relative)
        if self.root is not None:
            return str(Path(self.root) / relative)
        return share_path(str(relative))


_registry: Dict[str, SimWorld] = {}


def worlds() -> Dict[str, SimWorld]:
    """Every registered world by name (read from the ``pearl.worlds`` entry points once per process).

    Raises:
        PearlError: an entry point that does not load, is not a :class:`SimWorld`, registers under
            another name than its world's, or a name registered twice (each names the entry point).
    """
    if _registry:
        return _registry
    from importlib.metadata import entry_points

    from pearl_pomdp.errors import PearlError

    found: Dict[str, SimWorld] = {}
    for point in sorted(entry_points(group=ENTRY_POINT_GROUP), key=lambda p: p.name):
        where = f"entry point {point.name} = {point.value} (group {ENTRY_POINT_GROUP})"
        try:
            world = point.load()
        except Exception as err:   # a plug-in's own import error, whatever it is: named, not a traceback
            raise PearlError(f"{where}: does not load: {type(err).__name__}: {err}") from None
        if not isinstance(world, SimWorld):
            raise PearlError(f"{where}: is a {type(world).__name__}, not a pearl_sim.worlds.SimWorld")
        if world.name != point.name:
            raise PearlError(f"{where}: registers world {world.name!r} under the name {point.name!r}")
        if point.name in found:
            raise PearlError(f"{where}: a second world named {point.name!r}")
        found[point.name] = world
    if not found:
        raise PearlError(f"no simulated world is registered (entry-point group {ENTRY_POINT_GROUP}): "
                         "is pearl_pomdp installed (pip install -e .)?")
    _registry.update(found)
    return _registry


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
    known = worlds()
    if name not in known:
        raise SpecError(domain_path, "name", f"no simulated world for domain {name!r} (worlds: "
                        + ", ".join(f"{w.name}: {w.description}" for w in known.values()) + ")")
    return known[name]


def load_attribute(spec: str):
    """The object named by ``module:attr``."""
    import importlib

    module, _, attr = spec.partition(":")
    return getattr(importlib.import_module(module), attr)
