"""The reception job as a ``py_trees`` behaviour tree: the reception study's non-POMDP baseline.

Written, as a ROS 2 developer would write the robot's behaviour manager without a POMDP, from the
world's specification (docs/reception.md) and committed before any POMDP policy ran in the
reception world. It is an :class:`~pearl_pomdp.interfaces.ObservingDecider` run inside the same
core :class:`~pearl_pomdp.executive.Executive` as the POMDP policies, so the same tracker rules
apply (step timeouts close with ``unheard``; drives end only with an arrival; a battery reading
that keeps its bin is no observation). It ignores the belief: each closed step
:meth:`ReceptionBehaviourTree.observe` writes what was heard onto the blackboard, and
:meth:`ReceptionBehaviourTree.execute` ticks the tree, whose chosen leaf names the action.

Tree (a selector without memory: every tick re-checks the guards in priority order)::

    Reception  (Selector)
    ├── Charge       battery low ∧ no visitor with the robot        → Dock
    ├── Hand over    visitor ∧ destination confirmed ∧ there        → HandOver
    ├── Escort       visitor ∧ destination confirmed ∧ not there    → EscortTo<destination>
    ├── Confirm      visitor ∧ destination only heard (speech)      → Confirm<destination> (≤ 2 times)
    ├── Ask          visitor ∧ no destination ∧ no back-off         → AskDestination (≤ 3 times, then back off)
    ├── Greet        at the desk ∧ someone seen or a hello heard    → Greet
    ├── Back to desk away from the desk ∧ no visitor                → ReturnToDesk
    └── Idle                                                        → Wait

Rules and thresholds, each with its reason:

* **A touch is unambiguous, speech is not** (:data:`TOUCH`): a destination touched on the screen
  is taken as confirmed; a spoken one is confirmed first (``ConfirmGallery``/``ConfirmOffice``),
  because the recogniser confuses words and inserts fillers. A ``yes`` confirms; a ``no``
  forgets the destination (ask again); the other place named replaces it.
* **Confirm up to 2 times** (:data:`CONFIRM_ATTEMPTS`): twice unanswered, the spoken destination is
  taken (the visitor heard twice and did not object; a robot that asks a third time is tiresome).
* **Ask up to 3 times, then back off 2 steps** (:data:`ASK_ATTEMPTS`, :data:`ASK_BACKOFF_TICKS`):
  a visitor who does not answer three questions may still say it unasked while the robot waits.
* **Greet on any detection or hello at the desk**: the detector cannot tell a visitor from a
  passer-by, and a visitor kept waiting costs more than one greeting of nobody. A greeting that
  nobody answers (silence) is taken as a passer-by; any answer (a hello, a destination, a yes)
  means a visitor is with the robot. A destination heard at any time means a visitor is there.
* **A hand-over answered with ``no``** is the wrong place: the destination is forgotten and asked again.
* **Dock on ``charge_low``** when no visitor is with the robot (a visitor is finished first: the
  battery's low bin leaves a quarter of the charge, hours of driving in this hall).
* **Drive retry**: an arrival at another place than the one driven to repeats the drive (the
  escort branch stays active until the arrival matches).
"""
from __future__ import annotations

import itertools
from typing import Callable, List, Optional

import py_trees
from py_trees.common import Status

from pearl_sim.world_tree import Act, TreeDecider
from pearl_sim.world_tree import branch as tree_branch

__all__ = ["ReceptionBehaviourTree", "build_reception_tree", "ASK_ATTEMPTS", "ASK_BACKOFF_TICKS",
           "CONFIRM_ATTEMPTS"]

ASK_ATTEMPTS = 3
ASK_BACKOFF_TICKS = 2
CONFIRM_ATTEMPTS = 2

#: The reception domain's observation symbols the tree reads.
SILENCE = "unheard"
PLACES = {"at_desk": "desk", "at_gallery": "gallery", "at_office": "office"}
SPOKEN = {"gallery": "gallery", "office": "office"}
TOUCH = {"t_gallery": "gallery", "t_office": "office"}
ESCORT = {"gallery": "EscortToGallery", "office": "EscortToOffice"}
CONFIRM = {"gallery": "ConfirmGallery", "office": "ConfirmOffice"}
ANSWERS = ("hello", "yes", "no", "gallery", "office", "t_gallery", "t_office")

#: Every blackboard key the tree uses (relative to the tree's own namespace).
KEYS = ("action", "heard", "location", "visitor", "destination", "confirmed", "asks", "confirms", "backoff",
        "battery_low", "seen")

_instances = itertools.count()


def build_reception_tree(namespace: str) -> py_trees.behaviour.Behaviour:
    """The tree of the module doc, its blackboard keys under ``namespace``."""
    ns = namespace

    def branch(name: str, guard: Callable, action) -> py_trees.behaviour.Behaviour:
        return tree_branch(name, ns, KEYS, guard, action)

    return py_trees.composites.Selector("Reception", memory=False, children=[
        branch("Charge", lambda bb: bb.battery_low and not bb.visitor, "Dock"),
        branch("Hand over", lambda bb: bb.visitor and bb.confirmed and bb.location == bb.destination, "HandOver"),
        branch("Escort", lambda bb: bb.visitor and bb.confirmed and bb.location != bb.destination,
               lambda bb: ESCORT[bb.destination]),
        branch("Confirm", lambda bb: bb.visitor and bb.destination is not None and not bb.confirmed,
               lambda bb: CONFIRM[bb.destination]),
        branch("Ask", lambda bb: bb.visitor and bb.destination is None and bb.backoff == 0, "AskDestination"),
        branch("Greet", lambda bb: not bb.visitor and bb.location == "desk" and bb.seen, "Greet"),
        branch("Back to desk", lambda bb: not bb.visitor and bb.location != "desk", "ReturnToDesk"),
        Act("Idle", ns, KEYS, "Wait"),
    ])


class ReceptionBehaviourTree(TreeDecider):
    """The tree as an :class:`~pearl_pomdp.interfaces.ObservingDecider` and a controller
    (``name``, ``decider``) for the reception study and demo.

    Args:
        name: the controller's name in the study (``behaviour_tree``).
        actions: the model's action names (a decision carries the index into them).
    """

    def __init__(self, name: str = "behaviour_tree", actions: Optional[List[str]] = None):
        super().__init__(name, list(actions) if actions is not None else [
            "Wait", "Greet", "AskDestination", "ConfirmGallery", "ConfirmOffice", "EscortToGallery",
            "EscortToOffice", "HandOver", "ReturnToDesk", "Dock"], f"/reception_bt_{next(_instances)}", KEYS,
            build_reception_tree)

    def reset(self) -> None:
        """A fresh episode: the robot at the desk, nobody there, the battery taken as fine."""
        self.root.stop(Status.INVALID)
        bb = self.blackboard
        bb.action, bb.heard, bb.location = None, SILENCE, "desk"
        bb.visitor, bb.destination, bb.confirmed = False, None, False
        bb.asks, bb.confirms, bb.backoff = 0, 0, 0
        bb.battery_low, bb.seen = False, False

    def _forget_visitor(self) -> None:
        bb = self.blackboard
        bb.visitor, bb.destination, bb.confirmed, bb.asks, bb.confirms = False, None, False, 0, 0

    def observe(self, action: str, observation: str) -> None:
        """A step closed: ``action`` opened it, ``observation`` closed it → the blackboard."""
        bb = self.blackboard
        heard = observation
        bb.heard = heard
        bb.backoff = max(0, bb.backoff - 1)
        # What the action itself settled.
        if action == "Greet":
            bb.seen = False
            if heard in ANSWERS:
                bb.visitor = True          # someone answered: a visitor, not a passer-by
        elif action == "HandOver":
            if heard == "no":
                bb.destination, bb.confirmed, bb.confirms = None, False, 0   # the wrong place: ask again
            else:
                self._forget_visitor()
        elif action in ("ReturnToDesk", "Dock"):
            self._forget_visitor()           # (the tree never leaves a visitor on purpose)
        elif action == "AskDestination" and heard not in SPOKEN and heard not in TOUCH:
            bb.asks += 1
            if bb.asks >= ASK_ATTEMPTS:
                bb.asks, bb.backoff = 0, ASK_BACKOFF_TICKS
        elif action in CONFIRM.values() and bb.destination is not None:
            if heard == "yes":
                bb.confirmed = True
            elif heard == "no":
                bb.destination, bb.confirms = None, 0
            elif heard not in SPOKEN and heard not in TOUCH:
                bb.confirms += 1
                if bb.confirms >= CONFIRM_ATTEMPTS:
                    bb.confirmed = True     # asked twice, no objection: go
        # What the observation says, whatever the action.
        if heard in PLACES:
            bb.location = PLACES[heard]
        elif heard == "charge_low":
            bb.battery_low = True
        elif heard == "charge_ok":
            bb.battery_low = False
        elif heard in TOUCH:
            bb.visitor, bb.destination, bb.confirmed = True, TOUCH[heard], True
        elif heard in SPOKEN and not bb.confirmed:
            bb.visitor = True
            if bb.destination != SPOKEN[heard]:
                bb.destination, bb.confirms = SPOKEN[heard], 0
        elif heard == "person_seen" or (heard == "hello" and not bb.visitor):
            bb.seen = bb.location == "desk" and not bb.visitor
        elif heard == "nobody" and not bb.visitor:
            bb.seen = False
        if action == "Dock" and heard in PLACES:
            bb.battery_low = False
