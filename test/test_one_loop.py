"""One decision loop (issue 10): the study's fast path and the robot's ROS graph run the same loop.

The same seeded scenarios go through (a) the core :class:`~pearl_pomdp.executive.Executive`
driven by the world's clock (what ``pearl experiment`` runs) and (b) the real
belief_tracker / hierarchical_policy / action_executor nodes in one process over DDS under
``/clock`` (what ``pearl demo`` runs). Both must produce the same actions and beliefs
equal to 1e-12 — silences closed by the tracker's timeout and drives that never time out
included — so the study measures what the robot does. Six seeds per scenario here;
``python bench/one_loop.py --seeds 20`` runs the same comparison on more (one JSON object).
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
from ros_helpers import DOMAIN, allocate_domain_id, configure_test_process  # noqa: E402

from pearl_pomdp.model.domain_yaml import load_domain  # noqa: E402
from pearl_sim.nursing_home.agents import Controller  # noqa: E402
from pearl_sim.nursing_home.experiment import episode_executive  # noqa: E402
from pearl_sim.loop import ExecutiveBackend, run_episode  # noqa: E402
from pearl_sim.nursing_home.scenario import load_scenarios  # noqa: E402
from pearl_sim.nursing_home.world import World  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
SCENARIOS = ("figure4", "table4_dialog", "info_request")
#: Seeds per scenario in the suite (its time budget); ``bench/one_loop.py`` runs 20 or more.
SEEDS = range(6)
#: Steps per episode: enough for contact, a reminder, a drive and silences in every scenario.
STEPS = 14


@pytest.fixture(scope="module")
def pearl(pearl_policy):
    from pearl_pomdp.hierarchy import load_hierarchical_policy

    domain = load_domain(DOMAIN)
    return domain, domain.compile(), load_hierarchical_policy(pearl_policy, domain)


def fast(domain, model, decider, scenario, seed):
    world = World(scenario, seed=seed, domain=domain)
    backend = ExecutiveBackend(episode_executive(Controller("hierarchical", decider), domain, scenario, model))
    trace = run_episode(world, backend, max_steps=STEPS)
    timeouts = sum(step.source == "timeout" for step in backend.executive.steps)
    return trace.actions, backend.beliefs(), timeouts


def on_graph(domain, model, decider, scenario, seed, tmp_path):
    """The same episode through the Pearl nodes in one process, /clock driven by the loop."""
    import rclpy
    from rclpy.context import Context
    from rclpy.signals import SignalHandlerOptions
    from pearl_interfaces.msg import Belief

    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
    from pearl_pomdp.nodes.graph import PearlGraph
    from pearl_pomdp.nodes import conversions as cv
    from pearl_pomdp.nodes.sim_clock import SimClockDriver
    from pearl_sim.nodes import GraphBackend, SimulatedHardware

    configure_test_process(tmp_path)
    context = Context()
    # Domains 150..229: other tests of this suite (and other suites on the machine) use 1..101,
    # and a stranger's latched /pearl/action would be taken for this graph's first action.
    domain_id = 150 + allocate_domain_id() % 80
    rclpy.init(args=["--ros-args", "--log-level", "error"], context=context, domain_id=domain_id,
               signal_handler_options=SignalHandlerOptions.NO)
    graph = None
    sim = None
    try:
        graph = PearlGraph(context=context, domain=domain, model=model, decider=decider, parameter_services=False,
                           overrides={"belief_tracker": scenario.tracker_parameters()})
        world = World(scenario, seed=seed, domain=domain)
        sim = SimulatedHardware(context, world, domain)
        for node in sim.nodes:
            graph.add_node(node)
        beliefs = []
        listener = graph.add_node(rclpy.create_node("parity_listener", context=context))
        # Keep every belief (the tracker's latched publisher keeps only the last for late joiners).
        every = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE,
                           durability=DurabilityPolicy.TRANSIENT_LOCAL)
        listener.create_subscription(Belief, "/pearl/belief",
                                     lambda m: beliefs.append(cv.msg_to_belief(m)), every)
        assert graph.spin_until(lambda: graph.tracker.belief_pub.get_subscription_count() >= 2 and beliefs,
                                timeout_sec=20.0), "the listener never got b0"
        driver = SimClockDriver(graph, wait_s=20.0)
        trace = run_episode(world, GraphBackend(graph, sim, driver), max_steps=STEPS)
        updates = graph.tracker.core.counters()["updates"]
        graph.spin_until(lambda: len(beliefs) >= updates + 1, timeout_sec=10.0)
        return trace.actions, beliefs
    finally:
        if sim is not None:
            sim.destroy()
        if graph is not None:
            graph.shutdown()
        rclpy.try_shutdown(context=context)


@pytest.mark.parametrize("name", SCENARIOS)
def test_study_path_and_ros_graph_agree(pearl, name, tmp_path):
    domain, model, decider = pearl
    (scenario,) = load_scenarios(REPO / "config" / "scenarios" / f"{name}.yaml")
    drives = silences = 0
    for seed in SEEDS:
        actions, beliefs, timeouts = fast(domain, model, decider, scenario, seed)
        ros_actions, ros_beliefs = on_graph(domain, model, decider, scenario, seed, tmp_path)
        assert ros_actions == actions, f"{name} seed {seed}: actions differ"
        assert len(ros_beliefs) == len(beliefs), f"{name} seed {seed}: {len(ros_beliefs)} vs {len(beliefs)} beliefs"
        for k, (a, b) in enumerate(zip(ros_beliefs, beliefs)):
            assert np.max(np.abs(a - b)) <= 1e-12, f"{name} seed {seed}: belief {k} differs"
        drives += sum(a in ("GotoPatientRoom", "GuideToPhysio", "GoHome") for a in actions)
        silences += timeouts
    # The rules that differ between a naive loop and the robot's must have been exercised.
    assert drives > 0, f"{name}: no drive in {len(SEEDS)} seeds: the parity check missed the drive rule"
    assert silences > 0, f"{name}: no step closed by the timeout in {len(SEEDS)} seeds"
