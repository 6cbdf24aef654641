"""The simulated ward: one robot, three residents with reminders, requests and their own whereabouts.

:class:`WardWorld` is the ground truth the POMDP only sees through noisy messages, and the world the
ward study runs every controller in (docs/ward.md, "The world"). It has the interface the episode
loop needs (:class:`pearl_sim.loop.World`): :meth:`act` carries out an action to its end and returns
every message produced meanwhile (timestamped); :meth:`wait` lets time pass with the robot idle
until a message is produced. The loop and the robot's tracker decide when a step closes.

Messages (the modality of ``config/ward.domain.yaml`` each belongs to):

* ``Arrival`` — the navigation's ``at_<place>`` when a drive ends;
* ``Call`` — ``call_<name>``: a resident in their room presses the call button when a need arises
  (probability ``presses_call``) and again every :data:`CALL_AGAIN_SECONDS` while unserved;
* ``Voice`` — what a resident says (through the word-error recogniser): their need, unasked, every
  :data:`SPEAK_AGAIN_SECONDS` with the robot idle at their place (probability ``speaks_up``); the
  answer to a question, a reminder or a service;
* ``Presence`` — ``person_seen`` when the robot arrives where a resident is (missed with
  probability ``detector.miss``).

Residents follow their scenario: they move at their ``moves`` times, a medication reminder falls
due at each ``pills`` time (overdue ``late_after`` seconds later), a need arises at each
``requests`` time (a second need waits until the first is met). A reminder reaches a resident only
where they are (their room or the lounge, with the robot there), and so does a service.

The world scores what a ward nurse would: requests met and the seconds each waited, medications
taken (on time, overdue, or not at all), wrong actions, questions with nobody there.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Dict, List, Optional

from pearl_sim.messages import Message, StepResult
from pearl_sim.ward.scenario import HOME, RESIDENTS, Resident, WardScenario
from pearl_sim.world_base import StudyWorld

__all__ = ["WardWorld", "WardMetrics", "UTTERANCES", "CONFUSIONS", "SPEAK_SECONDS", "ANSWER_SECONDS",
           "CALL_AGAIN_SECONDS", "SPEAK_AGAIN_SECONDS"]

#: Seconds a spoken action (a reminder, a question) takes before an answer.
SPEAK_SECONDS = 3.0
#: Seconds a resident takes to answer.
ANSWER_SECONDS = 2.0
#: Seconds a service takes (fetching water from the room's jug, helping up with a nurse, a short chat).
SERVE_SECONDS = 8.0
#: A resident with an unmet need in their room presses the call button again this often (s).
CALL_AGAIN_SECONDS = 60.0
#: A resident with an unmet need and the robot idle beside them speaks up again this often (s).
SPEAK_AGAIN_SECONDS = 20.0

#: What a resident says for each intent (chosen at random, then passed through the recogniser).
UTTERANCES: Dict[str, List[str]] = {
    "water": ["could i have some water", "i am thirsty", "a drink please", "some tea please"],
    "help": ["help me up please", "i need to go to the bathroom", "can you get the nurse", "help"],
    "talk": ["would you talk with me", "i would like some company", "let us chat a while"],
    "yes": ["yes thank you", "okay", "thanks", "yes"],
    "no": ["no", "nothing thanks", "not now"],
}
#: Words of this ward the recogniser confuses.
CONFUSIONS: Dict[str, List[str]] = {
    "water": ["waiter", "later", "otter"],
    "drink": ["rink", "think"],
    "help": ["helm", "kelp", "yelp"],
    "talk": ["walk", "stalk", "torque"],
    "chat": ["hat", "cat"],
    "yes": ["yet", "less"],
    "no": ["know", "now", "go"],
    "thanks": ["tanks", "banks"],
    "nurse": ["purse", "worse"],
}
DRIVES = {"GoToStation": "station", "GoToRoomAnn": "room_ann", "GoToRoomBob": "room_bob",
          "GoToRoomCleo": "room_cleo", "GoToLounge": "lounge"}


@dataclass
class WardMetrics:
    """Scores of an episode."""

    steps: int = 0
    requests: int = 0
    requests_met: int = 0
    #: Per met request, seconds from the need arising to the service.
    request_wait: List[float] = field(default_factory=list)
    pills: int = 0
    pills_on_time: int = 0
    pills_overdue: int = 0
    questions: int = 0
    unprompted_questions: int = 0
    wrong_actions: int = 0
    wrong: List[str] = field(default_factory=list)


@dataclass
class _Person:
    spec: Resident
    at: str = "room"
    pill: str = "none"                # none | due | late
    pill_since: float = 0.0
    need: str = "none"
    need_since: float = 0.0
    queued: List[str] = field(default_factory=list)
    next_call: float = float("inf")
    next_speak: float = 0.0
    moves: List = field(default_factory=list)
    pills: List = field(default_factory=list)
    requests: List = field(default_factory=list)


class WardWorld(StudyWorld):
    """Ground-truth simulation of one ward episode.

    Args:
        scenario: the episode.
        seed: overrides ``scenario.seed`` (every random draw comes from it).
        word_error_rate: overrides the scenario's recogniser word error rate (a study's noise level);
            a resident's own ``word_error_rate`` still wins for their speech.
    """

    UTTERANCES = UTTERANCES
    CONFUSIONS = CONFUSIONS
    scenario: WardScenario

    def __init__(self, scenario: WardScenario, seed: Optional[int] = None, word_error_rate: Optional[float] = None):
        super().__init__(scenario, seed, word_error_rate, HOME)
        self.people = {r.name: _Person(r, at=r.at, moves=list(r.moves), pills=list(r.pills),
                                       requests=list(r.requests)) for r in scenario.residents}
        self.metrics = WardMetrics()
        self._happen()

    # ------------------------------------------------------------------ queries
    def place_of(self, person: _Person) -> Optional[str]:
        """The robot's place where ``person`` is (their room or the lounge), ``None`` when out."""
        return {"room": person.spec.room, "lounge": "lounge"}.get(person.at)

    def truth(self) -> Dict[str, str]:
        """The true state in ``config/ward.domain.yaml``'s feature terms (for scoring)."""
        state = {"RobotAt": self.robot_at}
        for name in RESIDENTS:
            p = self.people[name]
            state.update({f"{name}At": p.at, f"{name}Pill": p.pill, f"{name}Need": p.need})
        return state

    @property
    def all_met(self) -> bool:
        """Every request that arose was met and every medication that fell due was taken."""
        m = self.metrics
        return (m.requests_met == m.requests and m.pills_on_time + m.pills_overdue == m.pills
                and all(p.need == "none" and not p.queued for p in self.people.values()))

    # ------------------------------------------------------------------ stepping
    def act(self, action: str) -> StepResult:
        """Carry out ``action`` to its end; every message produced meanwhile, in time order."""
        start = self.time
        events: List[str] = []
        self.metrics.steps += 1
        wrong: Optional[str] = None
        if action in DRIVES:
            self._drive(DRIVES[action], events)
        elif action == "Wait":
            pass                                   # the loop idles the world until a message or the timeout
        else:
            for verb in ("Remind", "Ask", "Serve"):
                if action.startswith(verb) and action[len(verb):] in self.people:
                    wrong = getattr(self, f"_{verb.lower()}")(self.people[action[len(verb):]], events)
                    break
            else:
                raise ValueError(f"the ward world does not know action {action!r}")
        return self._close(action, start, events, wrong)

    def _idle(self, seconds: float, events: List[str]) -> None:
        self._advance(seconds, events, idle=True)

    # ------------------------------------------------------------ spoken actions
    def _here(self, p: _Person) -> bool:
        return self.place_of(p) == self.robot_at

    def _reply(self, p: _Person, intent: str, events: List[str]) -> None:
        self._advance(ANSWER_SECONDS, events)
        self._pending.append(self._say(p.spec, intent))

    def _remind(self, p: _Person, events: List[str]) -> Optional[str]:
        self._advance(SPEAK_SECONDS, events)
        if not self._here(p):
            self.metrics.unprompted_questions += 1
            return f"reminded {p.spec.name}, who is not here"
        if p.pill == "none":
            self._reply(p, "no", events)
            return f"reminded {p.spec.name} with no medication due"
        self.metrics.pills_on_time += p.pill == "due"
        self.metrics.pills_overdue += p.pill == "late"
        events.append(f"{p.spec.name} takes the medication ({'on time' if p.pill == 'due' else 'overdue'})")
        p.pill = "none"
        self._reply(p, "yes", events)
        return None

    def _ask(self, p: _Person, events: List[str]) -> Optional[str]:
        self.metrics.questions += 1
        self._advance(SPEAK_SECONDS, events)
        if not self._here(p):
            self.metrics.unprompted_questions += 1
            events.append(f"unprompted question: {p.spec.name} is not here")
            return None
        self._reply(p, p.need if p.need != "none" else "no", events)
        return None

    def _serve(self, p: _Person, events: List[str]) -> Optional[str]:
        self._advance(SERVE_SECONDS, events)
        if not self._here(p):
            return f"served {p.spec.name}, who is not here"
        if p.need == "none":
            self._reply(p, "no", events)
            return f"served {p.spec.name}, who wanted nothing"
        self.metrics.requests_met += 1
        self.metrics.request_wait.append(self.time - p.need_since)
        events.append(f"{p.spec.name}'s request ({p.need}) is met")
        p.need, p.next_call = "none", float("inf")
        if p.queued:
            self._arise(p, p.queued.pop(0), events)
        self._reply(p, "yes", events)
        return None

    # -------------------------------------------------------------------- drives
    def _drive(self, goal: str, events: List[str]) -> None:
        if goal != self.robot_at:
            self._advance(self.scenario.distance(self.robot_at, goal) / self.scenario.robot_speed, events)
            self.robot_at = goal
            events.append(f"the robot reaches {goal}")
        self._pending.append(Message(self.time, "Arrival", f"at_{goal}"))
        if any(self._here(p) for p in self.people.values()) and self.rng.random() >= self.scenario.detector_miss:
            self._pending.append(Message(self.time, "Presence", "person_seen"))
        for p in self.people.values():
            p.next_speak = self.time + 2.0

    # ---------------------------------------------------------------- time flow
    def _advance(self, seconds: float, events: List[str], idle: bool = False) -> None:
        end = self.time + seconds
        while end - self.time > 1e-12:
            self.time += min(1.0, end - self.time)
            self._happen(events, idle)

    def _arise(self, p: _Person, need: str, events: List[str]) -> None:
        p.need, p.need_since = need, self.time
        self.metrics.requests += 1
        events.append(f"{p.spec.name} wants {need}")
        p.next_call = self.time
        p.next_speak = self.time + 1.0

    def _happen(self, events: Optional[List[str]] = None, idle: bool = False) -> None:
        """What happens at this second: moves, medications falling due, needs, call buttons, speaking up."""
        events = events if events is not None else []
        for p in self.people.values():
            while p.moves and p.moves[0][0] <= self.time:
                _, p.at = p.moves.pop(0)
                events.append(f"{p.spec.name} goes to {p.at}")
            while p.pills and p.pills[0] <= self.time:
                p.pills.pop(0)
                self.metrics.pills += 1
                if p.pill == "none":
                    p.pill, p.pill_since = "due", self.time
                    events.append(f"{p.spec.name}'s medication falls due")
                else:
                    self.metrics.pills -= 1      # the earlier one still open: they take one dose
            if p.pill == "due" and self.time - p.pill_since >= p.spec.late_after:
                p.pill = "late"
                events.append(f"{p.spec.name}'s medication is overdue")
            while p.requests and p.requests[0][0] <= self.time:
                _, need = p.requests.pop(0)
                if p.need == "none":
                    self._arise(p, need, events)
                else:
                    p.queued.append(need)
            if p.need != "none" and p.at == "room" and self.time >= p.next_call:
                p.next_call = self.time + CALL_AGAIN_SECONDS
                if self.rng.random() < p.spec.presses_call:
                    self._pending.append(Message(self.time, "Call", f"call_{p.spec.name.lower()}"))
            if idle and p.need != "none" and self._here(p) and self.time >= p.next_speak:
                p.next_speak = self.time + SPEAK_AGAIN_SECONDS
                if self.rng.random() < p.spec.speaks_up:
                    self._pending.append(self._say(p.spec, p.need))

    def _say(self, resident: Resident, intent: str) -> Message:
        """What ``resident`` says for ``intent``, through the recogniser at their (or the ward's) error rate."""
        return self._spoken(resident, intent)
