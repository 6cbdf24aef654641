"""Experiment harness: statistics, the scripted baseline and episode scoring."""
from pathlib import Path

import pytest

from pearl_pomdp.model.domain_yaml import load_domain
from pearl_pomdp.speech import KeywordFilter
from pearl_sim.nursing_home.agents import ScriptedAgent
from pearl_sim.nursing_home.experiment import run_episode, with_word_error_rate
from pearl_sim.stats import proportion_ci, t_ci
from pearl_sim.nursing_home.scenario import load_scenarios, parse_scenarios
from pearl_sim.nursing_home.world import Message

REPO = Path(__file__).resolve().parents[1]


def test_wilson_interval_matches_hand_computation():
    # 11 of 12: p = .9167; Wilson 95% (z = 1.96) = [0.6461, 0.9851] (computed by hand).
    ci = proportion_ci(11, 12)
    assert ci["rate"] == pytest.approx(11 / 12)
    assert ci["low"] == pytest.approx(0.6461, abs=1e-4) and ci["high"] == pytest.approx(0.9851, abs=1e-4)
    assert proportion_ci(0, 0)["rate"] is None


def test_t_interval_matches_hand_computation():
    # values 1..5: mean 3, sd 1.5811, t(0.975, 4 df) = 2.7764, half-width 2.7764 * 1.5811 / sqrt(5) = 1.9632
    out = t_ci([1, 2, 3, 4, 5])
    assert out["mean"] == 3 and out["ci95"] == pytest.approx(1.9632, abs=1e-4)
    assert out["low"] == pytest.approx(3 - 1.9632, abs=1e-4) and out["high"] == pytest.approx(3 + 1.9632, abs=1e-4)
    # One value, or values all equal: the mean exactly (scipy's own interval is NaN there); none: no mean.
    assert t_ci([4.0])["ci95"] == 0 and t_ci([2, 2, 2])["low"] == t_ci([2, 2, 2])["high"] == 2
    assert t_ci([None])["mean"] is None and t_ci([1, None, 3])["n"] == 2


def test_message_symbols_follow_the_tracker_rules():
    """World messages become symbols through the tracker's own mapper (one mapping for robot and study)."""
    from pearl_pomdp.tracking import BeliefTracker, StepSettings

    domain = load_domain(REPO / "config/pearl.domain.yaml")
    tracker = BeliefTracker(domain.compile(), domain, StepSettings(step_timeout=5.0))
    symbol = lambda m: tracker.on_input(m.modality.lower(), m.text, m.time).symbol  # noqa: E731
    assert symbol(Message(0, "Speech", "give me the whether forecast")) == "weather"
    assert symbol(Message(0, "Touchscreen", "t_time")) == "t_time"
    assert symbol(Message(0, "Laser", "atRoom")) == "atRoom"
    tracker.reset()                                             # (the three above wait in the queue)
    tracker.on_action("DoNothing", 10.0)
    assert tracker.on_tick(15.0).closed.observation == "unknown"      # nothing heard → the timeout symbol


@pytest.fixture(scope="module")
def pearl():
    domain = load_domain(REPO / "config/pearl.domain.yaml")
    return domain, KeywordFilter(domain.keywords)


def test_scripted_agent_guides_a_clear_speaker(pearl):
    domain, kf = pearl
    sc = parse_scenarios("name: s\nmax_steps: 25\nappointments: [{at: 1, kind: physio}]\nspeech: {word_error_rate: 0}\n"
                         "resident: {walking_speed: 0.5, willingness: 1.0, answers_door: 1.0, touchscreen: 0}\n")[0]
    r = run_episode(sc, ScriptedAgent(), domain, kf, seed=1)
    # Waits for the scheduler, then contact → remind → guide, in that order.
    assert r.actions[0] == "DoNothing"
    order = [r.actions.index(a) for a in ("GotoPatientRoom", "RingDoorBell", "RemindPhysioAppt", "GuideToPhysio")]
    assert order == sorted(order)
    assert r.guidance_completed and r.wrong_actions == 0
    # Return: the domain's R on the true state, discounted; the reminder (+50) is in it.
    assert r.discounted_return > 0


def test_fixed_pace_fails_slow_residents_where_adaptation_succeeds(pearl):
    domain, kf = pearl
    study = load_scenarios(REPO / "config/scenarios/study.yaml")
    slow = [s for s in study if s.resident.walking_speed <= 0.1]
    adaptive = [run_episode(s, ScriptedAgent(), domain, kf, pace_adaptation=True) for s in slow]
    fixed = [run_episode(s, ScriptedAgent(), domain, kf, pace_adaptation=False) for s in slow]
    assert sum(r.guidance_completed for r in adaptive) == len(slow)
    assert sum(r.guidance_completed for r in fixed) == 0
    assert sum(r.residents_lost for r in fixed) == len(slow)


def test_with_word_error_rate_overrides_resident_setting():
    sc = parse_scenarios("name: w\nresident: {word_error_rate: 0.1}\n")[0]
    assert with_word_error_rate(sc, 0.4).word_error_rate == 0.4
    assert with_word_error_rate(sc, 0.4).resident.word_error_rate is None
