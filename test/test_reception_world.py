"""The reception world's mechanics (pearl_sim/reception/world.py), with values worked out by hand
from docs/reception.md's specification, and its scenario files' errors."""
from __future__ import annotations

import math
from dataclasses import replace

import pytest

from pearl_pomdp.errors import SpecError
from pearl_sim.reception.scenario import ReceptionScenario, Visitor, load_reception_scenarios
from pearl_sim.reception.world import ANSWER_SECONDS, BATTERY_PERIOD, SPEAK_SECONDS, ReceptionWorld

#: The desk at (0, 0), the office at (12, -20): sqrt(144 + 400) m.
OFFICE_M = math.sqrt(544.0)
GALLERY_M = math.sqrt(1000.0)


def _hall(**over) -> ReceptionScenario:
    base = ReceptionScenario(name="hall", seed=3, detector_miss=0.0, passers_per_minute=0.0, word_error_rate=0.0,
                             visitors=[Visitor(name="Ms Ito", arrive=10.0, wish="office", walking_speed=0.5,
                                               says_hello=0.0, touchscreen=1.0, volunteers=0.0)])
    return replace(base, **over)


def test_a_visitor_is_seen_greeted_escorted_at_their_pace_and_handed_over():
    w = ReceptionWorld(_hall())
    first = w.act("Wait")
    # The battery driver's first reading comes at once: 100 %.
    assert [(m.modality, m.text) for m in first.messages] == [("Charge", "1.000")]
    seen = w.wait(until=30.0)
    assert (seen.end, [(m.modality, m.text) for m in seen.messages]) == (10.0, [("Presence", "person_seen")])
    assert w.truth() == {"Visitor": "waiting", "Wish": "office", "RobotAt": "desk", "Battery": "ok"}
    w.act("Greet")
    assert w.truth()["Visitor"] == "engaged" and w.metrics.visitors_greeted == 1
    asked = w.act("AskDestination")
    # She touches the screen (touchscreen 1.0) after the question and her answer time.
    assert [(m.modality, m.text) for m in asked.messages] == [("Touch", "t_office")]
    assert asked.end - asked.start == SPEAK_SECONDS + ANSWER_SECONDS
    start = w.time
    escort = w.act("EscortToOffice")
    # The robot slows from 0.7 m/s to her 0.5 m/s: 23.32 m in 46.65 s, arrival reported at the end.
    assert escort.end - start == pytest.approx(OFFICE_M / 0.5, abs=1e-9)
    assert escort.messages[-1].text == "at_office" and escort.wrong is None
    # Battery: 1.5 h of driving per charge, 6 h idle: every second before the drive idles, every second of it drives.
    idle_s, drive_s = start, OFFICE_M / 0.5
    assert w.battery == pytest.approx(1.0 - idle_s / (6 * 3600) - drive_s / (1.5 * 3600), abs=1e-12)
    # Readings every 30 s: at 30 and 60 s (during the drive), before the arrival.
    assert [m.time for m in escort.messages if m.modality == "Charge"] == [30.0, 60.0]
    handed = w.act("HandOver")
    assert handed.wrong is None and w.metrics.visitors_served == 1
    # Arrival at 10 s; the hand-over is spoken 3 s after the drive's end.
    assert w.metrics.time_to_handover == [pytest.approx(start + OFFICE_M / 0.5 + SPEAK_SECONDS - 10.0)]
    assert w.served_all and w.truth()["Visitor"] == "none"


def test_wrong_actions_are_the_ones_the_protocol_lists():
    w = ReceptionWorld(_hall(visitors=[Visitor(name="Mr Lee", arrive=0.0, wish="gallery", touchscreen=0.0,
                                               says_hello=0.0, volunteers=0.0)]))
    assert w.act("HandOver").wrong == "handed over nobody"
    w.act("Greet")
    assert w.act("Greet").wrong is None                 # twice: awkward, not a task error
    assert w.act("EscortToOffice").wrong == "escorted Mr Lee to the office, not the gallery"
    assert w.act("HandOver").wrong == "handed Mr Lee over at the office, not the gallery"
    assert w.act("ReturnToDesk").wrong == "left Mr Lee at the office without a hand-over"
    assert (w.metrics.visitors_left, w.truth()["Visitor"]) == (1, "none")
    assert w.act("Greet").wrong == "greeted nobody"
    assert w.act("EscortToGallery").wrong == "escorted nobody"
    asked = w.act("ConfirmGallery")
    assert asked.wrong is None and w.metrics.unprompted_questions == 1 and w.metrics.clarifications == 1
    assert w.metrics.wrong_actions == 6 and not w.served_all


def test_an_ungreeted_visitor_leaves_after_their_patience_and_the_detector_says_nobody():
    w = ReceptionWorld(_hall(visitors=[Visitor(name="Ms Roy", arrive=5.0, wish="gallery", patience=60.0,
                                               says_hello=0.0)]))
    w.act("Wait")
    assert [m.text for m in w.wait(until=100.0).messages] == ["person_seen"]
    # 5 + 60 = 65 s; the 30 s and 60 s battery readings come first: 1 - 30/21600 = 0.99861, 1 - 60/21600 = 0.99722.
    texts = []
    while w.time < 65.0:
        texts += [(m.time, m.text) for m in w.wait(until=100.0).messages]
    assert texts == [(30.0, "0.999"), (60.0, "0.997"), (65.0, "nobody")]
    assert (w.metrics.visitors_left, w.truth()["Visitor"]) == (1, "none")


def test_docking_charges_while_the_robot_stays_and_a_flat_battery_strands_it():
    w = ReceptionWorld(_hall(battery=0.5, visitors=[]))
    w.act("Dock")                                       # at the desk already: docks at once
    before, t0 = w.battery, w.time
    w.wait(until=t0 + 60.0)
    w.wait(until=t0 + 60.0)
    # Full in 10 min: +0.1 a minute, no drain while docked.
    assert w.battery == pytest.approx(before + 60.0 / 600.0, abs=1e-12)
    flat = ReceptionWorld(_hall(battery=0.01, drive_hours=0.01, visitors=[]))   # 36 s of driving per charge
    flat.act("EscortToGallery")
    assert flat.metrics.stranded and flat.robot_at == "desk"   # it never got there
    assert flat.act("ReturnToDesk").messages[-1].text == "at_desk"


def test_passers_by_set_the_detector_off_only_at_the_desk():
    busy = _hall(passers_per_minute=6.0, visitors=[])
    w = ReceptionWorld(busy, seed=1)
    w.act("Wait")
    seen = sum(m.text == "person_seen" for _ in range(30) for m in w.wait(until=w.time + 8.0).messages)
    assert seen > 0
    away = ReceptionWorld(busy, seed=1)
    away.act("EscortToGallery")
    seen = sum(m.text == "person_seen" for _ in range(30) for m in away.wait(until=away.time + 8.0).messages)
    assert seen == 0


def test_the_battery_driver_reports_every_period():
    w = ReceptionWorld(_hall(visitors=[]))
    times = [m.time for m in w.act("Wait").messages]
    while w.time < 3 * BATTERY_PERIOD:
        times += [m.time for m in w.wait(until=3 * BATTERY_PERIOD).messages]
    assert times == [0.0, 30.0, 60.0, 90.0]


def test_scenario_errors_name_the_file_and_field(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("world: reception\nepisodes:\n  - visitors: [{wish: cafe}]\n")
    with pytest.raises(SpecError, match=r"bad.yaml: episodes\[0\].visitors\[0\].wish: 'cafe' is not a place"):
        load_reception_scenarios(bad)
    bad.write_text("world: reception\nrobot: {speed: 9}\n")
    with pytest.raises(SpecError, match=r"bad.yaml: robot.speed: 9 m/s is outside \[0.1, 3\]"):
        load_reception_scenarios(bad)
    bad.write_text("world: nursing\n")
    with pytest.raises(SpecError, match="world: 'nursing': this file is not for the reception world"):
        load_reception_scenarios(bad)


def test_the_shipped_study_file_has_the_protocols_six_episodes():
    from pathlib import Path

    study = load_reception_scenarios(Path(__file__).resolve().parents[1] / "config/scenarios/reception/study.yaml")
    assert [s.name for s in study] == ["one_visitor", "quiet_visitor", "two_visitors", "slow_visitor", "low_battery",
                                       "busy_hall"]
    assert all(s.max_steps == 40 and s.step_timeout == 8.0 for s in study)
    assert (study[4].battery, study[5].passers_per_minute) == (0.28, 2.0)
