"""rosbag2 metadata: QoS profiles and ``metadata.yaml``, in rosbag2's own YAML layout.

rosbag2 writes its YAML with yaml-cpp (block style, two-space indents, a sequence inside a
map indented by two more, ``~`` for null, ``""`` for the empty string). :func:`dump_yaml`
reproduces that layout for the documents rosbag2 writes, so a bag written here reads the
same as one from ``ros2 bag record`` — in ``metadata.yaml``, in the MCAP ``rosbag2``
metadata record and in each channel's ``offered_qos_profiles``.
"""
from __future__ import annotations

import functools
import json
import re
from dataclasses import dataclass, field
from typing import Any, Dict, List, Mapping, Optional, Sequence, Tuple

from pearl_pomdp.bags import well_known as wk
from pearl_pomdp.errors import PearlError

Duration = Tuple[int, int]  # (sec, nsec), as rmw_time_t


def _policy_name(value: Any, names: Mapping[int, str], what: str) -> str:
    if isinstance(value, bool):
        raise ValueError(f"{what}: {value!r} is not a policy")
    if isinstance(value, int):
        if value not in names:
            raise ValueError(f"{what}: unknown rmw value {value}")
        return names[value]
    text = str(value).strip().lower()
    if text not in names.values():
        raise ValueError(f"{what}: {value!r} is not one of {sorted(set(names.values()))}")
    return text


def _duration(value: Any, what: str) -> Duration:
    if isinstance(value, Mapping) and "sec" in value and "nsec" in value:
        sec, nsec = int(value["sec"]), int(value["nsec"])
        # Foxy-era "infinite" spellings, translated as rosbag2 does on read.
        if (sec, nsec) in ((0x7FFFFFFF, 0xFFFFFFFF), (0x7FFFFFFF, 0x7FFFFFFF)) or \
                sec * 1_000_000_000 + nsec == 0x7FFFFFFFFFFFFFFF:
            return wk.DURATION_INFINITE
        return sec, nsec
    raise ValueError(f"{what}: expected {{sec, nsec}}, got {value!r}")


@dataclass(frozen=True)
class QosProfile:
    """A QoS profile as rosbag2 records it (rmw names, durations as ``(sec, nsec)``).

    ``history``: keep_last/keep_all/system_default; ``reliability``: reliable/best_effort/…;
    ``durability``: volatile/transient_local/…; ``liveliness``: automatic/manual_by_topic/….
    """

    history: str = "keep_last"
    depth: int = 10
    reliability: str = "reliable"
    durability: str = "volatile"
    deadline: Duration = wk.DURATION_INFINITE
    lifespan: Duration = wk.DURATION_INFINITE
    liveliness: str = "automatic"
    liveliness_lease_duration: Duration = wk.DURATION_INFINITE
    avoid_ros_namespace_conventions: bool = False

    def to_dict(self) -> Dict[str, Any]:
        """The mapping rosbag2 (metadata v9) writes, keys in its order."""
        return {
            "history": self.history,
            "depth": int(self.depth),
            "reliability": self.reliability,
            "durability": self.durability,
            "deadline": {"sec": self.deadline[0], "nsec": self.deadline[1]},
            "lifespan": {"sec": self.lifespan[0], "nsec": self.lifespan[1]},
            "liveliness": self.liveliness,
            "liveliness_lease_duration": {"sec": self.liveliness_lease_duration[0],
                                          "nsec": self.liveliness_lease_duration[1]},
            "avoid_ros_namespace_conventions": bool(self.avoid_ros_namespace_conventions),
        }

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> "QosProfile":
        """Parse rosbag2's form: v9 names or pre-v9 integers (ValueError names the field)."""
        if not isinstance(d, Mapping):
            raise ValueError(f"QoS profile must be a mapping, got {d!r}")
        try:
            return cls(
                history=_policy_name(d.get("history", 1), wk.HISTORY_NAMES, "history"),
                depth=int(d.get("depth", 0)),
                reliability=_policy_name(d.get("reliability", 1), wk.RELIABILITY_NAMES, "reliability"),
                durability=_policy_name(d.get("durability", 2), wk.DURABILITY_NAMES, "durability"),
                deadline=_duration(d.get("deadline", {"sec": 0, "nsec": 0}), "deadline"),
                lifespan=_duration(d.get("lifespan", {"sec": 0, "nsec": 0}), "lifespan"),
                liveliness=_policy_name(d.get("liveliness", 1), wk.LIVELINESS_NAMES, "liveliness"),
                liveliness_lease_duration=_duration(
                    d.get("liveliness_lease_duration", {"sec": 0, "nsec": 0}), "liveliness_lease_duration"),
                avoid_ros_namespace_conventions=bool(d.get("avoid_ros_namespace_conventions", False)),
            )
        except (TypeError, ValueError) as err:
            raise ValueError(str(err)) from None

    def brief(self) -> str:
        """One line for ``bag-info``: ``reliable/volatile, history keep_last(10)``.

        History is named because its value alone is ambiguous: a recorder learns each
        publisher's QoS from DDS discovery, which carries no history or depth, so rosbag2
        (and our recorder) store history ``unknown`` — shown as ``history unknown``.
        """
        hist = f"{self.history}({self.depth})" if self.history == "keep_last" else self.history
        return f"{self.reliability}/{self.durability}, history {hist}"


def qos_list_yaml(profiles: Sequence[QosProfile]) -> str:
    """The ``offered_qos_profiles`` channel-metadata string (yaml-cpp ``YAML::Dump`` of the list)."""
    return dump_yaml([p.to_dict() for p in profiles])


def parse_qos_list(text_or_list: Any, where: str) -> List[QosProfile]:
    """Parse ``offered_qos_profiles`` from a YAML string (channel metadata, metadata < v9) or a list.

    Raises:
        PearlError naming ``where`` when it is not a list of QoS mappings.
    """
    import yaml

    value = text_or_list
    if isinstance(value, (bytes, str)):
        if not str(value).strip():
            return []
        try:
            value = _cached_yaml(value)  # channels of one bag mostly share the same text
        except yaml.YAMLError as err:
            raise PearlError(f"{where}: offered_qos_profiles is not YAML ({err})") from None
    if value is None:
        return []
    if not isinstance(value, list):
        raise PearlError(f"{where}: offered_qos_profiles must be a list, got {type(value).__name__}")
    out = []
    for i, item in enumerate(value):
        try:
            out.append(QosProfile.from_dict(item))
        except ValueError as err:
            raise PearlError(f"{where}: offered_qos_profiles[{i}]: {err}") from None
    return out


@functools.lru_cache(maxsize=256)
def _cached_yaml(text):
    return load_yaml(text)


def load_yaml(text):
    """``yaml.safe_load`` with libyaml's C loader when available (bags hold many small documents)."""
    import yaml

    return yaml.load(text, Loader=getattr(yaml, "CSafeLoader", yaml.SafeLoader))


# --- yaml-cpp-style emitter ----------------------------------------------------------------
_PLAIN = re.compile(r"^[A-Za-z0-9_/][A-Za-z0-9_/.\-]*$")
_SPECIAL = {"true", "false", "yes", "no", "on", "off", "null", "y", "n", "~"}
_NUMBER = re.compile(r"^[-+]?(\d+\.?\d*([eE][-+]?\d+)?|\.\d+|0x[0-9a-fA-F]+|0o[0-7]+|\.inf|\.nan)$", re.I)


def _scalar(value: Any) -> str:
    if value is None:
        return "~"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        return repr(value)
    text = str(value)
    if text and _PLAIN.match(text) and text.lower() not in _SPECIAL and not _NUMBER.match(text):
        return text
    return json.dumps(text, ensure_ascii=False)  # a valid YAML double-quoted scalar


def _is_block(value: Any) -> bool:
    return isinstance(value, (Mapping, list, tuple)) and len(value) > 0


def _emit(value: Any, indent: int, out: List[str]) -> None:
    pad = " " * indent
    if isinstance(value, Mapping):
        for key, item in value.items():
            if _is_block(item):
                out.append(f"{pad}{key}:")
                _emit(item, indent + 2, out)
            else:
                out.append(f"{pad}{key}: {_inline(item)}")
    else:
        for item in value:
            if _is_block(item):
                start = len(out)
                _emit(item, indent + 2, out)
                out[start] = f"{pad}- " + out[start][indent + 2:]
            else:
                out.append(f"{pad}- {_inline(item)}")


def _inline(value: Any) -> str:
    if isinstance(value, Mapping):
        return "{}"
    if isinstance(value, (list, tuple)):
        return "[]"
    return _scalar(value)


def dump_yaml(value: Any) -> str:
    """YAML text in yaml-cpp's block layout (no trailing newline, as ``YAML::Dump``)."""
    if not _is_block(value):
        return _inline(value)
    lines: List[str] = []
    _emit(value, 0, lines)
    return "\n".join(lines)


# --- metadata.yaml ---------------------------------------------------------------------------
@dataclass
class TopicMetadata:
    """One topic of a bag, as ``topics_with_message_count[].topic_metadata`` describes it."""

    name: str
    type: str
    serialization_format: str = wk.SERIALIZATION_FORMAT
    offered_qos_profiles: List[QosProfile] = field(default_factory=list)
    type_description_hash: str = ""

    def to_dict(self) -> Dict[str, Any]:
        return {
            "name": self.name,
            "type": self.type,
            "serialization_format": self.serialization_format,
            "offered_qos_profiles": [q.to_dict() for q in self.offered_qos_profiles],
            "type_description_hash": self.type_description_hash,
        }


def bag_metadata(*, files: Sequence[Tuple[str, int, int, int]], topics: Sequence[Tuple[TopicMetadata, int]],
                 start_ns: int, duration_ns: int, message_count: int,
                 custom_data: Optional[Mapping[str, str]] = None, ros_distro: str = wk.ROS_DISTRO,
                 compression_format: str = "", compression_mode: str = "") -> Dict[str, Any]:
    """The ``rosbag2_bagfile_information`` mapping (v9), keys in rosbag2's order.

    Args:
        files: ``(relative path, start ns, duration ns, message count)`` per storage file.
        topics: ``(topic metadata, message count)`` per topic.
    """
    return {
        "version": wk.METADATA_VERSION,
        "storage_identifier": wk.STORAGE_IDENTIFIER,
        "duration": {"nanoseconds": int(duration_ns)},
        "starting_time": {"nanoseconds_since_epoch": int(start_ns)},
        "message_count": int(message_count),
        "topics_with_message_count": [
            {"topic_metadata": t.to_dict(), "message_count": int(n)} for t, n in topics
        ],
        "compression_format": compression_format,
        "compression_mode": compression_mode,
        "relative_file_paths": [f[0] for f in files],
        "files": [
            {"path": p, "starting_time": {"nanoseconds_since_epoch": int(s)},
             "duration": {"nanoseconds": int(d)}, "message_count": int(n)}
            for p, s, d, n in files
        ],
        "custom_data": dict(custom_data) if custom_data else None,
        "ros_distro": ros_distro,
    }


def metadata_yaml(info: Mapping[str, Any]) -> str:
    """The full ``metadata.yaml`` text for a ``rosbag2_bagfile_information`` mapping."""
    return dump_yaml({wk.METADATA_TOP_KEY: info}) + "\n"
