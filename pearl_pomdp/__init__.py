"""Pearl POMDP: a hierarchical POMDP behaviour manager for ROS 2 service robots.

The core (everything but :mod:`pearl_pomdp.nodes`) imports no ROS and can be used as a plain
Python library. The few words a user needs are here (each imported on first use, so
``import pearl_pomdp`` stays cheap)::

    import pearl_pomdp as pp

    model = pp.load_model("test/data/pomdp/tiger.95.POMDP")   # or pp.load_domain("x.domain.yaml")
    result = pp.solve(model, "incprune", horizon=15)          # or pp.plan(domain, hierarchy)
    track = pp.BeliefFilter(model)                            # the belief, eq. 5
    b = track.update(track.initial(), "listen", "tiger-left")
    action = result.policy.action(b)

* load: :func:`load_model` (a flat model from ``.pomdp``, ``.pomdpx`` or a domain ``.yaml``),
  :func:`load_domain` (a factored domain), :func:`load_hierarchy`;
* plan: :func:`solve` (a flat policy by solver name), :func:`plan` (a hierarchy);
* decide: :func:`load_decider` (a policy spec — a saved policy, ``online[:TRIALS]``, or a
  hierarchy to plan — as a decider: ``execute(belief) ->`` :class:`Decision`);
* track: :class:`BeliefFilter` (``update(belief, action, observation)``).
"""
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # pragma: no cover - the names resolve on first use (below)
    from pearl_pomdp.belief import BeliefFilter
    from pearl_pomdp.deciders import load_decider
    from pearl_pomdp.hierarchy import load_hierarchy, plan
    from pearl_pomdp.interfaces import Decision
    from pearl_pomdp.model import load_model
    from pearl_pomdp.model.domain_yaml import load_domain
    from pearl_pomdp.solvers.registry import solve

#: Each exported name's module.
_HOMES = {"load_model": "pearl_pomdp.model", "load_domain": "pearl_pomdp.model.domain_yaml",
          "load_hierarchy": "pearl_pomdp.hierarchy", "solve": "pearl_pomdp.solvers.registry",
          "plan": "pearl_pomdp.hierarchy", "load_decider": "pearl_pomdp.deciders",
          "BeliefFilter": "pearl_pomdp.belief", "Decision": "pearl_pomdp.interfaces"}

__all__ = list(_HOMES)


def __getattr__(name: str):
    # ``__version__`` is looked up on first use: importlib.metadata costs ~20 ms of start-up
    # that every node and command would otherwise pay before doing anything.
    if name == "__version__":
        from importlib import metadata

        try:
            version = metadata.version("pearl_pomdp")
        except metadata.PackageNotFoundError:  # running from a source tree without install
            version = "0+unknown"
        globals()["__version__"] = version
        return version
    from pearl_pomdp.lazy import lazy_attribute

    return lazy_attribute(globals(), _HOMES, name)
