"""Residents specified before the study: the paper's six, the seeded generator, and the
world effects of the new resident fields."""
import pytest

from pearl_pomdp.errors import SpecError
from pearl_sim.nursing_home.residents import (RANGES, effective_word_error_rate, generate_residents, paper_residents,
                                 parse_population, resident_scenarios, study_template)
from pearl_sim.nursing_home.scenario import parse_scenarios
from pearl_sim.nursing_home.world import World

STUDY = "config/scenarios/study.yaml"


def test_paper_residents_are_the_six_of_the_study_file():
    residents = paper_residents(STUDY)
    assert [r.name for r in residents] == list("ABCDEF")
    assert [r.fields["walking_speed"] for r in residents] == [0.05, 0.1, 0.2, 0.35, 0.6, 1.0]


def test_generator_is_seeded_and_in_range():
    a, b = generate_residents(20, seed=3), generate_residents(20, seed=3)
    assert [p.fields for p in a] == [p.fields for p in b]
    assert [p.fields for p in a] != [p.fields for p in generate_residents(20, seed=4)]
    for p in a:
        lo, hi = RANGES["walking_speed"]
        assert lo <= p.fields["walking_speed"] <= hi
        assert RANGES["articulation_wer"][0] <= p.articulation_wer <= RANGES["articulation_wer"][1]
    cases = resident_scenarios(study_template(STUDY), a)
    assert len(cases) == 60 and cases[0].scenario.resident.hearing == a[0].fields["hearing"]


@pytest.mark.parametrize("spec", ["generated:0", "generated:100000", "generated:x", "octogenarians", ""])
def test_bad_population_is_one_clear_error(spec):
    with pytest.raises(SpecError, match="--residents"):
        parse_population(spec, STUDY)


def test_out_of_range_profile_names_the_resident_and_field():
    profile = generate_residents(1)[0]
    profile.fields["hearing"] = 1.5
    with pytest.raises(SpecError, match=r"G01\.resident\.hearing"):
        resident_scenarios(study_template(STUDY), [profile])


def test_effective_word_error_rate_combines_independent_errors():
    assert effective_word_error_rate(0.0, 0.1) == pytest.approx(0.1)
    assert effective_word_error_rate(0.5, 0.1) == pytest.approx(0.55)


SCENE = """
name: t
seed: 1
resident: {answers_door: 1.0, touchscreen: 0.0, %s}
speech: {word_error_rate: 0.0}
appointments: [{at: 0, kind: vitamin}]
"""


def _remind(extra: str, seeds=range(40)):
    delivered = 0
    for seed in seeds:
        world = World(parse_scenarios(SCENE % extra)[0], seed=seed)
        world.act("GotoPatientRoom")
        world.act("RingDoorBell")
        world.act("RemindVitamin")
        delivered += world.metrics.reminders_delivered
    return delivered


def test_hearing_loses_sentences_and_responsiveness_loses_answers():
    assert _remind("hearing: 1.0") == 40
    assert 5 < _remind("hearing: 0.5") < 35
    silent = 0
    for seed in range(40):
        world = World(parse_scenarios(SCENE % "responsiveness: 0.5")[0], seed=seed)
        world.act("GotoPatientRoom")
        world.act("RingDoorBell")
        silent += not world.act("CheckUserPresent").messages
    assert 5 < silent < 35


def test_forgetting_and_changing_her_mind():
    world = World(parse_scenarios(SCENE % "forgets: 1.0")[0], seed=0)
    world.info_goal = "time"
    world.act("DoNothing")
    assert world.info_goal is None
    world = World(parse_scenarios(SCENE % "changes_mind: 1.0")[0], seed=0)
    world.wants_guidance = True
    world.act("DoNothing")
    assert world.wants_guidance is False
