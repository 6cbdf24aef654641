"""The tracker's step protocol without ROS: every documented case, with tiger's hand-computed beliefs
(listen + hear-left from uniform → [0.85, 0.15])."""
from __future__ import annotations

import numpy as np
import pytest

from pearl_pomdp.model.pomdp import Pomdp
from pearl_pomdp.tracking import StepProtocol


def tiger(impossible: bool = False) -> Pomdp:
    O_listen = [[1.0, 0.0], [0.0, 1.0]] if impossible else [[0.85, 0.15], [0.15, 0.85]]
    return Pomdp.create(["tiger-left", "tiger-right"], ["listen", "open-left", "open-right"],
                        ["hear-left", "hear-right"], [np.eye(2), np.full((2, 2), 0.5), np.full((2, 2), 0.5)],
                        np.array([O_listen, [[0.5, 0.5]] * 2, [[0.5, 0.5]] * 2]),
                        np.array([[-1.0, -100.0, 10.0], [-1.0, 10.0, -100.0]]), name="tiger")


def test_action_then_observation_closes_a_step():
    p = StepProtocol(tiger())
    assert p.on_action("listen", 1.0) is None and p.step_open
    r = p.on_observation("hear-left", "speech", 2.0)
    assert (r.step, r.action, r.observation, r.source, r.zero_likelihood) == (1, "listen", "hear-left", "speech", False)
    np.testing.assert_allclose(r.belief, [0.85, 0.15])
    assert not p.step_open and p.counters["updates"] == 1


def test_observation_before_action_waits_for_it():
    p = StepProtocol(tiger())
    assert p.on_observation("hear-left", "laser", 0.5) is None
    assert p.counters["queued"] == 1 and p.step == 0
    r = p.on_action("listen", 1.0)
    np.testing.assert_allclose(r.belief, [0.85, 0.15])
    assert r.source == "laser" and not p.pending


def test_queue_overflow_drops_the_oldest():
    p = StepProtocol(tiger(), max_pending=1)
    p.on_observation("hear-right", "speech", 0.0)
    p.on_observation("hear-left", "speech", 0.1)
    assert p.counters["dropped_overflow"] == 1 and [x.symbol for x in p.pending] == ["hear-left"]
    assert "dropped queued observation 'hear-right'" in p.take_events()[1].text
    np.testing.assert_allclose(p.on_action("listen", 1.0).belief, [0.85, 0.15])


def test_stale_observations_are_dropped_and_the_step_stays_open():
    p = StepProtocol(tiger(), stale_after=5.0)
    p.on_observation("hear-left", "speech", 0.0)
    assert p.on_action("listen", 10.0) is None
    assert p.counters["dropped_stale"] == 1 and p.step_open and p.step == 0


def test_timeout_closes_the_step_with_the_timeout_observation():
    p = StepProtocol(tiger(), step_timeout=2.0, timeout_observation="hear-right")
    p.on_action("listen", 10.0)
    assert p.on_tick(11.999) is None
    r = p.on_tick(12.0)
    assert (r.observation, r.source) == ("hear-right", "timeout") and p.counters["timeouts"] == 1
    np.testing.assert_allclose(r.belief, [0.15, 0.85])
    assert p.on_tick(100.0) is None  # no open step: nothing to close


def test_second_action_replaces_the_open_one_and_unknown_actions_are_ignored():
    p = StepProtocol(tiger())
    p.on_action("open-left", 0.0)
    p.on_action("listen", 0.1)
    assert p.on_action("dance", 0.2) is None
    assert p.counters["replaced_actions"] == 1 and p.counters["unknown_actions"] == 1
    assert p.current_action == "listen"
    np.testing.assert_allclose(p.on_observation("hear-left", "speech", 1.0).belief, [0.85, 0.15])


def test_zero_likelihood_is_counted():
    p = StepProtocol(tiger(impossible=True))
    p.on_action("listen", 0.0)
    p.on_observation("hear-left", "speech", 0.1)  # now certain: tiger-left
    p.on_action("listen", 0.2)
    r = p.on_observation("hear-right", "speech", 0.3)  # impossible from tiger-left
    assert r.zero_likelihood and p.counters["zero_likelihood"] == 1
    assert np.isfinite(r.belief).all() and r.belief.sum() == pytest.approx(1.0)


def test_bad_settings_name_the_parameter():
    with pytest.raises(ValueError, match=r"timeout_observation 'unknown' is not an observation of tiger "
                                         r"\(valid: hear-left, hear-right\)"):
        StepProtocol(tiger(), step_timeout=1.0)
    with pytest.raises(ValueError, match="step_timeout must be >= 0"):
        StepProtocol(tiger(), step_timeout=-1.0)
    with pytest.raises(ValueError, match="'roar' is not an observation of tiger"):
        StepProtocol(tiger()).on_observation("roar", "speech", 0.0)


def test_no_timeout_actions_wait_for_an_input_however_long():
    # A drive ends with a laser landmark, never with silence: the step stays open.
    p = StepProtocol(tiger(), step_timeout=2.0, timeout_observation="hear-right", no_timeout_actions=["open-left"])
    p.on_action("open-left", 0.0)
    assert p.on_tick(500.0) is None and p.step_open and p.counters["timeouts"] == 0
    r = p.on_observation("hear-left", "laser", 501.0)
    assert (r.action, r.observation, r.source) == ("open-left", "hear-left", "laser")
    p2 = StepProtocol(tiger(), step_timeout=2.0, timeout_observation="hear-right", no_timeout_actions=["open-left"])
    p2.on_action("listen", 0.0)
    assert p2.on_tick(2.0).source == "timeout"      # other actions still time out
    with pytest.raises(ValueError, match="no_timeout_actions names 'fly'"):
        StepProtocol(tiger(), step_timeout=2.0, timeout_observation="hear-right", no_timeout_actions=["fly"])


def test_zero_likelihood_is_reported_once(caplog):
    """The step loop reports a recovery as one event (the node logs it); the filter does not log it again."""
    import logging

    p = StepProtocol(tiger(impossible=True))
    p.on_action("listen", 0.0)
    p.on_observation("hear-left", "speech", 0.1)
    p.on_action("listen", 1.0)
    with caplog.at_level(logging.WARNING, logger="pearl_pomdp.belief"):
        p.on_observation("hear-right", "speech", 1.1)  # impossible after a certain tiger-left
    events = [e for e in p.take_events() if "zero likelihood" in e.text]
    assert p.counters["zero_likelihood"] == 1 and len(events) == 1
    assert "pearl_pomdp.belief" not in {r.name for r in caplog.records}
