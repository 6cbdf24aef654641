"""The working day (pearl_sim/nursing_home/day.py, docs/day.md Part 1): her routine, the session,
the battery over hours, the questions she voices, the checklist and the day score."""
from pathlib import Path

import pytest

from pearl_sim.nursing_home.day import (APPOINTMENT_SLOTS, CHARGE_RATE, CHECKLIST_WINDOW, DAY_SECONDS, DAY_START,
                                        DRIVE_DRAIN, IDLE_DRAIN, SCORE_WEIGHTS, SESSION_SECONDS, SETTLE_SECONDS,
                                        STAFF_TAKE_AFTER, VITAMIN_WINDOW, VITAMIN_WINDOW_AFTERNOON, DayPlan, DayWorld, clock, day_scenario,
                                        day_score, plan_day)

REPO = Path(__file__).resolve().parents[1]


def _world(seed=0, plan=None, **resident):
    fields = {"name": "Mrs B", "walking_speed": 0.5, "willingness": 1.0, "answers_door": 1.0, "touchscreen": 0.0}
    fields.update(resident)
    plan = plan if plan is not None else plan_day(seed)
    return DayWorld(day_scenario(fields, 0.0, seed, plan=plan), plan)


def _until(w, t):
    """Let the world run to ``t`` (``wait`` returns at each scheduler announcement)."""
    while w.time < t - 1e-9:
        w.wait(t)


def _plan(activities=(), appointment=2 * 3600.0, question=None):
    """A hand-made day: ``appointment`` in world seconds, reminders well away from it."""
    return DayPlan(seed=0, activities=tuple(activities), appointment=appointment, vitamin_due=10 * 3600.0,
                   checklist_due=11 * 3600.0, arrival_question=question)


@pytest.mark.parametrize("seed", range(40))
def test_plan_day_keeps_the_specified_windows_and_never_overlaps(seed):
    plan = plan_day(seed)
    assert plan == plan_day(seed)                                  # the seed decides the day
    assert plan.appointment + DAY_START in APPOINTMENT_SLOTS
    window = VITAMIN_WINDOW_AFTERNOON if plan.appointment + DAY_START < 12 * 3600 else VITAMIN_WINDOW
    assert window[0] <= plan.vitamin_due + DAY_START <= window[1]
    assert CHECKLIST_WINDOW[0] <= plan.checklist_due + DAY_START <= CHECKLIST_WINDOW[1]
    names = [a[2] for a in plan.activities]
    assert {"breakfast", "lunch", "nap", "supper"} <= set(names)
    for (s0, e0, _), (s1, e1, _) in zip(plan.activities, plan.activities[1:]):
        assert s0 <= e0 <= s1 <= e1
    # Every reminder falls due when she is free in her room (the schedule is a care plan's): not at a
    # fixed point, and the others not in her session or on the slowest walker's way back from it.
    for due in (plan.vitamin_due, plan.physio_due, plan.checklist_due):
        assert plan.activity(due) in (None, "visit"), (clock(due), plan.activity(due))
    back = plan.appointment + SESSION_SECONDS + 30 / 0.05
    for due in (plan.vitamin_due, plan.checklist_due):
        assert not plan.physio_due <= due <= back, (clock(due), clock(plan.appointment))


def test_clock_reads_the_day():
    assert clock(0) == "08:00" and clock(DAY_SECONDS - 60) == "19:59" and clock(5400) == "09:30"


def test_battery_drains_idle_at_four_hours_and_charges_docked_at_two_and_a_half():
    w = _world(plan=_plan(appointment=6 * 3600.0))
    w.docked = False                                       # at home, off the charger: idle drain
    _until(w, 3600.0)
    assert w.battery == pytest.approx(1.0 - 3600 * IDLE_DRAIN, abs=1e-9) == pytest.approx(0.75, abs=1e-9)
    w.docked = True
    _until(w, 2 * 3600.0)
    assert w.battery == pytest.approx(min(1.0, 0.75 + 3600 * CHARGE_RATE), abs=1e-9) == 1.0
    # Driving: the 15 m to her room at 0.6 m/s is 25 s at the driving rate, and it undocks.
    w.act("GotoPatientRoom")
    assert not w.docked and w.robot_at == "room"
    assert w.battery == pytest.approx(1.0 - 25 * DRIVE_DRAIN, abs=1e-9)
    assert w.metrics.metres_driven == 15.0


def test_an_empty_battery_stops_the_robot_for_the_rest_of_the_day():
    w = _world(plan=_plan(appointment=6 * 3600.0))
    w.act("GotoPatientRoom")
    w.battery = 10 * IDLE_DRAIN                          # ten seconds of charge left
    _until(w, w.time + 20.0)
    assert w.dead and w.battery == 0.0 and w.checklist()["battery_empty"] is True
    result = w.act("GoHome")                             # a drive never arrives
    assert result.messages == [] and w.robot_at == "room"
    assert w.checklist()["battery_low_s"] >= 10.0


def test_at_breakfast_her_room_is_empty_and_a_ring_there_is_unprompted():
    plan = _plan(activities=[(-600.0, 5400.0, "breakfast")], appointment=6 * 3600.0)
    w = _world(plan=plan)
    assert w.resident_at == "dining" and w.resident_state() == "breakfast"
    w.act("GotoPatientRoom")
    result = w.act("RingDoorBell")
    assert result.messages == [] and not w.engaged
    assert w.checklist()["unprompted"] == 1
    _until(w, 5500.0)                                        # breakfast over: back in her room
    assert w.resident_at == "room" and w.resident_state() == "room"
    assert w.act("RingDoorBell").messages[0].text in ("yes", "t_yes") or w.engaged
    assert w.engaged


def test_asleep_she_hears_no_bell():
    w = _world(plan=_plan(activities=[(0.0, 3600.0, "nap")], appointment=6 * 3600.0))
    w.act("GotoPatientRoom")
    assert w.act("RingDoorBell").messages == [] and not w.engaged and w.resident_state() == "asleep"


def test_the_session_starts_at_the_appointment_and_she_walks_back_after_45_minutes():
    appointment = 1800.0
    plan = _plan(appointment=appointment)
    w = _world(plan=plan, walking_speed=1.0)
    _until(w, plan.physio_due + 1)                            # the physio reminder falls due (15 min before)
    w.act("GotoPatientRoom")
    w.act("RingDoorBell")
    w.act("RemindPhysioAppt")
    assert w.wants_guidance and w.checklist()["reminders_on_time"] == 1
    w.act("GuideToPhysio")
    assert w.resident_at == "physio" and w.checklist()["walks_completed"] == 1
    w.act("TerminateGuidance")
    _until(w, appointment + 1)
    assert w.in_session and not w.engaged and w.resident_state() == "therapy"
    assert w.truth()["UserPresent"] == "no" and w.truth()["UserLocation"] == "physio"
    _until(w, appointment + SESSION_SECONDS + 1)
    assert not w.in_session and w.resident_at == "corridor"
    _until(w, appointment + SESSION_SECONDS + 35)             # 30 m at 1 m/s
    assert w.resident_at == "room"


def test_a_late_arrival_still_gets_two_minutes_before_her_session():
    plan = _plan(appointment=1200.0)
    w = _world(plan=plan, walking_speed=1.0)
    _until(w, plan.physio_due + 1)
    w.act("GotoPatientRoom")
    w.act("RingDoorBell")
    _until(w, 1250.0)                                         # past the appointment, not yet walked
    w.act("RemindPhysioAppt")
    w.act("GuideToPhysio")
    arrived = w.time
    assert w.resident_at == "physio" and not w.in_session
    _until(w, arrived + SETTLE_SECONDS - 2)
    assert not w.in_session
    _until(w, arrived + SETTLE_SECONDS + 2)
    assert w.in_session


def test_the_staff_take_her_when_the_robot_never_comes_and_the_walk_is_missed():
    plan = _plan(appointment=1800.0)
    w = _world(plan=plan)
    _until(w, plan.appointment + STAFF_TAKE_AFTER + 2)
    c = w.checklist()
    assert w.resident_at == "physio" and c["staff_walks"] == 1 and c["walks_completed"] == 0
    assert "physio" not in w.due                            # the reminder lapsed, missed
    assert c["reminders_due"] == 1 and c["reminders_delivered"] == 0


def test_a_question_is_raised_only_when_she_voices_it_to_the_robot():
    w = _world(plan=_plan(appointment=6 * 3600.0))
    w._latent = ("time", w.time)                          # she has come to want the time
    _until(w, 60.0)
    assert w.info_goal is None and w.checklist()["questions_raised"] == 0
    w.act("GotoPatientRoom")
    w.act("RingDoorBell")                                 # in contact: she voices it
    assert w.info_goal == "time" and w.checklist()["questions_raised"] == 1
    w.act("TellTime")
    c = w.checklist()
    assert c["questions_answered"] == 1 and len(c["answer_delay_s"]) == 1 and 0 < c["answer_delay_s"][0] < 10


def test_the_truth_says_what_she_wants_before_she_says_it_and_when_the_robot_sits_on_its_dock():
    """Amendment 4: her unvoiced question is her UserInfoGoal in the truth the fit counts (the checklist
    still counts only voiced ones); amendment 3: with the day domain, Battery=docked while it charges."""
    from pearl_pomdp.model.domain_yaml import load_domain
    from pearl_sim.nursing_home.scenario import default_domain

    day_domain = load_domain(REPO / "config/pearl_day.domain.yaml")
    plan = _plan(appointment=6 * 3600.0)
    fields = {"name": "Mrs B", "walking_speed": 0.5, "willingness": 1.0, "answers_door": 1.0, "touchscreen": 0.0}
    w = DayWorld(day_scenario(fields, 0.0, 0, plan=plan), plan, domain=day_domain)
    assert w.truth()["Battery"] == "docked" and w.truth()["UserInfoGoal"] == "none"
    w._latent = ("weather", w.time)
    _until(w, 60.0)
    assert w.truth()["UserInfoGoal"] == "wantWeather" and w.checklist()["questions_raised"] == 0
    w.act("GotoPatientRoom")                              # off the dock: the level again
    assert w.truth()["Battery"] == "ok"
    day_domain.state_index(w.truth())                     # every value is the day domain's
    # The episode domain has no dock: the same world speaks its terms.
    e = DayWorld(day_scenario(fields, 0.0, 0, plan=plan), plan, domain=default_domain())
    assert e.truth()["Battery"] == "ok"
    default_domain().state_index(e.truth())


def test_an_unvoiced_question_is_dropped_after_30_minutes():
    w = _world(plan=_plan(appointment=6 * 3600.0))
    w._latent = ("weather", 0.0)
    _until(w, 1801.0)
    assert w._latent is None


def test_station_share_counts_the_time_nothing_is_wanted():
    w = _world(plan=_plan(appointment=6 * 3600.0))
    _until(w, 1000.0)                                         # docked at home, nothing wanted
    w.act("GotoPatientRoom")
    _until(w, w.time + 1000.0)                                # away, nothing wanted
    c = w.checklist()
    # 1000 s home + 3 s of the drive's start... of ~2025 s with nothing wanted, about half at the station.
    assert c["station_share"] == pytest.approx(1000.0 / (1000.0 + 25.0 + 1000.0), abs=0.002)


def test_day_score_weights_are_the_protocols():
    perfect = {"reminders_due": 3, "reminders_on_time": 3, "walks_wanted": 1, "walks_completed": 1,
               "questions_raised": 0, "questions_answered": 0, "station_share": 1.0, "docked_at_end": True,
               "battery_empty": False, "battery_low_s": 0.0, "unprompted_per_hour": 0.0, "wrong_actions": 0}
    assert day_score(perfect) == 100.0
    assert sum(v for v in SCORE_WEIGHTS.values() if v > 0) == 100.0
    worse = dict(perfect, reminders_on_time=2, walks_completed=0, station_share=0.5, docked_at_end=False,
                 battery_low_s=1800.0, unprompted_per_hour=0.5, wrong_actions=1)
    # 30·2/3 + 0 + 15 + 5 + 0 + 10·0.5 − 1 − 2
    assert day_score(worse) == pytest.approx(20 + 15 + 5 + 5 - 1 - 2)
    assert day_score(dict(perfect, battery_empty=True)) == 90.0


def _run_tree_day(seed, day_rules):
    from pearl_sim.nursing_home.experiment import episode_executive
    from pearl_sim.loop import ExecutiveBackend, run_episode
    from pearl_sim.nursing_home.behaviour_tree import PearlBehaviourTree
    from pearl_sim.nursing_home.scenario import default_domain

    domain = default_domain()
    w = _world(seed=seed, walking_speed=0.3)
    tree = PearlBehaviourTree("day_tree", list(domain.actions), day_rules=day_rules)
    run_episode(w, ExecutiveBackend(episode_executive(tree, domain, w.scenario)), stop_when=lambda: w.done)
    return w


def test_a_whole_day_with_the_day_tree_docks_and_delivers():
    w = _run_tree_day(3, day_rules=True)
    c = w.checklist()
    assert w.done and w.time >= DAY_SECONDS
    assert c["reminders_due"] == 3 and c["reminders_delivered"] == 3
    assert c["docked_at_end"] is True and not c["battery_empty"] and c["station_share"] > 0.9


def test_without_the_dock_rule_the_tree_never_charges_and_the_battery_runs_out():
    w = _run_tree_day(3, day_rules=False)
    c = w.checklist()
    # It still goes home, but never docks: 4 h of idle drain empty the battery by midday.
    assert c["docked_at_end"] is False and c["battery_empty"] is True
    assert day_score(c) < day_score(_run_tree_day(3, day_rules=True).checklist()) - 10


def test_the_battery_driver_reports_every_30_s_only_to_a_domain_that_reads_it():
    """Protocol 3: with the day domain (a BatteryState input) the world publishes the driver's percentage
    every BATTERY_PERIOD s, the level it has then; the episode domain declares no such input and hears none."""
    from pearl_pomdp.model.domain_yaml import load_domain
    from pearl_sim.nursing_home.day import BATTERY_PERIOD

    plan = _plan(appointment=6 * 3600.0)
    fields = {"name": "Mrs B", "walking_speed": 0.5, "willingness": 1.0, "answers_door": 1.0, "touchscreen": 0.0}
    w = DayWorld(day_scenario(fields, 0.0, 0, plan=plan), plan, domain=load_domain(REPO / "config/pearl_day.domain.yaml"))
    w.docked = False                                     # idle off the dock: it drains
    readings = []
    while w.time < 125.0 - 1e-9:
        readings += [(m.time, float(m.text)) for m in w.wait(125.0).messages if m.modality == "Charge"]
    assert [t for t, _ in readings] == [1.0, 1.0 + BATTERY_PERIOD, 1.0 + 2 * BATTERY_PERIOD, 1.0 + 3 * BATTERY_PERIOD,
                                        1.0 + 4 * BATTERY_PERIOD]
    assert all(level == pytest.approx(1.0 - t * IDLE_DRAIN, abs=1e-4) for t, level in readings)
    e = _world(plan=plan)                                # the episode domain: no battery input
    e.docked = False
    heard = []
    while e.time < 125.0 - 1e-9:
        heard += e.wait(125.0).messages
    assert not [m for m in heard if m.modality == "Charge"]


def test_the_day_domain_reads_the_battery_low_below_20_and_ok_again_at_25_percent():
    """The Charge input's bins and hysteresis say what protocol 3 fixed: a reading observes a change of
    bin only; low below 20 %, ok again at 25 %, so a level dithering at 20 % does not flap."""
    from pearl_pomdp.model.domain_yaml import load_domain
    from pearl_pomdp.tracking.readers import NumberReader

    charge = next(ch for ch in load_domain(REPO / "config/pearl_day.domain.yaml").inputs if ch.modality == "Charge")
    assert (charge.kind, charge.type, charge.topic) == ("number", "sensor_msgs/msg/BatteryState", "/battery_state")
    reader = NumberReader(charge)
    heard = [reader.read(f"{x:.4f}")[:2] for x in (0.9, 0.21, 0.2001, 0.1999, 0.2100, 0.2499, 0.25, 0.2)]
    assert heard == [("battery_ok", "number"), ("battery_ok", "unchanged"), ("battery_ok", "unchanged"),
                     ("battery_low", "number"), ("battery_low", "unchanged"), ("battery_low", "unchanged"),
                     ("battery_ok", "number"), ("battery_ok", "unchanged")]
