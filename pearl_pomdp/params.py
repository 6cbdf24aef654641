"""The node parameters file (``config/pearl_nodes.yaml``), read without ROS.

One source per default: the robot (``--params-file`` in the launch file), ``PearlGraph``
(demo, replay, tests) and the fast experiment path all take the node parameters from this
file, so the demo and the robot run with the same step rules.

The file is in the ROS 2 params-file format: ``node_name: {ros__parameters: {...}}``, with
``/**`` for parameters every node shares.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any, Dict, Union

from pearl_pomdp.errors import PearlError

__all__ = ["default_params_file", "load_params_file", "node_params", "step_settings"]

PARAMS_NAME = "config/pearl_nodes.yaml"


def default_params_file() -> Path:
    """The shipped ``config/pearl_nodes.yaml`` (package share directory or source tree)."""
    from pearl_pomdp.launch_xml import package_share_dir

    share = package_share_dir("pearl_pomdp")
    if share is None or not (share / PARAMS_NAME).is_file():
        raise PearlError(f"{PARAMS_NAME}: not found in the package share directory ({share}); "
                         "reinstall the package or pass a params file")
    return share / PARAMS_NAME


def load_params_file(path: Union[str, Path, None] = None) -> Dict[str, Dict[str, Any]]:
    """``{node name or '/**': {parameter: value}}`` of a ROS 2 params file.

    Raises:
        PearlError: unreadable file, or not in the params-file format (names the file and key).
    """
    from pearl_pomdp.yaml_lines import load_yaml

    p = Path(path) if path is not None else default_params_file()
    data = load_yaml(p)
    if not isinstance(data, dict):
        raise PearlError(f"{p}: a params file maps node names to {{ros__parameters: ...}}")
    out: Dict[str, Dict[str, Any]] = {}
    for node, section in data.items():
        if not isinstance(section, dict) or not isinstance(section.get("ros__parameters"), dict):
            raise PearlError(f"{p}: {node}: expected a 'ros__parameters' mapping")
        out[str(node).lstrip("/") if str(node) != "/**" else "/**"] = dict(section["ros__parameters"])
    return out


def node_params(node: str, path: Union[str, Path, None] = None) -> Dict[str, Any]:
    """The parameters ``node`` gets from the file: the shared ``/**`` section, then its own."""
    table = load_params_file(path)
    return {**table.get("/**", {}), **table.get(node, {})}


def step_settings(path: Union[str, Path, None] = None, **overrides: Any):
    """The belief tracker's :class:`~pearl_pomdp.tracking.StepSettings` from the params file."""
    from pearl_pomdp.tracking import StepSettings

    return StepSettings.from_params({**node_params("belief_tracker", path), **overrides})


