"""The ward job as a ``py_trees`` behaviour tree for several residents: the ward study's baseline.

Written, as a ROS 2 developer would write the ward robot's behaviour manager without a POMDP, from
the world's specification (docs/ward.md) and committed before any POMDP policy ran in the ward. It
is an :class:`~pearl_pomdp.interfaces.ObservingDecider` run inside the same core
:class:`~pearl_pomdp.executive.Executive` as the POMDP policies (the same tracker rules: step
timeouts close with ``unheard``, drives end only with an arrival). It ignores the belief: each
closed step :meth:`WardBehaviourTree.observe` writes what was heard onto the blackboard, one entry
per resident, and :meth:`WardBehaviourTree.execute` ticks the tree.

Tree (a selector without memory; the per-resident branches are built once per resident, in the
order of the most urgent open task first)::

    Ward  (Selector)
    ├── Serve here     a resident with a known need where the robot is      → Serve<name>
    ├── Find the need  a need heard here from an unknown speaker (lounge)   → Ask<name> of the next one there
    ├── Go to a call   a call button pressed (oldest first)                 → GoToRoom<name>
    ├── Remind here    a resident due a round where the robot is            → Remind<name>
    ├── Round          a resident due a round (oldest first)                → GoTo their room, then the lounge
    ├── Home           nothing to do and away from the station             → GoToStation
    └── Idle                                                                → Wait

Rules and thresholds, each with its reason:

* **The call button and a spoken need are the only evidence of a request**: a ``call_<name>``
  says that resident waits in their room; a need heard in a room is that room's resident's; a need
  heard in the lounge may be anyone's there, so the tree asks the residents it has not ruled out,
  in order (``Ask<name>``), and serves the one who names a need.
* **A service answered with ``no`` or silence** means the resident was not there or wanted
  nothing: the request is dropped (a call repeats every minute if it is still open).
* **Medication rounds every** :data:`ROUND_STEPS` **steps per resident**: the tree does not know
  the medication schedule (the POMDP does not either); it reminds each resident when their round
  is due, in their room, and if nobody answers there, in the lounge; after the lounge it gives up
  until the next round (the resident may be out). A ``yes`` or a ``no`` closes the round.
* **Requests before rounds**: a resident waiting for help up is a fall risk; a medication round can
  wait a few steps.
* **Go home** to the station when idle: it is central (the shortest drive to every room).
"""
from __future__ import annotations

import itertools
from typing import Callable, Dict, List, Optional

import py_trees
from py_trees.common import Status

from pearl_sim.ward.scenario import HOME, RESIDENTS
from pearl_sim.world_tree import Act, TreeDecider
from pearl_sim.world_tree import branch as tree_branch

__all__ = ["WardBehaviourTree", "build_ward_tree", "ROUND_STEPS", "ACTIONS"]

#: Steps between two medication rounds of one resident.
ROUND_STEPS = 30
#: The ward domain's actions, in its order.
ACTIONS = ["Wait", "GoToStation", "GoToRoomAnn", "GoToRoomBob", "GoToRoomCleo", "GoToLounge",
           "RemindAnn", "AskAnn", "ServeAnn", "RemindBob", "AskBob", "ServeBob", "RemindCleo", "AskCleo", "ServeCleo"]
SILENCE = "unheard"
NEED_WORDS = ("water", "help", "talk")
ROOM = {n: f"room_{n.lower()}" for n in RESIDENTS}
GOTO = {"station": "GoToStation", "room_ann": "GoToRoomAnn", "room_bob": "GoToRoomBob", "room_cleo": "GoToRoomCleo",
        "lounge": "GoToLounge"}
ARRIVALS = {f"at_{p}": p for p in GOTO}
KEYS = ("action", "location", "step", "need", "called", "round_due", "round_tried", "lounge_need", "lounge_asked")

_instances = itertools.count()


def _where(bb, n: str) -> str:
    """Where the tree looks for resident ``n`` next on a round: their room, then the lounge."""
    return "lounge" if bb.round_tried[n] else ROOM[n]


def _need_here(bb) -> Optional[str]:
    for n in RESIDENTS:
        if bb.need[n] and bb.need[n] == bb.location:
            return n
    return None


def _oldest(table: Dict[str, Optional[int]]) -> Optional[str]:
    open_ = [(v, n) for n, v in table.items() if v is not None]
    return min(open_)[1] if open_ else None


def _round_due(bb) -> Optional[str]:
    due = {n: bb.round_due[n] if bb.round_due[n] is not None and bb.round_due[n] <= bb.step else None
           for n in RESIDENTS}
    return _oldest(due)


def _next_to_ask(bb) -> Optional[str]:
    return next((n for n in RESIDENTS if n not in bb.lounge_asked), None)


def build_ward_tree(namespace: str) -> py_trees.behaviour.Behaviour:
    """The tree of the module doc, its blackboard keys under ``namespace``."""
    ns = namespace

    def branch(name: str, guard: Callable, action) -> py_trees.behaviour.Behaviour:
        return tree_branch(name, ns, KEYS, guard, action)

    def round_target(bb) -> Optional[str]:
        n = _round_due(bb)
        return None if n is None else n

    return py_trees.composites.Selector("Ward", memory=False, children=[
        branch("Serve here", lambda bb: _need_here(bb) is not None, lambda bb: f"Serve{_need_here(bb)}"),
        branch("Find the need", lambda bb: bb.lounge_need and bb.location == "lounge" and _next_to_ask(bb) is not None,
               lambda bb: f"Ask{_next_to_ask(bb)}"),
        branch("Go to a call", lambda bb: _oldest(bb.called) is not None,
               lambda bb: GOTO[ROOM[str(_oldest(bb.called))]]),
        branch("Remind here", lambda bb: round_target(bb) is not None and _where(bb, str(round_target(bb))) == bb.location,
               lambda bb: f"Remind{round_target(bb)}"),
        branch("Round", lambda bb: round_target(bb) is not None, lambda bb: GOTO[_where(bb, str(round_target(bb)))]),
        branch("Home", lambda bb: bb.location != HOME, "GoToStation"),
        Act("Idle", ns, KEYS, "Wait"),
    ])


class WardBehaviourTree(TreeDecider):
    """The tree as an :class:`~pearl_pomdp.interfaces.ObservingDecider` and a controller (``name``,
    ``decider``) for the ward study.

    Args:
        name: the controller's name in the study (``behaviour_tree``).
        actions: the model's action names (a decision carries the index into them).
    """

    def __init__(self, name: str = "behaviour_tree", actions: Optional[List[str]] = None):
        super().__init__(name, list(actions) if actions is not None else list(ACTIONS), f"/ward_bt_{next(_instances)}",
                         KEYS, build_ward_tree)

    def reset(self) -> None:
        """A fresh episode: at the station, nothing known; each resident's first round staggered
        by a third of :data:`ROUND_STEPS` (one round at a time)."""
        self.root.stop(Status.INVALID)
        bb = self.blackboard
        bb.action, bb.location, bb.step = None, HOME, 0
        bb.need = {n: None for n in RESIDENTS}           # the place where a known need waits
        bb.called = {n: None for n in RESIDENTS}         # the step of an open call
        bb.round_due = {n: i * ROUND_STEPS // len(RESIDENTS) for i, n in enumerate(RESIDENTS)}
        bb.round_tried = {n: False for n in RESIDENTS}   # True: the room was tried, the lounge is next
        bb.lounge_need, bb.lounge_asked = False, []

    def observe(self, action: str, observation: str) -> None:
        """A step closed: ``action`` opened it, ``observation`` closed it → the blackboard."""
        bb = self.blackboard
        heard = observation
        bb.step = bb.step + 1
        need, called, due, tried = dict(bb.need), dict(bb.called), dict(bb.round_due), dict(bb.round_tried)
        asked = list(bb.lounge_asked)
        if heard in ARRIVALS:
            bb.location = ARRIVALS[heard]
            bb.lounge_need, asked = False, []
        for n in RESIDENTS:
            if action == f"Serve{n}":
                need[n], called[n] = None, None      # met, or not there / nothing wanted: dropped
                bb.lounge_need, asked = False, []
            elif action == f"Remind{n}":
                if heard in ("yes", "no"):
                    due[n], tried[n] = bb.step + ROUND_STEPS, False
                elif tried[n]:
                    due[n], tried[n] = bb.step + ROUND_STEPS, False   # nobody in the lounge either: next round
                else:
                    tried[n] = True
            elif action == f"Ask{n}":
                asked.append(n)
                if heard in NEED_WORDS:
                    need[n] = bb.location
                    bb.lounge_need, asked = False, []
                elif not [m for m in RESIDENTS if m not in asked]:
                    bb.lounge_need, asked = False, []
        if heard.startswith("call_"):
            n = heard[len("call_"):].capitalize()
            if n in called and called[n] is None:
                called[n] = bb.step
        elif heard in NEED_WORDS and not action.startswith("Ask"):
            owner = next((n for n in RESIDENTS if ROOM[n] == bb.location), None)
            if owner is not None:
                need[owner] = bb.location
            elif bb.location == "lounge":
                bb.lounge_need = True
        for n in RESIDENTS:
            if called[n] is not None and bb.location == ROOM[n] and need[n] is None:
                need[n] = ROOM[n]                    # at the room of a call: serve them there
                called[n] = None
        bb.need, bb.called, bb.round_due, bb.round_tried, bb.lounge_asked = need, called, due, tried, asked
