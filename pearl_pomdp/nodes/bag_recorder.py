"""Record ROS 2 topics into a rosbag2 bag (the stand-in for ``ros2 bag record -s mcap``).

:class:`Recorder` lives on an rclpy node. It polls the ROS graph, and for each wanted topic
that has a publisher it creates a ``raw=True`` subscription — the bytes are written exactly
as received, never deserialised and re-serialised — with rosbag2's QoS adaptation: reliable
only if every publisher offers reliable, transient-local only if every publisher offers it.
The topic's ``offered_qos_profiles`` and RIHS01 type hash come from
``get_publishers_info_by_topic()``. Log time is the node's clock (so ``use_sim_time`` gives
sim-time stamps, as with rosbag2); publish time is the middleware's source timestamp.

This module imports rclpy (it is the ROS side of :mod:`pearl_pomdp.bags`); the rest of the
package reads and writes bags without ROS.
"""
from __future__ import annotations

import importlib
import sys
import threading
from typing import Any, Callable, Dict, Iterable, List, Optional, Set

from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from pearl_pomdp.bags import msgdefs
from pearl_pomdp.bags import well_known as wk
from pearl_pomdp.bags.metadata import QosProfile
from pearl_pomdp.bags.writer import BagWriter
from pearl_pomdp.errors import PearlError

_NS = 1_000_000_000

#: The decision loop's topics a bag must hold from their first message ...
LOOP_TOPICS = ("/pearl/belief", "/pearl/decision", "/pearl/action")
#: ... and those of them that are latched (depth 1): b0 and the answer to it, already out
#: when the recorder joins.
LATCHED_LOOP_TOPICS = ("/pearl/belief", "/pearl/action")


def message_class(type_name: str):
    """The Python class of a ROS 2 message type name (``std_msgs/msg/String`` → String)."""
    pkg, ns, name = msgdefs.split_type(type_name)
    try:
        return getattr(importlib.import_module(f"{pkg}.{ns}"), name)
    except (ImportError, AttributeError):
        raise PearlError(f"{type_name}: message type not installed (no Python module {pkg}.{ns}.{name})") from None


def _duration(d) -> tuple:
    ns = int(d.nanoseconds)
    if ns >= 0x7FFFFFFFFFFFFFFF:
        return wk.DURATION_INFINITE
    return ns // _NS, ns % _NS


def qos_from_rclpy(q: QoSProfile) -> QosProfile:
    """rclpy's QoSProfile (as the graph reports it) → the profile rosbag2 records."""
    return QosProfile(
        history=wk.HISTORY_NAMES.get(int(q.history), "unknown"),
        depth=int(q.depth),
        reliability=wk.RELIABILITY_NAMES.get(int(q.reliability), "unknown"),
        durability=wk.DURABILITY_NAMES.get(int(q.durability), "unknown"),
        deadline=_duration(q.deadline),
        lifespan=_duration(q.lifespan),
        liveliness=wk.LIVELINESS_NAMES.get(int(q.liveliness), "unknown"),
        liveliness_lease_duration=_duration(q.liveliness_lease_duration),
        avoid_ros_namespace_conventions=bool(q.avoid_ros_namespace_conventions),
    )


def subscription_qos(offered: List[QoSProfile], depth: int = 100) -> QoSProfile:
    """rosbag2's ``adapt_request_to_offers``: the request compatible with every publisher."""
    reliable = bool(offered) and all(q.reliability == ReliabilityPolicy.RELIABLE for q in offered)
    latched = bool(offered) and all(q.durability == DurabilityPolicy.TRANSIENT_LOCAL for q in offered)
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST, depth=depth,
        reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
        durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE,
    )


def _hidden(topic: str) -> bool:
    return any(part.startswith("_") for part in topic.split("/") if part)


class Recorder:
    """Subscribe to topics as they appear and write every message to a :class:`BagWriter`.

    Args:
        node: the rclpy node to subscribe on (its clock stamps log times).
        writer: an open bag writer (the recorder does not close it).
        topics: topic names to record; ``None`` records every topic that is not hidden.
        exclude: topic names never recorded.
        discovery_period: seconds between graph polls (a timer on ``node``).
        on_subscribe: called with ``(topic, type)`` after each new subscription.
    """

    def __init__(self, node: Node, writer: BagWriter, topics: Optional[Iterable[str]] = None, *,
                 exclude: Iterable[str] = (), discovery_period: float = 0.05,
                 on_subscribe: Optional[Callable[[str, str], None]] = None):
        self.node = node
        self.writer = writer
        self.wanted: Optional[Set[str]] = None if topics is None else {self._fq(t) for t in topics}
        self.exclude = {self._fq(t) for t in exclude}
        self.on_subscribe = on_subscribe
        self.subscriptions: Dict[str, Any] = {}   # topic → rclpy Subscription
        self.counts: Dict[str, int] = {}
        self._lock = threading.Lock()
        self._warned: Set[str] = set()
        self.discover()
        # The timer ticks on the steady clock: graph discovery must not stop when /clock does.
        from rclpy.clock import Clock, ClockType

        self._timer = node.create_timer(discovery_period, self.discover, clock=Clock(clock_type=ClockType.STEADY_TIME))

    def _fq(self, topic: str) -> str:
        return topic if topic.startswith("/") else "/" + topic

    def discover(self) -> List[str]:
        """Subscribe to wanted topics that now have publishers; returns the new ones."""
        new = []
        for topic, types in self.node.get_topic_names_and_types():
            if topic in self.subscriptions or topic in self.exclude:
                continue
            if self.wanted is not None and topic not in self.wanted:
                continue
            if self.wanted is None and _hidden(topic):
                continue
            if len(types) != 1:
                self._warn(topic, f"{topic} has several types {types}; not recorded")
                continue
            infos = self.node.get_publishers_info_by_topic(topic)
            if not infos:
                continue  # only subscribers so far: wait for a publisher to learn the QoS
            type_name = types[0]
            try:
                cls = message_class(type_name)
            except PearlError as err:
                self._warn(topic, str(err))
                continue
            type_hash = str(infos[0].topic_type_hash)
            if not type_hash.startswith("RIHS"):
                type_hash = msgdefs.try_type_hash(type_name) or ""
            offered = [i.qos_profile for i in infos]
            self.writer.add_topic(topic, type_name, qos=[qos_from_rclpy(q) for q in offered], type_hash=type_hash)
            self.counts[topic] = 0
            self.subscriptions[topic] = self.node.create_subscription(
                cls, topic, self._callback(topic), subscription_qos(offered), raw=True)
            new.append(topic)
            if self.on_subscribe:
                self.on_subscribe(topic, type_name)
        return new

    def recording(self, topics: Iterable[str], received: bool = False) -> bool:
        """Whether every topic in ``topics`` has a subscription matched with at least one
        publisher (and, with ``received``, has delivered at least one message).

        A run must not start before that: a latched topic of depth 1 (``/pearl/belief``) keeps
        only its newest message for a reader that joins late, and even a matched reader gets
        the latched one only some time after the match — if the first step's belief is
        published in between, b0 never reaches the bag (seen: a demo bag one belief short, one
        run in three under load). ``received=True`` waits for the latched message itself."""
        return all((sub := self.subscriptions.get(self._fq(t))) is not None and sub.get_publisher_count() > 0
                   and (not received or self.counts.get(self._fq(t), 0) > 0) for t in topics)

    def wait_until_recording(self, spin_until: Callable[..., bool], timeout_sec: float,
                             topics: Iterable[str] = LOOP_TOPICS,
                             latched: Iterable[str] = LATCHED_LOOP_TOPICS) -> None:
        """Spin (``spin_until(condition, timeout_sec=…)``, the caller's executor) until every topic
        in ``topics`` is matched and every one in ``latched`` has delivered its latched message
        (:meth:`recording`); a run started before that loses b0 from its bag.

        Raises:
            PearlError: naming the topics still missing after ``timeout_sec``.
        """
        topics, latched = tuple(topics), tuple(latched)
        if not spin_until(lambda: self.recording(topics) and self.recording(latched, received=True),
                          timeout_sec=timeout_sec):
            missing = [t for t in topics + tuple(t for t in latched if t not in topics)
                       if not self.recording([t], received=t in latched)]
            raise PearlError(f"the bag recorder did not get {', '.join(missing)} within {timeout_sec} s")

    def _callback(self, topic: str):
        writer, clock, counts = self.writer, self.node.get_clock(), self.counts

        def on_message(data: bytes, info: dict) -> None:
            log_time = clock.now().nanoseconds
            publish_time = info.get("source_timestamp") or log_time
            seq = info.get("publication_sequence_number") or None
            if writer.closed:
                return
            writer.write(topic, data, log_time, publish_time, seq)
            counts[topic] += 1

        return on_message

    def _warn(self, topic: str, text: str) -> None:
        if topic not in self._warned:
            self._warned.add(topic)
            self.node.get_logger().warning(text)

    def stop(self) -> None:
        """Stop discovering and receiving (the writer stays open)."""
        self._timer.cancel()
        for sub in self.subscriptions.values():
            self.node.destroy_subscription(sub)
        self.subscriptions.clear()


def log(text: str) -> None:
    """A progress line on stderr (tests wait for these instead of sleeping)."""
    print(text, file=sys.stderr, flush=True)
