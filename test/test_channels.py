"""Input channels declared by the domain (issue 25): parsing, the load-time errors, the number →
symbol step with hysteresis against hand-worked values, and the tracker on a domain's own inputs."""
from __future__ import annotations

import textwrap
from pathlib import Path

import numpy as np
import pytest

from pearl_pomdp.channels import NumberDiscretiser
from pearl_pomdp.errors import SpecError
from pearl_pomdp.model.domain_yaml import load_domain, parse_domain
from pearl_pomdp.tracking import BeliefTracker, StepSettings

REPO = Path(__file__).resolve().parents[1]

#: A robot that knows its battery only from a percentage, and hears "hello" or nothing.
BATTERY = textwrap.dedent("""\
    name: battery-robot
    discount: 0.9
    features:
      Battery: [ok, low]
      Visitor: [absent, present]
    start:
      Battery: {ok: 0.8, low: 0.2}
      Visitor: absent
    modalities:
      Charge:
        symbols: [battery_ok, battery_low]
        input:
          kind: number
          topic: /robot/battery_state
          type: sensor_msgs/msg/BatteryState
          range: [0.0, 1.0]
          bins: {battery_low: [0.0, 0.2], battery_ok: [0.2, 1.0]}
          hysteresis: 0.05
      Voice:
        symbols: [hello, silent]
        input: {kind: speech, topic: /robot/speech, unknown: silent, silence: silent}
    keywords:
      hello: [hello, hi]
    actions:
      Wait: {}
      Greet: {}
    observations:
      default:
        mix:
          - weight: 0.5
            parents: [Battery]
            table:
              ok: {battery_ok: 0.9, battery_low: 0.1}
              low: {battery_ok: 0.2, battery_low: 0.8}
          - weight: 0.5
            parents: [Visitor]
            table:
              absent: {hello: 0.1, silent: 0.9}
              present: {hello: 0.7, silent: 0.3}
    rewards:
      - {action: Greet, when: {Visitor: present}, reward: 1, why: a greeted visitor}
    """)


def battery(text: str = BATTERY, source: str = "battery.domain.yaml"):
    return parse_domain(text, source=source)


# ------------------------------------------------------------------------------ hysteresis
def test_hysteresis_against_hand_worked_values():
    """low [0, 0.2), ok [0.2, 1], h = 0.05: ok needs >= 0.25 to come back, low needs < 0.15."""
    d = NumberDiscretiser(battery().input("charge"))
    readings = [0.30, 0.17, 0.1501, 0.149, 0.22, 0.2499, 0.2501, 0.151, 1.0, 0.0]
    expected = ["battery_ok",   # first reading: its own bin
                "battery_ok",   # 0.17 is below 0.2 but inside ok's band [0.15, 1.05]
                "battery_ok",   # 0.1501: just inside the band
                "battery_low",  # 0.149 < 0.15: leaves ok
                "battery_low",  # 0.22 >= 0.2 but below low's band end 0.25
                "battery_low",  # 0.2499 < 0.25
                "battery_ok",   # 0.2501: out of low's band [-0.05, 0.25)
                "battery_ok",   # 0.151 >= 0.15
                "battery_ok", "battery_low"]
    assert [d.read(x) for x in readings] == expected
    assert d.read(1.2) is None and d.read(float("nan")) is None and d.symbol == "battery_low"   # kept
    d.reset()
    assert d.read(0.2) == "battery_ok" and d.read(0.19) == "battery_ok"   # a boundary is the upper bin's


def test_three_bins_without_hysteresis_follow_the_edges():
    text = BATTERY.replace("symbols: [battery_ok, battery_low]", "symbols: [battery_ok, battery_low, battery_empty]") \
        .replace("bins: {battery_low: [0.0, 0.2], battery_ok: [0.2, 1.0]}",
                 "bins: {battery_empty: [0.0, 0.05], battery_low: [0.05, 0.2], battery_ok: [0.2, 1.0]}") \
        .replace("hysteresis: 0.05", "hysteresis: 0") \
        .replace("ok: {battery_ok: 0.9, battery_low: 0.1}", "ok: {battery_ok: 0.9, battery_low: 0.1, battery_empty: 0}") \
        .replace("low: {battery_ok: 0.2, battery_low: 0.8}", "low: {battery_ok: 0.2, battery_low: 0.6, battery_empty: 0.2}")
    d = NumberDiscretiser(battery(text).input("charge"))
    assert [d.read(x) for x in (0.5, 0.2, 0.1999, 0.05, 0.0499, 0.0, 0.05)] == \
        ["battery_ok", "battery_ok", "battery_low", "battery_low", "battery_empty", "battery_empty", "battery_low"]


# ------------------------------------------------------------------------------ parsing
def test_declared_inputs_and_the_generic_ones():
    d = battery()
    charge, voice = d.inputs
    assert (charge.name, charge.kind, charge.topic, charge.type, charge.range, charge.hysteresis, charge.report) == \
        ("charge", "number", "/robot/battery_state", "sensor_msgs/msg/BatteryState", (0.0, 1.0), 0.05, "change")
    assert [(b.symbol, b.low, b.high) for b in charge.bins] == [("battery_low", 0.0, 0.2), ("battery_ok", 0.2, 1.0)]
    assert (voice.kind, voice.unknown, voice.silence, voice.type) == ("speech", "silent", "silent", "pearl_interfaces/msg/RecognisedSpeech")
    assert d.silence_symbol == "silent"
    # A modality written as a plain list gets the generic input (no names of any robot).
    table4 = load_domain(REPO / "config" / "table4.domain.yaml")
    (speech,) = table4.inputs
    assert (speech.name, speech.kind, speech.topic, speech.unknown, speech.declared) == \
        ("speech", "speech", "/pearl/speech", "unknown", False)


def test_pearls_four_inputs_are_declarations_in_its_domain_with_and_without_the_fit():
    for fitted in (True, False):
        d = load_domain(REPO / "config" / "pearl.domain.yaml", fitted=fitted)
        assert [(c.name, c.kind, c.topic, c.declared) for c in d.inputs] == [
            ("speech", "speech", "/pearl/speech", True), ("touchscreen", "symbol", "/pearl/touchscreen", True),
            ("laser", "symbol", "/pearl/laser", True), ("reminder", "symbol", "/pearl/reminder", True)]
        assert d.silence_symbol == "unknown" and d.input("speech").unknown == "unknown"
    assert "fitted:" in (REPO / "config" / "pearl.domain.yaml").read_text()


@pytest.mark.parametrize("old, new, where, problem", [
    # The three errors of the issue: an unknown kind, a topic twice, bins that do not cover the range.
    ("kind: number", "kind: thermometer", "modalities.Charge.input.kind",
     "unknown kind 'thermometer'; expected one of speech, symbol, number"),
    ("topic: /robot/speech", "topic: /robot/battery_state", "modalities.Voice.input.topic",
     "topic /robot/battery_state is declared twice (also by modality Charge); each input needs its own topic"),
    ("battery_ok: [0.2, 1.0]}", "battery_ok: [0.25, 1.0]}", "modalities.Charge.input.bins",
     "the bins do not cover the range [0.0, 1.0]: nothing covers [0.2, 0.25) between battery_low and battery_ok"),
    ("battery_ok: [0.2, 1.0]}", "battery_ok: [0.2, 0.9]}", "modalities.Charge.input.bins",
     "the bins do not cover the range [0.0, 1.0]: nothing covers (0.9, 1]"),
    ("battery_low: [0.0, 0.2]", "battery_low: [0.1, 0.2]", "modalities.Charge.input.bins",
     "the bins do not cover the range [0.0, 1.0]: nothing covers [0, 0.1)"),
    ("battery_ok: [0.2, 1.0]}", "battery_ok: [0.15, 1.0]}", "modalities.Charge.input.bins",
     "bins battery_low and battery_ok overlap on [0.15, 0.2)"),
    ("bins: {battery_low: [0.0, 0.2], battery_ok: [0.2, 1.0]}", "bins: {battery_low: [0.0, 0.2]}",
     "modalities.Charge.input.bins", "symbol 'battery_ok' of modality Charge has no bin"),
    ("hysteresis: 0.05", "hysteresis: 0.2", "modalities.Charge.input.hysteresis",
     "0.2 is not smaller than the narrowest bin (0.2 wide)"),
    ("unknown: silent,", "unknown: hello,", "modalities.Voice.input.unknown", "'hello' has keywords"),
    ("kind: speech,", "kind: speech, qos: fast,", "modalities.Voice.input.qos", "unknown qos 'fast'"),
    ("kind: speech, topic: /robot/speech, unknown: silent,", "kind: symbol, topic: /robot/speech,", "keywords.hello", "'hello' is a symbol of the symbol input Voice; "
                                                          "keywords belong to speech inputs"),
    ("type: sensor_msgs/msg/BatteryState", "type: BatteryState", "modalities.Charge.input.type",
     "'BatteryState' is not a ROS message type"),
])
def test_one_clear_error_naming_the_file_the_field_and_what_is_wrong(old, new, where, problem):
    assert old in BATTERY
    with pytest.raises(SpecError) as err:
        battery(BATTERY.replace(old, new, 1), source="robots/battery.domain.yaml")
    assert err.value.source == "robots/battery.domain.yaml" and err.value.where == where
    assert problem in err.value.problem
    assert str(err.value).startswith("robots/battery.domain.yaml:") and err.value.line is not None


# ------------------------------------------------------------------------------ the tracker
def test_a_number_input_observes_its_bin_once_per_change_and_the_belief_is_the_filters():
    d = battery()
    t = BeliefTracker(d.compile(), d, StepSettings(step_timeout=0.0))
    assert [c.name for c in t.channels] == ["charge", "voice"]
    t.on_action("Wait", 0.0)
    first = t.on_input("charge", 0.12, 1.0)   # battery_low: P(low) = 0.2·0.8·0.5 / (0.2·0.8·0.5 + 0.8·0.1·0.5)
    assert (first.kind, first.symbol, first.heard) == ("closed", "battery_low", "number")
    marginal = t.marginals()["Battery"]
    assert marginal["low"] == pytest.approx(0.16 / 0.24, abs=1e-12)
    t.on_action("Wait", 2.0)
    for x in (0.1, 0.18, 0.24):   # still battery_low (0.24 is inside low's band): no observation
        held = t.on_input("charge", x, 3.0)
        assert (held.kind, held.symbol, held.heard, held.closed) == ("idle", "battery_low", "unchanged", None)
    assert t.step_open and t.counters()["unchanged_charge"] == 3
    back = t.on_input("charge", 0.8, 4.0).closed   # battery_ok closes the open step
    p_low = (0.16 / 0.24) * 0.2 / ((0.16 / 0.24) * 0.2 + (0.08 / 0.24) * 0.9)
    assert back.observation == "battery_ok" and t.marginals()["Battery"]["low"] == pytest.approx(p_low, abs=1e-12)
    bad = t.on_input("charge", 1.5, 5.0)
    assert (bad.kind, t.counters()["invalid_charge"], t.warnings()) == ("invalid", 1, 1)
    t.on_action("Greet", 6.0)
    assert t.on_input("voice", "oh hi there", 7.0).symbol == "hello"
    t.on_action("Greet", 8.0)
    assert t.on_input("voice", "what a day", 9.0).symbol == "silent" and t.counters()["unknown_speech"] == 1
    t.reset()   # back to b0: the number input forgets its bin, so the next reading is new
    t.on_action("Wait", 10.0)
    assert t.on_input("charge", 0.9, 11.0).kind == "closed"


def test_the_silence_symbol_closes_a_timed_out_step_and_every_reading_can_be_reported():
    d = battery(BATTERY.replace("hysteresis: 0.05", "hysteresis: 0.05\n      report: every"))
    t = BeliefTracker(d.compile(), d, StepSettings(step_timeout=5.0))
    assert t.timeout_observation == "silent"
    t.on_action("Wait", 0.0)
    assert t.on_tick(5.0).closed.observation == "silent"
    t.on_action("Wait", 5.0)
    assert t.on_input("charge", 0.9, 6.0).closed.observation == "battery_ok"
    t.on_action("Wait", 6.0)
    assert t.on_input("charge", 0.9, 7.0).closed.observation == "battery_ok"   # report: every


def test_pearl_defaults_live_in_pearls_files_not_in_the_code():
    from pearl_pomdp.params import step_settings

    code, pearl = StepSettings(), step_settings()
    assert (code.timeout_observation, code.nav_failed_observation, code.place_feature, code.drive_category) == \
        ("", "", "", "")
    assert (pearl.nav_failed_observation, pearl.place_feature, pearl.drive_category) == \
        ("navFailed", "RobotLocation", "Move")
    source = "".join(path.read_text() for path in [*(REPO / "pearl_pomdp" / "tracking").glob("*.py"),
                                                     REPO / "pearl_pomdp" / "channels.py"])
    for pearl_name in ('"navFailed"', '"RobotLocation"', '"Move"', '"touchscreen"', '"laser"', '"reminder"'):
        assert pearl_name not in source, pearl_name
    # Drive deadlines without the domain's names are an error naming the parameter.
    d = load_domain(REPO / "config" / "pearl.domain.yaml")
    with pytest.raises(ValueError, match="nav_failed_observation: drive deadlines"):
        BeliefTracker(d.compile(), d, StepSettings(drive_speed=0.5, drive_category="Move",
                                                   places=(("home", 0.0, 0.0), ("room", 1.0, 0.0))))


def test_a_flat_model_has_one_observation_input():
    d = battery()
    t = BeliefTracker(d.compile(), None, StepSettings(step_timeout=0.0))
    (only,) = t.channels
    assert (only.name, only.kind, only.topic) == ("observation", "symbol", "/pearl/observation")
    t.on_action("Wait", 0.0)
    assert t.on_input("observation", "battery_low", 1.0).closed is not None
    with pytest.raises(ValueError, match="unknown input 'speech'; inputs: observation"):
        t.on_input("speech", "hello", 2.0)
    np.testing.assert_allclose(t.belief.sum(), 1.0)
