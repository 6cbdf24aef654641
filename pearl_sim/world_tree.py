"""What the reception's and the ward's behaviour trees share: the leaves, a branch and the decider around a tree.

Both trees are selectors without memory over guarded branches — a :class:`Guard` reading the
blackboard, then an :class:`Act` writing the step's action — and both run as an
:class:`~pearl_pomdp.interfaces.ObservingDecider` in the core executive: each closed step the
world's ``observe`` writes what was heard onto the blackboard, and :meth:`TreeDecider.execute`
ticks the tree and returns the action its chosen leaf names. What each tree checks, in what order,
and how each reads an observation stay in ``pearl_sim/reception/behaviour_tree.py`` and
``pearl_sim/ward/behaviour_tree.py``. (The nursing home's tree, ``pearl_sim/nursing_home/behaviour_tree.py``,
has leaves of its own: effects, judges, memory.)
"""
from __future__ import annotations

import math
from typing import Callable, List, Sequence

import py_trees
from py_trees.common import Access, Status

from pearl_pomdp.interfaces import Decision, TraceStep

__all__ = ["Guard", "Act", "branch", "TreeDecider"]


class _Behaviour(py_trees.behaviour.Behaviour):
    """A behaviour with a blackboard client on the tree's namespace (every one of ``keys``)."""

    def __init__(self, name: str, namespace: str, keys: Sequence[str], write: bool = False):
        super().__init__(name=name)
        self.bb = self.attach_blackboard_client(name=name, namespace=namespace)
        for key in keys:
            self.bb.register_key(key=key, access=Access.WRITE if write else Access.READ)


class Guard(_Behaviour):
    """SUCCESS when ``predicate(blackboard)`` holds, else FAILURE."""

    def __init__(self, name: str, namespace: str, keys: Sequence[str], predicate: Callable):
        super().__init__(name, namespace, keys)
        self.predicate = predicate

    def update(self) -> Status:
        return Status.SUCCESS if self.predicate(self.bb) else Status.FAILURE


class Act(_Behaviour):
    """Chooses ``action`` (or ``action(blackboard)``) for this step: writes it and succeeds."""

    def __init__(self, name: str, namespace: str, keys: Sequence[str], action):
        super().__init__(name, namespace, keys, write=True)
        self.action = action

    def update(self) -> Status:
        self.bb.action = self.action(self.bb) if callable(self.action) else self.action
        return Status.SUCCESS


def branch(name: str, namespace: str, keys: Sequence[str], guard: Callable, action) -> py_trees.behaviour.Behaviour:
    """A guarded branch: a sequence without memory of ``Guard(name?)`` then ``Act(name)``."""
    return py_trees.composites.Sequence(name, memory=False, children=[
        Guard(f"{name}?", namespace, keys, guard), Act(name, namespace, keys, action)])


class TreeDecider:
    """A behaviour tree as an :class:`~pearl_pomdp.interfaces.ObservingDecider` and a controller
    (``name``, ``decider``); a subclass defines ``reset()`` (called here, at the end) and ``observe()``.

    Args:
        name: the controller's name in the study (``behaviour_tree``).
        actions: the model's action names (a decision carries the index into them).
        namespace: the tree's blackboard namespace (one per instance).
        keys: every blackboard key the tree uses (relative to ``namespace``).
        build: ``namespace`` -> the tree's root (its name is the trace's when no leaf is chosen).
    """

    def __init__(self, name: str, actions: List[str], namespace: str, keys: Sequence[str],
                 build: Callable[[str], py_trees.behaviour.Behaviour]):
        self.name = name
        self.decider = self
        self.actions = list(actions)
        self._index = {a: i for i, a in enumerate(self.actions)}
        self.namespace = namespace
        self.keys = tuple(keys)
        self.root = build(namespace)
        self.tree = py_trees.trees.BehaviourTree(self.root)
        self.blackboard = py_trees.blackboard.Client(name=f"{name} executive", namespace=namespace)
        for key in self.keys:
            self.blackboard.register_key(key=key, access=Access.WRITE)
        self.reset()

    def reset(self) -> None:
        """A fresh episode (the subclass's blackboard values)."""
        raise NotImplementedError

    def execute(self, belief=None) -> Decision:
        """Tick the tree; the action its chosen leaf names (the belief is not used)."""
        bb = self.blackboard
        bb.action = None
        self.tree.tick()
        action = bb.action if bb.action is not None else "Wait"
        tip = self.root.tip()
        where = tip.name if tip is not None else self.root.name
        return Decision(self._index[action], action, [TraceStep(self.name, where, math.nan),
                                                      TraceStep(where, action, math.nan)])

    def snapshot(self) -> dict:
        """The blackboard's values (for tests and transcripts)."""
        return {key: getattr(self.blackboard, key) for key in self.keys}
