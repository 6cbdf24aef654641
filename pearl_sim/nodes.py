"""The nursing home's simulated hardware over DDS, and the real graph as the robot of the episode loop.

The physics of the nursing home is one :class:`~pearl_sim.nursing_home.world.World` (one
resident, one robot, one scheduler). Its sensors are the frame's
(:class:`~pearl_sim.world_hardware.WorldHardware`, as for every world): one node ``sim_pearl``
with a publisher per input Pearl's domain declares — ``/pearl/speech`` (recogniser text, with
word errors, as the domain's speech input declares it: pearl_interfaces/RecognisedSpeech),
``/pearl/touchscreen``, ``/pearl/laser`` (landmark reached), ``/pearl/reminder`` (scheduler:
``g_physio`` …) — plus ``/pearl/sim/said`` (what she actually said, for transcripts),
``/pearl/sim/truth`` and the robot's pose on ``/pearl/pose`` (geometry_msgs/PoseStamped):
:class:`SimulatedHardware`.

:class:`GraphBackend` makes the real Pearl graph the robot of the episode loop
(:func:`pearl_sim.loop.run_episode`): each message the world produces is published on its
modality's input at its time, with ``/clock`` moved there first by the graph's
:class:`~pearl_pomdp.nodes.sim_clock.SimClockDriver`; when nothing is heard the clock
moves to the tracker's own deadline and its timer closes the step (docs/design.md §6).
Everything is seeded, so a scenario replays identically.

The separate-process simulator (``pearl_sim_world``, :mod:`pearl_sim.nursing_home.world_node`) publishes
through the same :class:`SimulatedHardware`, from its own node. Which inputs there are, on which topics
and of which types, the domain declares (``modalities.<M>.input``); ``RELIABLE`` is their QoS.
"""
from __future__ import annotations

from typing import List

from pearl_sim.world_hardware import RELIABLE, WorldHardware  # noqa: F401  (RELIABLE: re-exported, the inputs' QoS)


class SimulatedHardware(WorldHardware):
    """The nursing home's sensors: the frame's :class:`~pearl_sim.world_hardware.WorldHardware` of the
    world ``pearl``, with the robot's pose on ``/pearl/pose``.

    Args:
        context: an initialised rclpy context (the same as the Pearl nodes').
        world: the simulated nursing home.
        domain: the domain the graph runs, whose inputs the publishers follow (default: the shipped
            ``config/pearl.domain.yaml``).
        node: the rclpy node to publish from (``pearl_sim_world``'s own); ``None``: a node ``sim_pearl``.

    Attributes:
        nodes: the rclpy nodes, to add to an executor (none when given ``node``). ``/clock`` is published
            by the graph's :class:`~pearl_pomdp.nodes.sim_clock.SimClockDriver` (or ``pearl_sim_world``), not here.
    """

    def __init__(self, context, world, domain=None, node=None):
        if domain is None:
            from pearl_sim.nursing_home.scenario import default_domain

            domain = default_domain()
        super().__init__(context, world, domain, "pearl", pose_topic="/pearl/pose", node=node)


class GraphBackend:
    """The real Pearl nodes as the robot of :func:`pearl_sim.loop.run_episode` (over DDS, under /clock).

    ``hardware`` is any simulated hardware with ``publishers`` (to wait for), ``outgoing(message)``
    → ``(publisher, ROS message)`` and ``publish_said(text)``: :class:`SimulatedHardware` (the
    nursing home), :class:`pearl_sim.world_hardware.WorldHardware` (every world of the frame).
    Each world message is published by the simulated node of its modality at its time
    (the :class:`~pearl_pomdp.nodes.sim_clock.SimClockDriver` moves ``/clock`` there first
    and waits for the graph's answer); a deadline is reached by moving ``/clock`` to it, so
    the tracker node's own timer closes the step.

    Raises:
        PearlError: the graph did not answer within the driver's wait (names the phase).
    """

    def __init__(self, graph, hardware, driver):
        self.graph, self.hardware, self.driver = graph, hardware, driver
        self.now_ns = 0

    def start(self) -> List[str]:
        from pearl_pomdp.errors import PearlError

        if not self.driver.wait_until_matched(list(self.hardware.publishers.values())):
            raise PearlError("the Pearl graph gave no first action (is the policy node running?)")
        return list(self.driver.actions)

    def _advance(self, t_ns: int) -> None:
        from pearl_pomdp.errors import PearlError

        if t_ns > self.now_ns:
            if not self.driver.set_time(t_ns):
                raise PearlError(f"the Pearl graph did not settle at sim time {t_ns * 1e-9:.3f} s")
            self.now_ns = t_ns

    def deliver(self, message) -> List[str]:
        from pearl_pomdp.errors import PearlError
        from pearl_sim.loop import clock_ns

        # Counted before the clock moves: a deadline the move reaches decides an action too (the loop
        # takes it, as it takes the core executive's).
        before = len(self.driver.actions)
        self._advance(clock_ns(message.time))
        if message.said:
            self.hardware.publish_said(message.said)
        publisher, msg = self.hardware.outgoing(message)
        if not self.driver.feed(publisher, msg):
            raise PearlError(f"the Pearl graph did not take {message.modality} {message.text!r} "
                             f"at {message.time:.3f} s")
        return self.driver.actions[before:]

    def tick(self, t_ns: int) -> List[str]:
        before = len(self.driver.actions)
        self._advance(t_ns)
        return self.driver.actions[before:]

    def deadline(self):
        return self.graph.tracker.core.deadline()
