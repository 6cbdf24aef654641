"""Pearl's working day: the nursing-home world from 08:00 to 20:00 (docs/day.md, Part 1).

:class:`DayWorld` is the episode world (:class:`~pearl_sim.nursing_home.world.World`) given a *later*:
the resident's routine (meals in the dining room, a nap, the lounge, a visitor), the physiotherapy
appointment **and the session itself** (45 minutes with the therapist, during which she neither
hears nor needs the robot, then her walk back), the day's reminders from a schedule, questions that
arise at a rate while she is awake in her room, and the robot's battery over hours (a TurtleBot 4's
published figures: 4 h idle, 2 h 30 min driving, 2 h 30 min to charge on its dock). Every number is
a module constant below, each from docs/day.md, where its source is given; the specification was
committed before any policy ran on a day.

The world still speaks the Pearl domain's terms (Table 3 + Battery): a resident at a meal is, in
the model's coarse ``UserLocation``, not at the department (``room``), and a ring at her empty room
goes unanswered — what the model learns of her day it learns from the data (``pearl fit``).

It computes the nurse's checklist (:meth:`DayWorld.checklist`) and the day score (:func:`day_score`)
with the weights the protocol fixed.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Dict, List, Optional, Tuple

import numpy as np

from pearl_sim.messages import Message, StepResult
from pearl_sim.nursing_home.world import (LOW_BATTERY, REMINDER_LEAD, SESSION_SECONDS, SETTLE_SECONDS,  # noqa: F401 (the day's too)
                                          SPEAK_SECONDS, Metrics, World)

__all__ = ["DAY_SECONDS", "DayPlan", "DayMetrics", "DayWorld", "plan_day", "day_scenario", "day_score",
           "SCORE_WEIGHTS", "clock"]

#: The day: 08:00 (world time 0) to 20:00.
DAY_START = 8 * 3600
DAY_SECONDS = 12 * 3600
#: Battery (TurtleBot 4: 4 h idle, 2 h 30 min driving, 2 h 30 min to charge), as fractions a second.
IDLE_DRAIN = 1.0 / (4 * 3600)
DRIVE_DRAIN = 1.0 / (2.5 * 3600)
CHARGE_RATE = 1.0 / (2.5 * 3600)
#: The battery driver publishes its percentage this often (s), when the domain reads it (protocol 3).
BATTERY_PERIOD = 30.0
#: The message type of a battery driver's reading.
BATTERY_TYPE = "sensor_msgs/msg/BatteryState"
#: A reminder delivered within this many seconds of falling due is on time.
ON_TIME_SECONDS = 600.0
#: Questions arise at 0.5 an hour while she is awake in her room, are kept 30 min unvoiced.
QUESTION_RATE = 0.5 / 3600
QUESTION_KEEP_SECONDS = 1800.0
#: What surrounds the physiotherapy session (the session itself: the episode world's SESSION_SECONDS …).
STAFF_TAKE_AFTER = 600.0         # not at the department 10 min after her appointment: the staff take her
ARRIVAL_QUESTION = 0.5           # half of the paper's guidances were followed by a question
#: The appointment slots (morning list after breakfast, afternoon list after the activity hour).
APPOINTMENT_SLOTS = (10 * 3600, 10.5 * 3600, 11 * 3600, 16.5 * 3600)
#: Windows (clock seconds) the vitamin and checklist reminders fall due in: the vitamin after breakfast
#: on a day with an afternoon appointment, with the afternoon medication round on a day with a morning
#: one (her morning is then the session's).
VITAMIN_WINDOW = (9.75 * 3600, 10.25 * 3600)
VITAMIN_WINDOW_AFTERNOON = (16.25 * 3600, 16.75 * 3600)
CHECKLIST_WINDOW = (18.25 * 3600, 18.75 * 3600)
#: Her fixed points: (start, end, activity), clock seconds; each moves by ±JITTER a day.
ROUTINE: Tuple[Tuple[float, float, str], ...] = (
    (8 * 3600, 9.5 * 3600, "breakfast"),
    (12 * 3600, 13.5 * 3600, "lunch"),
    (13.5 * 3600, 15 * 3600, "nap"),
    (15 * 3600, 16 * 3600, "lounge"),
    (17 * 3600, 18 * 3600, "supper"),
    (18 * 3600, 19 * 3600, "visit"),
)
JITTER = 600.0
LOUNGE_PROBABILITY = 0.5
VISIT_PROBABILITY = 0.3
#: Where each activity takes her: away from her room (the robot cannot reach her) or in it.
AWAY = {"breakfast": "dining", "lunch": "dining", "supper": "dining", "lounge": "lounge"}

#: The day score's weights (docs/day.md, fixed before any run).
SCORE_WEIGHTS = {"reminders_on_time": 30.0, "walks": 25.0, "questions": 15.0, "station": 10.0,
                 "docked_at_end": 10.0, "battery": 10.0, "unprompted_per_hour": -2.0, "wrong_actions": -2.0}


def clock(t: float) -> str:
    """World seconds as the day's clock time, ``HH:MM``."""
    minutes = int((DAY_START + t) // 60)
    return f"{minutes // 60:02d}:{minutes % 60:02d}"


@dataclass(frozen=True)
class DayPlan:
    """One day's draws (world seconds from 08:00): her fixed points, the appointment, the reminders."""

    seed: int
    activities: Tuple[Tuple[float, float, str], ...]
    appointment: float
    vitamin_due: float
    checklist_due: float
    arrival_question: Optional[str]

    @property
    def physio_due(self) -> float:
        """When the physio reminder falls due."""
        return self.appointment - REMINDER_LEAD

    def activity(self, t: float) -> Optional[str]:
        """Her fixed point at world time ``t`` (``None``: free, in her room)."""
        for start, end, name in self.activities:
            if start <= t < end:
                return name
        return None


def plan_day(seed: int) -> DayPlan:
    """The day's draws for ``seed``, from their own random stream (the world's stays its own)."""
    rng = np.random.default_rng([int(seed), 20261206])
    activities = []
    for start, end, name in ROUTINE:
        shift = float(rng.uniform(-JITTER, JITTER))
        take = True
        if name == "lounge":
            take = bool(rng.random() < LOUNGE_PROBABILITY)
        elif name == "visit":
            take = bool(rng.random() < VISIT_PROBABILITY)
        if take:
            activities.append((start + shift - DAY_START, end + shift - DAY_START, name))
    # No two fixed points overlap: a later one starts when the earlier ends.
    activities.sort()
    for i in range(1, len(activities)):
        prev_end = activities[i - 1][1]
        start, end, name = activities[i]
        if start < prev_end:
            activities[i] = (prev_end, max(end, prev_end), name)
    appointment = float(APPOINTMENT_SLOTS[int(rng.integers(len(APPOINTMENT_SLOTS)))]) - DAY_START
    morning = appointment + DAY_START < 12 * 3600
    vitamin = float(rng.uniform(*(VITAMIN_WINDOW_AFTERNOON if morning else VITAMIN_WINDOW))) - DAY_START
    checklist = float(rng.uniform(*CHECKLIST_WINDOW)) - DAY_START
    question = str(rng.choice(["time", "weather"])) if rng.random() < ARRIVAL_QUESTION else None
    return DayPlan(int(seed), tuple(activities), appointment, vitamin, checklist, question)


def day_scenario(resident: Optional[dict] = None, word_error_rate: float = 0.25, seed: int = 0,
                 name: str = "day", plan: Optional[DayPlan] = None, speech: Optional[dict] = None):
    """The episode-world scenario of one day: the shipped map, robot and timeout, her profile
    (``resident:`` fields), the recogniser's word error rate and the plan's three reminders.
    ``speech``: a scenario ``speech:`` mapping instead (e.g. the measured recogniser channel at an
    SNR, docs/speech.md), which ``word_error_rate`` then does not enter."""
    from pearl_sim.nursing_home.scenario import _build

    plan = plan if plan is not None else plan_day(seed)
    reminders = sorted([(plan.vitamin_due, "vitamin"), (plan.physio_due, "physio"), (plan.checklist_due, "checklist")])
    data: Dict[str, object] = {
        "name": name, "seed": int(seed), "step_timeout": 8.0, "max_steps": 100_000,
        "map": {"home": [0, 0], "room": [15, 0], "physio": [15, 30]},
        "robot": {"speed": 0.6, "pace_adaptation": True},
        "speech": dict(speech) if speech else {"word_error_rate": float(word_error_rate)},
        "resident": dict(resident or {"name": "Mrs B"}),
        "appointments": [{"at": at, "kind": kind} for at, kind in reminders],
        "questions": ([{"ask": plan.arrival_question, "when": "at_physio"}] if plan.arrival_question else []),
    }
    return _build(data, f"<day {name}>", "")


@dataclass
class DayMetrics(Metrics):
    """The episode scores plus what the day's checklist needs."""

    reminders_on_time: int = 0
    reminder_delay_s: List[float] = field(default_factory=list)
    answer_delay_s: List[float] = field(default_factory=list)
    doorbells_where_she_is_not: int = 0
    battery_low_s: float = 0.0
    battery_empty: bool = False
    nothing_wanted_s: float = 0.0
    at_station_s: float = 0.0
    metres_driven: float = 0.0
    staff_walks: int = 0


class DayWorld(World):
    """The nursing home for a whole day (see the module doc).

    Args:
        scenario: the day's scenario (:func:`day_scenario`).
        plan: the day's draws (:func:`plan_day`); default: drawn from the scenario's seed.
        seed, domain: as for :class:`~pearl_sim.nursing_home.world.World`.
    """

    def __init__(self, scenario, plan: Optional[DayPlan] = None, seed: Optional[int] = None, domain=None):
        self.plan = plan if plan is not None else plan_day(scenario.seed if seed is None else seed)
        self.docked = True              # the day starts on the charger, full
        self.dead = False
        self.activity: Optional[str] = None
        self._latent: Optional[Tuple[str, float]] = None
        self._voiced_at: Optional[float] = None
        self._due_at: Dict[str, float] = {}
        from pearl_sim.nursing_home.scenario import default_domain

        speaks = domain if domain is not None else default_domain()     # the terms the world speaks
        battery = next((f for f in speaks.features if f.name == "Battery"), None)
        #: The domain tells a robot on its dock from a charged one off it (the day domain's Battery):
        #: the truth then says ``docked`` whenever it charges at home.
        self._reports_dock = battery is not None and "docked" in battery.values
        #: The modality of the domain's battery reading (a ``number`` input of a BatteryState), if any:
        #: the world then publishes the driver's percentage every BATTERY_PERIOD s (docs/day.md,
        #: protocol 3); a domain without one sees the world protocol 2 saw.
        self._battery_modality = next((ch.modality for ch in speaks.inputs
                                       if ch.kind == "number" and ch.type == BATTERY_TYPE), None)
        self._next_reading = 0.0        # the driver's first reading comes at once
        super().__init__(scenario, seed=seed, domain=domain)
        self.appointment_at = self.plan.appointment
        self.metrics: DayMetrics = DayMetrics()
        self._question_rng = np.random.default_rng([self.seed, 3])
        self._apply_routine([])

    # ------------------------------------------------------------------ queries
    @property
    def done(self) -> bool:
        """True at 20:00."""
        return self.time >= DAY_SECONDS - 1e-9

    def resident_state(self) -> str:
        """Where she is and what she does, for the day's timeline."""
        if self.in_session:
            return "therapy"
        if self._follower is not None:
            return "walking with the robot"
        if self.resident_at == "corridor":
            return "corridor"
        if self.activity in AWAY:
            return self.activity
        if self.activity == "nap":
            return "asleep"
        return "room" if self.resident_at == "room" else self.resident_at

    def truth(self) -> Dict[str, str]:
        """The episode world's truth, with two things only a day has: ``Battery=docked`` while it charges
        on its dock at home (when the domain has that value), and her question as ``UserInfoGoal`` from
        the moment she has it in mind — Table 3's feature is what she wants to know, said or not yet
        said (she says it when the robot is with her and waits or asks)."""
        state = super().truth()
        if self._reports_dock and self.docked and self.robot_at == "home":
            state["Battery"] = "docked"
        if state["UserInfoGoal"] == "none" and self._latent is not None:
            state["UserInfoGoal"] = {"time": "wantTime", "weather": "wantWeather"}[self._latent[0]]
        return state

    # ------------------------------------------------------------------ acting
    def act(self, action: str) -> StepResult:
        """As the episode world; a robot whose battery is empty does nothing anyone notices."""
        if not self.dead:
            return super().act(action)
        start = self.time
        events: List[str] = []
        self.metrics.steps += 1
        self._stuck = action in self.moves       # a drive never arrives: the deadline closes it
        if not self._stuck:
            self._advance(SPEAK_SECONDS, events)
        return StepResult(action, start, self.time, [], events, None)

    def _act_RechargeBattery(self, listening, events):
        if self.robot_at == "home" and not self.docked:
            self.docked = True
            events.append("docked: charging")
        return self._spontaneous(listening), None

    def _act_RingDoorBell(self, listening, events):
        unreachable = self.activity == "nap" or self.in_session or self.resident_at != self.robot_at
        if unreachable and not self.engaged:
            self.metrics.doorbells_where_she_is_not += 1
            events.append("rang where she is not (away, asleep or in therapy)")
            return None, None
        return super()._act_RingDoorBell(listening, events)

    def _remind(self, kind, listening, events):
        delivered = self.metrics.reminders_delivered
        reply = super()._remind(kind, listening, events)
        if self.metrics.reminders_delivered > delivered and kind in self._due_at:
            delay = self.time - self._due_at.pop(kind)
            self.metrics.reminder_delay_s.append(delay)
            self.metrics.reminders_on_time += int(delay <= ON_TIME_SECONDS)
        return reply

    def _tell(self, kind, listening, events):
        answered = self.metrics.questions_answered
        reply = super()._tell(kind, listening, events)
        if self.metrics.questions_answered > answered and self._voiced_at is not None:
            self.metrics.answer_delay_s.append(self.time - self._voiced_at)
            self._voiced_at = None
        return reply

    def _move(self, goal, action, events):
        if self.docked:
            events.append("undocked")
        self.docked = False
        origin = self.robot_at
        before = self.metrics.blocked_drives
        messages = super()._move(goal, action, events)
        distance = self.scenario.distance(origin, goal)
        self.metrics.metres_driven += 0.5 * distance if self.metrics.blocked_drives > before else distance
        return messages

    def _spontaneous(self, listening):
        # A resident with a visitor talks with her visitor, not the robot.
        if self.activity == "visit" and not self.info_goal:
            return None
        return super()._spontaneous(listening)

    # ---------------------------------------------------------------- time flow
    def _power(self, dt, moving, events):
        if self.dead:
            return
        if moving:
            self.battery -= dt * DRIVE_DRAIN
        elif self.docked and self.robot_at == "home":
            self.battery = min(1.0, self.battery + dt * CHARGE_RATE)
        else:
            self.battery -= dt * IDLE_DRAIN
        if self.battery <= 0.0:
            self.battery, self.dead = 0.0, True
            self.metrics.battery_empty = True
            events.append("the battery is empty: the robot stops")

    def _live(self, dt, moving, events):
        self._read_battery()
        self._apply_routine(events)
        self._physiotherapy(events)
        self._questions_arise(dt, events)
        m = self.metrics
        if self.battery < LOW_BATTERY:
            m.battery_low_s += dt
        if not self.due and not self.wants_guidance and self.info_goal is None:
            m.nothing_wanted_s += dt
            if self.robot_at == "home" and not moving:
                m.at_station_s += dt

    def _read_battery(self) -> None:
        """The battery driver's reading, queued like the scheduler's announcements (heard when the
        robot is not mid-action); the tracker observes a change of bin only."""
        if self._battery_modality is not None and self.time >= self._next_reading - 1e-9:
            self._next_reading = self.time + BATTERY_PERIOD
            self._scheduler_queue.append(Message(self.time, self._battery_modality, f"{self.battery:.4f}"))

    def _raise_due(self, events):
        before = set(self.due)
        super()._raise_due(events)
        for kind in self.due:
            if kind not in before:
                self._due_at.setdefault(kind, self.time)

    def _free(self) -> bool:
        """She is not in someone's hands (walking with the robot, in therapy, on her way back)."""
        return (self._follower is None and not self.in_session and self._return_at is None
                and self.resident_at != "physio" and self.resident_at != "corridor")

    def _apply_routine(self, events: List[str]) -> None:
        activity = self.plan.activity(self.time)
        if activity == self.activity or not self._free():
            return
        name = self.scenario.resident.name
        self.activity = activity
        place = AWAY.get(activity or "", "room")
        if place != self.resident_at:
            if self.engaged:
                self.engaged = False
            events.append(f"{name} goes to the {place}" if place != "room"
                          else f"{name} is back in her room")
            self.resident_at = place
        elif activity == "nap":
            self.engaged = False
            events.append(f"{name} naps")
        elif activity == "visit":
            events.append(f"a visitor comes to see {name}")

    def _physiotherapy(self, events: List[str]) -> None:
        """The episode world's session, and the staff: not at the department
        :data:`STAFF_TAKE_AFTER` after her appointment, she is taken there (not by the robot)."""
        if (not self._session_done and self._arrived_at is None
                and self.time >= self.plan.appointment + STAFF_TAKE_AFTER
                and self._follower is None and self.resident_at != "physio"):
            self.resident_at, self.engaged = "physio", False
            self.metrics.staff_walks += 1
            self.wants_guidance = False
            self._lapse_reminder("physio", events)
            self._physio_questions = []          # she asks the staff, not the robot
            self.activity = None
            events.append(f"the staff take {self.scenario.resident.name} to physiotherapy")
        super()._physiotherapy(events)

    def _lapse_reminder(self, kind: str, events: List[str]) -> None:
        if kind in self.due:
            self._due_at.pop(kind, None)
        super()._lapse_reminder(kind, events)

    def _question_lapses(self) -> None:
        super()._question_lapses()
        self._voiced_at = None

    def _questions_arise(self, dt: float, events: List[str]) -> None:
        name = self.scenario.resident.name
        awake_in_room = (self.resident_at == "room" and self._free() and self.activity not in ("nap", "visit"))
        if self.info_goal is not None and self._voiced_at is None:
            self._voiced_at = self.time          # the arrival question (the episode world raised it)
        if self._latent is not None and self.time - self._latent[1] > QUESTION_KEEP_SECONDS:
            self._latent = None                  # she asked a nurse, or forgot
        if awake_in_room and self._latent is None and self.info_goal is None:
            if self._question_rng.random() < QUESTION_RATE * dt:
                self._latent = (str(self._question_rng.choice(["time", "weather"])), self.time)
        if self._latent is not None and self.info_goal is None and self.engaged and self._near():
            self.info_goal, self._voiced_at = self._latent[0], self.time
            self._latent = None
            self.metrics.questions_raised += 1
            events.append(f"{name} wants to know the {self.info_goal}")

    # ---------------------------------------------------------------- scores
    def checklist(self) -> Dict[str, object]:
        """The nurse's checklist for the day so far (docs/day.md, *What the world counts*)."""
        m = self.metrics
        hours = max(self.time, 1.0) / 3600.0
        unprompted = m.unprompted_questions + m.doorbells_where_she_is_not
        return {
            "reminders_due": m.reminders_due, "reminders_delivered": m.reminders_delivered,
            "reminders_on_time": m.reminders_on_time, "reminder_delay_s": [round(d, 1) for d in m.reminder_delay_s],
            "walks_wanted": m.walk_wishes, "walks_completed": m.guidances_completed,
            "walk_s": [round(d, 1) for d in m.time_to_goal], "staff_walks": m.staff_walks,
            "questions_raised": m.questions_raised, "questions_answered": m.questions_answered,
            "answer_delay_s": [round(d, 1) for d in m.answer_delay_s],
            "unprompted": unprompted, "unprompted_per_hour": round(unprompted / hours, 4),
            "wrong_actions": m.wrong_actions, "clarifications": m.clarifications,
            "battery_low_s": round(m.battery_low_s, 1), "battery_empty": m.battery_empty,
            "battery_at_end": round(self.battery, 4), "docked_at_end": bool(self.docked and self.robot_at == "home"),
            "station_share": round(m.at_station_s / m.nothing_wanted_s, 4) if m.nothing_wanted_s > 0 else 1.0,
            "metres_driven": round(m.metres_driven, 1), "steps": m.steps, "hours": round(hours, 3),
        }


def day_score(checklist: Dict[str, object]) -> float:
    """The day score (docs/day.md): 100 for a perfect day, with the protocol's weights."""
    def share(part: str, whole: str) -> float:
        total = float(checklist[whole])  # type: ignore[arg-type]
        return float(checklist[part]) / total if total > 0 else 1.0  # type: ignore[arg-type]

    w = SCORE_WEIGHTS
    battery = 0.0 if checklist["battery_empty"] else 1.0 - min(1.0, float(checklist["battery_low_s"]) / 3600.0)  # type: ignore[arg-type]
    score = (w["reminders_on_time"] * share("reminders_on_time", "reminders_due")
             + w["walks"] * min(1.0, share("walks_completed", "walks_wanted"))
             + w["questions"] * share("questions_answered", "questions_raised")
             + w["station"] * float(checklist["station_share"])  # type: ignore[arg-type]
             + w["docked_at_end"] * float(bool(checklist["docked_at_end"]))
             + w["battery"] * battery
             + w["unprompted_per_hour"] * float(checklist["unprompted_per_hour"])  # type: ignore[arg-type]
             + w["wrong_actions"] * float(checklist["wrong_actions"]))  # type: ignore[arg-type]
    return round(score, 4)
