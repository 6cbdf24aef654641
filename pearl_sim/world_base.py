"""What the reception's and the ward's simulated worlds share (:class:`StudyWorld`, their base class).

Both are ground truth behind the episode loop's :class:`pearl_sim.loop.World`: a seeded random
stream, a clock, the robot's place, messages produced and not yet handed to the loop, and people
whose speech goes through the word-error recogniser. Here are the parts that are the same in both:
the seeding, :meth:`StudyWorld.truth_record`, :meth:`StudyWorld.wait`'s idle loop, the close of an
action (a wrong action scored, the messages in time order) and a person's speech through one
recogniser per error rate. What happens in the world (its actions, people and time flow) is each
world's own. The nursing home (``pearl_sim/nursing_home/world.py``) stands on this frame too, with
its own scheduler wait and speech path (through the real recogniser channel).
"""
from __future__ import annotations

from typing import Any, Dict, List, Optional

import numpy as np

from pearl_sim.asr import SpeechRecogniser
from pearl_sim.messages import Message, StepResult

__all__ = ["StudyWorld"]


class StudyWorld:
    """The common frame of a reception or ward world (a base class; see the module doc).

    Args:
        scenario: the episode (``seed``, ``word_error_rate`` and what the world reads of it).
        seed: overrides ``scenario.seed`` (every random draw comes from it).
        word_error_rate: overrides the scenario's recogniser word error rate (a study's noise level);
            a person's own ``word_error_rate`` still wins for their speech.
        home: where the robot starts.

    A subclass sets :attr:`UTTERANCES` and :attr:`CONFUSIONS`, defines ``truth()``, ``act()`` (ending
    in :meth:`_close`) and :meth:`_idle`, and sets ``metrics`` (with ``wrong_actions`` and ``wrong``).
    """

    #: What a person says for each intent (one is chosen at random, then passed through the recogniser).
    UTTERANCES: Dict[str, List[str]] = {}
    #: Words the recogniser confuses (acoustically close words).
    CONFUSIONS: Dict[str, List[str]] = {}
    metrics: Any

    def __init__(self, scenario, seed: Optional[int], word_error_rate: Optional[float], home: str):
        self.scenario = scenario
        self.seed = scenario.seed if seed is None else int(seed)
        self.rng = np.random.default_rng(self.seed)
        self.word_error_rate = scenario.word_error_rate if word_error_rate is None else float(word_error_rate)
        self._recognisers: Dict[float, SpeechRecogniser] = {}
        self.time = 0.0
        self.robot_at = home
        self._pending: List[Message] = []       # messages produced and not yet handed to the loop

    def truth(self) -> Dict[str, str]:
        """The true state in the domain's feature terms (for scoring)."""
        raise NotImplementedError

    def truth_record(self, phase: str, action: str = "", result: Optional[StepResult] = None) -> dict:
        """The true state now as a truth record (``phase`` ``start``/``end`` of an action; with ``result``,
        the action's ``events`` and ``wrong``): :mod:`pearl_pomdp.world_truth` describes it, a
        simulator publishes it as ``pearl_interfaces/WorldTruth`` on ``/WORLD/sim/truth``."""
        body = {"time": self.time, "phase": phase, "action": action, "state": self.truth()}
        if result is not None:
            body.update(events=result.events, wrong=result.wrong)
        return body

    def wait(self, until: float) -> StepResult:
        """Let time pass with the robot idle until a message is produced or ``until`` (world seconds)."""
        start = self.time
        events: List[str] = []
        while not self._pending and self.time < until - 1e-9:
            self._idle(min(1.0, until - self.time), events)
        messages, self._pending = self._pending, []
        return StepResult("", start, self.time, messages, events, None)

    def _idle(self, seconds: float, events: List[str]) -> None:
        """Let ``seconds`` pass with the robot idle (what :meth:`wait` does each second)."""
        raise NotImplementedError

    def _close(self, action: str, start: float, events: List[str], wrong: Optional[str]) -> StepResult:
        """The end of ``action`` begun at ``start``: a wrong action counted and told, every message in time order."""
        if wrong:
            self.metrics.wrong_actions += 1
            self.metrics.wrong.append(f"{action}: {wrong}")
            events.append(f"wrong action: {wrong}")
        messages, self._pending = sorted(self._pending, key=lambda m: m.time), []
        return StepResult(action, start, self.time, messages, events, wrong)

    def _spoken(self, person, intent: str) -> Message:
        """What ``person`` (a visitor, a resident) says for ``intent``: an utterance through the recogniser
        at their ``word_error_rate`` or, when theirs is ``None``, the world's."""
        options = self.UTTERANCES[intent]
        said = options[self.rng.integers(len(options))]
        wer = self.word_error_rate if person.word_error_rate is None else person.word_error_rate
        if wer not in self._recognisers:
            # One recogniser per error rate, each seeded from the episode (reproducible per seed).
            self._recognisers[wer] = SpeechRecogniser(word_error_rate=wer, confusions=dict(self.CONFUSIONS),
                                                      seed=self.seed + 7919 + len(self._recognisers))
        return Message(self.time, "Voice", self._recognisers[wer].recognise(said), said=said, meant=intent)
