"""A simulated world's true state as a bag records it (``/WORLD/sim/truth``), read without ROS.

A simulator publishes the world's *truth record* at the start and at the end of every action
(``pearl_sim.world_base.StudyWorld.truth_record``): a mapping

    {"time": <the world's time, s>, "phase": "start" | "end", "action": <name; '' for the state
     after the last action>, "state": {feature: value, …}}

and, when the record closes an action, also ``"events"`` (what happened, one line each) and
``"wrong"`` (why the action was wrong, ``None`` when it was not). ``pearl fit`` counts transitions
between the ``start`` states; the checks on a recording read ``state`` and ``events``.

On the wire it is ``pearl_interfaces/msg/WorldTruth`` (:data:`TRUTH_TYPE`: the state as parallel
feature-name and value arrays, ``has_outcome`` for ``events``/``wrong``); the ROS layer builds it
(:func:`pearl_pomdp.nodes.conversions.truth_to_msg`). Bags recorded before that message hold the
record as JSON in a ``std_msgs/String``; :func:`truth_records` reads both, so an old bag gives the
same records, and the same fit, as a new one.
"""
from __future__ import annotations

from typing import Any, Dict, List

from pearl_pomdp.bags import well_known as wk
from pearl_pomdp.bags.reader import BagReader, cdr_string
from pearl_pomdp.errors import PearlError

__all__ = ["TRUTH_TYPE", "truth_topic", "truth_topics", "truth_from_msg", "truth_records"]

#: The message type of ``/WORLD/sim/truth``.
TRUTH_TYPE = "pearl_interfaces/msg/WorldTruth"
_SUFFIX = "/sim/truth"


def truth_topic(world_name: str) -> str:
    """Where world ``world_name``'s true state goes (``/pearl/sim/truth``, ``/reception/sim/truth`` …)."""
    return f"/{world_name}{_SUFFIX}"


def truth_topics(reader: BagReader) -> List[str]:
    """The bag's truth topics (``/WORLD/sim/truth``), in the order the bag first names them."""
    return [t for t in reader.topics if t.startswith("/") and t.endswith(_SUFFIX) and t.count("/") == 3]


def truth_from_msg(msg: Any, where: str = "truth") -> Dict[str, Any]:
    """The truth record of a ``WorldTruth`` message — a ROS message object or any object with its
    fields (a bag's message decoded by ``mcap-ros2-support``).

    Raises:
        PearlError: ``feature_names`` and ``feature_values`` differ in length (names ``where``).
    """
    names, values = list(msg.feature_names), list(msg.feature_values)
    if len(names) != len(values):
        raise PearlError(f"{where}: {len(names)} feature_names but {len(values)} feature_values "
                         "(one value per feature)")
    record: Dict[str, Any] = {"time": float(msg.world_time), "phase": str(msg.phase), "action": str(msg.action),
                              "state": dict(zip(names, values))}
    if msg.has_outcome:
        record.update(events=list(msg.events), wrong=str(msg.wrong) or None)
    return record


def _json_record(data: bytes, where: str) -> Dict[str, Any]:
    import json

    try:
        record = json.loads(cdr_string(data))
    except (ValueError, UnicodeDecodeError) as err:
        raise PearlError(f"{where}: not a std_msgs/String holding a JSON truth record ({err})") from None
    if not isinstance(record, dict) or not isinstance(record.get("state"), dict):
        raise PearlError(f"{where}: the JSON truth record has no \"state\" mapping of feature to value")
    return record


def truth_records(reader: BagReader, topic: str) -> List[Dict[str, Any]]:
    """Every truth record the bag holds on ``topic``, in order: ``pearl_interfaces/msg/WorldTruth``,
    or the JSON ``std_msgs/String`` of a bag recorded before it.

    Raises:
        PearlError: the topic has another type, or a message does not decode (names the bag, the
            topic, the message's number and what is wrong).
    """
    recorded = reader.topics[topic].type
    if recorded == TRUTH_TYPE:
        decode = reader.decoder(topic)
    elif recorded != wk.STRING_TYPE:
        raise PearlError(f"{reader.path}: topic {topic}: recorded as {recorded}; a truth topic is {TRUTH_TYPE} "
                         f"(or, in a bag recorded before it, JSON in {wk.STRING_TYPE})")
    out = []
    for i, m in enumerate(reader.read_messages([topic])):
        where = f"{reader.path}: topic {topic}: message {i}"
        if recorded == wk.STRING_TYPE:
            out.append(_json_record(m.data, where))
            continue
        try:
            msg = decode(m.data)
        except Exception as err:   # mcap_ros2 raises plain errors (struct, index, value) on bad bytes
            raise PearlError(f"{where}: not a {TRUTH_TYPE} ({type(err).__name__}: {err})") from None
        out.append(truth_from_msg(msg, where))
    return out
