"""``pearl_sim_world`` (its own process, as under launch/pearl_sim.launch.xml) against a manager played by
the test: it carries out every action the manager publishes, also two that come back to back (the
tracker closes a step the moment an action opens it when an observation was queued, and the policy
answers at once), and when a closed step gets no action it ends with exit 1 and one line naming
/pearl/action and the step within ``answer_timeout`` wall seconds instead of holding its clock forever."""
from __future__ import annotations

import sys
import time
from pathlib import Path
from typing import List

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
from ros_helpers import DISCOVERY_TIMEOUT, Proc, ros_env, wait_for  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
WORLD = Path(sys.executable).with_name("pearl_sim_world")
SCENARIO = REPO / "config" / "scenarios" / "figure4.yaml"

pytestmark = pytest.mark.ros


class Manager:
    """The manager's side of the world's topics: actions and beliefs out (latched, as the policy and
    the tracker publish them), the world's inputs and truth in."""

    def __init__(self, context):
        import rclpy
        from rclpy.executors import SingleThreadedExecutor

        from pearl_interfaces.msg import Action, Belief
        from pearl_pomdp.nodes.common import LATCHED_QOS
        from pearl_pomdp.nodes.bag_recorder import message_class
        from pearl_pomdp.nodes.conversions import WorldTruthMsg
        from pearl_pomdp.model.domain_yaml import load_domain
        from pearl_sim.nodes import RELIABLE

        self._Action, self._Belief = Action, Belief
        self.node = rclpy.create_node("fake_manager", context=context)
        self.executor = SingleThreadedExecutor(context=context)
        self.executor.add_node(self.node)
        self.truth: List = []
        self.truth_sub = self.node.create_subscription(WorldTruthMsg, "/pearl/sim/truth", self.truth.append, RELIABLE)
        # The world starts its clock once its inputs have readers: created after the truth reader.
        # One reader per input Pearl's domain declares, as the tracker has them (the simulator's scenario
        # runs that domain).
        inputs = load_domain(Path(__file__).resolve().parents[1] / "config" / "pearl.domain.yaml").inputs
        self.inputs = [self.node.create_subscription(message_class(ch.type), ch.topic, lambda _: None, RELIABLE)
                       for ch in inputs]
        self.action_pub = self.node.create_publisher(Action, "/pearl/action", LATCHED_QOS)
        self.belief_pub = self.node.create_publisher(Belief, "/pearl/belief", LATCHED_QOS)

    def action(self, name: str) -> None:
        self.action_pub.publish(self._Action(name=name))

    def belief(self, step: int) -> None:
        self.belief_pub.publish(self._Belief(step=step, run=1))

    def ended(self) -> List[str]:
        """The actions the world carried out (its "end" truth records), in order."""
        return [m.action for m in self.truth if m.phase == "end"]

    def wait(self, predicate, timeout: float) -> bool:
        return wait_for(predicate, timeout, self.executor)

    def close(self) -> None:
        self.executor.shutdown()
        self.node.destroy_node()


@pytest.fixture
def world_and_manager(ros_context, tmp_path):
    """``start(*params)`` → ``(world process, manager)``: matched, the first action (DoNothing) carried out."""
    context, domain_id = ros_context
    made = []

    def start(*params: str):
        world = Proc([str(WORLD), "--ros-args", "-p", f"scenario:={SCENARIO}", "-p", "rate:=20.0",
                      *[a for p in params for a in ("-p", p)]], ros_env(domain_id, tmp_path), tmp_path, "world")
        manager = Manager(context)
        made.append((world, manager))
        matched = manager.wait(lambda: manager.action_pub.get_subscription_count() > 0
                               and manager.belief_pub.get_subscription_count() > 0
                               and manager.truth_sub.get_publisher_count() > 0
                               and all(s.get_publisher_count() > 0 for s in manager.inputs), DISCOVERY_TIMEOUT)
        assert matched, world.stderr()[-2000:]
        manager.action("DoNothing")      # the answer to b0: the world starts its clock
        assert manager.wait(lambda: manager.ended() == ["DoNothing"], DISCOVERY_TIMEOUT), world.stderr()[-2000:]
        return world, manager

    try:
        yield start
    finally:
        for world, manager in made:
            manager.close()
            world.stop()


def test_the_world_carries_out_two_actions_that_come_back_to_back(world_and_manager):
    world, manager = world_and_manager()
    # Step 1 closes, its action opens step 2, which closes at once (a queued observation) and is answered:
    # two actions within a millisecond, before the world's executor took the first.
    manager.belief(1)
    manager.action("RingDoorBell")
    manager.belief(2)
    manager.action("CheckUserPresent")
    assert manager.wait(lambda: len(manager.ended()) >= 3, 15.0), (manager.ended(), world.stderr()[-2000:])
    assert manager.ended() == ["DoNothing", "RingDoorBell", "CheckUserPresent"]
    assert world.returncode is None     # still running: the clock goes on (step 3 is open)


def test_a_world_whose_manager_never_answers_a_step_ends_with_one_line(world_and_manager):
    world, manager = world_and_manager("answer_timeout:=2.0")
    manager.belief(1)                   # step 1 closed; the policy never answers it
    closed = time.monotonic()
    code = world.wait(20.0)
    waited = time.monotonic() - closed
    err = world.stderr()
    assert code == 1, err[-2000:]
    assert 2.0 <= waited < 10.0
    lines = [line for line in err.splitlines() if line.startswith("pearl_sim_world: error:")]
    assert lines == ["pearl_sim_world: error: no action on /pearl/action answered step 1 (closed on /pearl/belief) "
                     "within answer_timeout 2 wall seconds; the world carried out 1 action(s), the last 'DoNothing'"], \
        err[-2000:]
