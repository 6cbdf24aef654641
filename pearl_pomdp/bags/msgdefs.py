"""Message definitions and type hashes as rosbag2 stores them, from the shipped interface files.

ROS 2 packages install ``share/<pkg>/msg/<Type>.msg`` (raw text, comments included) and
``share/<pkg>/msg/<Type>.json`` (the type description with its RIHS01 hash). The PyPI
wheels ship them under ``<venv>/share``; a ROS install has them under each prefix of
``AMENT_PREFIX_PATH``. This module reads only those files: it imports no ROS package.

:func:`message_definition` reproduces rosbag2_cpp's ``LocalMessageDefinitionSource``:
the root type's ``.msg`` text, then for each dependency (depth-first, each once, in the
sorted order of a ``std::set``) ``"\\n" + "="*80 + "\\nMSG: " + dep + "\\n" + dep_text``,
where ``dep`` is spelled as in the ``.msg`` (``std_msgs/Header``) or, without a package,
prefixed with the current package.
"""
from __future__ import annotations

import functools
import json
import os
import re
import sys
from pathlib import Path
from typing import List, Optional, Tuple

from pearl_pomdp.bags import well_known as wk
from pearl_pomdp.errors import PearlError

_FIELD_TYPE = re.compile(wk.MSG_FIELD_TYPE_PATTERN)
_NAME = r"[a-zA-Z][a-zA-Z0-9_]*"
_TYPE_2 = re.compile(rf"^({_NAME})/({_NAME})$")
_TYPE_3 = re.compile(rf"^({_NAME})/({_NAME})/({_NAME})$")
_MAX_DEPTH = 50  # rosbag2's ROSBAG2_CPP_LOCAL_MESSAGE_DEFINITION_SOURCE_MAX_RECURSION_DEPTH


class DefinitionNotFound(PearlError):
    """No interface file for a type in any searched prefix."""


def share_prefixes() -> List[Path]:
    """Prefixes searched for ``share/<pkg>``: ``AMENT_PREFIX_PATH`` entries, then ``sys.prefix``."""
    prefixes: List[Path] = []
    for entry in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep):
        if entry:
            prefixes.append(Path(entry))
    prefixes.append(Path(sys.prefix))
    seen, out = set(), []
    for p in prefixes:
        if p not in seen:
            seen.add(p)
            out.append(p)
    return out


def split_type(type_name: str) -> Tuple[str, str, str]:
    """``pkg/msg/Name`` or ``pkg/Name`` → ``(pkg, "msg", Name)``; PearlError otherwise."""
    m = _TYPE_3.match(type_name)
    if m:
        return m.group(1), m.group(2), m.group(3)
    m = _TYPE_2.match(type_name)
    if m:
        return m.group(1), "msg", m.group(2)
    raise PearlError(f"{type_name!r}: not a ROS 2 message type name (expected pkg/msg/Name)")


def _interface_file(type_name: str, suffix: str) -> Path:
    pkg, ns, name = split_type(type_name)
    for prefix in share_prefixes():
        candidate = prefix / "share" / pkg / ns / f"{name}{suffix}"
        if candidate.is_file():
            return candidate
    raise DefinitionNotFound(
        f"{type_name}: no share/{pkg}/{ns}/{name}{suffix} under "
        + ", ".join(str(p) for p in share_prefixes())
        + " (is the message package installed? set AMENT_PREFIX_PATH)"
    )


@functools.lru_cache(maxsize=None)
def _msg_text(type_name: str) -> str:
    # Bytes as shipped: rosbag2 reads the file raw (no newline translation).
    path = _interface_file(type_name, ".msg")
    try:
        return path.read_bytes().decode("utf-8")
    except UnicodeDecodeError as err:
        raise PearlError(f"{path}: not UTF-8 text ({err.reason} at byte {err.start})") from None


def msg_dependencies(text: str, package: str) -> List[str]:
    """Dependencies named in a ``.msg`` text, as rosbag2 finds them, sorted like ``std::set``.

    Args:
        text: raw ``.msg`` text.
        package: the package of the type the text belongs to (prefixes bare names).
    """
    deps = set()
    for m in _FIELD_TYPE.finditer(text):
        name = m.group(1)
        if name in wk.PRIMITIVE_TYPES:
            continue
        deps.add(name if "/" in name else f"{package}/{name}")
    # std::set<std::string> orders by bytes; Python's str order agrees for ASCII names.
    return sorted(deps)


@functools.lru_cache(maxsize=None)
def message_definition(type_name: str) -> str:
    """rosbag2's full ``ros2msg`` definition text of ``type_name`` (e.g. ``std_msgs/msg/String``)."""
    seen = set()

    def append(name: str, depth: int) -> str:
        if depth <= 0:
            raise PearlError(f"{type_name}: message definition nests deeper than {_MAX_DEPTH} levels")
        text = _msg_text(name)
        pkg = split_type(name)[0]
        out = [text]
        for dep in msg_dependencies(text, pkg):
            if dep not in seen:
                seen.add(dep)
                out.append(f"\n{wk.DEFINITION_SEPARATOR}\nMSG: {dep}\n")
                out.append(append(dep, depth - 1))
        return "".join(out)

    return append(type_name, _MAX_DEPTH)


@functools.lru_cache(maxsize=None)
def type_hash(type_name: str) -> str:
    """The RIHS01 type hash of ``type_name`` from the shipped ``.json`` type description."""
    path = _interface_file(type_name, ".json")
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
        pkg, ns, name = split_type(type_name)
        full = f"{pkg}/{ns}/{name}"
        for entry in doc["type_hashes"]:
            if entry["type_name"] == full:
                return str(entry["hash_string"])
    except (ValueError, KeyError, TypeError) as err:
        raise PearlError(f"{path}: type_hashes: unreadable type description ({err})") from None
    raise PearlError(f"{path}: type_hashes: no entry for {type_name}")


def try_type_hash(type_name: str) -> Optional[str]:
    """:func:`type_hash`, or ``None`` when the type's description is not installed."""
    try:
        return type_hash(type_name)
    except PearlError:
        return None
