"""Navigation that can fail (issue 14 item 3): drive deadlines in the core tracker, navFailed,
the simulator's blocked corridor, and the manager's reaction — in the fast path and over DDS."""
from __future__ import annotations

import math
import re
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
from ros_helpers import DOMAIN  # noqa: E402

from pearl_pomdp.errors import SpecError  # noqa: E402
from pearl_pomdp.model.domain_yaml import load_domain  # noqa: E402
from pearl_pomdp.navigation import DriveDeadline, DriveTimer, Place  # noqa: E402
from pearl_pomdp.params import step_settings  # noqa: E402
from pearl_pomdp.tracking import BeliefTracker, StepSettings  # noqa: E402
from pearl_sim.nursing_home.scenario import load_scenarios, parse_scenarios  # noqa: E402
from pearl_sim.nursing_home.world import World  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
NAV_BLOCKED = REPO / "config" / "scenarios" / "nav_blocked.yaml"
#: The params file's places: home (0, 0) → room (8, 3.5) is 8.7321 m.
HOME_TO_ROOM = math.hypot(8.0, 3.5)


@pytest.fixture(scope="module")
def pearl():
    domain = load_domain(DOMAIN)
    return domain, domain.compile()


@pytest.fixture(scope="module")
def designer():
    """The designer's rows (the shipped file without its fitted section): the posterior below is
    hand-computed from them."""
    domain = load_domain(DOMAIN, fitted=False)
    return domain, domain.compile()


def tracker(pearl, **overrides) -> BeliefTracker:
    domain, model = pearl
    return BeliefTracker(model, domain, step_settings(**overrides))


def place_marginal(t: BeliefTracker) -> dict:
    return t.marginals()["RobotLocation"]


# ------------------------------------------------------------------ core
def test_a_drive_that_never_arrives_closes_at_its_deadline_with_navFailed(designer):
    t = tracker(designer)
    assert t.on_action("GotoPatientRoom", 100.0).kind == "opened"
    expected = 10.0 + 1.5 * 1.4 * HOME_TO_ROOM / 0.6          # the params file's drive rule
    assert t.deadline() == pytest.approx(100.0 + expected)
    assert expected == pytest.approx(40.562, abs=1e-3)
    assert t.on_tick(100.0 + expected - 0.01).closed is None and t.step_open
    out = t.on_tick(100.0 + expected)
    closed = out.closed
    assert (closed.action, closed.observation, closed.source) == ("GotoPatientRoom", "navFailed", "nav_deadline")
    assert t.counters()["nav_failures"] == 1 and t.counters()["timeouts"] == 0
    assert t.warnings() == 1                                   # /diagnostics turns WARN
    assert "did not arrive within its deadline of 40.6 s" in t.last_nav_failure
    assert any(e.level == "warn" and "navFailed" in e.text for e in out.events)
    # The domain's rows: a failed drive most likely left the robot where it was.
    marginal = place_marginal(t)
    assert marginal["home"] == pytest.approx(0.03 * 0.9 / (0.03 * 0.9 + 0.97 * 0.01))
    assert marginal["home"] > 0.7 and marginal["physio"] == 0.0


def test_an_arrival_before_the_deadline_closes_the_drive_as_before(pearl):
    t = tracker(pearl)
    t.on_action("GotoPatientRoom", 0.0)
    closed = t.on_input("laser", "atRoom", 30.0).closed
    assert closed.observation == "atRoom" and t.deadline() is None
    assert place_marginal(t)["room"] > 0.99
    # The next drive is timed from where the belief puts the robot now: room → physio.
    t.on_action("GoHome", 31.0)
    assert t.deadline() == pytest.approx(31.0 + 10.0 + 2.1 * HOME_TO_ROOM / 0.6)


def test_progress_reports_move_the_drive_deadline_while_the_robot_gets_closer(pearl):
    """Nav2's distance remaining (a path length: no path factor) times what is left of the drive."""
    t = tracker(pearl)
    t.on_action("GotoPatientRoom", 100.0)
    assert t.deadline() == pytest.approx(100.0 + 10.0 + 2.1 * HOME_TO_ROOM / 0.6)   # 140.56: from home
    # A detour: 20 m of path left at 105 s — later than the guess from the straight line.
    out = t.on_drive_progress("GotoPatientRoom", 20.0, 105.0)
    assert out.kind == "moved" and t.deadline() == pytest.approx(105.0 + 10.0 + 1.5 * 20.0 / 0.6)   # 165
    # Closer: 4 m at 130 s — earlier.
    assert t.on_drive_progress("GotoPatientRoom", 4.0, 130.0).kind == "moved"
    assert t.deadline() == pytest.approx(130.0 + 10.0 + 1.5 * 4.0 / 0.6)                        # 150
    # Standing still or backing off gains no time; a report for another action moves nothing.
    assert t.on_drive_progress("GotoPatientRoom", 4.0, 140.0).kind == "idle"
    assert t.on_drive_progress("GotoPatientRoom", 6.0, 141.0).kind == "idle"
    assert t.on_drive_progress("GoHome", 0.5, 142.0).kind == "idle"
    assert t.deadline() == pytest.approx(150.0)
    assert t.counters()["drive_progress"] == 5 and t.counters()["deadline_moves"] == 2
    assert t.warnings() == 0                                   # progress is no warning
    # The moved deadline is the one the step closes at.
    assert t.on_tick(149.9).closed is None
    assert t.on_tick(150.0).closed.observation == "navFailed"
    # No report once the step is closed, none without a timed drive.
    assert t.on_drive_progress("GotoPatientRoom", 1.0, 151.0).kind == "idle" and t.deadline() is None
    t.on_action("TellTime", 152.0)
    assert t.on_drive_progress("TellTime", 1.0, 153.0).kind == "idle"


def test_progress_never_moves_a_deadline_past_drive_max_seconds_and_resumes_from_the_journal(pearl):
    t = tracker(pearl, drive_max_seconds=120.0)
    t.on_action("GotoPatientRoom", 0.0)
    t.on_drive_progress("GotoPatientRoom", 500.0, 60.0)       # 10 + 1250 s wanted: capped at 120 s from the start
    assert t.deadline() == pytest.approx(120.0)
    assert t.on_drive_progress("GotoPatientRoom", float("nan"), 61.0).kind == "idle"
    assert t.on_drive_progress("GotoPatientRoom", -1.0, 61.0).kind == "idle"
    t.on_drive_progress("GotoPatientRoom", 3.0, 62.0)
    assert t.deadline() == pytest.approx(62.0 + 10.0 + 7.5)
    resumed = tracker(pearl, drive_max_seconds=120.0)
    resumed.resume(t.journal_state())
    assert resumed.deadline() == pytest.approx(79.5)           # the moved deadline survives a restart


def test_guidance_is_timed_at_the_slowest_residents_pace_and_speech_still_times_out(pearl):
    domain, model = pearl
    settings = step_settings(location_names=["home", "room", "physio"], **{
        "locations.home": [0.0, 0.0, 0.0], "locations.room": [15.0, 0.0, 0.0], "locations.physio": [15.0, 30.0, 0.0]})
    t = BeliefTracker(model, domain, settings)
    timer = t.drive_timer
    assert timer.goals == {"GotoPatientRoom": "room", "GuideToPhysio": "physio", "GoHome": "home"}
    assert timer.seconds("GuideToPhysio", "room") == pytest.approx(min(1800.0, 10 + 2.1 * 30 / 0.03))
    assert timer.seconds("GotoPatientRoom", "home") == pytest.approx(62.5)
    assert timer.seconds("GotoPatientRoom", None) == pytest.approx(10 + 2.1 * 30 / 0.6)  # from the farthest: physio
    t.on_action("TellTime", 0.0)
    assert t.deadline() == pytest.approx(10.0)                # step_timeout of the params file


def test_drive_speed_zero_keeps_drives_untimed(pearl):
    t = tracker(pearl, drive_speed=0.0)
    t.on_action("GotoPatientRoom", 0.0)
    assert t.drive_timer is None and t.deadline() is None and t.on_tick(1e6).closed is None


def test_a_drive_goal_without_a_pose_is_a_named_error(pearl):
    domain, model = pearl
    with pytest.raises(ValueError, match=r"location_names: drive GuideToPhysio goes to 'physio', which has no pose"):
        BeliefTracker(model, domain, step_settings(location_names=["home", "room"]))
    with pytest.raises(ValueError, match="place_feature 'Where' is not a feature"):
        BeliefTracker(model, domain, step_settings(place_feature="Where"))
    with pytest.raises(ValueError, match=r"drive_slack must be in \[1, 10\], got 0.5"):
        BeliefTracker(model, domain, step_settings(drive_slack=0.5))


def test_a_domain_without_navFailed_keeps_drives_untimed_and_says_so():
    from pearl_pomdp.model.domain_yaml import parse_domain

    from pearl_pomdp.fit import FITTED_MARKER

    text = (REPO / "config" / "pearl.domain.yaml").read_text().split(FITTED_MARKER)[0]
    old = text.replace("symbols: [atRoom, atPhysio, atHome, navFailed, userLost]", "symbols: [atRoom, atPhysio, atHome]")
    for symbol in ("navFailed", "userLost"):   # as the domain was before issue 14 (a recorded bag's copy)
        old = _drop_symbol(old, symbol)
    domain = parse_domain(old, "old.domain.yaml")
    t = BeliefTracker(domain.compile(), domain, step_settings())
    assert t.drive_timer is None
    assert any("drives have no deadline" in e.text for e in t.startup_events)


def _drop_symbol(text: str, symbol: str) -> str:
    """Remove ``symbol: p`` from every row and move its mass to the row's first entry."""
    def fix(match):
        row = match.group(0)
        m = re.search(rf",\s*{symbol}: ([0-9.]+)", row) or re.search(rf"{symbol}: ([0-9.]+),\s*", row)
        if not m:
            return row
        mass = float(m.group(1))
        row = row.replace(m.group(0), "", 1)
        first = re.search(r"\{\s*([A-Za-z_]+): ([0-9.]+)", row)
        return row.replace(first.group(0), "{" + f"{first.group(1)}: {float(first.group(2)) + mass:.6g}", 1)

    return re.sub(r"\{[^{}\n]*\}", fix, text)


def test_drive_timer_validates_its_inputs():
    places = {"a": Place("a", 0, 0), "b": Place("b", 3, 4)}
    timer = DriveTimer({"Go": "b"}, places, DriveDeadline(speed=1.0, path_factor=1.0, slack=1.0, margin=0.0))
    assert timer.seconds("Go", "a") == pytest.approx(5.0) and timer.seconds("Talk", "a") is None
    with pytest.raises(ValueError, match="guide_speed must be > 0"):
        DriveTimer({"Go": "b"}, places, guide_speed=0.0)


# ------------------------------------------------------------------ the simulator
def test_scenario_blocked_field_is_checked():
    base = "name: t\n"
    (s,) = parse_scenarios(base + "blocked: [{between: [home, room], from: 10, until: 60}]\n")
    assert s.is_blocked("room", "home", 10.0) and not s.is_blocked("home", "room", 60.0)
    assert not s.is_blocked("home", "room", 9.0) and not s.is_blocked("room", "physio", 20.0)
    (forever,) = parse_scenarios(base + "blocked: [{between: [room, physio]}]\n")
    assert forever.is_blocked("physio", "room", 1e9)
    for bad, where in (("[{between: [home, kitchen]}]", "blocked[0].between"),
                       ("[{between: [home, home]}]", "blocked[0].between"),
                       ("[{between: [home, room], from: 5, until: 5}]", "blocked[0].until"),
                       ("[{between: [home, room], when: 5}]", "blocked[0].when")):
        with pytest.raises(SpecError, match=re.escape(where)):
            parse_scenarios(base + f"blocked: {bad}\n")


def test_a_blocked_drive_reports_nothing_and_the_scheduler_waits():
    (s,) = load_scenarios(NAV_BLOCKED)
    world = World(s, seed=0)
    result = world.act("GotoPatientRoom")
    assert result.messages == [] and world.robot_at == "home" and world.metrics.blocked_drives == 1
    assert any("blocked" in e for e in result.events)
    waited = world.wait(200.0)                       # the physio reminder fell due at 5 s
    assert waited.messages == [] and world.time == pytest.approx(200.0)
    assert world.act("GotoPatientRoom").messages == []  # still blocked at 200 s
    world.wait(310.0)
    arrived = world.act("GotoPatientRoom")           # cleared at 300 s
    assert [m.text for m in arrived.messages] == ["atRoom"] and world.robot_at == "room"


def run_fast(scenario, seed, decider, pearl):
    from pearl_sim.nursing_home.agents import Controller
    from pearl_sim.nursing_home.experiment import episode_executive
    from pearl_sim.loop import ExecutiveBackend, run_episode

    domain, model = pearl
    world = World(scenario, seed=seed, domain=domain)
    backend = ExecutiveBackend(episode_executive(Controller("hierarchical", decider), domain, scenario, model))
    trace = run_episode(world, backend)
    return world, backend, trace


def test_the_manager_retries_a_blocked_drive_and_carries_on_once_it_is_clear(pearl, pearl_policy):
    from pearl_pomdp.hierarchy import load_hierarchical_policy

    (scenario,) = load_scenarios(NAV_BLOCKED)
    decider = load_hierarchical_policy(pearl_policy, pearl[0])
    completed = 0
    for seed in range(10):
        world, backend, trace = run_fast(scenario, seed, decider, pearl)
        steps = backend.executive.steps
        assert len(trace.actions) == scenario.max_steps        # ran to the end: nothing hung
        failed = [s for s in steps if s.observation == "navFailed"]
        # Every drive started while the corridor was blocked (before 300 s) closed at its deadline
        # of 62.5 s (15 m at 0.6 m/s), and each was followed by another try.
        assert len(failed) == world.metrics.blocked_drives >= 4
        assert all(s.source == "nav_deadline" and s.action == "GotoPatientRoom" for s in failed)
        for i, s in enumerate(steps):
            if s.observation != "navFailed":
                continue
            started = steps[i - 1].time if i > 0 else 0.0
            assert s.time - started == pytest.approx(62.5)       # the drive's deadline, from when it started
            assert steps[i + 1].action == "GotoPatientRoom"     # retry
        assert backend.executive.tracker.counters()["nav_failures"] == len(failed)
        completed += world.metrics.guidances_completed
    assert completed >= 8, f"only {completed} of 10 guidances completed after the corridor cleared"


# ------------------------------------------------------------------ over DDS
def test_over_dds_the_drive_closes_at_its_deadline_diagnostics_say_why_and_actions_agree(
        pearl, pearl_policy, tmp_path):
    """The nav_blocked episode through the real nodes under /clock: the same actions and
    beliefs as the fast path, and /diagnostics names the missed deadline."""
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.context import Context
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
    from rclpy.signals import SignalHandlerOptions
    from pearl_interfaces.msg import Belief

    from ros_helpers import allocate_domain_id, configure_test_process
    from pearl_pomdp.hierarchy import load_hierarchical_policy
    from pearl_pomdp.nodes.graph import PearlGraph
    from pearl_pomdp.nodes import conversions as cv
    from pearl_pomdp.nodes.sim_clock import SimClockDriver
    from pearl_sim.loop import run_episode
    from pearl_sim.nodes import GraphBackend, SimulatedHardware

    domain, model = pearl
    decider = load_hierarchical_policy(pearl_policy, domain)
    (scenario,) = load_scenarios(NAV_BLOCKED)
    steps = 9
    world_fast, backend_fast, _ = run_fast(scenario, 3, decider, pearl)
    fast_actions = [s.action for s in backend_fast.executive.steps][:steps]
    fast_beliefs = backend_fast.beliefs()

    configure_test_process(tmp_path)
    context = Context()
    rclpy.init(args=["--ros-args", "--log-level", "error"], context=context,
               domain_id=allocate_domain_id(), signal_handler_options=SignalHandlerOptions.NO)
    graph = sim = None
    try:
        graph = PearlGraph(context=context, domain=domain, model=model, decider=decider, parameter_services=False,
                           overrides={"belief_tracker": {**scenario.tracker_parameters(), "diagnostics_period": 3600.0}})
        world = World(scenario, seed=3, domain=domain)
        sim = SimulatedHardware(context, world, domain)
        for node in sim.nodes:
            graph.add_node(node)
        beliefs, statuses = [], []
        listener = graph.add_node(rclpy.create_node("nav_listener", context=context))
        every = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE,
                           durability=DurabilityPolicy.TRANSIENT_LOCAL)
        listener.create_subscription(Belief, "/pearl/belief",
                                     lambda m: beliefs.append(cv.msg_to_belief(m)), every)
        listener.create_subscription(DiagnosticArray, "/diagnostics",
                                     lambda m: statuses.extend(s for s in m.status if "belief_tracker" in s.name), 50)
        assert graph.spin_until(lambda: beliefs and graph.tracker.diag_pub.get_subscription_count() >= 1,
                                timeout_sec=20.0)
        driver = SimClockDriver(graph, wait_s=20.0)
        trace = run_episode(world, GraphBackend(graph, sim, driver), max_steps=steps)
        assert trace.actions == fast_actions
        updates = graph.tracker.core.counters()["updates"]
        assert graph.spin_until(lambda: len(beliefs) >= updates + 1, timeout_sec=10.0)
        for k, b in enumerate(beliefs[:updates + 1]):
            assert np.max(np.abs(b - fast_beliefs[k])) <= 1e-12, f"belief {k} differs"
        assert graph.tracker.counters()["nav_failures"] >= 4
        assert graph.spin_until(lambda: any(any(kv.key == "last_nav_failure" for kv in s.values) for s in statuses),
                                timeout_sec=5.0), "no /diagnostics status named the missed deadline"
        warn = [s for s in statuses if any(kv.key == "last_nav_failure" for kv in s.values)][-1]
        from diagnostic_msgs.msg import DiagnosticStatus

        assert warn.level == DiagnosticStatus.WARN
        values = {kv.key: kv.value for kv in warn.values}
        assert "GotoPatientRoom did not arrive within its deadline of 62.5 s" in values["last_nav_failure"]
        assert "missed their deadline" in warn.message
        assert int(values["nav_failures"]) >= 1
    finally:
        if sim is not None:
            sim.destroy()
        if graph is not None:
            graph.shutdown()
        rclpy.try_shutdown(context=context)

