"""Robot controllers that the experiment compares, behind one small interface.

An agent chooses the next action and is told what the world answered::

    agent.reset()
    action = agent.act()
    agent.observe(action, symbol)   # symbol: the observation that closed the step

:class:`PomdpAgent` wraps the core :class:`~pearl_pomdp.executive.Executive`
(belief tracking + any decider: hierarchical, flat point-based, QMDP, most-likely
state). :class:`ScriptedAgent` is the baseline a behaviour tree or state machine
would encode: it reacts to the last keyword it heard, without a belief and
without clarification questions.
"""
from __future__ import annotations

from typing import Optional, Protocol

from pearl_pomdp.speech import KeywordFilter
from pearl_sim.world import Message

#: Symbol that closes a step in which nothing was heard (the tracker's timeout rule).
TIMEOUT_SYMBOL = "unknown"


def message_symbol(message: Optional[Message], keyword_filter: KeywordFilter) -> str:
    """The observation symbol of a world message, as the belief tracker maps it.

    Speech goes through the keyword filter; touchscreen, laser and reminder messages
    carry their symbol; silence until the timeout is Speech ``unknown``.
    """
    if message is None:
        return TIMEOUT_SYMBOL
    if message.modality == "Speech":
        return keyword_filter.classify(message.text)
    return message.text


class Agent(Protocol):
    """What the experiment needs from a controller."""

    name: str

    def reset(self) -> None: ...

    def act(self) -> str: ...

    def observe(self, action: str, symbol: str) -> None: ...


class PomdpAgent:
    """A POMDP controller: the core executive with a given decider.

    Args:
        name: label in reports.
        executive: a :class:`pearl_pomdp.executive.Executive`.
    """

    def __init__(self, name: str, executive):
        self.name = name
        self.executive = executive
        self.last_decision = None

    def reset(self) -> None:
        self.executive.reset()

    def act(self) -> str:
        self.last_decision = self.executive.decide()
        return self.last_decision.action_name

    def observe(self, action: str, symbol: str) -> None:
        self.executive.observe(action, symbol)


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

    def __init__(self, name: str = "scripted"):
        self.name = name
        self.reset()

    def reset(self) -> None:
        self.pending: list = []
        self.location = "home"
        self.contact = False
        self.guiding = False
        self.last = TIMEOUT_SYMBOL
        self.rang = False

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
