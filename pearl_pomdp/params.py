"""The node parameters file (``config/pearl_nodes.yaml``), read without ROS.

One source per default: the code holds the defaults (the tracker's in
:class:`pearl_pomdp.tracking.StepSettings`), this file only what the Pearl robot sets
differently. The robot (``--params-file`` in the launch file, and each node's own
``defaults_file``: :mod:`pearl_pomdp.nodes.defaults`), ``PearlGraph`` (demo, replay, tests) and
the fast experiment path (:func:`step_settings`) all apply it, so the demo, the study and the
robot follow the same rules.

The file is in the ROS 2 params-file format (Nav2's ``nav2_params.yaml`` convention):
``node_name: {ros__parameters: {...}}``, with ``/**`` for parameters every node shares.
:func:`node_parameters` returns what ``--params-file`` would give one node: ``/**`` first,
then ``/**/node_name``, then ``node_name`` (later wins, as in rcl), with nested mappings
flattened to dotted names (``actions: {TellTime: {say: …}}`` → ``actions.TellTime.say``).
It is read with the one YAML loader (:mod:`pearl_pomdp.yaml_lines`: errors name the line).
"""
from __future__ import annotations

import copy
import functools
from pathlib import Path
from typing import Any, Dict, Union

from pearl_pomdp.errors import PearlError, SpecError

__all__ = ["default_params_file", "flatten", "node_parameters", "step_settings"]

PARAMS_NAME = "config/pearl_nodes.yaml"


def default_params_file() -> Path:
    """The shipped ``config/pearl_nodes.yaml`` (package share directory or source tree)."""
    from pearl_pomdp.launch_xml import package_share_dir

    share = package_share_dir("pearl_pomdp")
    if share is None or not (share / PARAMS_NAME).is_file():
        raise PearlError(f"{PARAMS_NAME}: not found in the package share directory ({share}); "
                         "reinstall the package or pass a params file")
    return share / PARAMS_NAME


def flatten(tree: Any, prefix: str = "") -> Dict[str, Any]:
    """``{"a": {"b": 1}}`` → ``{"a.b": 1}``; lists and scalars are leaves, empty mappings set nothing."""
    if not isinstance(tree, dict):
        return {prefix: tree}
    out: Dict[str, Any] = {}
    for key, value in tree.items():
        name = f"{prefix}.{key}" if prefix else str(key)
        if isinstance(value, dict) and value:
            out.update(flatten(value, name))
        elif not isinstance(value, dict):
            out[name] = value
    return out


def node_parameters(node_name: str, path: Union[str, Path, None] = None) -> Dict[str, Any]:
    """The flattened parameters that the params file ``path`` gives ``node_name`` (see the module doc).

    ``path`` ``None``: the shipped file.

    Raises:
        SpecError: the file is missing, not YAML, or a section has no ``ros__parameters``
            mapping (the message names the file, the section and the line).
    """
    from pearl_pomdp.yaml_lines import line_of

    p = Path(path) if path is not None else default_params_file()
    try:
        text = p.read_text(encoding="utf-8")
    except OSError as err:
        raise SpecError(p, "", f"cannot read: {err.strerror or err}") from None
    data = _parsed(text, str(p))
    if data is None:
        return {}
    if not isinstance(data, dict):
        raise SpecError(p, "", "expected a mapping of node names to {ros__parameters: ...}")
    out: Dict[str, Any] = {}
    for section in ("/**", f"/**/{node_name}", node_name, f"/{node_name}"):
        if section not in data:
            continue
        body = data[section]
        if not isinstance(body, dict) or not isinstance(body.get("ros__parameters", {}), dict):
            raise SpecError(p, section, "expected {ros__parameters: {name: value, ...}}", line=line_of(data, section))
        out.update(flatten(body.get("ros__parameters") or {}))
    return copy.deepcopy(out)   # the parsed file is shared (_parsed): the caller gets its own values


@functools.lru_cache(maxsize=16)
def _parsed(text: str, source: str) -> Any:
    """The YAML ``text`` of the params file ``source``, parsed once per content: a study reads the file
    for every episode (:func:`step_settings`), ~30 ms a parse. Keyed by the text read, so an edited
    file is parsed again. Nobody may change what it returns (:func:`node_parameters` copies out)."""
    from pearl_pomdp.yaml_lines import parse_yaml

    return parse_yaml(text, source)


def step_settings(path: Union[str, Path, None] = None, **overrides: Any):
    """The belief tracker's :class:`~pearl_pomdp.tracking.StepSettings` as the node runs them: the
    code's defaults, then the params file's ``/**`` and ``belief_tracker`` sections, then ``overrides``."""
    from pearl_pomdp.tracking import StepSettings

    return StepSettings.from_params({**node_parameters("belief_tracker", path), **overrides})


