"""The core BeliefTracker on raw inputs: recogniser confidence, drives from the domain's categories."""
from pathlib import Path

from pearl_pomdp.model.domain_yaml import load_domain
from pearl_pomdp.speech import Utterance, speech_message, utterance
from pearl_pomdp.tracking import BeliefTracker, StepSettings

REPO = Path(__file__).resolve().parents[1]


def pearl(**settings):
    domain = load_domain(REPO / "config" / "pearl.domain.yaml")
    return BeliefTracker(domain.compile(), domain, StepSettings(**settings))


def test_a_keyword_heard_below_the_confidence_floor_is_unknown():
    t = pearl(step_timeout=5.0, confidence_floor=0.5)
    t.on_action("ConfirmGuideToPhysio", 0.0)
    low = t.on_input("speech", speech_message("yes", 0.3), 1.0)
    assert (low.symbol, low.text, low.confidence) == ("unknown", "yes", 0.3)
    assert low.closed.observation == "unknown" and t.counters()["low_confidence"] == 1
    t.on_action("ConfirmGuideToPhysio", 2.0)
    clear = t.on_input("speech", speech_message("yes", 0.9), 3.0)
    assert clear.symbol == "yes" and clear.closed.confidence == 0.9
    plain = pearl(confidence_floor=0.5)
    assert plain.on_input("speech", "yes", 0.0).symbol == "yes"      # plain text: confidence 1


def test_a_typed_utterance_carries_its_confidence_and_a_recognisers_symbol():
    """/pearl/speech as pearl_interfaces/RecognisedSpeech: the same rules as the JSON it replaces."""
    t = pearl(confidence_floor=0.5)
    t.on_action("ConfirmGuideToPhysio", 0.0)
    low = t.on_input("speech", Utterance("yes", 0.3), 1.0)
    assert (low.symbol, low.heard, low.text, low.confidence) == ("unknown", "low_confidence", "yes", 0.3)
    t.on_action("ConfirmWantTime", 2.0)
    # The recogniser mapped the words itself: its symbol is taken, the words kept for the log.
    mapped = t.on_input("speech", Utterance("mumble mumble", 0.9, "time"), 3.0)
    assert (mapped.symbol, mapped.heard, mapped.text, mapped.closed.observation) == ("time", "symbol",
                                                                                     "mumble mumble", "time")
    t.on_action("ConfirmWantTime", 4.0)
    # A symbol that is not the input's is ignored: the keyword filter reads the words.
    foreign = t.on_input("speech", Utterance("what's the weather", 0.9, "atRoom"), 5.0)
    assert (foreign.symbol, foreign.heard) == ("weather", "keyword")
    # A symbol below the floor is unknown, as a keyword would be.
    t.on_action("ConfirmWantTime", 6.0)
    assert t.on_input("speech", Utterance("", 0.2, "yes"), 7.0).symbol == "unknown"
    assert t.counters()["low_confidence"] == 2
    # A confidence that is not in [0, 1] is 1.0, as in the JSON form (nothing said is lost).
    assert [utterance("yes", c).confidence for c in (float("nan"), 7.0, -0.1, 0.25)] == [1.0, 1.0, 1.0, 0.25]


def test_drives_never_time_out_and_come_from_the_drive_category():
    # The code names no category (a generic domain has no drives unless it says so); Pearl's
    # params file sets drive_category: Move (test_node_defaults checks the file is applied).
    assert pearl(step_timeout=5.0).no_timeout_actions == frozenset()
    t = pearl(step_timeout=5.0, drive_category="Move")
    assert t.no_timeout_actions == {"GotoPatientRoom", "GuideToPhysio", "GoHome"}
    t.on_action("GuideToPhysio", 0.0)
    assert t.deadline() is None and t.on_tick(1000.0).closed is None
    t.on_input("laser", "atPhysio", 200.0)
    t.on_action("DoNothing", 200.0)
    assert t.deadline() == 205.0 and t.on_tick(205.0).closed.source == "timeout"
