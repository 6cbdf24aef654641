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


def _fsync_spy(monkeypatch, gate=None):
    """Record the path of every fd fsynced; ``gate``: an event the fsync thread's fsyncs wait for
    (the thread held back), the caller's own fsyncs never wait. An earlier test's background syncs are
    flushed first (the thread holds them up to ``SYNC_INTERVAL``), so only this test's are seen."""
    import os
    import threading

    from pearl_pomdp.journal import flush_journals

    assert flush_journals(timeout=10.0)

    synced = []
    real = os.fsync

    def spy(fd):
        synced.append(Path(os.readlink(f"/proc/self/fd/{fd}")))
        if gate is not None and threading.current_thread().name == "pearl-journal-fsync":
            assert gate.wait(10.0), "the test never released the fsync thread"
        real(fd)

    monkeypatch.setattr(os, "fsync", spy)
    return synced


def test_a_background_write_is_in_place_before_its_fsync_and_on_disk_after_the_flush(pearl, tmp_path, monkeypatch):
    """``background``: the caller returns with the new journal readable (what a killed node's restart
    reads) while the fsync thread is still held back; flushing waits for the file's and the directory's
    fsync."""
    import threading

    from pearl_pomdp.journal import flush_journals

    gate = threading.Event()
    synced = _fsync_spy(monkeypatch, gate)
    j = journal(tmp_path, sync="background")
    done = threading.Event()
    threading.Thread(target=lambda: (j.write({"step": 1}), done.set()), daemon=True).start()
    assert done.wait(5.0), "a background write waited for its fsync"
    assert j.load().state == {"step": 1}
    assert flush_journals(timeout=0.2) is False        # the fsync is held back: not on disk yet
    gate.set()
    assert flush_journals(timeout=10.0) is True
    assert j.path.resolve() in synced and j.path.parent.resolve() in synced


def test_background_writes_faster_than_the_sync_interval_share_rounds_and_a_lone_write_is_synced_soon(
        tmp_path, monkeypatch):
    """``background``: 200 writes back to back (a flood, or steps back to back) cost a handful of fsync
    rounds, not 200, and still reach the disk; a write after a quiet spell is on disk within about one
    :data:`SYNC_INTERVAL`; a flush does not wait for the interval."""
    import time

    from pearl_pomdp.journal import SYNC_INTERVAL, flush_journals

    synced = _fsync_spy(monkeypatch)
    j = journal(tmp_path, sync="background")
    start = time.monotonic()
    for step in range(200):
        j.write({"step": step})
    burst = time.monotonic() - start
    assert flush_journals(timeout=10.0) is True
    rounds = synced.count(j.path.resolve())
    # one round per interval the burst lasted, plus the first and the flush's
    assert 1 <= rounds <= burst / SYNC_INTERVAL + 3, f"{rounds} fsync rounds for 200 writes in {burst:.2f} s"
    assert j.load().state == {"step": 199}
    time.sleep(1.5 * SYNC_INTERVAL)                # a quiet spell
    synced.clear()
    j.write({"step": 200})
    start = time.monotonic()
    while j.path.resolve() not in synced and time.monotonic() - start < 5.0:
        time.sleep(0.005)
    assert j.path.resolve() in synced and time.monotonic() - start <= SYNC_INTERVAL + 0.5
    synced.clear()
    j.write({"step": 201})                         # inside the interval: held back ...
    start = time.monotonic()
    assert flush_journals(timeout=10.0) is True    # ... until the flush asks for it now
    assert time.monotonic() - start < SYNC_INTERVAL / 2 and j.path.resolve() in synced


@pytest.mark.parametrize("sync", ["background", "fsync", "none"])
def test_a_written_journal_is_byte_for_byte_what_json_dumps_gives(tmp_path, sync):
    """The write splices the base64 of large arrays in without ``json.dumps`` scanning them; the file is
    still exactly the plain dump, with awkward strings (quotes, NUL, non-ASCII) beside two arrays."""
    rng = np.random.default_rng(5)
    big, small = rng.random(233_280), rng.random(3)
    state = {"num_states": 233_280, "belief": encode_array(big), "open_action": 'Say "\0 hé"',
             "queue": [{"topic": "speech", "text": "\u0000"}], "weights": encode_array(small), "step": 7}
    j = journal(tmp_path, sync=sync)
    j.write(state, now=1234.5)
    token = json.loads(j.path.read_text())["base"]   # the whole write's random token (module doc)
    assert isinstance(token, str) and len(token) == 16
    body = {"format": FORMAT, "kind": j.kind, "domain": j.domain, "domain_hash": j.domain_hash,
            "written_at": 1234.5, "base": token, "state": state}
    assert j.path.read_bytes() == json.dumps(body, separators=(",", ":")).encode("utf-8")
    assert np.array_equal(decode_array(json.loads(j.path.read_text())["state"]["belief"]), big)


def test_an_fsync_write_is_on_disk_when_it_returns(tmp_path, monkeypatch):
    synced = _fsync_spy(monkeypatch)
    j = journal(tmp_path, sync="fsync")
    j.write({"step": 1})
    assert len(synced) == 2 and synced[1] == j.path.parent.resolve()   # the temporary file, then the directory
    none = journal(tmp_path / "n", sync="none")
    none.write({"step": 1})
    assert len(synced) == 2 and none.load().state == {"step": 1}


def test_an_unknown_sync_mode_names_the_parameter(tmp_path):
    with pytest.raises(ValueError, match=r"journal_sync: 'always' is not one of fsync, background, none"):
        journal(tmp_path, sync="always")


def test_a_writer_killed_between_unlinking_and_renaming_leaves_the_next_journal_to_resume_from(tmp_path):
    """``background``/``none`` write the next journal complete beside the old one, unlink the old and
    rename the next: a death in between leaves only the next one, and load() reads it."""
    from pearl_pomdp.journal import _next_path

    j = journal(tmp_path, sync="none")
    j.write({"step": 1})
    j.write({"step": 2})
    assert j.load().state == {"step": 2} and not _next_path(j.path).exists()
    j.path.rename(_next_path(j.path))          # as if killed after the unlink, before the rename
    found = j.load()
    assert found.state == {"step": 2} and "resuming from journal" in found.reason
    j.write({"step": 3})
    assert j.load().state == {"step": 3} and not _next_path(j.path).exists()
    _next_path(j.path).write_text('{"format": "pearl-jou')   # killed while writing the next one
    assert j.load().state == {"step": 3}
    j.remove()
    assert not j.path.exists() and not _next_path(j.path).exists()
    assert j.load().state is None


def _kill_a_writer_repeatedly(path: Path, writer: str, rounds: int, kind: str = "belief_tracker"):
    """Run ``writer`` (Python that journals to ``sys.argv[1]`` as fast as it can and prints a count now
    and then) and SIGKILL it ``rounds`` times at spread moments (after 1-4 printed counts, then 0-12 ms);
    yield each time the count it had printed last and what :meth:`Journal.load` then finds."""
    import signal
    import subprocess
    import sys

    for round_ in range(rounds):
        proc = subprocess.Popen([sys.executable, "-c", writer, str(path)], stdout=subprocess.PIPE, text=True,
                                cwd=REPO)
        try:
            assert proc.stdout is not None
            for _ in range(1 + round_ % 4):
                reported = int(proc.stdout.readline())
            time.sleep(0.003 * (round_ % 5))
        finally:
            proc.send_signal(signal.SIGKILL)
            proc.wait(10)
        found = Journal(path, kind, "d", "sha256:0").load()
        assert found.state is not None, found.reason
        yield reported, found.state
        Journal(path, kind, "d", "sha256:0").remove()


@pytest.mark.parametrize("sync", ["none", "background"])
def test_a_writer_killed_at_any_moment_leaves_a_journal_that_loads(tmp_path, sync):
    """SIGKILL a process that journals as fast as it can, 12 times at spread moments: every time the
    journal loads whole, at a step at or after the one it had reported as written."""
    writer = (
        "import sys\n"
        "from pearl_pomdp.journal import Journal\n"
        f"j = Journal(sys.argv[1], 'belief_tracker', 'd', 'sha256:0', sync={sync!r})\n"
        "step = 0\n"
        "while True:\n"
        "    j.write({'step': step, 'pad': 'x' * (step % 9000)})\n"
        "    if step % 50 == 0:\n"
        "        print(step, flush=True)\n"
        "    step += 1\n")
    for reported, state in _kill_a_writer_repeatedly(tmp_path / "killed.json", writer, 12):
        assert state["step"] >= reported and state["pad"] == "x" * (state["step"] % 9000)


@pytest.mark.parametrize("sync", ["background", "fsync", "none"])
def test_a_write_with_the_same_arrays_goes_to_the_small_update_file_and_loads_whole(tmp_path, sync):
    """A step opening (same belief object, new small fields) replaces only ``name.update.json``; the
    whole journal keeps its bytes; load() gives the state of the last write, arrays included."""
    from pearl_pomdp.journal import update_path

    belief = encode_array(np.random.default_rng(2).dirichlet(np.ones(233_280)))
    j = journal(tmp_path, sync=sync)
    j.write({"belief": belief, "step": 4, "open_action": None}, now=100.0)
    whole = j.path.read_bytes()
    j.write({"belief": belief, "step": 4, "open_action": "GuideToPhysio"}, now=101.0)
    assert j.path.read_bytes() == whole and (j.writes, j.updates) == (2, 1)
    assert update_path(j.path).name == "belief_tracker.update.json"
    assert update_path(j.path).stat().st_size < 400 < len(whole) // 1000
    found = j.load(now=102.0)
    assert found.state == {"belief": belief, "step": 4, "open_action": "GuideToPhysio"}
    assert found.age == pytest.approx(1.0)                     # the update's time, not the whole write's
    # An equal array that is another object (a new belief equal in value) is written whole.
    j.write({"belief": encode_array(decode_array(belief)), "step": 5, "open_action": None}, now=103.0)
    assert j.path.read_bytes() != whole and j.updates == 1
    assert j.load(now=103.0).state["step"] == 5
    j.remove()
    assert not update_path(j.path).exists() and j.load().state is None


def test_an_update_of_an_older_whole_journal_is_never_applied(tmp_path):
    """Whole write A, an update of A, whole write B: B loads without A's update (its token is A's). A
    damaged or foreign update is left unused; the whole journal loads as it is."""
    from pearl_pomdp.journal import _next_path, update_path

    first, second = encode_array(np.array([0.25, 0.75])), encode_array(np.array([0.5, 0.5]))
    j = journal(tmp_path, sync="none")
    j.write({"belief": first, "step": 1, "open_action": None})
    j.write({"belief": first, "step": 1, "open_action": "TellTime"})
    stale = update_path(j.path).read_bytes()
    j.write({"belief": second, "step": 2, "open_action": None})
    assert j.load().state == {"belief": second, "step": 2, "open_action": None}
    # as if killed after B's whole write, before its update: A's update is still there
    update_path(j.path).write_bytes(stale)
    assert j.load().state == {"belief": second, "step": 2, "open_action": None}
    j.write({"belief": second, "step": 2, "open_action": "TellWeather"})
    assert j.load().state["open_action"] == "TellWeather"
    # the update's writer killed between unlinking and renaming: the next update is read
    update_path(j.path).rename(_next_path(update_path(j.path)))
    assert j.load().state["open_action"] == "TellWeather"
    _next_path(update_path(j.path)).unlink()
    for damaged in ('{"format": "pearl-jou', json.dumps({"format": FORMAT, "kind": "hierarchical_policy",
                                                          "base": json.loads(j.path.read_text())["base"],
                                                          "domain_hash": j.domain_hash, "written_at": 1.0,
                                                          "state": {"step": 99}})):
        update_path(j.path).write_text(damaged)
        assert j.load().state == {"belief": second, "step": 2, "open_action": None}


def test_a_tracker_journals_a_step_opening_as_an_update_and_resumes_it(pearl, tmp_path):
    """The tracker keeps its encoded belief until the belief changes, so a step's opening and a
    queued input are updates, and a closed step is written whole; each loads as the tracker was."""
    t = tracker(pearl)
    j = journal(tmp_path, sync="none")
    j.write(t.journal_state())
    t.on_action("GotoPatientRoom", 1.0)              # opens: the same belief
    j.write(t.journal_state())
    t.on_input("laser", "atRoom", 2.0)               # closes: a new belief
    j.write(t.journal_state())
    t.on_input("speech", "what time is it", 3.0)     # queued: no step open
    j.write(t.journal_state())
    t.on_action("RingDoorBell", 4.0)                 # the queued input closes it at once; a new belief
    j.write(t.journal_state())
    t.on_action("TellTime", 5.0)
    j.write(t.journal_state())
    assert (j.writes, j.updates) == (6, 3)
    second = tracker(pearl)
    second.resume(j.load().state)
    assert np.array_equal(second.belief, t.belief)
    assert (second.step, second.open_action, second.opened_at, second.run, second.pending) == \
        (t.step, "TellTime", 5.0, t.run, 0)


@pytest.mark.parametrize("sync", ["none", "background"])
def test_a_writer_killed_at_any_moment_between_whole_writes_and_updates_loads_one_state(tmp_path, sync):
    """SIGKILL a process that writes a new array every third write and only small fields between
    (8 rounds; the plain writer's test above has 12):
    every time, the loaded small fields belong to the loaded array's write (never an update of
    another), at a write at or after the one reported."""
    writer = (
        "import sys\n"
        "import numpy as np\n"
        "from pearl_pomdp.journal import Journal, encode_array\n"
        f"j = Journal(sys.argv[1], 'belief_tracker', 'd', 'sha256:0', sync={sync!r})\n"
        "step = 0\n"
        "while True:\n"
        "    if step % 3 == 0:\n"
        "        arrays, of = encode_array(np.full(20_000, float(step))), step\n"
        "    j.write({'belief': arrays, 'of': of, 'step': step})\n"
        "    if step % 30 == 0:\n"
        "        print(step, flush=True)\n"
        "    step += 1\n")
    for reported, state in _kill_a_writer_repeatedly(tmp_path / "killed.json", writer, 8):
        assert state["step"] >= reported and state["of"] == state["step"] - state["step"] % 3
        assert np.all(decode_array(state["belief"]) == state["of"])


def test_growing_lists_are_appended_to_a_log_and_load_whole(tmp_path):
    """A simulator's calls only grow: each write appends the new ones as one line of the journal's log,
    the journal itself stays the same size however long the lists get, and load() gives them whole."""
    j = journal(tmp_path, sync="none")
    calls: list = []
    sizes = []
    for tick in range(300):
        calls.append(["wait", tick * 0.5])
        if tick % 7 == 0:
            calls.append(["act", f"A{tick}"])
        j.write({"now": tick * 0.5}, growing={"calls": calls, "taken": [c[1] for c in calls if c[0] == "act"]})
        sizes.append(j.path.stat().st_size)
    # a few digits more (the time, the log's line count), never the lists: ~6 kB by the end
    assert max(sizes) - min(sizes) <= 12 and len(json.dumps(calls)) > 10 * max(sizes)
    logs = sorted(j.path.parent.glob("belief_tracker.*.log"))
    assert len(logs) == 1 and len(logs[0].read_text().splitlines()) == 300
    found = j.load()
    assert found.state == {"now": 149.5, "calls": calls, "taken": [c[1] for c in calls if c[0] == "act"]}
    with pytest.raises(ValueError, match=r"growing field 'calls' has 3 items, 343 were logged"):
        j.write({}, growing={"calls": calls[:3], "taken": []})
    with pytest.raises(ValueError, match=r"growing fields \['calls'\], this journal logs \['calls', 'taken'\]"):
        j.write({}, growing={"calls": calls})


def test_a_resumed_journal_starts_a_fresh_log_and_drops_the_old_one_once_it_is_written(tmp_path):
    """A restarted node's Journal logs the whole lists it resumed in a log of its own; the old log is
    removed only after the journal names the new one; remove() leaves no log."""
    first = journal(tmp_path, sync="none")
    first.write({"now": 1.0}, growing={"calls": [1, 2, 3]})
    first.write({"now": 2.0}, growing={"calls": [1, 2, 3, 4]})
    second = journal(tmp_path, sync="none")
    state = second.load().state
    assert state == {"now": 2.0, "calls": [1, 2, 3, 4]}
    old = list(tmp_path.glob("j/*.log"))
    second.write({"now": 3.0}, growing={"calls": state["calls"] + [5]})
    new = list(tmp_path.glob("j/*.log"))
    assert len(old) == len(new) == 1 and old != new
    assert journal(tmp_path).load().state == {"now": 3.0, "calls": [1, 2, 3, 4, 5]}
    second.remove()
    assert not list(tmp_path.glob("j/*")) and second.load().state is None


def test_a_journal_whose_log_lacks_a_line_it_counts_is_refused_and_an_uncounted_line_is_ignored(tmp_path):
    j = journal(tmp_path, sync="none")
    j.write({"now": 1.0}, growing={"calls": ["a"]})
    counted = j.path.read_bytes()
    j.write({"now": 2.0}, growing={"calls": ["a", "b"]})
    j.path.write_bytes(counted)    # as if killed after the second line's append, before its journal
    assert j.load().state == {"now": 1.0, "calls": ["a"]}
    (log,) = tmp_path.glob("j/*.log")
    log.write_text(log.read_text().splitlines()[0][:-5] + "\n")     # the counted line cut short
    found = j.load()
    assert found.state is None
    assert f"refused journal {j.path}: its log {log} has 0 of the 1 whole lines it counts" in found.reason
    log.unlink()
    assert "has 0 of the 1 whole lines" in j.load().reason


@pytest.mark.parametrize("sync", ["none", "background"])
def test_a_writer_killed_at_any_moment_while_logging_loads_whole_lists(tmp_path, sync):
    """SIGKILL a process that appends to a growing list and journals after every item: every time the
    list loads whole (0..n-1, nothing missing or doubled) and agrees with the journal's own count."""
    writer = (
        "import sys\n"
        "from pearl_pomdp.journal import Journal\n"
        f"j = Journal(sys.argv[1], 'pearl_sim_world', 'd', 'sha256:0', sync={sync!r})\n"
        "calls = []\n"
        "while True:\n"
        "    calls.append(len(calls))\n"
        "    j.write({'n': len(calls)}, growing={'calls': calls})\n"
        "    if len(calls) % 50 == 0:\n"
        "        print(len(calls), flush=True)\n")
    for reported, state in _kill_a_writer_repeatedly(tmp_path / "killed.json", writer, 8, "pearl_sim_world"):
        assert state["n"] >= reported and state["calls"] == list(range(state["n"]))
