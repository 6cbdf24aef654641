"""The lifecycle supervisor's rules (pearl_pomdp/supervision.py): in order, heartbeat, comeback,
no restart loop."""
from __future__ import annotations

import pytest

from pearl_pomdp.supervision import Supervisor

NAMES = ["action_executor", "hierarchical_policy", "belief_tracker"]


def bring_up(sup: Supervisor, now: float = 0.0) -> list:
    """Answer every request as a healthy node does; the transitions asked, in order."""
    asked = []
    for name in sup.order:
        sup.answered(name, "unconfigured", now)
    for _ in range(10):
        todo, _ = sup.tick(now)
        for name, transition in todo:
            asked.append((name, transition))
            sup.transition_done(name, transition, True, now)
    return asked


def test_nodes_come_up_in_order_one_transition_at_a_time():
    sup = Supervisor(NAMES)
    assert sup.tick(0.0) == ([], [])          # nobody answered: nothing to do, nobody down
    sup.answered("belief_tracker", "unconfigured", 0.0)
    assert sup.tick(0.0)[0] == []             # the tracker waits for the executor and the policy
    asked = bring_up(sup)
    assert asked == [(n, t) for n in NAMES for t in ("configure", "activate")]
    assert all(sup.level(n) == "ok" for n in NAMES)


def test_a_node_in_a_transition_is_not_judged_by_its_heartbeat():
    sup = Supervisor(NAMES, heartbeat_timeout=2.0)
    for name in NAMES:
        sup.answered(name, "unconfigured", 0.0)
    todo, _ = sup.tick(0.0)
    assert todo == [("action_executor", "configure")]
    todo, events = sup.tick(60.0)             # configure takes a minute (a policy planned)
    assert todo == [] and all(e.node != "action_executor" for e in events)
    assert sup.nodes["action_executor"].state != "down"


def test_a_dead_node_is_reported_down_and_brought_back_when_respawned():
    sup = Supervisor(NAMES, heartbeat_timeout=2.0)
    bring_up(sup)
    for name in NAMES:
        if name != "hierarchical_policy":
            sup.answered(name, "active", 3.0)
    todo, events = sup.tick(3.0)
    assert todo == [] and [(e.level, e.node) for e in events] == [("error", "hierarchical_policy")]
    assert "no heartbeat for 3.0 s" in events[0].text and sup.level("hierarchical_policy") == "error"
    events = sup.answered("hierarchical_policy", "unconfigured", 5.0)       # respawned
    assert [e.level for e in events] == ["warn"] and "is back" in events[0].text
    asked = []
    for _ in range(3):
        todo, _ = sup.tick(5.0)
        for name, transition in todo:
            asked.append((name, transition))
            sup.transition_done(name, transition, True, 5.0)
    assert asked == [("hierarchical_policy", "configure"), ("hierarchical_policy", "activate")]
    assert sup.level("hierarchical_policy") == "ok" and sup.nodes["hierarchical_policy"].comebacks == 1


def test_a_restart_faster_than_the_heartbeat_is_noticed():
    sup = Supervisor(NAMES, heartbeat_timeout=5.0)
    bring_up(sup)
    events = sup.answered("belief_tracker", "unconfigured", 1.0)
    assert "is back" in events[0].text
    assert sup.tick(1.0)[0] == [("belief_tracker", "configure")]


def test_a_node_that_keeps_dying_is_left_down_not_restarted_in_a_loop():
    sup = Supervisor(NAMES, heartbeat_timeout=1.0, max_restarts=2, restart_window=100.0)
    bring_up(sup)
    now = 0.0
    comebacks = 0
    for _ in range(5):
        now += 10.0
        sup.answered("action_executor", "active", now)
        sup.answered("hierarchical_policy", "active", now)
        sup.answered("belief_tracker", "unconfigured", now)   # died and respawned again
        todo, _ = sup.tick(now)
        if todo:
            comebacks += 1
            for name, transition in todo:
                sup.transition_done(name, transition, True, now)
            todo, _ = sup.tick(now)
            for name, transition in todo:
                sup.transition_done(name, transition, True, now)
    assert comebacks == 2
    node = sup.nodes["belief_tracker"]
    assert node.left_down and sup.level("belief_tracker") == "error"
    assert sup.summary("belief_tracker").startswith("left down after 3")
    assert sup.tick(now + 1)[0] == []          # never touched again


def test_a_configure_that_fails_at_start_up_is_not_retried():
    sup = Supervisor(["belief_tracker"], max_restarts=2)
    sup.answered("belief_tracker", "unconfigured", 0.0)
    assert sup.tick(0.0)[0] == [("belief_tracker", "configure")]
    events = sup.transition_done("belief_tracker", "configure", False, 0.0)
    assert sup.nodes["belief_tracker"].left_down and sup.tick(1.0)[0] == []
    assert events[-1].level == "error" and "failed at start-up" in events[-1].text


def test_a_configure_that_keeps_failing_after_a_restart_is_given_up():
    sup = Supervisor(["belief_tracker"], max_restarts=2)
    bring_up(sup)
    sup.answered("belief_tracker", "unconfigured", 1.0)      # restarted: one comeback used
    tries = 0
    events = []
    for _ in range(10):
        todo, _ = sup.tick(1.0)
        for name, transition in todo:
            tries += 1
            events += sup.transition_done(name, transition, False, 1.0)
    assert tries == 2 and sup.nodes["belief_tracker"].left_down
    assert events[-1].level == "error" and "left down" in events[-1].text


def test_a_lost_transition_answer_asks_the_state_again():
    sup = Supervisor(["belief_tracker"])
    sup.answered("belief_tracker", "unconfigured", 0.0)
    assert sup.tick(0.0)[0] == [("belief_tracker", "configure")]
    events = sup.transition_done("belief_tracker", "configure", None, 1.0)
    assert events[0].level == "warn" and sup.tick(1.0)[0] == []       # state unknown: ask first
    sup.answered("belief_tracker", "inactive", 1.5)
    assert sup.tick(1.5)[0] == [("belief_tracker", "activate")]


@pytest.mark.parametrize("kwargs, why", [
    ({"names": []}, "no node"), ({"names": ["a", "a"]}, "named twice"),
    ({"names": ["a"], "heartbeat_timeout": 0}, "heartbeat_timeout"),
    ({"names": ["a"], "max_restarts": -1}, "max_restarts"),
    ({"names": ["a"], "restart_window": 0}, "restart_window"),
])
def test_bad_settings_are_refused_naming_them(kwargs, why):
    with pytest.raises(ValueError, match=why):
        Supervisor(**kwargs)


def test_after_start_a_down_node_does_not_hold_back_the_others():
    sup = Supervisor(NAMES, heartbeat_timeout=1.0)
    bring_up(sup)
    sup.answered("hierarchical_policy", "active", 5.0)
    sup.answered("belief_tracker", "unconfigured", 5.0)      # restarted; the executor is silent (down)
    todo, events = sup.tick(5.0)
    assert ("error", "action_executor") in [(e.level, e.node) for e in events]
    assert todo == [("belief_tracker", "configure")]
