"""The simulated ward (pearl_sim/ward): its scenarios' checks, and what each action does to the residents."""
import pytest

from pearl_pomdp.errors import SpecError
from pearl_sim.ward.scenario import Resident, WardScenario, load_ward_scenarios
from pearl_sim.ward.world import WardWorld

STUDY = "config/scenarios/ward/study.yaml"


def _scenario(**residents):
    people = [Resident(name=n, **residents.get(n, {})) for n in ("Ann", "Bob", "Cleo")]
    return WardScenario(name="t", seed=3, residents=people, word_error_rate=0.0, detector_miss=0.0)


def test_the_study_file_has_four_episodes_of_the_three_residents():
    scs = load_ward_scenarios(STUDY)
    assert [s.name for s in scs] == ["quiet_morning", "busy_ward", "moving_residents", "quiet_residents"]
    assert all([r.name for r in s.residents] == ["Ann", "Bob", "Cleo"] and s.max_steps == 60 for s in scs)
    bob = scs[3].residents[1]
    assert bob.at == "lounge" and bob.requests == [(60.0, "water")] and bob.word_error_rate == 0.4


@pytest.mark.parametrize("body, message", [
    ("residents: [{name: Ann}, {name: Bob}]", "residents: Cleo is missing"),
    ("residents: [{name: Ann}, {name: Bob}, {name: Dora}]", "residents[2].name: 'Dora': each of the domain's residents"),
    ("residents: [{name: Ann, requests: [{at: 5, need: tea}]}, {name: Bob}, {name: Cleo}]",
     "residents[0].requests[0].need: 'tea' is not a need (water, help, talk)"),
    ("residents: [{name: Ann, at: garden}, {name: Bob}, {name: Cleo}]", "residents[0].at: 'garden' is not a place"),
    ("robot: {speed: 9}\nresidents: [{name: Ann}, {name: Bob}, {name: Cleo}]", "robot.speed: 9 m/s is outside [0.1, 3]"),
])
def test_a_bad_scenario_names_the_file_and_field(tmp_path, body, message):
    path = tmp_path / "bad.yaml"
    path.write_text("world: ward\n" + body + "\n")
    with pytest.raises(SpecError) as err:
        load_ward_scenarios(path)
    assert str(err.value).startswith(str(path)) and message in str(err.value)


def test_a_call_brings_the_robot_and_a_service_where_the_resident_is_meets_the_need():
    world = WardWorld(_scenario(Bob={"requests": [(5.0, "water")], "presses_call": 1.0}))
    heard = world.wait(30.0)
    assert [(m.modality, m.text) for m in heard.messages] == [("Call", "call_bob")]
    assert world.truth()["BobNeed"] == "water" and world.truth()["RobotAt"] == "station"
    drive = world.act("GoToRoomBob")
    assert [m.text for m in drive.messages][:2] == ["at_room_bob", "person_seen"]
    assert drive.end - drive.start == pytest.approx(10.0 / 0.7)              # 10 m at 0.7 m/s
    ask = world.act("AskBob")
    assert ask.messages[-1].modality == "Voice" and ask.messages[-1].meant == "water"
    served = world.act("ServeBob")
    assert served.wrong is None and world.metrics.requests_met == 1 and world.truth()["BobNeed"] == "none"
    again = world.act("ServeBob")
    assert again.wrong == "served Bob, who wanted nothing" and world.metrics.wrong_actions == 1
    assert world.all_met


def test_a_reminder_reaches_a_resident_only_where_they_are_and_counts_on_time_or_overdue():
    world = WardWorld(_scenario(Ann={"pills": [1.0], "late_after": 30.0, "moves": [(2.0, "lounge")]}))
    world.wait(5.0)
    assert world.truth()["AnnPill"] == "due" and world.truth()["AnnAt"] == "lounge"
    world.act("GoToRoomAnn")
    assert world.act("RemindAnn").wrong == "reminded Ann, who is not here"
    world.wait(world.time + 30.0)
    assert world.truth()["AnnPill"] == "late"
    world.act("GoToLounge")
    assert world.act("RemindAnn").wrong is None
    m = world.metrics
    assert (m.pills, m.pills_on_time, m.pills_overdue) == (1, 0, 1) and world.truth()["AnnPill"] == "none"


def test_the_truth_is_a_state_of_the_ward_domain():
    from pearl_pomdp.model.domain_yaml import load_domain

    domain = load_domain("config/ward.domain.yaml")
    assert domain.num_states == 233_280 and len(domain.actions) == 15 and len(domain.observations) == 15
    world = WardWorld(load_ward_scenarios(STUDY)[1])
    world.wait(60.0)
    s = domain.state_index(world.truth())
    assert 0 <= s < domain.num_states and domain.state_values[s][0] == 0    # RobotAt: station
    assert world.truth()["AnnNeed"] == "help" and world.truth()["CleoAt"] == "lounge"
