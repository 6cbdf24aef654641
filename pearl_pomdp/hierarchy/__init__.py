"""Hierarchical POMDPs (Pineau & Thrun 2002; docs/design.md §4).

* :mod:`.spec` — the action hierarchy (YAML) and its validation: :func:`load_hierarchy`.
* :mod:`.parameterize` — PARAMETERIZE, eq. 11–17: a subtask's model from its children.
* :mod:`.abstraction` — state/observation abstraction, eq. 18, exact and checked.
* :mod:`.plan` — PLAN / SOLVE bottom-up: :func:`plan` → :class:`HierarchicalPolicy`.
* :mod:`.subtask` — one subtask's local policy (:class:`SubtaskPolicy`) and its choice.
* :mod:`.execute` — EXECUTE top-down at every step, a
  :class:`~pearl_pomdp.interfaces.Decision` with its trace.
* :mod:`.storage` — the policy directory behind :meth:`HierarchicalPolicy.save` /
  :func:`load_hierarchical_policy`.
"""
from pearl_pomdp.hierarchy.execute import HierarchicalPolicy, load_hierarchical_policy
from pearl_pomdp.hierarchy.plan import plan
from pearl_pomdp.hierarchy.spec import Hierarchy, SubtaskSpec, flat_hierarchy, load_hierarchy, parse_hierarchy
from pearl_pomdp.hierarchy.subtask import SubtaskPolicy

__all__ = ["HierarchicalPolicy", "SubtaskPolicy", "load_hierarchical_policy", "plan",
           "Hierarchy", "SubtaskSpec", "load_hierarchy", "parse_hierarchy", "flat_hierarchy"]
