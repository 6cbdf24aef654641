"""The tracker's step protocol without ROS, through its façade: every documented case, with tiger's
hand-computed beliefs (listen + hear-left from uniform → [0.85, 0.15]), and the outcome of each call."""
from __future__ import annotations

import numpy as np
import pytest

from pearl_pomdp.channels import InputChannel
from pearl_pomdp.model.pomdp import Pomdp
from pearl_pomdp.tracking import BeliefTracker, StepSettings

#: Three inputs that may each carry every symbol (a flat model has one, ``observation``; these
#: show the rules hold per input and name the input that closed a step).
TIGER_INPUTS = [InputChannel(name, name, kind, ("hear-left", "hear-right"), f"/tiger/{name}")
                for name, kind in (("speech", "speech"), ("touchscreen", "symbol"), ("laser", "symbol"))]


def tiger(impossible: bool = False) -> Pomdp:
    O_listen = [[1.0, 0.0], [0.0, 1.0]] if impossible else [[0.85, 0.15], [0.15, 0.85]]
    return Pomdp.create(["tiger-left", "tiger-right"], ["listen", "open-left", "open-right"],
                        ["hear-left", "hear-right"], [np.eye(2), np.full((2, 2), 0.5), np.full((2, 2), 0.5)],
                        np.array([O_listen, [[0.5, 0.5]] * 2, [[0.5, 0.5]] * 2]),
                        np.array([[-1.0, -100.0, 10.0], [-1.0, 10.0, -100.0]]), name="tiger")


def tracker(impossible: bool = False, **settings) -> BeliefTracker:
    """A flat tiger: every symbol is valid on every input; no timeout unless asked for."""
    settings.setdefault("step_timeout", 0.0)
    return BeliefTracker(tiger(impossible), settings=StepSettings(**settings), channels=TIGER_INPUTS)


def test_action_then_observation_closes_a_step():
    t = tracker()
    opened = t.on_action("listen", 1.0)
    assert (opened.kind, opened.closed) == ("opened", None) and t.step_open and t.open_action == "listen"
    out = t.on_input("speech", "hear-left", 2.0)
    r = out.closed
    assert (out.kind, out.symbol, out.heard) == ("closed", "hear-left", "symbol")
    assert (r.step, r.action, r.observation, r.source, r.zero_likelihood) == (1, "listen", "hear-left", "speech", False)
    np.testing.assert_allclose(r.belief, [0.85, 0.15])
    assert not t.step_open and t.counters()["updates"] == 1 and t.step == 1


def test_observation_before_action_waits_for_it():
    t = tracker()
    out = t.on_input("laser", "hear-left", 0.5)
    assert (out.kind, out.closed) == ("queued", None) and [e.kind for e in out.events] == ["queued"]
    assert t.counters()["queued"] == 1 and t.step == 0 and t.pending == 1
    closing = t.on_action("listen", 1.0)
    assert closing.kind == "closed"
    np.testing.assert_allclose(closing.closed.belief, [0.85, 0.15])
    assert closing.closed.source == "laser" and t.pending == 0


def test_queue_overflow_drops_the_oldest():
    t = tracker(max_pending=1)
    t.on_input("speech", "hear-right", 0.0)
    out = t.on_input("speech", "hear-left", 0.1)
    assert out.kind == "queued" and t.counters()["dropped_overflow"] == 1 and t.pending == 1
    assert "dropped queued observation 'hear-right'" in out.events[0].text
    np.testing.assert_allclose(t.on_action("listen", 1.0).closed.belief, [0.85, 0.15])


def test_no_queue_drops_at_once():
    t = tracker(max_pending=0)
    out = t.on_input("speech", "hear-left", 0.0)
    assert (out.kind, out.closed) == ("dropped", None) and t.counters()["dropped_overflow"] == 1
    assert t.on_action("listen", 1.0).kind == "opened"


def test_stale_observations_are_dropped_and_the_step_stays_open():
    t = tracker(stale_after=5.0)
    t.on_input("speech", "hear-left", 0.0)
    out = t.on_action("listen", 10.0)
    assert out.kind == "opened" and [e.kind for e in out.events] == ["stale"]
    assert t.counters()["dropped_stale"] == 1 and t.step_open and t.step == 0


def test_timeout_closes_the_step_with_the_timeout_observation():
    t = tracker(step_timeout=2.0, timeout_observation="hear-right")
    t.on_action("listen", 10.0)
    assert t.deadline() == 12.0
    assert t.on_tick(11.999).kind == "idle"
    out = t.on_tick(12.0)
    assert (out.kind, out.closed.observation, out.closed.source) == ("closed", "hear-right", "timeout")
    assert t.counters()["timeouts"] == 1 and [e.kind for e in out.events] == ["timeout"]
    np.testing.assert_allclose(out.closed.belief, [0.15, 0.85])
    assert t.on_tick(100.0).closed is None  # no open step: nothing to close


def test_second_action_replaces_the_open_one_and_unknown_actions_are_ignored():
    t = tracker()
    t.on_action("open-left", 0.0)
    replaced = t.on_action("listen", 0.1)
    assert replaced.kind == "opened" and [e.kind for e in replaced.events] == ["replaced_action"]
    unknown = t.on_action("dance", 0.2)
    assert unknown.kind == "unknown" and [e.kind for e in unknown.events] == ["ignored_action"]
    assert t.counters()["replaced_actions"] == 1 and t.counters()["unknown_actions"] == 1
    assert t.open_action == "listen"
    np.testing.assert_allclose(t.on_input("speech", "hear-left", 1.0).closed.belief, [0.85, 0.15])


def test_an_input_that_is_no_symbol_is_invalid_and_observes_nothing():
    t = tracker()
    t.on_action("listen", 0.0)
    out = t.on_input("touchscreen", "roar", 0.1)
    assert (out.kind, out.symbol, out.closed, out.heard) == ("invalid", None, None, "invalid")
    assert t.counters()["invalid_touchscreen"] == 1 and t.step_open and t.warnings() == 1
    with pytest.raises(ValueError, match="unknown input 'smell'; inputs: speech, touchscreen, laser$"):
        t.on_input("smell", "hear-left", 0.2)


def test_zero_likelihood_is_counted():
    t = tracker(impossible=True)
    t.on_action("listen", 0.0)
    t.on_input("speech", "hear-left", 0.1)  # now certain: tiger-left
    t.on_action("listen", 0.2)
    r = t.on_input("speech", "hear-right", 0.3).closed  # impossible from tiger-left
    assert r.zero_likelihood and t.counters()["zero_likelihood"] == 1
    assert np.isfinite(r.belief).all() and r.belief.sum() == pytest.approx(1.0)


def test_bad_settings_name_the_parameter():
    with pytest.raises(ValueError, match=r"timeout_observation 'unknown' is not an observation of tiger "
                                         r"\(valid: hear-left, hear-right; or step_timeout 0\)"):
        tracker(step_timeout=1.0, timeout_observation="unknown")
    # No domain, so no silence symbol: a timeout needs one named.
    with pytest.raises(ValueError, match=r"timeout_observation: step_timeout 1 s needs the symbol a silent step "
                                         r"closes with; set it \(valid: hear-left, hear-right\)"):
        tracker(step_timeout=1.0)
    with pytest.raises(ValueError, match=r"step_timeout must be in \[0, 3600\], got -1.0"):
        StepSettings(step_timeout=-1.0)
    with pytest.raises(ValueError, match=r"max_pending must be in \[0, 1000\], got 5000"):
        StepSettings(max_pending=5000)


def test_no_timeout_actions_wait_for_an_input_however_long():
    # A drive ends with a laser landmark, never with silence: the step stays open.
    t = tracker(step_timeout=2.0, timeout_observation="hear-right", no_timeout_actions=("open-left",))
    t.on_action("open-left", 0.0)
    assert t.on_tick(500.0).kind == "idle" and t.step_open and t.counters()["timeouts"] == 0
    r = t.on_input("laser", "hear-left", 501.0).closed
    assert (r.action, r.observation, r.source) == ("open-left", "hear-left", "laser")
    t2 = tracker(step_timeout=2.0, timeout_observation="hear-right", no_timeout_actions=("open-left",))
    t2.on_action("listen", 0.0)
    assert t2.on_tick(2.0).closed.source == "timeout"      # other actions still time out
    # Names the model does not have are ignored (a params file shared between domains).
    assert tracker(no_timeout_actions=("fly",)).no_timeout_actions == frozenset()


def test_abandon_step_leaves_the_belief_and_the_queue():
    t = tracker(step_timeout=2.0, timeout_observation="hear-right")
    t.on_action("listen", 0.0)
    out = t.abandon_step()
    assert out.kind == "abandoned" and not t.step_open and t.deadline() is None and t.step == 0
    np.testing.assert_allclose(t.belief, [0.5, 0.5])
    assert t.abandon_step().kind == "idle"


def test_set_live_checks_everything_before_changing_anything():
    t = tracker(step_timeout=2.0, timeout_observation="hear-right")
    t.on_action("listen", 0.0)
    t.set_live(step_timeout=5.0, stale_after=1.0, confidence_floor=0.5)
    assert t.deadline() == 5.0 and t.settings.stale_after == 1.0 and t.settings.confidence_floor == 0.5
    with pytest.raises(ValueError, match=r"confidence_floor must be in \[0, 1\], got 2.0"):
        t.set_live(step_timeout=7.0, confidence_floor=2.0)
    assert t.deadline() == 5.0 and t.settings.step_timeout == 5.0     # nothing applied
    no_unknown = tracker()   # no domain, no silence symbol: a timeout cannot be turned on
    with pytest.raises(ValueError, match="timeout_observation: step_timeout 3 s needs the symbol"):
        no_unknown.set_live(step_timeout=3.0)
    assert no_unknown.settings.step_timeout == 0.0


def test_reset_zeroes_every_counter():
    t = tracker()
    t.on_action("listen", 0.0)
    t.on_input("speech", "hear-left", 0.1)
    t.on_input("touchscreen", "roar", 0.2)
    t.reset()
    assert set(t.counters().values()) == {0} and t.step == 0 and not t.step_open
    np.testing.assert_allclose(t.belief, [0.5, 0.5])


def test_zero_likelihood_is_reported_once(caplog):
    """The step loop reports a recovery as one event (the node logs it); the filter does not log it again."""
    import logging

    t = tracker(impossible=True)
    t.on_action("listen", 0.0)
    t.on_input("speech", "hear-left", 0.1)
    t.on_action("listen", 1.0)
    with caplog.at_level(logging.WARNING, logger="pearl_pomdp.belief"):
        out = t.on_input("speech", "hear-right", 1.1)  # impossible after a certain tiger-left
    events = [e for e in out.events if "zero likelihood" in e.text]
    assert t.counters()["zero_likelihood"] == 1 and len(events) == 1
    assert "pearl_pomdp.belief" not in {r.name for r in caplog.records}


def test_history_keeps_every_closed_step_whichever_route_closed_it():
    t = tracker(step_timeout=2.0, timeout_observation="hear-right")
    t.keep_history()
    t.on_input("laser", "hear-left", 0.0)
    t.on_action("listen", 0.1)                    # closed by the queued input
    t.on_action("listen", 1.0)
    t.on_tick(3.0)                                # closed by the timeout
    t.on_action("listen", 4.0)
    t.on_input("speech", "hear-left", 4.5)        # closed by an input
    assert [(r.step, r.source) for r in t.history] == [(1, "laser"), (2, "timeout"), (3, "speech")]
