"""The core BeliefTracker on raw inputs: recogniser confidence, drives from the domain's categories."""
from pathlib import Path

from pearl_pomdp.model.factored import load_domain
from pearl_pomdp.speech import speech_message
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
