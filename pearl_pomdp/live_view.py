"""A live view of the behaviour manager in Foxglove (WebSocket protocol, ``foxglove-sdk``).

:class:`LiveView` starts a Foxglove WebSocket server and advertises one channel per thing a
roboticist watches (:data:`CHANNELS`); the caller hands it each value as it happens with
:meth:`LiveView.publish` (``pearl demo --foxglove`` calls it from its listeners; nothing here
imports ROS). Open Foxglove, connect to ``ws://HOST:PORT`` and load
``config/foxglove/pearl.layout.json``: belief marginals plotted over time, the action log,
the EXECUTE trace, the transcript in a log panel, and a 3D view of the map with the named
places and the robot's pose.

=========================  ===================  =====================================================
channel                    encoding / schema     what :meth:`LiveView.publish` takes
=========================  ===================  =====================================================
``/pearl/belief_marginals`` JSON                ``{"step", "action", "observation", "marginals":
                                                 {feature: {value: p}}}`` (the tracker's message)
``/pearl/action``          JSON                 ``{"action": name}`` or the name itself
``/pearl/decision``        JSON                 ``{"step", "belief_step", "action", "trace": [...], "latency_s",
                                                 "expansions"}`` (``conversions.msg_to_decision``)
``/pearl/transcript``      foxglove.Log         ``{"speaker": "resident"|"robot"|…, "text": str}``
``/pearl/guide_pace``      JSON                 the guide_pace node's state object
``/pearl/pose``            foxglove.PoseInFrame ``{"x", "y", "yaw"}`` (map frame)
``/pearl/places``          foxglove.SceneUpdate ``{name: [x, y, yaw]}`` (spheres and labels)
``/pearl/proposal``        JSON                 the policy's proposal (step, action, status: acted,
                                                 waiting for the operator's yes, proposed …)
``/pearl/operator/events`` JSON                 one operator event (``{"event", "action", "step",
                                                 "stamp", "autonomy", "detail"}``: veto, yes/no …)
=========================  ===================  =====================================================

Requires ``foxglove-sdk`` (installed with the ``ros`` extra of the README's install, or
``pip install foxglove-sdk``); importing this module without it raises ImportError naming the
package.
"""
from __future__ import annotations

import math
import threading
import time
from typing import Any, Dict, Mapping, Optional, Sequence

try:
    import foxglove
    from foxglove.channels import LogChannel, PoseInFrameChannel, SceneUpdateChannel
    from foxglove.websocket import ServerListener
    from foxglove.messages import (Color, Log, LogLevel, Pose, PoseInFrame, Quaternion, SceneEntity, SceneUpdate,
                                   SpherePrimitive, TextPrimitive, Timestamp, Vector3)
except ImportError as err:  # pragma: no cover - depends on the environment
    raise ImportError(f"pearl_pomdp.live_view needs foxglove-sdk (pip install foxglove-sdk): {err}") from None

__all__ = ["LiveView", "CHANNELS", "MAP_FRAME"]

MAP_FRAME = "map"

_MARGINALS_SCHEMA = {
    "type": "object",
    "properties": {
        "step": {"type": "integer"}, "action": {"type": ["string", "null"]},
        "observation": {"type": ["string", "null"]},
        "marginals": {"type": "object", "additionalProperties": {"type": "object",
                                                                 "additionalProperties": {"type": "number"}}},
    },
}
_ACTION_SCHEMA = {"type": "object", "properties": {"action": {"type": "string"}}}
_DECISION_SCHEMA = {
    "type": "object",
    "properties": {
        "step": {"type": "integer"}, "belief_step": {"type": "integer"}, "action": {"type": "string"},
        "latency_s": {"type": "number"}, "expansions": {"type": "integer"},
        "search": {"type": "object"},   # an online policy's search record (docs/online.md)
        "trace": {"type": "array", "items": {"type": "object", "properties": {
            "subtask": {"type": "string"}, "choice": {"type": "string"}, "value": {"type": "number"}}}},
    },
}
_GUIDE_SCHEMA = {"type": "object", "properties": {k: {"type": t} for k, t in (
    ("active", ["string", "null"]), ("state", "string"), ("speed", "number"), ("nav_speed", "number"),
    ("pace", "number"), ("behind", ["number", "null"]), ("waited", "number"), ("times_lost", "integer"))}}

_PROPOSAL_SCHEMA = {"type": "object", "properties": {
    "step": {"type": "integer"}, "action": {"type": "string"}, "source": {"type": "string"},
    "status": {"type": "string"}, "autonomy": {"type": "string"},
    "vetoed": {"type": "array", "items": {"type": "string"}},
    "deadline": {"type": ["number", "null"]}}}
_OPERATOR_EVENT_SCHEMA = {"type": "object", "properties": {
    "event": {"type": "string"}, "action": {"type": "string"}, "step": {"type": "integer"},
    "stamp": {"type": "number"}, "autonomy": {"type": "string"}, "detail": {"type": "string"}}}

#: topic → kind (``json`` with its JSON schema, or a Foxglove schema name).
CHANNELS: Dict[str, Any] = {
    "/pearl/belief_marginals": ("json", _MARGINALS_SCHEMA),
    "/pearl/action": ("json", _ACTION_SCHEMA),
    "/pearl/decision": ("json", _DECISION_SCHEMA),
    "/pearl/guide_pace": ("json", _GUIDE_SCHEMA),
    "/pearl/transcript": ("foxglove.Log", None),
    "/pearl/pose": ("foxglove.PoseInFrame", None),
    "/pearl/places": ("foxglove.SceneUpdate", None),
    "/pearl/proposal": ("json", _PROPOSAL_SCHEMA),
    "/pearl/operator/events": ("json", _OPERATOR_EVENT_SCHEMA),
}


def _stamp(seconds: float) -> Timestamp:
    sec = int(math.floor(seconds))
    return Timestamp(sec, int(round((seconds - sec) * 1e9)) % 1_000_000_000)


class _Subscriptions(ServerListener):
    """Counts the clients subscribed to each topic (so a caller can wait for a viewer)."""

    def __init__(self):
        super().__init__()
        self.lock = threading.Lock()
        self.by_topic: Dict[str, int] = {}

    def on_subscribe(self, client, channel) -> None:
        with self.lock:
            self.by_topic[channel.topic] = self.by_topic.get(channel.topic, 0) + 1

    def on_unsubscribe(self, client, channel) -> None:
        with self.lock:
            self.by_topic[channel.topic] = max(0, self.by_topic.get(channel.topic, 0) - 1)


def _pose(x: float, y: float, yaw: float) -> Pose:
    return Pose(position=Vector3(x=float(x), y=float(y), z=0.0),
                orientation=Quaternion(x=0.0, y=0.0, z=math.sin(yaw / 2.0), w=math.cos(yaw / 2.0)))


class LiveView:
    """A Foxglove WebSocket server with the Pearl channels (see the module doc).

    Args:
        host: interface to bind (default loopback only).
        port: TCP port; 0 picks a free one (see :attr:`port`).
        name: server name shown in Foxglove.

    Use as a context manager, or call :meth:`stop`. Values are timestamped with the time
    given to :meth:`publish` (e.g. sim time) or the wall clock.
    """

    def __init__(self, host: str = "127.0.0.1", port: int = 8765, name: str = "pearl"):
        self._context = foxglove.Context()
        self._channels: Dict[str, Any] = {}
        for topic, (kind, schema) in CHANNELS.items():
            if kind == "json":
                self._channels[topic] = foxglove.Channel(topic, schema=schema, message_encoding="json",
                                                         context=self._context)
            elif kind == "foxglove.Log":
                self._channels[topic] = LogChannel(topic, context=self._context)
            elif kind == "foxglove.PoseInFrame":
                self._channels[topic] = PoseInFrameChannel(topic, context=self._context)
            else:
                self._channels[topic] = SceneUpdateChannel(topic, context=self._context)
        self._subscriptions = _Subscriptions()
        self._server = foxglove.start_server(name=name, host=host, port=port, context=self._context,
                                             server_listener=self._subscriptions)
        self.published: Dict[str, int] = {topic: 0 for topic in CHANNELS}

    @property
    def port(self) -> int:
        """The TCP port the server listens on."""
        return int(self._server.port)

    @property
    def url(self) -> str:
        """``ws://127.0.0.1:PORT`` (what to enter in Foxglove's "Open connection")."""
        return f"ws://127.0.0.1:{self.port}"

    def subscribers(self, topic: str) -> int:
        """How many clients are subscribed to ``topic`` now."""
        with self._subscriptions.lock:
            return self._subscriptions.by_topic.get(topic, 0)

    def wait_for_subscribers(self, topics: Sequence[str], timeout: float) -> bool:
        """Wait up to ``timeout`` s until every topic of ``topics`` has a subscriber; True if so."""
        deadline = time.monotonic() + max(0.0, timeout)
        while not all(self.subscribers(t) for t in topics):
            if time.monotonic() >= deadline:
                return False
            time.sleep(0.05)
        return True

    def publish(self, topic: str, value: Any, stamp_s: Optional[float] = None) -> None:
        """Send ``value`` on ``topic`` (one of :data:`CHANNELS`, in the form the module doc gives).

        Raises:
            KeyError: ``topic`` is not a channel of the live view (the message lists them).
            ValueError: ``value`` lacks a field the channel needs (the message names it).
        """
        if topic not in self._channels:
            raise KeyError(f"live view has no channel {topic!r} (channels: {', '.join(CHANNELS)})")
        t = time.time() if stamp_s is None else float(stamp_s)
        log_time = int(round(t * 1e9))
        channel = self._channels[topic]
        try:
            if topic == "/pearl/action":
                channel.log({"action": value} if isinstance(value, str) else dict(value), log_time=log_time)
            elif topic == "/pearl/transcript":
                channel.log(Log(timestamp=_stamp(t), level=LogLevel.Info, message=str(value["text"]),
                                name=str(value.get("speaker", ""))), log_time=log_time)
            elif topic == "/pearl/pose":
                channel.log(PoseInFrame(timestamp=_stamp(t), frame_id=MAP_FRAME,
                                        pose=_pose(value["x"], value["y"], value.get("yaw", 0.0))), log_time=log_time)
            elif topic == "/pearl/places":
                channel.log(self._places(value, t), log_time=log_time)
            else:
                channel.log(dict(value), log_time=log_time)
        except (KeyError, TypeError) as err:
            raise ValueError(f"live view {topic}: value {value!r} lacks {err}") from None
        self.published[topic] += 1

    def publish_places(self, places: Mapping[str, Sequence[float]], stamp_s: Optional[float] = None) -> None:
        """Show the named places (``{name: [x, y, yaw]}``) on the map."""
        self.publish("/pearl/places", places, stamp_s)

    @staticmethod
    def _places(places: Mapping[str, Sequence[float]], t: float) -> SceneUpdate:
        entities = []
        for name, pose in places.items():
            x, y = float(pose[0]), float(pose[1])
            entities.append(SceneEntity(
                timestamp=_stamp(t), frame_id=MAP_FRAME, id=f"place/{name}",
                spheres=[SpherePrimitive(pose=_pose(x, y, 0.0), size=Vector3(x=0.6, y=0.6, z=0.6),
                                         color=Color(r=0.2, g=0.6, b=1.0, a=0.8))],
                texts=[TextPrimitive(pose=_pose(x, y + 0.6, 0.0), billboard=True, font_size=14.0,
                                     scale_invariant=True, color=Color(r=1.0, g=1.0, b=1.0, a=1.0), text=name)]))
        return SceneUpdate(entities=entities)

    def stop(self) -> None:
        """Stop the server (clients are disconnected)."""
        self._server.stop()

    def __enter__(self) -> "LiveView":
        return self

    def __exit__(self, *exc) -> None:
        self.stop()
