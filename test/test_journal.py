"""The journal (pearl_pomdp/journal.py) and the core tracker's journal state: a belief that
survives a crash, and old or foreign journals refused with one line naming the file."""
from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np
import pytest

from pearl_pomdp.journal import FORMAT, Journal, decode_array, default_path, domain_hash, encode_array
from pearl_pomdp.model.domain_yaml import load_domain
from pearl_pomdp.tracking import BeliefTracker, StepSettings

REPO = Path(__file__).resolve().parents[1]
DOMAIN = REPO / "config" / "pearl.domain.yaml"


@pytest.fixture(scope="module")
def pearl():
    domain = load_domain(DOMAIN)
    return domain, domain.compile()


def tracker(pearl, **settings) -> BeliefTracker:
    domain, model = pearl
    return BeliefTracker(model, domain, StepSettings(**{"step_timeout": 5.0, **settings}))


def journal(tmp_path, **kw) -> Journal:
    return Journal(tmp_path / "j" / "belief_tracker.json", "belief_tracker", str(DOMAIN), domain_hash(DOMAIN), **kw)


def test_arrays_round_trip_bit_for_bit():
    values = np.random.default_rng(3).dirichlet(np.ones(1000))
    assert np.array_equal(decode_array(encode_array(values)), values)
    with pytest.raises(ValueError, match="whole float64"):
        decode_array("AAAA")


def test_default_path_is_per_ros_home_domain_and_node():
    path = default_path("/pearl/belief_tracker", 17, {"ROS_HOME": "/r"})
    assert path == Path("/r/pearl/journal/domain17/pearl__belief_tracker.json")
    assert default_path("belief_tracker", 3, {}) == Path.home() / ".ros/pearl/journal/domain3/belief_tracker.json"


def test_a_tracker_resumes_mid_step_with_the_journaled_belief(pearl, tmp_path):
    """Two closed steps, a third open, one input queued: the journal restores all of it exactly,
    and the open step keeps its deadline."""
    first = tracker(pearl)
    first.on_input("reminder", "g_physio", 0.5)          # queued: no step open yet
    first.on_action("DoNothing", 1.0)                    # closed at once by the queued input
    first.on_action("GotoPatientRoom", 2.0)
    first.on_input("laser", "atRoom", 3.0)
    first.on_action("RingDoorBell", 4.0)                 # open when the node dies
    first.on_input("laser", "atRoom", 4.5)               # no: closes it; open another
    first.on_action("RemindPhysioAppt", 5.0)
    j = journal(tmp_path)
    j.write(first.journal_state())
    found = j.load()
    assert found.state is not None and found.reason.startswith(f"resuming from journal {j.path}")
    second = tracker(pearl)
    second.resume(found.state)
    assert np.max(np.abs(second.belief - first.belief)) <= 1e-12
    assert np.array_equal(second.belief, first.belief)
    assert (second.step, second.open_action, second.opened_at, second.run) == \
        (first.step, "RemindPhysioAppt", 5.0, first.run)
    assert second.deadline() == first.deadline() == 10.0
    assert second.counters()["updates"] == first.counters()["updates"] == 3
    # The policy's latched copy of the open step's action is that step, not a new one...
    again = second.on_action("RemindPhysioAppt", 7.0)
    assert again.kind == "resumed" and second.opened_at == 5.0 and second.counters()["replaced_actions"] == 0
    # ... and the step closes as it would have in the first tracker.
    a, b = second.on_input("speech", "yes", 8.0), first.on_input("speech", "yes", 8.0)
    assert a.closed is not None and b.closed is not None
    assert np.array_equal(a.closed.belief, b.closed.belief) and a.closed.step == b.closed.step == 4


def test_a_resumed_tracker_takes_a_new_action_after_its_step_closed(pearl, tmp_path):
    first = tracker(pearl)
    first.on_action("RingDoorBell", 1.0)
    second = tracker(pearl)
    second.resume(first.journal_state())
    second.on_input("speech", "yes", 2.0)
    assert second.on_action("RingDoorBell", 3.0).kind == "opened"   # a new step of the same action
    assert second.opened_at == 3.0


def test_queued_observations_survive(pearl):
    first = tracker(pearl)
    first.on_input("speech", "what time is it", 1.0)
    second = tracker(pearl)
    second.resume(first.journal_state())
    assert second.pending == 1
    out = second.on_action("DoNothing", 2.0)
    assert out.closed is not None and out.closed.observation == "time"


def test_reset_draws_a_new_run(pearl):
    t = tracker(pearl)
    runs = {t.run}
    for _ in range(3):
        t.reset()
        runs.add(t.run)
    assert len(runs) == 4


def test_an_old_journal_is_refused_naming_the_file_and_its_age(pearl, tmp_path):
    j = journal(tmp_path, max_age=30.0)
    j.write(tracker(pearl).journal_state(), now=time.time() - 45.0)
    found = j.load()
    assert found.state is None
    assert found.reason.startswith(f"refused journal {j.path}: written 45.")
    assert "more than journal_max_age 30 s" in found.reason and "\n" not in found.reason


def test_a_journal_of_another_domain_file_is_refused(pearl, tmp_path):
    j = journal(tmp_path)
    j.write(tracker(pearl).journal_state())
    edited = Journal(j.path, "belief_tracker", "edited.domain.yaml", domain_hash(DOMAIN.read_bytes() + b"\n# edit\n"))
    found = edited.load()
    assert found.state is None
    assert found.reason.startswith(f"refused journal {j.path}: written for another domain")
    assert "edited.domain.yaml" in found.reason


@pytest.mark.parametrize("damage, why", [
    (lambda body: "{not json", "not JSON"),
    (lambda body: json.dumps({**body, "format": "pearl-journal/0"}), "format 'pearl-journal/0'"),
    (lambda body: json.dumps({**body, "kind": "hierarchical_policy"}), "written by a 'hierarchical_policy' node"),
    (lambda body: json.dumps({k: v for k, v in body.items() if k != "state"}), "no written_at time or no state"),
])
def test_a_damaged_journal_is_refused(pearl, tmp_path, damage, why):
    j = journal(tmp_path)
    j.write(tracker(pearl).journal_state())
    body = json.loads(j.path.read_text())
    assert body["format"] == FORMAT
    j.path.write_text(damage(body))
    found = j.load()
    assert found.state is None and why in found.reason and str(j.path) in found.reason


def test_a_missing_journal_starts_afresh(tmp_path):
    found = journal(tmp_path).load()
    assert found.state is None and found.reason.startswith("no journal")


@pytest.mark.parametrize("field, value, why", [
    ("belief", encode_array(np.ones(3) / 3), "belief has 3 states"),
    ("belief", encode_array(np.full(576, 1.0)), "not a distribution"),
    ("open_action", "Fly", "open_action 'Fly' is not an action"),
    ("step", -1, "step -1 < 0"),
    ("run", "x", "malformed field"),
])
def test_a_journal_state_that_does_not_fit_the_model_is_refused(pearl, field, value, why):
    state = tracker(pearl).journal_state()
    state.update({field: value, "opened_at": 1.0})
    t = tracker(pearl)
    before = (t.belief.copy(), t.step, t.run)
    with pytest.raises(ValueError, match=why):
        t.resume(state)
    assert np.array_equal(t.belief, before[0]) and (t.step, t.run) == before[1:]
