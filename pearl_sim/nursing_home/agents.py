"""The robot controllers the experiment compares, all run through the one step loop.

Every controller is a :class:`~pearl_pomdp.interfaces.Decider` inside a core
:class:`~pearl_pomdp.executive.Executive` — the same belief tracker rules (timeouts,
queueing, drives, low-confidence speech) for all of them, as on the robot:

* the POMDP policies (hierarchical, flat point-based, QMDP, most-likely state) decide
  from the belief;
* :class:`ScriptedAgent`, a hand-written state machine (kept by name: ``scripted``), is an
  :class:`~pearl_pomdp.interfaces.ObservingDecider`: it ignores the belief and reacts to
  the last observation the tracker closed a step with. The study's main non-POMDP baseline
  is the py_trees behaviour tree, :class:`pearl_sim.nursing_home.behaviour_tree.PearlBehaviourTree`.

:class:`Controller` pairs a name with a decider; the experiment builds a fresh executive
for it per episode (the scenario sets the step timeout).
"""
from __future__ import annotations

import math
from typing import Optional

from pearl_pomdp.interfaces import Decision, TraceStep
from pearl_sim.planning import Controller  # noqa: F401  (re-exported: where callers find it)

#: Symbol that closes a step in which nothing was heard (the tracker's timeout rule).
TIMEOUT_SYMBOL = "unknown"


class ScriptedAgent:
    """A hand-written state machine of the kind a behaviour tree encodes.

    Rules, in priority order, on the last observation and a little memory:

    1. a scheduler reminder (``g_physio``…) is remembered as pending;
    2. pending reminder, robot not at the room → ``GotoPatientRoom``;
    3. at the room, not yet in contact → ``RingDoorBell`` (contact = any answer);
    4. in contact → the matching reminder;
    5. heard ``go``/``t_go`` while at the room → ``GuideToPhysio``;
    6. arrived at physio while guiding → ``TerminateGuidance``;
    7. heard ``time``/``weather`` (speech or screen) → ``TellTime``/``TellWeather``;
    8. otherwise ``DoNothing``; back home after a guidance → ``GoHome``.

    It never asks a clarification question, so every misrecognised keyword becomes
    an action — the behaviour the POMDP is meant to improve on.
    """

    REMIND = {"physio": "RemindPhysioAppt", "vitamin": "RemindVitamin", "checklist": "UpdateChecklist"}

    def __init__(self, name: str = "scripted", actions: Optional[list] = None):
        self.name = name
        self.decider = self  # a Controller of its own
        if actions is None:
            from pearl_sim.nursing_home.scenario import default_domain

            actions = default_domain().actions
        self._index = {a: i for i, a in enumerate(actions)}
        self.reset()

    def execute(self, belief) -> Decision:
        """The rule's action (the belief is not used: this controller has none)."""
        action = self.act()
        return Decision(self._index[action], action, [TraceStep(self.name, action, math.nan)])

    def reset(self) -> None:
        self.pending: list = []
        self.location = "home"
        self.contact = False
        self.guiding = False
        self.last = TIMEOUT_SYMBOL

    def act(self) -> str:
        heard = self.last
        if heard in ("go", "t_go") and self.location == "room" and self.contact:
            return "GuideToPhysio"
        if self.guiding and self.location == "physio":
            return "TerminateGuidance"
        if self.pending:
            if self.location != "room":
                return "GotoPatientRoom"
            if not self.contact:
                return "RingDoorBell"
            return self.REMIND[self.pending[0]]
        if heard in ("time", "t_time"):
            return "TellTime"
        if heard in ("weather", "t_weather"):
            return "TellWeather"
        return "DoNothing"

    def observe(self, action: str, symbol: str) -> None:
        self.last = symbol
        if symbol.startswith("g_") and symbol != "g_none":
            kind = symbol[2:]
            if kind not in self.pending:
                self.pending.append(kind)
        if symbol in ("atRoom", "atPhysio", "atHome"):
            self.location = {"atRoom": "room", "atPhysio": "physio", "atHome": "home"}[symbol]
        if action in ("GotoPatientRoom", "GoHome"):
            self.contact = False
        if action == "RingDoorBell" and symbol not in (TIMEOUT_SYMBOL,) and not symbol.startswith("g_"):
            self.contact = True
        if action in self.REMIND.values():
            kind = next(k for k, v in self.REMIND.items() if v == action)
            if kind in self.pending:
                self.pending.remove(kind)
        if action == "GuideToPhysio":
            self.guiding = True
        if action == "TerminateGuidance":
            self.guiding = False
