"""pearl_sim's ground-truth world, recogniser and scenario files."""
import re
from pathlib import Path

import pytest

from pearl_pomdp.errors import SpecError
from pearl_sim.asr import SpeechRecogniser
from pearl_sim.nursing_home.scenario import load_scenarios, parse_scenarios
from pearl_sim.nursing_home.world import World

REPO = Path(__file__).resolve().parents[1]
GUIDE = ["GotoPatientRoom", "RingDoorBell", "RemindPhysioAppt", "GuideToPhysio"]


def scenario(extra: str = ""):
    return parse_scenarios(
        "name: t\nappointments: [{at: 1, kind: physio}]\n"
        "resident: {walking_speed: 0.1, willingness: 1.0, answers_door: 1.0, touchscreen: 0.0}\n"
        "speech: {word_error_rate: 0.0}\n" + extra
    )[0]


# ----------------------------------------------------------------- recogniser
def test_recogniser_is_exact_without_errors_and_seeded():
    clean = SpeechRecogniser(word_error_rate=0.0, seed=1)
    assert clean.recognise("Give me the weather forecast for tomorrow") == "give me the weather forecast for tomorrow"
    a = [SpeechRecogniser(0.5, seed=3).recognise("what time is it please") for _ in range(1)]
    b = [SpeechRecogniser(0.5, seed=3).recognise("what time is it please") for _ in range(1)]
    assert a == b


def test_recogniser_error_rate_matches_its_setting():
    rec = SpeechRecogniser(word_error_rate=0.3, substitution=1.0, deletion=0.0, insertion=0.0, seed=5)
    words = "what is the weather like today".split()
    changed = total = 0
    for _ in range(2000):
        out = rec.recognise(" ".join(words)).split()
        assert len(out) == len(words)          # substitutions only keep the length
        changed += sum(o != w for o, w in zip(out, words))
        total += len(words)
    # Substitutes are drawn from confusions/fillers, which can equal the word itself only by chance.
    assert abs(changed / total - 0.3) < 0.03


def test_recogniser_confuses_weather_with_whether():
    rec = SpeechRecogniser(word_error_rate=1.0, substitution=1.0, deletion=0.0, insertion=0.0, seed=0)
    heard = {rec.recognise("weather") for _ in range(200)}
    assert heard <= {"whether", "feather", "wetter"} and "whether" in heard


# ------------------------------------------------------------------- scenarios
def test_shipped_scenarios_load_and_study_has_twelve_guidances_by_six_residents():
    study = load_scenarios(REPO / "config/scenarios/study.yaml")
    assert len(study) == 12
    assert len({s.resident.name for s in study}) == 6
    speeds = sorted({s.resident.walking_speed for s in study})
    assert speeds[0] == 0.05 and speeds[-1] == 1.0
    assert all(s.resident.willingness == 1.0 for s in study)      # base merged into each episode
    assert len({s.seed for s in study}) == 12                       # each episode its own seed
    for name in ("figure4", "table4_dialog", "info_request"):
        (sc,) = load_scenarios(REPO / f"config/scenarios/{name}.yaml")
        assert sc.name == name


@pytest.mark.parametrize("text, where, problem", [
    ("name: x\nresident: {walking_speed: 0.01}", "resident.walking_speed", "outside [0.05, 1.0] m/s"),
    ("name: x\nspeech: {word_error_rate: 1.5}", "speech.word_error_rate", "outside [0.0, 1.0]"),
    ("name: x\nappointments: [{at: 3, kind: dentist}]", "appointments[0].kind", "'dentist' is not one of physio"),
    ("name: x\nresident: {walking_sped: 0.3}", "resident.walking_sped", "unknown field"),
    ("name: x\nmap: {home: [0, 0], room: [1], physio: [2, 2]}", "map.room", "must be [x, y]"),
    ("name: x\nepisodes: [{resident: {willingness: 2}}]", "episodes[0].resident.willingness", "outside [0.0, 1.0]"),
    ("seed: 3", "name", "missing"),
])
def test_scenario_errors_name_file_and_field(text, where, problem):
    with pytest.raises(SpecError) as info:
        parse_scenarios(text, source="scen.yaml")
    message = str(info.value)
    # File, then the line the one YAML loader knows (the field's own, or its nearest parent's).
    assert re.match(r"scen\.yaml(:\d+)?: ", message) and where in message and problem in message


# ----------------------------------------------------------------------- world
def step(w: World, action: str, timeout: float = 10.0):
    """One classic step: the action, then (if it produced nothing) idle time until ``timeout``
    after it — what the step loop does with the tracker's deadline."""
    r = w.act(action)
    if r.messages:
        return r
    waited = w.wait(until=r.start + timeout)
    return type(r)(action, r.start, w.time, waited.messages, r.events + waited.events, r.wrong)


def test_scheduler_message_closes_an_idle_step_and_timeout_gives_none():
    w = World(scenario())
    first = step(w, "DoNothing")
    assert first.message.modality == "Reminder" and first.message.text == "g_physio"
    assert first.end == pytest.approx(1.0 + 0.0, abs=3.5)  # due at 1 s, heard within the speaking time
    w2 = World(parse_scenarios("name: quiet\nstep_timeout: 5\n")[0])
    r = step(w2, "DoNothing", timeout=5.0)
    assert r.message is None and r.end - r.start == pytest.approx(5.0)   # the timeout counts from the action


def test_contact_remind_and_guidance_with_pace_adaptation_completes():
    w = World(scenario(), pace_adaptation=True)
    step(w, "DoNothing")
    results = [step(w, a) for a in GUIDE]
    assert results[0].message.text == "atRoom"
    assert results[1].message.modality == "Speech" and w.engaged
    assert w.truth()["ReminderGoal"] == "none" and w.wants_guidance
    assert results[3].message.text == "atPhysio"
    # The adaptive robot drives at her 0.1 m/s: 30 m take ~300 s, and she stays within reach.
    assert results[3].end - results[3].start > 250
    for _ in range(3):
        step(w, "DoNothing")
    assert w.metrics.guidances_completed == 1 and w.metrics.residents_lost == 0
    assert w.truth()["UserLocation"] == "physio"


def test_fixed_pace_loses_a_slow_resident():
    w = World(scenario(), pace_adaptation=False)
    step(w, "DoNothing")
    results = [step(w, a) for a in GUIDE]
    assert results[3].end - results[3].start == pytest.approx(30 / 0.6, abs=1.0)
    assert w.metrics.residents_lost == 1 and w.metrics.guidances_completed == 0
    assert not w.engaged


def test_wrong_actions_are_counted_with_reasons():
    w = World(scenario())
    r = step(w, "RemindVitamin")
    assert r.wrong == "reminded of vitamin with no such reminder due"
    r = step(w, "TellTime")
    assert r.wrong == "told the time nobody asked for"
    assert w.metrics.wrong_actions == 2


def test_world_is_deterministic_for_a_seed():
    def run(seed):
        w = World(parse_scenarios("name: n\nspeech: {word_error_rate: 0.5}\nappointments: [{at: 1, kind: physio}]\n"
                                  "questions: [{ask: time, at: 1}]\nresident: {answers_door: 0.5}\n")[0], seed=seed)
        out = []
        for a in ["GotoPatientRoom", "RingDoorBell", "RingDoorBell", "DoNothing", "VerifyInfoRequest", "TellTime"]:
            m = step(w, a).message
            out.append(None if m is None else (m.modality, m.text))
        return out
    assert run(3) == run(3)
    assert any(run(3) != run(s) for s in range(4, 10))


def test_resident_speaks_through_the_real_recogniser_channel():
    """speech: {channel: recogniser}: espeak-ng in her voice, noise at the SNR, the domain's pocketsphinx;
    the message carries the recogniser's confidence, which the tracker parses (issue 13)."""
    from pearl_pomdp.model.domain_yaml import load_domain
    from pearl_pomdp.speech import parse_speech_message
    from pearl_pomdp.tracking import BeliefTracker, StepSettings

    sc = parse_scenarios("name: r\nspeech: {channel: recogniser, snr_db: 30}\nresident: {voice: slow}\n")[0]
    assert sc.speech == {"channel": "recogniser", "word_error_rate": 0.2, "snr_db": 30.0, "noise": "white"}
    domain = load_domain(REPO / "config" / "pearl.domain.yaml")
    w = World(sc, seed=1, domain=domain)
    m = w._say("weather")
    text, confidence = parse_speech_message(m.text)
    assert m.modality == "Speech" and m.meant == "weather" and 0.0 <= confidence <= 1.0 and text
    tracker = BeliefTracker(domain.compile(), domain, StepSettings(step_timeout=5.0))
    assert tracker.on_input("speech", m.text, 0.0).symbol == "weather"


@pytest.mark.parametrize("text, where, problem", [
    ("name: x\nspeech: {channel: sphinx}", "speech.channel", "'sphinx' is not one of recogniser"),
    ("name: x\nspeech: {channel: recogniser, snr_db: 99}", "speech.snr_db", "outside [-20.0, 60.0]"),
    ("name: x\nspeech: {channel: measured}", "speech.measured", "needs the file of `pearl calibrate-speech"),
    ("name: x\nresident: {voice: robotic}", "resident.voice", "'robotic' is not one of clear, slow"),
])
def test_speech_channel_errors_name_the_field(text, where, problem):
    with pytest.raises(SpecError) as info:
        parse_scenarios(text, source="scen.yaml")
    assert where in str(info.value) and problem in str(info.value)
