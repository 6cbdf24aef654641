"""What is in a bag, as ``ros2 bag info`` shows it (plus whether it had to be salvaged).

:func:`bag_info` returns a JSON-ready mapping; :func:`format_info` renders it the way
``ros2 bag info`` lays its report out (Files, Bag size, Storage id, Duration, Start, End,
Messages, Topic information), with each topic's QoS and a ``Salvaged:`` line when the bag
was cut short (recorder killed) and read up to the cut.
"""
from __future__ import annotations

import datetime as _dt
from typing import Any, Dict, List, Optional

from pearl_pomdp.bags.reader import BagReader

_NS = 1_000_000_000


def _stamp(ns: Optional[int]) -> Optional[str]:
    if ns is None:
        return None
    t = _dt.datetime.fromtimestamp(ns // _NS, tz=_dt.timezone.utc)
    return f"{t:%b %d %Y %H:%M:%S}.{(ns % _NS) // 1_000_000:03d} ({ns // _NS}.{ns % _NS:09d})"


def _size(n: int) -> str:
    size = float(n)
    for unit in ("B", "KiB", "MiB", "GiB"):
        if size < 1024 or unit == "GiB":
            return f"{n} {unit}" if unit == "B" else f"{size:.1f} {unit}"
        size /= 1024.0
    return f"{n} B"  # pragma: no cover


def bag_info(reader: BagReader) -> Dict[str, Any]:
    """Summary of an opened bag: files, size, times (ns), counts, topics with QoS, salvage state.

    ``metadata_mismatch`` lists disagreements between ``metadata.yaml`` and the messages
    actually in the files (empty for a healthy bag).
    """
    size = sum(f.stat().st_size for f in reader.files)
    meta = reader.metadata or {}
    topics: List[Dict[str, Any]] = []
    for t in reader.topics.values():
        topics.append({
            "name": t.name,
            "type": t.type,
            "count": t.message_count,
            "serialization_format": t.serialization_format,
            "type_description_hash": t.type_description_hash,
            "offered_qos_profiles": [q.to_dict() for q in t.offered_qos_profiles],
        })
    mismatch: List[str] = []
    if reader.metadata_file is not None:
        if meta.get("message_count") != reader.message_count:
            mismatch.append(f"message_count {meta.get('message_count')} in metadata.yaml, "
                            f"{reader.message_count} in the files")
        listed = {}
        for entry in meta.get("topics_with_message_count") or []:
            try:
                listed[entry["topic_metadata"]["name"]] = entry["message_count"]
            except (KeyError, TypeError):
                mismatch.append(f"malformed topics_with_message_count entry {entry!r}")
        for t in reader.topics.values():
            if t.name in listed and listed[t.name] != t.message_count:
                mismatch.append(f"{t.name}: {listed[t.name]} in metadata.yaml, {t.message_count} in the files")
    return {
        "bag": str(reader.path),
        "files": [str(f.name) for f in reader.files],
        "size_bytes": size,
        "storage_identifier": "mcap",
        "ros_distro": meta.get("ros_distro"),
        "library": reader.library,
        "metadata_yaml": reader.metadata_file is not None,
        "directory": reader.path.is_dir(),
        "duration_ns": reader.duration,
        "duration_s": reader.duration / _NS,
        "start_ns": reader.start_time,
        "end_ns": reader.end_time,
        "message_count": reader.message_count,
        "topics": topics,
        "salvaged": reader.salvaged,
        "problems": list(reader.problems),
        "metadata_mismatch": mismatch,
    }


def format_info(info: Dict[str, Any]) -> str:
    """The ``ros2 bag info``-style text for a :func:`bag_info` mapping."""
    from pearl_pomdp.bags.metadata import QosProfile

    lines = [
        f"Files:             {', '.join(info['files'])}",
        f"Bag size:          {_size(info['size_bytes'])}",
        f"Storage id:        {info['storage_identifier']}",
        f"ROS Distro:        {info['ros_distro'] or 'unknown'}",
        f"Duration:          {info['duration_s']:.9f}s",
        f"Start:             {_stamp(info['start_ns']) or '-'}",
        f"End:               {_stamp(info['end_ns']) or '-'}",
        f"Messages:          {info['message_count']}",
    ]
    label = "Topic information: "
    if not info["topics"]:
        lines.append(label)
    for i, t in enumerate(info["topics"]):
        qos = "; ".join(QosProfile.from_dict(q).brief() for q in t["offered_qos_profiles"]) or "-"
        lines.append(f"{label if i == 0 else ' ' * len(label)}Topic: {t['name']} | Type: {t['type']} | "
                     f"Count: {t['count']} | Serialization Format: {t['serialization_format']} | QoS: {qos}")
    if info["directory"] and not info["metadata_yaml"]:
        lines.append("metadata.yaml:     missing (recorder did not close the bag); read from the MCAP file")
    if info["salvaged"]:
        for p in info["problems"]:
            lines.append(f"Salvaged:          {p}; read every complete message before the cut")
    for m in info["metadata_mismatch"]:
        lines.append(f"Mismatch:          {m}")
    return "\n".join(lines)


def repair_bag(path) -> Dict[str, Any]:
    """Rewrite a salvaged bag directory into a complete one (like ``ros2 bag reindex``).

    Every complete message is copied, with its times, sequence number and topic metadata
    (QoS, type hash, definition), into a fresh ``<name>_0.mcap`` with footer, summary and
    ``metadata.yaml``; the damaged files are kept beside it as ``<file>.broken``. The
    ``custom_data`` of the damaged bag (from its metadata) is kept.

    Returns:
        ``{"bag", "messages", "kept": [renamed damaged files]}``.

    Raises:
        PearlError: ``path`` is not a bag directory, or is complete already.
    """
    import os
    import shutil
    from pathlib import Path

    from pearl_pomdp.bags.writer import BagWriter
    from pearl_pomdp.errors import PearlError

    path = Path(path)
    if not path.is_dir():
        raise PearlError(f"{path}: --repair needs a bag directory (it rewrites the bag in place)")
    reader = BagReader(path, salvage=True)
    if not reader.salvaged and reader.metadata_file is not None:
        raise PearlError(f"{path}: the bag is complete; nothing to repair")
    custom = dict((reader.metadata or {}).get("custom_data") or {})
    staging = path.parent / f".{path.name}.repair{os.getpid()}"
    if staging.exists():
        shutil.rmtree(staging)
    try:
        with BagWriter(staging / path.name, custom_data=custom, flush_each=False) as out:
            for t in reader.topics.values():
                out.add_topic(t.name, t.type, qos=t.offered_qos_profiles, type_hash=t.type_description_hash,
                              definition=t.definition, serialization_format=t.serialization_format)
            for m in reader.messages:
                out.write(m.topic, m.data, m.log_time, m.publish_time, m.sequence)
        kept = []
        for f in reader.files:
            broken = f.with_name(f.name + ".broken")
            f.rename(broken)
            kept.append(broken.name)
        for f in (staging / path.name).iterdir():
            os.replace(f, path / f.name)
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    return {"bag": str(path), "messages": reader.message_count, "kept": kept}
