"""The simulated nursing home: a robot, one resident, a scheduler (docs/design.md §7).

:class:`World` is the ground truth that the POMDP only observes through noisy
messages. It is richer than the Pearl model on purpose: positions in metres,
walking speeds from 5 cm/s, rests, a resident who loses a robot that drives on
without her, a recogniser with a word error rate. Its interface is the step
protocol of docs/design.md §6: the robot takes an action; the world answers with *one*
message (any modality) that closes the step, or ``None`` when nothing is heard
before ``step_timeout`` (the tracker maps that to Speech ``unknown``).

Guidance and walking pace (the paper's open problem). With
``pace_adaptation: false`` the robot drives to physiotherapy at its cruise speed,
as Pearl did in the paper's trials; a slow resident falls behind and, past
``lose_distance``, gives up and walks back to her room. With
``pace_adaptation: true`` the world does not decide the pace: the simulated resident
produces what a people tracker reports (her distance behind the robot, every
:data:`CONTROL_PERIOD` s) and the robot's speed comes from the manager's
:class:`pearl_pomdp.guide_pace.GuidePace` — the class the ``guide_pace`` node runs on a
robot, with the settings of ``config/pearl_nodes.yaml``'s ``guide_pace`` section. When
GuidePace declares her lost the world reports Laser ``userLost`` (as the node does) and
the navigation drives on alone.

Blocked corridors (scenario ``blocked:``). A drive through one never arrives: the robot
stops at the obstacle, no landmark is reported, and the scheduler keeps quiet (the robot
is still busy driving) until the manager gives the drive up at its deadline
(``navFailed``, :mod:`pearl_pomdp.tracking`) and takes its next action. The robot is then
taken to be back where it started.

Her physiotherapy session (docs/day.md, Part 1; here since protocol 4). A ``physio``
appointment is :data:`REMINDER_LEAD` after its reminder; at the department she goes into
her session then (or :data:`SETTLE_SECONDS` after arriving, if later) for
:data:`SESSION_SECONDS`, during which she neither hears nor needs the robot. An episode
lasts the scenario's ``max_steps``; :func:`until_pearl_leaves` ends one at Figure 4(f)
instead (``pearl demo``).

The world counts what an experimenter scores: reminders delivered, guidances
completed and their duration, clarification questions, and *wrong actions*
(reminding with nothing due, answering a question nobody asked, guiding a
resident who did not want to go, ending a guidance before the department).
"""
from __future__ import annotations

import functools
from dataclasses import dataclass, field
from typing import Callable, Dict, List, Optional

import numpy as np

from pearl_sim.asr import SpeechRecogniser
from pearl_sim.messages import Message, StepResult  # noqa: F401  (re-exported: the world's message types)
from pearl_sim.nursing_home.scenario import Scenario
from pearl_sim.world_base import StudyWorld

#: Seconds between the simulated people tracker's reports and GuidePace's control steps
#: during a guidance (the guide_pace node runs at 20 Hz; 0.5 s keeps the study fast).
CONTROL_PERIOD = 0.5
#: Metres within which the resident hears the robot and answers it.
EARSHOT = 3.0
#: Seconds a spoken action (say + display) takes before the answer.
SPEAK_SECONDS = 3.0
#: Seconds the resident takes to answer.
ANSWER_SECONDS = 2.0
#: The scheduler re-announces an outstanding reminder this often (s).
REANNOUNCE_SECONDS = 60.0
#: Battery fraction below which the battery counts as low.
LOW_BATTERY = 0.2
#: Her physiotherapy appointment and **the session** (docs/day.md, Part 1): the physio reminder falls
#: due 15 minutes before the appointment; the session starts at the appointment, or 2 minutes after she
#: arrives at the department if that is later (she settles in: the time for her arrival question), and
#: lasts 45 minutes (NICE CG162: 45 min of each therapy a day). During it she is with the therapist and
#: neither hears nor needs the robot; afterwards she walks back to her room (an aide goes with her).
REMINDER_LEAD = 900.0
SETTLE_SECONDS = 120.0
SESSION_SECONDS = 45 * 60.0

#: The domain feature whose value a drive sets: the robot's place (home, room, physio).
ROBOT_PLACE = "RobotLocation"
#: The Laser landmark the navigation reports on arrival at each place.
LANDMARKS = {"home": "atHome", "room": "atRoom", "physio": "atPhysio"}

#: Seconds of simulated time an episode run "until Pearl leaves" lasts at most (``pearl demo``,
#: ``bench/behaviour.py --until-left``; docs/day.md, protocol 4): her session starts 15 minutes after the
#: physio reminder, and the limit leaves the robot as long again to notice that nobody needs it.
LEAVE_LIMIT = 1800.0


def until_pearl_leaves(world: "World", limit: float = LEAVE_LIMIT) -> Callable[[], bool]:
    """The end of an episode run until Figure 4(f), "Pearl leaves": a test, asked before each action,
    that is true once the robot has been out and is back at its station with nothing wanted and nothing
    of the scenario still to come (no appointment, no scheduled question: docs/day.md, amendment 11) —
    or once ``limit`` seconds of simulated time have passed."""
    went_out = {"yes": False}

    def left() -> bool:
        if world.time >= limit:
            return True
        if world.robot_at != "home":
            went_out["yes"] = True
            return False
        return (went_out["yes"] and not world.due and not world.wants_guidance and world.info_goal is None
                and all(a.at <= world.time for a in world.scenario.appointments) and not world._questions)

    return left


@functools.lru_cache(maxsize=1)
def default_guide_pace():
    """``(GuidePaceConfig, lost_symbol)`` from ``config/pearl_nodes.yaml``'s ``guide_pace`` section
    (the settings the guide_pace node runs with), read once per process."""
    from pearl_pomdp.guide_pace import GuidePaceConfig
    from pearl_pomdp.params import node_parameters

    params = node_parameters("guide_pace")
    return GuidePaceConfig.from_params(params), str(params.get("lost_symbol", "userLost"))


def action_roles(domain) -> Dict[str, Dict[str, str]]:
    """What the world needs to know of the domain's actions, from its ``category:`` tags.

    Returns ``{"moves": {action: place}, "clarifications": {action: category}}``: a move is a
    ``category: Move`` action and its destination the value it most likely sets on :data:`ROBOT_PLACE`;
    a clarification is a ``category: Clarify`` action (a question asked to resolve uncertainty).
    """
    moves = {a: place for a in domain.actions if domain.categories.get(a) == "Move"
             and (place := domain.intended_effect(a, ROBOT_PLACE)) is not None}
    clarifications = {a: "Clarify" for a in domain.actions if domain.categories.get(a) == "Clarify"}
    return {"moves": moves, "clarifications": clarifications}

#: What the resident says for each intent (chosen at random, then passed through the recogniser).
UTTERANCES: Dict[str, List[str]] = {
    "yes": ["yes", "yes please", "sure", "yeah all right", "ok"],
    "no": ["no", "no thank you", "not now"],
    "time": ["what time is it", "can you tell me the time", "what is the time please"],
    "weather": ["what is the weather like", "give me the weather forecast for tomorrow", "will it rain today"],
    "go": ["let's go", "take me to physio please", "let's go to my appointment"],
    "chatter": ["hello pearl", "thank you", "that is nice", "hmm", "what did you say"],
}
TOUCH = {"yes": "t_yes", "no": "t_no", "time": "t_time", "weather": "t_weather", "go": "t_go"}


@dataclass
class Metrics:
    """Scores of an episode."""

    steps: int = 0
    reminders_delivered: int = 0
    guidances_started: int = 0
    guidances_completed: int = 0
    residents_lost: int = 0
    questions_answered: int = 0
    #: What the scenario asked for (counted, no effect on the world): reminders that fell due
    #: and questions the resident came to have, so an outcome scores only those.
    reminders_due: int = 0
    questions_raised: int = 0
    #: Times she came to want the walk (after the reminder, if willing): a guidance is
    #: *wanted* in an episode where this is above 0.
    walk_wishes: int = 0
    clarifications: int = 0
    #: Offers or confirmations about a goal the resident does not have at that moment
    #: ("Shall we walk to physiotherapy?" to a resident who does not want to go).
    unprompted_questions: int = 0
    wrong_actions: int = 0
    #: Guidances in which GuidePace declared the resident lost (``userLost`` reported).
    lost_reports: int = 0
    #: Per guidance, the robot's mean speed from start to arrival (m/s), door wait excluded.
    guide_speeds: List[float] = field(default_factory=list)
    #: Drives stopped by a blocked corridor (scenario ``blocked:``).
    blocked_drives: int = 0
    time_to_goal: List[float] = field(default_factory=list)
    wrong: List[str] = field(default_factory=list)


class World(StudyWorld):
    """Ground-truth simulation of one scenario episode.

    Args:
        scenario: the episode.
        seed: overrides ``scenario.seed`` (every stochastic piece is seeded from it).
        pace_adaptation: overrides ``scenario.pace_adaptation`` when not ``None``.
        domain: the Pearl FactoredDomain whose ``category:`` tags say which actions are
            drives and clarifications (default: the shipped ``config/pearl.domain.yaml``).
    """

    def __init__(self, scenario: Scenario, seed: Optional[int] = None, pace_adaptation: Optional[bool] = None,
                 domain=None, guide_pace=None):
        if domain is None:
            from pearl_sim.nursing_home.scenario import default_domain

            domain = default_domain()
        roles = action_roles(domain)
        self.moves: Dict[str, str] = roles["moves"]
        self.clarifications = frozenset(roles["clarifications"])
        # The frame's seeding, clock and place (the word-error rate is the scenario's or hers, below).
        super().__init__(scenario, seed, None, home="home")
        self.pace_adaptation = scenario.pace_adaptation if pace_adaptation is None else bool(pace_adaptation)
        # The manager's pace filter settings (GuidePaceConfig), the guide_pace node's own.
        self.guide_pace_config, self.lost_symbol = guide_pace if guide_pace is not None else default_guide_pace()
        resident = scenario.resident
        wer = scenario.word_error_rate if resident.word_error_rate is None else resident.word_error_rate
        self.asr = SpeechRecogniser(word_error_rate=wer, seed=self.seed + 7919)
        # The real speech channel (espeak-ng → noise → the domain's pocketsphinx recogniser, or
        # a calibrated sample of it) when the scenario asks for it; its own random stream, so
        # every other draw of the world stays as with the word-error model.
        self.speech_channel = None
        if scenario.speech.get("channel", "word_error") != "word_error":
            from pearl_sim.speech_channel import make_speech_channel

            self.speech_channel = make_speech_channel(scenario.speech, domain.keywords, source=scenario.source,
                                                      seed=self.seed + 7919)
            self.speech_rng = np.random.default_rng(self.seed + 104729)
        self.battery = 1.0
        self.resident_at = "room"        # room | physio | corridor
        self.engaged = False             # UserPresent: with the robot and attending to it
        self.wants_guidance = False
        self.info_goal: Optional[str] = None
        self.due: List[str] = []         # reminders due and not yet delivered
        self._appointments = sorted(scenario.appointments, key=lambda a: a.at)
        self._questions = [q for q in scenario.questions if q.when == "at_time"]
        self._physio_questions = [q for q in scenario.questions if q.when == "at_physio"]
        self._scheduler_queue: List[Message] = []
        self._last_announce: Dict[str, float] = {}
        self._guidance_due_at: Optional[float] = None
        self._follower: Optional[dict] = None   # a resident walking behind/after the robot
        self._return_at: Optional[float] = None  # a lost resident gets back to her room then
        self._stuck = False              # a drive stopped by a blocked corridor is still under way
        physio = [a.at for a in scenario.appointments if a.kind == "physio"]
        #: When her physiotherapy appointment is (its reminder falls due REMINDER_LEAD before); None: none.
        self.appointment_at: Optional[float] = physio[0] + REMINDER_LEAD if physio else None
        self.in_session = False
        self._arrived_at: Optional[float] = None
        self._session_at: Optional[float] = None
        self._session_done = False
        self.metrics = Metrics()
        self._advance(0.0, [])

    # ------------------------------------------------------------------ queries
    @property
    def done(self) -> bool:
        """True when the step budget is used up."""
        return self.metrics.steps >= self.scenario.max_steps

    def truth(self) -> Dict[str, str]:
        """The true state in the Pearl domain's feature terms (for transcripts and scoring)."""
        reminder = self.due[0] if self.due else "none"
        return {
            "RobotLocation": self.robot_at,
            "UserLocation": "physio" if self.resident_at == "physio" else "room",
            "UserPresent": "yes" if self.engaged else "no",
            "ReminderGoal": reminder,
            "UserMotionGoal": "toPhysioWithRobot" if self.wants_guidance else "none",
            "UserInfoGoal": {"time": "wantTime", "weather": "wantWeather"}.get(self.info_goal or "", "none"),
            "Battery": "low" if self.battery < LOW_BATTERY else "ok",
        }

    # ------------------------------------------------------------------ stepping
    def act(self, action: str) -> StepResult:
        """Carry out ``action`` and return what it did, with every message it produced (timestamped).

        An action runs to completion (a sentence is finished, a drive arrives) before the
        next one starts. The world does not decide when a step closes: the messages go to
        the step loop (:mod:`pearl_sim.loop`), whose tracker rules decide. When the action
        produced no message, the loop lets time pass with :meth:`wait`.
        """
        start = self.time
        events: List[str] = []
        wrong: Optional[str] = None
        self._stuck = False
        self.metrics.steps += 1
        if action in self.clarifications:
            self.metrics.clarifications += 1
        if action in self.moves:
            moved = self._move(self.moves[action], action, events)
            if self._was_guide and not self._follower_started:
                wrong = "guided a resident who did not want to go" if not self._was_willing else None
            self._finish(action, wrong, events)
            return StepResult(action, start, self.time, moved, events, wrong)
        self._advance(SPEAK_SECONDS, events)
        resident = self.scenario.resident
        self._lapses(resident, events)
        listening = self.engaged and self._near()
        if listening and resident.hearing < 1.0 and action != "RingDoorBell" and self.rng.random() >= resident.hearing:
            listening = False          # she did not hear the sentence (a draw only for a hard-of-hearing resident)
            events.append(f"{resident.name} did not hear the robot")
        handler = getattr(self, f"_act_{action}", None)
        if handler is None:
            raise ValueError(f"the simulated world does not know action {action!r}")
        reply, wrong = handler(listening, events)
        if (reply is not None and listening and action != "RingDoorBell" and resident.responsiveness < 1.0
                and self.rng.random() >= resident.responsiveness):
            reply = None               # heard it but does not answer
        messages: List[Message] = []
        if reply is not None:
            self._advance(ANSWER_SECONDS, events)
            messages.append(self._say(reply))
        self._finish(action, wrong, events)
        return StepResult(action, start, self.time, messages, events, wrong)

    def wait(self, until: float) -> StepResult:
        """Let time pass with the robot idle, until the scheduler speaks or ``until`` (world seconds).

        The scheduler announces a due reminder only while the robot is idle (it does not
        talk over the robot); an announcement made during an action waits for this.
        Returns the (at most one) message heard, timestamped, and the events of the wait.
        """
        start = self.time
        events: List[str] = []
        # A robot stuck at a blocked corridor is not idle: the scheduler waits for it too.
        while (self._stuck or not self._scheduler_queue) and self.time < until - 1e-9:
            self._advance(min(1.0, until - self.time), events)
        messages: List[Message] = []
        if self._scheduler_queue and not self._stuck:
            queued = self._scheduler_queue.pop(0)
            messages.append(Message(self.time, queued.modality, queued.text, queued.said))
        return StepResult("", start, self.time, messages, events, None)

    def _lapses(self, resident, events: List[str]) -> None:
        """Memory and changing her mind (draws only when the resident has them)."""
        if resident.forgets > 0.0 and self.info_goal is not None and self.rng.random() < resident.forgets:
            events.append(f"{resident.name} forgets she wanted the {self.info_goal}")
            self.info_goal = None
        if (resident.changes_mind > 0.0 and self.wants_guidance and self._follower is None
                and self.resident_at == "room" and self.rng.random() < resident.changes_mind):
            events.append(f"{resident.name} changes her mind about the walk")
            self.wants_guidance = False

    # ------------------------------------------------------------ action effects
    def _act_DoNothing(self, listening, events):
        return self._spontaneous(listening), None

    def _act_RechargeBattery(self, listening, events):
        if self.robot_at == "home":
            self.battery = 1.0
            events.append("battery recharged")
        return self._spontaneous(listening), None

    def _act_RingDoorBell(self, listening, events):
        if self.engaged:
            return "yes", None   # rude (the domain charges -5) but not a wrong task action
        if self.in_session:
            return None, None    # she is with her therapist
        if self.robot_at == self.resident_at and self.rng.random() < self.scenario.resident.answers_door:
            self.engaged = True
            events.append(f"{self.scenario.resident.name} comes to the door")
            return "yes", None
        return None, None

    def _act_CheckUserPresent(self, listening, events):
        return ("yes" if listening else None), None

    def _remind(self, kind: str, listening: bool, events):
        if kind not in self.due:
            return ("chatter" if listening else None), f"reminded of {kind} with no such reminder due"
        if not listening:
            return None, None
        self.due.remove(kind)
        self._last_announce.pop(kind, None)
        self.metrics.reminders_delivered += 1
        events.append(f"{kind} reminder delivered")
        if kind == "physio":
            self._guidance_due_at = self.time
            if self.rng.random() < self.scenario.resident.willingness:
                self.wants_guidance = True
                self.metrics.walk_wishes += 1
                events.append(f"{self.scenario.resident.name} wants to be walked to physiotherapy")
                return "go" if self.rng.random() < 0.5 else "yes", None
            return "no", None
        return "yes", None

    def _act_RemindPhysioAppt(self, listening, events):
        return self._remind("physio", listening, events)

    def _act_RemindVitamin(self, listening, events):
        return self._remind("vitamin", listening, events)

    def _act_UpdateChecklist(self, listening, events):
        return self._remind("checklist", listening, events)

    def _act_TerminateGuidance(self, listening, events):
        if not self.wants_guidance:
            return ("chatter" if listening else None), "ended a guidance that was not happening"
        self.wants_guidance = False
        if self.resident_at != "physio":
            self._follower = None
            return ("no" if listening else None), "ended the guidance before the department"
        events.append("guidance ended at the physiotherapy department")
        return ("chatter" if listening else None), None

    def _tell(self, kind: str, listening: bool, events):
        if self.info_goal != kind:
            wrong = f"told the {kind} nobody asked for"
            return (self.info_goal if (listening and self.info_goal) else ("chatter" if listening else None)), wrong
        if not listening:
            return None, None
        self.info_goal = None
        self.metrics.questions_answered += 1
        events.append(f"{kind} question answered")
        return "chatter", None

    def _act_TellTime(self, listening, events):
        return self._tell("time", listening, events)

    def _act_TellWeather(self, listening, events):
        return self._tell("weather", listening, events)

    def _unprompted(self, about: str, has_goal: bool, events) -> None:
        if not has_goal:
            self.metrics.unprompted_questions += 1
            events.append(f"unprompted question: {about} (the resident has no such wish)")

    def _act_ConfirmGuideToPhysio(self, listening, events):
        self._unprompted("offered the walk to physiotherapy", self.wants_guidance, events)
        return (("yes" if self.wants_guidance else "no") if listening else None), None

    def _act_VerifyInfoRequest(self, listening, events):
        self._unprompted("asked what she would like to know", self.info_goal is not None, events)
        return ((self.info_goal or "no") if listening else None), None

    def _act_ConfirmWantTime(self, listening, events):
        self._unprompted("asked whether she wants the time", self.info_goal == "time", events)
        return (("yes" if self.info_goal == "time" else "no") if listening else None), None

    def _act_ConfirmWantWeather(self, listening, events):
        self._unprompted("asked whether she wants the weather", self.info_goal == "weather", events)
        return (("yes" if self.info_goal == "weather" else "no") if listening else None), None

    def _act_ConfirmGoHome(self, listening, events):
        return (("no" if self.wants_guidance else "yes") if listening else None), None

    def _act_ConfirmDone(self, listening, events):
        return ((self.info_goal or "yes") if listening else None), None

    def _spontaneous(self, listening: bool) -> Optional[str]:
        """What an attending resident says when the robot just waits."""
        if not listening:
            return None
        if self.info_goal:
            return self.info_goal
        if self.wants_guidance and self.resident_at == "room":
            return "go"
        return "chatter" if self.rng.random() < 0.2 else None

    # -------------------------------------------------------------------- moving
    def _move(self, goal: str, action: str, events: List[str]) -> List[Message]:
        """Drive to ``goal``: the messages the navigation produced (the landmark; ``userLost``
        first when the guide lost her; none when the corridor is blocked)."""
        origin = self.robot_at
        distance = self.scenario.distance(origin, goal)
        together = self.engaged and self._near() and self.resident_at == origin
        self._was_willing = self.wants_guidance
        self._follower_started = False
        # A guidance is the drive to the department, where the resident's appointment is.
        self._was_guide = goal == "physio"
        if self.scenario.is_blocked(origin, goal, self.time):
            self._drive_blocked(origin, goal, distance, together, events)
            return []
        messages: List[Message] = []
        if self._was_guide and together and self.wants_guidance and goal != origin:
            self._follower_started = True
            self.metrics.guidances_started += 1
            self._follower = {"pos": 0.0, "length": distance, "rest_until": -1.0, "origin": origin}
            self.resident_at = "corridor"
            events.append(f"guiding {self.scenario.resident.name} to physiotherapy")
            lost = self._drive_guided(distance, events)
            if lost is not None:
                messages.append(lost)
        else:
            if self.engaged and goal != origin:
                self.engaged = False
                if self.wants_guidance and self._was_guide:
                    events.append("the robot drives off without the resident")
            self._advance(distance / self.scenario.robot_speed, events, moving=True)
        self.robot_at = goal
        return messages + [Message(self.time, "Laser", LANDMARKS[goal])]

    def _drive_blocked(self, origin: str, goal: str, distance: float, together: bool,
                       events: List[str]) -> None:
        """The corridor from ``origin`` to ``goal`` is blocked: the robot drives up to the obstacle
        (half way) and stops there; nothing is reported. The step stays open until the
        manager's drive deadline; the robot counts as back at ``origin`` afterwards."""
        self.metrics.blocked_drives += 1
        events.append(f"the corridor from {origin} to {goal} is blocked: the robot stops at the obstacle")
        if self.engaged and not (together and self._was_guide and self.wants_guidance):
            self.engaged = False     # it drove off without her, as any drive does
        self._advance(0.5 * distance / self.scenario.robot_speed, events, moving=True)
        self._stuck = True
        return None

    def _drive_guided(self, distance: float, events: List[str]) -> Optional[Message]:
        """Drive ``distance`` metres with the resident following; returns the ``userLost`` message, if any.

        Fixed pace: cruise speed. Adaptive: every :data:`CONTROL_PERIOD` s the simulated people
        tracker gives her distance behind the robot (``None`` once she has given up and left)
        and the manager's :class:`~pearl_pomdp.guide_pace.GuidePace` turns the navigation's
        cruise speed into the speed driven — no pace logic of its own here.
        """
        from pearl_pomdp.guide_pace import GuidePace

        vmax = self.scenario.robot_speed
        guide = GuidePace(self.guide_pace_config) if self.pace_adaptation else None
        robot_pos, seconds, lost = 0.0, 0.0, None
        while robot_pos < distance - 1e-9 and seconds < 100_000:
            if guide is not None:
                speed = guide.step(CONTROL_PERIOD, robot_pos, self._people_tracker(robot_pos), nav_speed=vmax)
                if guide.became_lost:
                    # Reported once, as the guide_pace node does; the manager's next action ends
                    # the guidance filter, and the navigation drives on at its own speed.
                    lost = Message(self.time, "Laser", self.lost_symbol)
                    self.metrics.lost_reports += 1
                    events.append(f"guide_pace lost {self.scenario.resident.name}: {self.lost_symbol} reported")
                    guide = None
            else:
                speed = vmax
            robot_pos = min(distance, robot_pos + speed * CONTROL_PERIOD)
            self._advance(CONTROL_PERIOD, events, moving=True, robot_pos=robot_pos)
            seconds += CONTROL_PERIOD
        if seconds > 0:
            self.metrics.guide_speeds.append(distance / seconds)
        # An adaptive guide waits at the door until she is in; a fixed-pace robot reports arrival at once.
        while self.pace_adaptation and lost is None and self._follower is not None and seconds < 100_000:
            self._advance(1.0, events, moving=False, robot_pos=distance)
            seconds += 1
        return lost

    def _people_tracker(self, robot_pos: float) -> Optional[float]:
        """What a people tracker on the robot reports: her distance behind it (m), ``None`` when
        she is not following any more."""
        if self._follower is None:
            return None
        return max(0.0, robot_pos - self._follower["pos"])

    def _walk_follower(self, dt: float, robot_pos: Optional[float], events: List[str]) -> None:
        f = self._follower
        assert f is not None  # called only while a resident follows
        resident = self.scenario.resident
        if robot_pos is None:       # robot waiting at the destination
            robot_pos = f["length"]
        if self.time < f["rest_until"]:
            return
        if resident.rest_probability and self.rng.random() < resident.rest_probability * dt:
            f["rest_until"] = self.time + resident.rest_seconds
            return
        f["pos"] = min(robot_pos, f["pos"] + resident.walking_speed * dt, f["length"])
        if robot_pos - f["pos"] > resident.lose_distance:
            self._follower = None
            self.engaged = False
            self.resident_at = "corridor"
            self._return_at = self.time + f["pos"] / resident.walking_speed
            self.metrics.residents_lost += 1
            events.append(f"{resident.name} falls {robot_pos - f['pos']:.0f} m behind, loses the robot and walks back")
            return
        if f["pos"] >= f["length"] - 1e-9:
            self._follower = None
            self.resident_at = "physio"
            self.metrics.guidances_completed += 1
            if self._guidance_due_at is not None:
                self.metrics.time_to_goal.append(self.time - self._guidance_due_at)
            events.append(f"{resident.name} arrives at physiotherapy")
            for q in self._physio_questions:
                self.info_goal = q.ask
                self.metrics.questions_raised += 1
                events.append(f"{resident.name} wants to know the {self.info_goal}")
            self._physio_questions = []

    def _near(self) -> bool:
        if self._follower is not None:
            return False
        return self.resident_at == self.robot_at

    # ---------------------------------------------------------------- time flow
    def _advance(self, seconds: float, events: List[str], moving: bool = False, robot_pos: Optional[float] = None) -> None:
        """Let ``seconds`` pass: walkers walk, reminders fall due, questions arise, the battery drains."""
        end = self.time + seconds
        while True:
            dt = min(1.0, end - self.time)
            if dt <= 1e-12:
                break
            self.time += dt
            self._power(dt, moving, events)
            if self._follower is not None:
                self._walk_follower(dt, robot_pos, events)
            if self._return_at is not None and self.time >= self._return_at:
                self.resident_at, self._return_at = "room", None
                events.append(f"{self.scenario.resident.name} is back in her room")
            self._live(dt, moving, events)
        self._raise_due(events)

    def _power(self, dt: float, moving: bool, events: List[str]) -> None:
        """The battery over ``dt`` seconds: an episode drains it while driving only (``battery_seconds``)."""
        if moving:
            self.battery = max(0.0, self.battery - dt / self.scenario.battery_seconds)

    def _live(self, dt: float, moving: bool, events: List[str]) -> None:
        """What else happens in each second: her physiotherapy session (the working day adds her
        routine: :class:`pearl_sim.nursing_home.day.DayWorld`)."""
        self._physiotherapy(events)

    def _physiotherapy(self, events: List[str]) -> None:
        """The session at the department (see :data:`SESSION_SECONDS`): it starts at the appointment or
        :data:`SETTLE_SECONDS` after her arrival, whichever is later, and ends with her walk back."""
        if self._session_done or self.appointment_at is None:
            return
        name = self.scenario.resident.name
        if self.resident_at == "physio" and self._arrived_at is None:
            self._arrived_at = self.time
            self._session_at = max(self.appointment_at, self.time + SETTLE_SECONDS)
        if not self.in_session and self._session_at is not None and self.time >= self._session_at:
            self.in_session, self.engaged = True, False
            self._lapse_reminder("physio", events)
            if self.info_goal is not None:
                events.append(f"{name}'s question goes unanswered: her session starts")
                self._question_lapses()
            events.append(f"{name}'s physiotherapy session starts")
        if self.in_session and self._session_at is not None and self.time >= self._session_at + SESSION_SECONDS:
            self.in_session, self._session_done = False, True
            self.wants_guidance = False
            self.resident_at = "corridor"
            self._return_at = self.time + self.scenario.distance("physio", "room") / self.scenario.resident.walking_speed
            events.append(f"{name}'s session ends; she walks back to her room")

    def _lapse_reminder(self, kind: str, events: List[str]) -> None:
        """A reminder no longer worth delivering (she is at her appointment): it stays missed."""
        if kind in self.due:
            self.due.remove(kind)
            self._last_announce.pop(kind, None)
            events.append(f"{kind} reminder lapsed undelivered")

    def _question_lapses(self) -> None:
        """Her question is gone unanswered (she went into her session)."""
        self.info_goal = None

    def _raise_due(self, events: List[str]) -> None:
        while self._appointments and self._appointments[0].at <= self.time:
            kind = self._appointments.pop(0).kind
            if kind not in self.due:
                self.due.append(kind)
                self.metrics.reminders_due += 1
                events.append(f"{kind} reminder falls due")
        for kind in self.due:
            last = self._last_announce.get(kind)
            if last is None or self.time - last >= REANNOUNCE_SECONDS:
                self._last_announce[kind] = self.time
                self._scheduler_queue.append(Message(self.time, "Reminder", f"g_{kind}"))
        # A question falling due while she is in her session waits until it ends.
        while self._questions and self._questions[0].at <= self.time and not self.in_session:
            self.info_goal = self._questions.pop(0).ask
            self.metrics.questions_raised += 1
            events.append(f"{self.scenario.resident.name} wants to know the {self.info_goal}")

    def _say(self, intent: str) -> Message:
        options = UTTERANCES[intent]
        said = options[self.rng.integers(len(options))]
        if intent in TOUCH and self.rng.random() < self.scenario.resident.touchscreen:
            return Message(self.time, "Touchscreen", TOUCH[intent], said=f"(touches '{TOUCH[intent]}')", meant=intent)
        if self.speech_channel is not None:
            from pearl_pomdp.speech import speech_message

            heard = self.speech_channel.hear(intent, said, self.scenario.resident.voice, self.speech_rng)
            text = heard.text if heard.confidence >= 1.0 else speech_message(heard.text, heard.confidence)
            return Message(self.time, "Speech", text, said=said, meant=intent)
        return Message(self.time, "Speech", self.asr.recognise(said), said=said, meant=intent)

    def _finish(self, action: str, wrong: Optional[str], events: List[str]) -> None:
        if wrong:
            self.metrics.wrong_actions += 1
            self.metrics.wrong.append(f"{action}: {wrong}")
            events.append(f"wrong action: {wrong}")
