"""What a simulated world answers the robot's loop with: timestamped input messages, and per action a
:class:`StepResult` (shared by every world: :mod:`pearl_sim.nursing_home.world`, :mod:`pearl_sim.reception.world`)."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import List, Optional

__all__ = ["Message", "StepResult"]


@dataclass
class Message:
    """One input message: the domain ``modality`` it belongs to (its input is ``modality.lower()``) and its text.

    For speech, ``text`` is the recogniser's output and ``said`` what the person said.
    """

    time: float
    modality: str
    text: str
    said: str = ""
    meant: str = ""   # the speaker's intent, for transcripts


@dataclass
class StepResult:
    """What one action (or a wait) did: its time span, the messages it produced and notable events."""

    action: str
    start: float
    end: float
    messages: List[Message] = field(default_factory=list)
    events: List[str] = field(default_factory=list)
    wrong: Optional[str] = None

    @property
    def message(self) -> Optional[Message]:
        """The first message, or ``None`` when nothing was heard."""
        return self.messages[0] if self.messages else None
