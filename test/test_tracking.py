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


def test_a_word_during_a_drive_waits_for_the_step_after_it():
    # She asks the time while Pearl guides her: GuideToPhysio's table gives no speech, so the word
    # does not end the walk in the belief (before, it closed the step and the filter threw it away).
    t = pearl(step_timeout=5.0, drive_category="Move")
    t.on_action("GuideToPhysio", 0.0)
    asked = t.on_input("speech", "what time is it", 40.0)
    assert (asked.kind, asked.closed, asked.symbol) == ("queued", None, "time")
    assert [e.kind for e in asked.events] == ["held"] and "'GuideToPhysio' never gives it" in asked.events[0].text
    assert t.step_open and t.open_action == "GuideToPhysio" and t.pending == 1
    assert t.counters()["held"] == 1 and t.counters()["zero_likelihood"] == 0
    arrived = t.on_input("laser", "atPhysio", 200.0).closed
    assert (arrived.action, arrived.observation, arrived.zero_likelihood) == ("GuideToPhysio", "atPhysio", False)
    # After the drive the word is an early input like any other: the next action's step closes
    # with it at once, here a wait (Figure 4 after the walk), whose table hears her questions.
    heard = t.on_action("DoNothing", 201.0).closed
    assert (heard.action, heard.observation, heard.source) == ("DoNothing", "time", "speech") and t.pending == 0
    # (This model was certain she had no question, so the filter's recovery lets the word decide.)
    marginals = t.marginals(heard.belief)["UserInfoGoal"]
    assert marginals["wantTime"] > 0.9


def test_only_drives_hold_what_they_cannot_give():
    t = pearl(step_timeout=5.0, drive_category="Move")
    # A question step closes with whatever comes first, even a word its table never gives (a
    # misheard answer is still the answer): the filter's recovery, as before.
    t.on_action("RemindPhysioAppt", 0.0)
    closed = t.on_input("speech", "what time is it", 1.0).closed
    assert closed is not None and closed.zero_likelihood and t.counters()["held"] == 0
    # A word queued before a drive is not used up by it: the drive waits for its landmark.
    t.on_input("speech", "what is the weather", 2.0)
    assert t.on_action("GoHome", 3.0).closed is None and t.pending == 1
    assert t.on_input("laser", "atHome", 30.0).closed.observation == "atHome"
    assert t.on_action("DoNothing", 31.0).closed.observation == "weather"
    # Without drives (no drive_category), every input closes the open step as before.
    free = pearl(step_timeout=5.0)
    free.on_action("GuideToPhysio", 0.0)
    assert free.on_input("speech", "what time is it", 40.0).closed.observation == "time"
