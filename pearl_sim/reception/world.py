"""The simulated reception hall: a robot at a front desk, visitors, a person detector, a battery.

:class:`ReceptionWorld` is the ground truth the POMDP only sees through noisy messages, and the
world the reception study runs every controller in (docs/reception.md, "The world"). It has the
interface the episode loop needs (:class:`pearl_sim.loop.World`): :meth:`act` carries out an
action to its end and returns every message produced meanwhile (timestamped); :meth:`wait`
lets time pass with the robot idle until a message is produced. The loop and the robot's
tracker decide when a step closes, never the world.

Messages (the modality of ``config/reception.domain.yaml`` each belongs to):

* ``Presence`` — the person detector on the robot: ``person_seen`` when a visitor walks up to
  the desk while the robot is there (missed with probability ``detector.miss``), when the robot
  comes back to the desk where visitors wait, and for passers-by (a Poisson stream of
  ``detector.passers_per_minute`` while the robot is at the desk); ``nobody`` when a waiting
  visitor gives up and leaves while the robot is there.
* ``Voice`` — what a visitor says, through the word-error recogniser
  (:class:`pearl_sim.asr.SpeechRecogniser` with this hall's confusable words);
* ``Touch`` — a destination button (``t_gallery``/``t_office``), for the fraction of answers a
  visitor gives on the screen;
* ``Arrival`` — the navigation's ``at_<place>`` when a drive ends;
* ``Charge`` — the battery driver's percentage, every :data:`BATTERY_PERIOD` seconds (the tracker
  bins it and observes a change of bin only).

Visitors: each walks up at their ``arrive`` time and queues at the desk; the first in the queue is
the one a greeting reaches. A greeted visitor stays with the robot (follows its escorts at their
own walking speed: the robot slows to them) until handed over, or until the robot drives off to
the desk without them. An ungreeted visitor leaves after ``patience`` seconds. The battery drains
idle and faster while driving; ``Dock`` drives to the charger beside the desk and docks: the robot
charges (to full in ``charge_minutes``) for as long as it stays there, until its next drive;
a flat battery strands the robot (its drives go nowhere).

The world scores what an experimenter would: visitors served (handed over where they wanted to go),
the seconds from arrival to hand-over, visitors who left unserved, clarification questions, questions
with nobody to answer (unprompted), wrong actions, and whether the robot was stranded.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Dict, List, Optional

from pearl_sim.messages import Message, StepResult
from pearl_sim.reception.scenario import DESTINATIONS, HOME, ReceptionScenario, Visitor
from pearl_sim.world_base import StudyWorld

__all__ = ["ReceptionWorld", "ReceptionMetrics", "UTTERANCES", "CONFUSIONS", "SPEAK_SECONDS", "ANSWER_SECONDS",
           "BATTERY_PERIOD", "LOW_BATTERY", "HELLO_AGAIN_SECONDS"]

#: Seconds a spoken action takes before an answer.
SPEAK_SECONDS = 3.0
#: Seconds a visitor takes to answer.
ANSWER_SECONDS = 2.0
#: The battery driver publishes its percentage this often (s).
BATTERY_PERIOD = 30.0
#: Battery fraction below which the battery counts as low (the domain's charge_low bin).
LOW_BATTERY = 0.25
#: A visitor left waiting at the desk (robot there) tries a hello again this often (s).
HELLO_AGAIN_SECONDS = 20.0

#: What a visitor says for each intent (chosen at random, then passed through the recogniser).
UTTERANCES: Dict[str, List[str]] = {
    "hello": ["hello", "hi there", "good morning", "good afternoon"],
    "gallery": ["the gallery please", "i would like to see the exhibition", "where are the paintings"],
    "office": ["i have a meeting in the office", "the office please", "i have an appointment upstairs"],
    "yes": ["yes", "yes please", "that is right", "yeah"],
    "no": ["no", "no not there", "that is wrong"],
    "chatter": ["thank you", "okay", "hmm", "nice building", "thanks goodbye"],
}
#: Words of this hall the recogniser confuses (acoustically close words).
CONFUSIONS: Dict[str, List[str]] = {
    "gallery": ["galley", "salary", "calorie"],
    "office": ["offers", "of this", "orifice"],
    "exhibition": ["exhibit shun", "inhibition"],
    "meeting": ["eating", "meting"],
    "appointment": ["a point meant", "disappointment"],
    "paintings": ["pointings", "paint inks"],
    "yes": ["yet", "less", "jess"],
    "no": ["know", "now", "go"],
    "hello": ["yellow", "fellow"],
    "right": ["write", "white"],
}
TOUCH = {"gallery": "t_gallery", "office": "t_office"}
ARRIVAL = {"desk": "at_desk", "gallery": "at_gallery", "office": "at_office"}
#: Actions the world knows, and the place each drive goes to.
DRIVES = {"EscortToGallery": "gallery", "EscortToOffice": "office", "ReturnToDesk": HOME, "Dock": HOME}
CLARIFICATIONS = ("AskDestination", "ConfirmGallery", "ConfirmOffice")


@dataclass
class ReceptionMetrics:
    """Scores of an episode."""

    steps: int = 0
    visitors_arrived: int = 0
    visitors_greeted: int = 0
    visitors_served: int = 0
    #: Visitors who gave up waiting ungreeted, or were left behind by the robot.
    visitors_left: int = 0
    clarifications: int = 0
    unprompted_questions: int = 0
    wrong_actions: int = 0
    docks: int = 0
    stranded: bool = False
    #: Per served visitor, seconds from reaching the desk to the hand-over.
    time_to_handover: List[float] = field(default_factory=list)
    wrong: List[str] = field(default_factory=list)


@dataclass
class _Person:
    spec: Visitor
    state: str = "coming"            # coming | waiting | engaged | served | left
    waiting_since: float = 0.0
    next_hello: float = 0.0


class ReceptionWorld(StudyWorld):
    """Ground-truth simulation of one reception episode.

    Args:
        scenario: the episode.
        seed: overrides ``scenario.seed`` (every random draw comes from it).
        word_error_rate: overrides the scenario's recogniser word error rate (a study's noise
            level); a visitor's own ``word_error_rate`` still wins for their speech.
    """

    UTTERANCES = UTTERANCES
    CONFUSIONS = CONFUSIONS
    scenario: ReceptionScenario

    def __init__(self, scenario: ReceptionScenario, seed: Optional[int] = None,
                 word_error_rate: Optional[float] = None):
        super().__init__(scenario, seed, word_error_rate, HOME)
        self.battery = float(scenario.battery)
        self.docked = False                     # on the charger (after Dock, until the next drive)
        self.people = [_Person(v) for v in scenario.visitors]
        self.metrics = ReceptionMetrics()
        self._next_battery = 0.0                # the driver's first reading comes at once
        self._next_passer = self._draw_passer(0.0)
        self._happen([], at_desk=True)

    # ------------------------------------------------------------------ queries
    def truth(self) -> Dict[str, str]:
        """The true state in ``config/reception.domain.yaml``'s feature terms (for scoring)."""
        current = self._engaged() or self._first_waiting()
        visitor = "none" if current is None else ("engaged" if current.state == "engaged" else "waiting")
        nxt = current or next((p for p in self.people if p.state == "coming"), None)
        return {"Visitor": visitor, "Wish": nxt.spec.wish if nxt is not None else DESTINATIONS[0],
                "RobotAt": self.robot_at, "Battery": "low" if self.battery < LOW_BATTERY else "ok"}

    @property
    def served_all(self) -> bool:
        """Every visitor of the scenario was handed over where they wanted to go, and the robot never stranded."""
        return self.metrics.visitors_served == len(self.people) and not self.metrics.stranded

    def _engaged(self) -> Optional[_Person]:
        return next((p for p in self.people if p.state == "engaged"), None)

    def _first_waiting(self) -> Optional[_Person]:
        waiting = [p for p in self.people if p.state == "waiting"]
        return min(waiting, key=lambda p: p.waiting_since) if waiting else None

    # ------------------------------------------------------------------ stepping
    def act(self, action: str) -> StepResult:
        """Carry out ``action`` to its end; every message produced meanwhile, in time order."""
        start = self.time
        events: List[str] = []
        self.metrics.steps += 1
        if action in CLARIFICATIONS:
            self.metrics.clarifications += 1
        handler = getattr(self, f"_act_{action}", None)
        if action in DRIVES:
            wrong = self._drive(action, DRIVES[action], events)
        elif handler is None:
            raise ValueError(f"the reception world does not know action {action!r}")
        else:
            self._advance(SPEAK_SECONDS, events)
            engaged = self._engaged()
            reply, wrong = handler(engaged, events)
            speaker = engaged or self._engaged()     # the visitor a greeting just reached answers too
            if reply is not None and speaker is not None:
                self._advance(ANSWER_SECONDS, events)
                self._pending.append(self._say(speaker.spec, reply))
        return self._close(action, start, events, wrong)

    def _idle(self, seconds: float, events: List[str]) -> None:
        self._advance(seconds, events)

    # ------------------------------------------------------------ spoken actions
    def _act_Wait(self, engaged: Optional[_Person], events):
        if engaged is None or not self._with_robot(engaged):
            return None, None
        if self.rng.random() < engaged.spec.volunteers:
            return engaged.spec.wish, None
        return ("chatter" if self.rng.random() < 0.1 else None), None

    def _act_Greet(self, engaged: Optional[_Person], events):
        if engaged is not None:
            return "hello", None          # greeting twice: awkward (the domain charges it), not a task error
        waiting = self._first_waiting() if self.robot_at == HOME else None
        if waiting is None:
            return None, "greeted nobody"
        waiting.state = "engaged"
        self.metrics.visitors_greeted += 1
        events.append(f"{waiting.spec.name} is greeted")
        # The greeting asks where they want to go: some answer it at once.
        if self.rng.random() < 0.3:
            return waiting.spec.wish, None
        return ("hello" if self.rng.random() < 0.7 else "chatter"), None

    def _act_AskDestination(self, engaged: Optional[_Person], events):
        if engaged is None:
            self._unprompted("asked where to go with nobody there", events)
            return None, None
        return engaged.spec.wish, None

    def _confirm(self, place: str, engaged: Optional[_Person], events):
        if engaged is None:
            self._unprompted(f"asked to confirm the {place} with nobody there", events)
            return None, None
        return ("yes" if engaged.spec.wish == place else "no"), None

    def _act_ConfirmGallery(self, engaged, events):
        return self._confirm("gallery", engaged, events)

    def _act_ConfirmOffice(self, engaged, events):
        return self._confirm("office", engaged, events)

    def _act_HandOver(self, engaged: Optional[_Person], events):
        if engaged is None:
            return None, "handed over nobody"
        if self.robot_at != engaged.spec.wish:
            return "no", f"handed {engaged.spec.name} over at the {self.robot_at}, not the {engaged.spec.wish}"
        engaged.state = "served"
        self.metrics.visitors_served += 1
        self.metrics.time_to_handover.append(self.time - engaged.spec.arrive)
        events.append(f"{engaged.spec.name} is handed over at the {self.robot_at}")
        return "chatter", None

    def _unprompted(self, what: str, events: List[str]) -> None:
        self.metrics.unprompted_questions += 1
        events.append(f"unprompted question: {what}")

    def _with_robot(self, person: _Person) -> bool:
        return person.state == "engaged"

    # -------------------------------------------------------------------- drives
    def _drive(self, action: str, goal: str, events: List[str]) -> Optional[str]:
        """Drive to ``goal`` (an engaged visitor follows an escort; a drive to the desk leaves them);
        ``Dock`` charges at the desk afterwards. The arrival is reported at the end."""
        engaged = self._engaged()
        wrong: Optional[str] = None
        self.docked = False
        if action.startswith("EscortTo"):
            if engaged is None:
                wrong = "escorted nobody"
            elif engaged.spec.wish != goal:
                wrong = f"escorted {engaged.spec.name} to the {goal}, not the {engaged.spec.wish}"
        elif engaged is not None and goal == HOME:
            engaged.state = "left"
            self.metrics.visitors_left += 1
            wrong = f"left {engaged.spec.name} at the {self.robot_at} without a hand-over"
            events.append(f"{engaged.spec.name} is left behind and finds their own way")
            engaged = None
        if self.metrics.stranded:
            self._advance(1.0, events)
        elif goal != self.robot_at:
            pace = self.scenario.robot_speed
            if engaged is not None:
                pace = min(pace, engaged.spec.walking_speed)
                events.append(f"escorting {engaged.spec.name} to the {goal} at {pace:.2f} m/s")
            self._advance(self.scenario.distance(self.robot_at, goal) / pace, events, moving=True)
            if not self.metrics.stranded:
                self.robot_at = goal
                events.append(f"the robot reaches the {goal}")
                if goal == HOME:
                    self._see_waiting(events)
        if action == "Dock" and self.robot_at == HOME:
            # Docked: it charges from now on while it stays at the desk (until its next drive).
            self.metrics.docks += 1
            self.docked = True
            events.append("the robot docks and charges")
        self._pending.append(Message(self.time, "Arrival", ARRIVAL[self.robot_at]))
        return wrong

    def _see_waiting(self, events: List[str]) -> None:
        if self._first_waiting() is not None and self.rng.random() >= self.scenario.detector_miss:
            self._pending.append(Message(self.time, "Presence", "person_seen"))

    # ---------------------------------------------------------------- time flow
    def _draw_passer(self, now: float) -> float:
        rate = self.scenario.passers_per_minute / 60.0
        return now + float(self.rng.exponential(1.0 / rate)) if rate > 0 else float("inf")

    def _advance(self, seconds: float, events: List[str], moving: bool = False) -> None:
        """Let ``seconds`` pass in steps of at most 1 s: visitors arrive and give up, passers-by
        walk past the desk, the battery drains (or charges, docked) and reports."""
        end = self.time + seconds
        while end - self.time > 1e-12:
            dt = min(1.0, end - self.time)
            self.time += dt
            if self.docked:
                self.battery = min(1.0, self.battery + dt / (self.scenario.charge_minutes * 60.0))
            else:
                per_hour = self.scenario.drive_hours if moving and not self.metrics.stranded else self.scenario.idle_hours
                self.battery = max(0.0, self.battery - dt / (per_hour * 3600.0))
            if self.battery <= 0.0 and not self.metrics.stranded:
                self.metrics.stranded = True
                events.append("the battery is flat: the robot is stranded")
            self._happen(events, at_desk=self.robot_at == HOME and not moving)

    def _happen(self, events: List[str], at_desk: bool) -> None:
        """What happens at this second: arrivals, give-ups, hellos, passers-by, the battery's report."""
        for p in self.people:
            if p.state == "coming" and p.spec.arrive <= self.time:
                p.state, p.waiting_since = "waiting", self.time
                p.next_hello = self.time + 2.0
                self.metrics.visitors_arrived += 1
                events.append(f"{p.spec.name} walks up to the desk (wants the {p.spec.wish})")
                if at_desk and self.rng.random() >= self.scenario.detector_miss:
                    self._pending.append(Message(self.time, "Presence", "person_seen"))
            elif p.state == "waiting" and self.time - p.waiting_since >= p.spec.patience:
                p.state = "left"
                self.metrics.visitors_left += 1
                events.append(f"{p.spec.name} gives up waiting and leaves")
                if at_desk and self.rng.random() >= self.scenario.detector_miss:
                    self._pending.append(Message(self.time, "Presence", "nobody"))
            elif p.state == "waiting" and at_desk and self.time >= p.next_hello:
                p.next_hello = self.time + HELLO_AGAIN_SECONDS
                if self.rng.random() < p.spec.says_hello:
                    self._pending.append(self._say(p.spec, "hello"))
        if self.time >= self._next_passer:
            self._next_passer = self._draw_passer(self.time)
            if at_desk and self.rng.random() >= self.scenario.detector_miss:
                self._pending.append(Message(self.time, "Presence", "person_seen"))
                events.append("someone walks past the desk")
        if self.time >= self._next_battery:
            self._next_battery = self.time + BATTERY_PERIOD
            self._pending.append(Message(self.time, "Charge", f"{self.battery:.3f}"))

    def _say(self, visitor: Visitor, intent: str) -> Message:
        """What ``visitor`` says for ``intent``: a touch for a destination (their touchscreen share),
        else an utterance through the recogniser."""
        if intent in TOUCH and self.rng.random() < visitor.touchscreen:
            return Message(self.time, "Touch", TOUCH[intent], said=f"(touches '{TOUCH[intent]}')", meant=intent)
        return self._spoken(visitor, intent)
