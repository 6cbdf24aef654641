"""Lock-step simulated time for a :class:`~pearl_pomdp.nodes.graph.PearlGraph`: the one driver
that replay and the demo share.

Nodes under ``use_sim_time`` only see time move when ``/clock`` is published. The driver
does that in named phases, each waiting until the graph has finished reacting — never
by wall-clock pacing, so a run does not depend on the machine's speed:

* :meth:`SimClockDriver.set_time` — publish ``/clock``; wait until every node's clock
  shows it; run every timer that fell due (a step timeout); :meth:`settle`.
* :meth:`SimClockDriver.feed` — publish one input; wait until the tracker has taken it
  (one of its counters moved); :meth:`settle`.
* :meth:`SimClockDriver.feed_operator` — publish one operator input (veto, command) to the
  policy; wait until the policy has taken it; :meth:`settle`.
* :meth:`SimClockDriver.settle` — wait until the policy has answered every belief the
  tracker published and the tracker has received every action the policy published
  (without an operator: ``decisions == 1 + updates``, every action received back; an action
  waiting for the operator's yes, or only proposed, is an answer that publishes nothing).

A missing answer ends a wait after ``wait_s`` wall seconds with a warning and ``False``
(shown as a mismatch by replay, an error by the demo), never a hang.
"""
from __future__ import annotations

from typing import Callable, List, Optional

__all__ = ["SimClockDriver"]


class SimClockDriver:
    """Drives a graph's ``/clock`` and inputs in lock-step (see the module doc).

    Args:
        graph: a :class:`~pearl_pomdp.nodes.graph.PearlGraph` with ``use_sim_time``.
        wait_s: wall seconds any one wait may take.

    Attributes:
        node: the driver's own node (on the graph's executor): the ``/clock`` publisher and
            the ``/pearl/action`` listener.
        actions: every action the policy published, in order.
    """

    def __init__(self, graph, wait_s: float = 10.0, clock_topic: str = "/clock",
                 action_topic: str = "/pearl/action"):
        import rclpy
        from rosgraph_msgs.msg import Clock

        from pearl_pomdp.nodes import conversions as cv
        from pearl_pomdp.nodes.common import LATCHED_QOS

        self.graph = graph
        self.wait_s = float(wait_s)
        self.node = graph.add_node(rclpy.create_node("pearl_sim_clock", context=graph.context))
        self.clock_pub = self.node.create_publisher(Clock, clock_topic, 10)
        self.actions: List[str] = []
        self.node.create_subscription(cv.ActionMsg, action_topic, lambda m: self.actions.append(cv.msg_to_action(m)),
                                      LATCHED_QOS)
        self._clocks = [n.get_clock() for n in graph.nodes if n is not self.node]
        self._clock_type = Clock

    # ------------------------------------------------------------------ waits
    def wait(self, predicate: Callable[[], bool], what: str) -> bool:
        """Spin until ``predicate()``; ``False`` (with a warning) after ``wait_s`` wall seconds."""
        if self.graph.spin_until(predicate, timeout_sec=self.wait_s):
            return True
        self.node.get_logger().warning(f"sim clock: gave up waiting for {what} after {self.wait_s} s")
        return False

    def wait_for_clock_readers(self, extra: int = 1) -> None:
        """Block until every sim-time node of the graph, plus ``extra`` other readers (a bag
        recorder), subscribes to this driver's ``/clock``: a ``/clock`` sent before a reader
        matched is lost to it, and a bag missing one would replay its inputs at the wrong time.

        Raises:
            PearlError: fewer readers than that within ``wait_s`` wall seconds (how many came).
        """
        from pearl_pomdp.errors import PearlError

        readers = extra + sum(1 for n in self.graph.nodes if n.get_parameter("use_sim_time").value)
        if not self.graph.spin_until(lambda: self.clock_pub.get_subscription_count() >= readers,
                                     timeout_sec=self.wait_s):
            raise PearlError(f"/clock reached {self.clock_pub.get_subscription_count()} of {readers} "
                             f"subscribers within {self.wait_s} s")

    def drain(self) -> None:
        """Run every callback that is ready now (timers that fell due after a clock jump)."""
        from rclpy.executors import TimeoutException

        executor = self.graph.executor
        while True:
            try:
                handler, _entity, _node = executor.wait_for_ready_callbacks(timeout_sec=0.0)
            except TimeoutException:
                return
            handler()
            if handler.exception() is not None:
                raise handler.exception()

    def settled(self) -> bool:
        """Every belief answered, every answer back at the tracker (see the module doc)."""
        tracker, policy = self.graph.tracker, self.graph.policy
        answered = getattr(policy, "beliefs_answered", policy.decisions)
        published = getattr(policy, "actions_published", policy.decisions)
        return (tracker.core is not None and answered == 1 + tracker.core.step and len(self.actions) >= published
                and tracker.actions_received >= published)

    def settle(self) -> bool:
        """Wait until the graph is :meth:`settled`."""
        return self.wait(self.settled, "the policy's answer")

    def wait_until_matched(self, publishers) -> bool:
        """Wait until ``publishers`` and the /clock publisher reach a subscriber and b0 was answered
        (the first action arrived, unless the operator's level holds it)."""
        ok = self.wait(lambda: all(p.get_subscription_count() > 0 for p in publishers)
                       and self.clock_pub.get_subscription_count() > 0, "subscriptions to match")
        policy = self.graph.policy
        return self.wait(lambda: getattr(policy, "beliefs_answered", len(self.actions)) > 0 and self.settled(),
                         "the first action") and ok

    # ----------------------------------------------------------------- phases
    def set_time(self, t_ns: int, raw: Optional[bytes] = None) -> bool:
        """Publish ``/clock`` = ``t_ns`` (or the recorded bytes ``raw`` of that time) and settle."""
        if raw is not None:
            self.clock_pub.publish(raw)
        else:
            sec, nsec = divmod(int(t_ns), 1_000_000_000)
            msg = self._clock_type()
            msg.clock.sec, msg.clock.nanosec = int(sec), int(nsec)
            self.clock_pub.publish(msg)
        ok = self.wait(lambda: all(c.now().nanoseconds >= t_ns for c in self._clocks), f"/clock {t_ns} ns")
        self.drain()
        return self.settle() and ok

    def feed(self, publisher, msg) -> bool:
        """Publish one input (a message, or raw CDR bytes) with ``publisher``; wait until the tracker took it; settle."""
        tracker = self.graph.tracker
        before = tracker.counters()
        publisher.publish(msg)
        ok = self.wait(lambda: tracker.counters() != before, f"the tracker to take {publisher.topic_name}")
        return self.settle() and ok

    def feed_operator(self, publisher, msg) -> bool:
        """Publish one operator input (veto, command) to the policy; wait until it took it; settle."""
        policy = self.graph.policy
        before = policy.operator_inputs
        publisher.publish(msg)
        ok = self.wait(lambda: policy.operator_inputs > before, f"the policy to take {publisher.topic_name}")
        return self.settle() and ok

    def answer(self, yes: bool) -> bool:
        """The operator's yes/no to the waiting action (the policy's confirm path, called in-process); settle."""
        self.graph.policy.answer(yes)
        return self.settle()

    def next_timer_deadline(self) -> Optional[int]:
        """Sim time (ns) at which the next node timer on sim time falls due, or ``None``."""
        best = None
        for n in self.graph.nodes:
            if n is self.node:
                continue
            now = n.get_clock().now().nanoseconds
            for tm in n.timers:
                if tm.clock is not n.get_clock() or tm.is_canceled():
                    continue  # steady/system-clock timers do not follow /clock
                left = tm.time_until_next_call()
                if left is not None:
                    best = now + left if best is None else min(best, now + left)
        return best
