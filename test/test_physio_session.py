"""Her physiotherapy session in the episode world (pearl_sim/nursing_home/world.py; docs/day.md, Part 1
and protocol 4): the appointment falls 15 minutes after its reminder, the session starts then or two
minutes after she arrives, lasts 45 minutes, and during it she neither hears nor needs the robot."""
import dataclasses
from pathlib import Path

from pearl_sim.nursing_home.scenario import Question, load_scenarios
from pearl_sim.nursing_home.world import REMINDER_LEAD, SESSION_SECONDS, SETTLE_SECONDS, World

REPO = Path(__file__).resolve().parents[1]
FIGURE4 = REPO / "config" / "scenarios" / "figure4.yaml"


def _figure4(**changes):
    scenario = load_scenarios(FIGURE4)[0]
    resident = dataclasses.replace(scenario.resident, touchscreen=0.0, rest_probability=0.0, walking_speed=0.5)
    return dataclasses.replace(scenario, resident=resident, word_error_rate=0.0, **changes)


def _until(w, t):
    while w.time < t - 1e-9:
        w.wait(t)


def _walk_her_to_physio(w):
    for action in ("GotoPatientRoom", "RingDoorBell", "RemindPhysioAppt", "GuideToPhysio"):
        w.act(action)
    assert w.resident_at == "physio" and w.robot_at == "physio" and w.engaged


def test_the_appointment_is_fifteen_minutes_after_its_reminder():
    w = World(_figure4())
    assert w.appointment_at == 5 + REMINDER_LEAD == 905.0


def test_she_goes_into_her_session_at_the_appointment_and_no_longer_hears_the_robot():
    w = World(_figure4(), seed=4)
    _walk_her_to_physio(w)
    arrived = w.time
    assert arrived + SETTLE_SECONDS < w.appointment_at       # she walks 30 m at 0.5 m/s: early
    _until(w, w.appointment_at - 2)
    assert not w.in_session and w.truth()["UserPresent"] == "yes"
    _until(w, w.appointment_at + 2)
    assert w.in_session and w.truth()["UserPresent"] == "no" and w.truth()["UserLocation"] == "physio"
    # Neither a question nor the doorbell reaches her: no answer, and the doorbell does not fetch her.
    assert w.act("CheckUserPresent").messages == []
    assert w.act("RingDoorBell").messages == [] and not w.engaged


def test_her_session_ends_after_45_minutes_and_she_walks_back_to_her_room():
    w = World(_figure4(), seed=4)
    _walk_her_to_physio(w)
    _until(w, w.appointment_at + SESSION_SECONDS + 1)
    assert not w.in_session and w.resident_at == "corridor"
    _until(w, w.appointment_at + SESSION_SECONDS + 30 / 0.5 + 2)
    assert w.resident_at == "room"


def test_a_late_arrival_still_gets_two_minutes_before_her_session():
    # The appointment 15 min after a reminder at 5 s; she walks at 0.03 m/s: 1,000 s for the 30 m.
    scenario = _figure4()
    scenario = dataclasses.replace(scenario, resident=dataclasses.replace(scenario.resident, walking_speed=0.03))
    w = World(scenario, seed=4, pace_adaptation=True)
    _walk_her_to_physio(w)
    arrived = w.time
    assert arrived > w.appointment_at
    _until(w, arrived + SETTLE_SECONDS - 2)
    assert not w.in_session
    _until(w, arrived + SETTLE_SECONDS + 2)
    assert w.in_session


def test_her_unanswered_question_lapses_when_her_session_starts():
    w = World(_figure4(), seed=4)
    _walk_her_to_physio(w)
    assert w.info_goal == "weather"                         # Figure 4(e): she asks on arrival
    _until(w, w.appointment_at + 2)
    assert w.info_goal is None and w.truth()["UserInfoGoal"] == "none"
    assert w.metrics.questions_answered == 0 and w.metrics.questions_raised == 1


def test_a_question_falling_due_in_her_session_waits_until_it_ends():
    w = World(_figure4(questions=[Question(ask="time", at=1000.0)]), seed=4)
    _walk_her_to_physio(w)
    _until(w, 1100)
    assert w.in_session and w.info_goal is None and w.metrics.questions_raised == 0
    _until(w, w.appointment_at + SESSION_SECONDS + 2)
    assert w.info_goal == "time" and w.metrics.questions_raised == 1


def test_an_episode_without_a_physio_appointment_has_no_session():
    w = World(_figure4(appointments=[]), seed=4)
    assert w.appointment_at is None
    _until(w, 4000)
    assert not w.in_session


def test_until_pearl_leaves_waits_for_her_scheduled_questions_then_for_the_robot_at_home():
    from pearl_sim.nursing_home.world import until_pearl_leaves

    w = World(_figure4(appointments=[], questions=[Question(ask="time", at=300.0)]), seed=4)
    left = until_pearl_leaves(w)
    assert not left()                                   # never been out
    w.act("GotoPatientRoom")
    assert not left()
    w.act("GoHome")
    assert w.robot_at == "home" and not left()          # home, but her question is still to come
    _until(w, 310)
    assert w.info_goal == "time" and not left()         # she wants the time: nothing is over
    w.info_goal = None                                  # (answered by someone)
    assert left()


def test_until_pearl_leaves_ends_at_its_time_limit_wherever_the_robot_is():
    from pearl_sim.nursing_home.world import until_pearl_leaves

    w = World(_figure4(), seed=4)
    left = until_pearl_leaves(w, limit=100.0)
    w.act("GotoPatientRoom")
    assert not left()
    _until(w, 101)
    assert w.robot_at == "room" and left()
