"""Read one node's parameters out of a ROS 2 params file, without ROS.

A params file (``config/pearl_nodes.yaml``) is keyed ``node_name: ros__parameters: {...}``,
with ``/**`` for parameters every node shares (Nav2's ``nav2_params.yaml`` convention).
:func:`node_parameters` returns what ``--params-file`` would give the node ``node_name``:
``/**`` first, then ``/**/node_name``, then ``node_name`` (later wins, as in rcl), with nested
mappings flattened to dotted names (``actions: {TellTime: {say: …}}`` →
``actions.TellTime.say``).

The nodes that need tables too large for code (what each action says, where each place
is) read their *defaults* from this file, so one file holds them and ``--ros-args -p`` /
``--params-file`` still override each value.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any, Dict

import yaml

from pearl_pomdp.errors import PathLike, SpecError

__all__ = ["node_parameters", "flatten"]


def flatten(tree: Any, prefix: str = "") -> Dict[str, Any]:
    """``{"a": {"b": 1}}`` → ``{"a.b": 1}``; lists and scalars are leaves."""
    if not isinstance(tree, dict):
        return {prefix: tree}
    out: Dict[str, Any] = {}
    for key, value in tree.items():
        name = f"{prefix}.{key}" if prefix else str(key)
        if isinstance(value, dict) and value:
            out.update(flatten(value, name))
        elif isinstance(value, dict):
            continue  # ``DoNothing: {}``: nothing to set
        else:
            out[name] = value
    return out


def node_parameters(path: PathLike, node_name: str) -> Dict[str, Any]:
    """The flattened parameters that ``path`` gives the node ``node_name`` (see the module doc).

    Raises:
        SpecError: the file is missing, is not YAML, or a section has no ``ros__parameters``
            mapping (the message names the file and the section).
    """
    path = Path(path)
    try:
        data = yaml.safe_load(path.read_text(encoding="utf-8"))
    except OSError as err:
        raise SpecError(path, "", f"cannot read: {err.strerror or err}") from None
    except yaml.YAMLError as err:
        mark = getattr(err, "problem_mark", None)
        raise SpecError(path, "", f"not YAML: {getattr(err, 'problem', err)}",
                        line=mark.line + 1 if mark is not None else None) from None
    if data is None:
        return {}
    if not isinstance(data, dict):
        raise SpecError(path, "", "expected a mapping of node names to {ros__parameters: ...}")
    out: Dict[str, Any] = {}
    for section in ("/**", f"/**/{node_name}", node_name, f"/{node_name}"):
        if section not in data:
            continue
        body = data[section]
        if not isinstance(body, dict) or not isinstance(body.get("ros__parameters", {}), dict):
            raise SpecError(path, section, "expected {ros__parameters: {name: value, ...}}")
        out.update(flatten(body.get("ros__parameters") or {}))
    return out
