"""The ROS side of the domain's input channels: each channel's message type, field and QoS.

The core (:mod:`pearl_pomdp.channels`) knows a channel's kind, topic, type *name* and bins;
this module turns that into an rclpy subscription the ``belief_tracker`` node can make:

* ``speech`` channels read ``pearl_interfaces/msg/RecognisedSpeech`` (text, confidence, symbol: an
  :class:`~pearl_pomdp.speech.Utterance`; what the recogniser node publishes) or the text of a
  ``std_msgs/msg/String`` (plain text, or the JSON of a bag recorded before the typed message);
  ``symbol`` channels read the text of ``std_msgs/msg/String``.
* ``number`` channels read one numeric field of any installed message type: the channel's
  ``field:`` (dots for nested fields), else the type's usual one — ``data`` for the
  ``std_msgs`` numbers (``Float32``, ``Float64``, ``Int32`` …), ``percentage`` for
  ``sensor_msgs/msg/BatteryState``, ``range`` for ``sensor_msgs/msg/Range``,
  ``temperature`` for ``sensor_msgs/msg/Temperature`` and so on (:data:`USUAL_FIELDS`).
* The QoS is the channel's reliability (``reliable`` or ``best_effort``, the latter for sensor
  drivers that publish best effort, which a reliable subscription would never match) and
  keep-last depth, both remappable by the node's ``inputs.<name>.qos`` / ``.depth`` parameters.

Every problem is a :class:`~pearl_pomdp.nodes.common.NodeSetupError` at configure time naming
the domain file, the field and what is wrong (a type that is not installed, a field it lacks
or that is not a number).
"""
from __future__ import annotations

import importlib
from dataclasses import dataclass
from typing import Any, Callable, Union

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from pearl_pomdp.channels import SPEECH_TYPE, SPEECH_TYPES, TEXT_TYPE, InputChannel
from pearl_pomdp.nodes.common import NodeSetupError
from pearl_pomdp.nodes.conversions import msg_to_speech
from pearl_pomdp.speech import Utterance

__all__ = ["ChannelReader", "USUAL_FIELDS", "reader_for", "qos_profile"]

#: The field a number channel reads when it names none, by message type (``data`` otherwise).
USUAL_FIELDS = {
    "sensor_msgs/msg/BatteryState": "percentage",
    "sensor_msgs/msg/Range": "range",
    "sensor_msgs/msg/Temperature": "temperature",
    "sensor_msgs/msg/RelativeHumidity": "relative_humidity",
    "sensor_msgs/msg/Illuminance": "illuminance",
    "sensor_msgs/msg/FluidPressure": "fluid_pressure",
}


@dataclass(frozen=True)
class ChannelReader:
    """How the node subscribes to one channel: the message class and what it hands the core."""

    channel: InputChannel
    msg_type: Any
    #: message → the core's input data (an Utterance or text for speech, text for symbol, a float for number).
    read: Callable[[Any], Union[str, float, Utterance]]
    #: The message field read (``data``, ``percentage`` …).
    field: str


def _message_class(type_name: str, where: str) -> Any:
    package, _, name = type_name.partition("/msg/")
    try:
        return getattr(importlib.import_module(f"{package}.msg"), name)
    except (ImportError, AttributeError):
        raise NodeSetupError(f"{where}.type: {type_name} is not an installed message type "
                             f"(no {name} in the Python package {package}.msg)") from None


def _get(msg: Any, path: str) -> Any:
    for part in path.split("."):
        msg = getattr(msg, part)
    return msg


def reader_for(channel: InputChannel, source: str) -> ChannelReader:
    """The :class:`ChannelReader` of ``channel``, declared in the domain file ``source``.

    Raises:
        NodeSetupError: a speech channel on another type than ``pearl_interfaces/msg/RecognisedSpeech``
            or ``std_msgs/msg/String``, a symbol channel on another than ``std_msgs/msg/String``; a number
            channel whose type is not installed, or lacks the field, or whose field is not a
            number (the message names ``source`` and ``modalities.<M>.input``).
    """
    where = f"{source}: modalities.{channel.modality}.input"
    if channel.kind == "speech" and channel.type == SPEECH_TYPE:
        cls = _message_class(channel.type, where)
        return ChannelReader(channel, cls, msg_to_speech, "text")
    if channel.kind in ("speech", "symbol"):
        if channel.type != TEXT_TYPE:
            wanted = " or ".join(SPEECH_TYPES) if channel.kind == "speech" else TEXT_TYPE
            raise NodeSetupError(f"{where}.type: a {channel.kind} input reads {wanted}, not {channel.type}")
        cls = _message_class(channel.type, where)
        return ChannelReader(channel, cls, lambda msg: str(msg.data), "data")
    cls = _message_class(channel.type, where)
    field = channel.field or USUAL_FIELDS.get(channel.type, "data")
    try:
        sample = _get(cls(), field)
    except AttributeError:
        raise NodeSetupError(f"{where}.field: {channel.type} has no field {field!r}"
                             + ("" if channel.field else " (name the number to read with field:)")) from None
    if isinstance(sample, bool) or not isinstance(sample, (int, float)):
        raise NodeSetupError(f"{where}.field: {channel.type}.{field} is not a number "
                             f"({type(sample).__name__}); a number input reads one number")
    return ChannelReader(channel, cls, lambda msg: float(_get(msg, field)), field)


def qos_profile(reliability: str, depth: int) -> QoSProfile:
    """Volatile keep-last ``depth``, reliable or best effort (a channel's subscription)."""
    return QoSProfile(depth=depth, history=HistoryPolicy.KEEP_LAST,
                      reliability=(ReliabilityPolicy.BEST_EFFORT if reliability == "best_effort"
                                   else ReliabilityPolicy.RELIABLE),
                      durability=DurabilityPolicy.VOLATILE)
