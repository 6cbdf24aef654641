"""Parameter defaults from the package's params file (``config/pearl_nodes.yaml``).

The code holds every default (for the tracker: :class:`pearl_pomdp.tracking.StepSettings`);
the shipped params file holds only what the Pearl robot sets differently — its places, what
each action says and where it drives, which landmark each place is, the guidances, the
tracker's stale and drive rules — each with its reason. Every Pearl node of the launch file
declares a ``defaults_file`` parameter (default ``config/pearl_nodes.yaml``, looked up like
every file parameter: working directory, then the package share directory), reads the
``/**`` and ``<node default name>`` sections of it (:func:`pearl_pomdp.params.node_parameters`)
and declares each parameter with the file's value as its default. So

* ``ros2 run pearl_pomdp belief_tracker`` (or any node) with no parameters behaves as under the
  launch file (``test/test_node_params.py`` checks every node);
* ``--params-file`` and ``-p`` still override every value (they are overrides in rclpy);
* ``-p defaults_file:=''`` starts from the code's defaults (no places, no action table);
* a node given a ``domain`` and no ``defaults_file`` reads that domain's own params file instead:
  ``NAME_nodes.yaml`` beside ``NAME.domain.yaml`` (Pearl's ``config/pearl.domain.yaml`` gives
  ``config/pearl_nodes.yaml``); a domain without one whose ``name:`` is Pearl's (a copy of Pearl's
  domain, as ``pearl demo`` writes) reads Pearl's file; any other only the code's defaults. Pearl's
  values never reach another robot (``-p domain:=courier.domain.yaml`` alone starts a courier node).
"""
from __future__ import annotations

import re
from dataclasses import replace
from pathlib import Path
from typing import Any, Dict, List, Mapping, Optional, Sequence

from pearl_pomdp.errors import SpecError
from pearl_pomdp.nodes.common import NodeSetupError, Param, PearlNode, resolve_path
from pearl_pomdp.params import node_parameters

__all__ = ["DEFAULTS_FILE", "DOMAIN_SUFFIX", "NODES_SUFFIX", "FileDefaults", "domain_params_file"]

#: The params file the package ships; its sections hold every node's defaults.
DEFAULTS_FILE = "config/pearl_nodes.yaml"

#: A domain ``NAME.domain.yaml`` keeps its robot's node params in ``NAME_nodes.yaml`` beside it.
DOMAIN_SUFFIX, NODES_SUFFIX = ".domain.yaml", "_nodes.yaml"


def _domain_name(path: Path) -> Optional[str]:
    """The top-level ``name:`` of a domain file (``None``: none, or unreadable)."""
    try:
        found = re.search(r"^name:\s*['\"]?([^'\"#\s]+)", path.read_text(encoding="utf-8"), re.MULTILINE)
    except (OSError, UnicodeDecodeError):
        return None
    return found.group(1) if found else None


def domain_params_file(domain: str) -> Optional[Path]:
    """The node params file of the domain file ``domain`` (a parameter value, looked up like every
    file parameter): ``NAME_nodes.yaml`` beside ``NAME.domain.yaml``; else, for a domain named as
    Pearl's (``config/pearl.domain.yaml``'s ``name:``), Pearl's :data:`DEFAULTS_FILE`; else ``None``
    (also when the domain file is missing: the node's own ``domain`` check reports that)."""
    try:
        path = resolve_path(domain, "domain")
    except NodeSetupError:
        return None
    if path.name.endswith(DOMAIN_SUFFIX):
        params = path.with_name(path.name[: -len(DOMAIN_SUFFIX)] + NODES_SUFFIX)
        if params.is_file():
            return params
    try:
        pearl = resolve_path(DEFAULTS_FILE, "defaults_file")
    except NodeSetupError:
        return None
    own = pearl.with_name(pearl.name[: -len(NODES_SUFFIX)] + DOMAIN_SUFFIX)
    name = _domain_name(path)
    return pearl if name is not None and name == _domain_name(own) else None


def _type_name(value: Any) -> str:
    if isinstance(value, bool):
        return "a bool"
    if isinstance(value, (int, float)):
        return "a number" if isinstance(value, float) else "an integer"
    if isinstance(value, str):
        return "a string"
    if isinstance(value, list):
        return "a list of numbers" if value and isinstance(value[0], (int, float)) else "a list of strings"
    return type(value).__name__


def _fits(value: Any, default: Any) -> Any:
    """``value`` converted to the type of ``default``, or raise ``TypeError``."""
    if isinstance(default, bool) or isinstance(value, bool):
        if isinstance(default, bool) and isinstance(value, bool):
            return value
        raise TypeError
    if isinstance(default, float) and isinstance(value, (int, float)):
        return float(value)
    if isinstance(default, int) and isinstance(value, int):
        return value
    if isinstance(default, str) and isinstance(value, str):
        return value
    if isinstance(default, list) and isinstance(value, list):
        if default and isinstance(default[0], float):
            if all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value):
                return [float(v) for v in value]
            raise TypeError
        if all(isinstance(v, str) for v in value):
            return list(value)
    raise TypeError


class FileDefaults:
    """The defaults a node reads from its ``defaults_file`` (see the module doc).

    Args:
        node: the node; its ``defaults_file`` parameter is declared here.

    Attributes:
        path: the file read (``None`` when ``defaults_file`` is empty).
        values: ``{dotted name: value}`` from the file's ``/**`` and node sections.
    """

    PARAM = Param("defaults_file", DEFAULTS_FILE,
                  "Params file whose '/**' and node sections give this node's defaults ('': none); "
                  "when only 'domain' is given: that domain's NAME_nodes.yaml, if it has one")

    def __init__(self, node: PearlNode):
        value = node.declare_table([self.PARAM])["defaults_file"]
        self.section = node.DEFAULT_NAME
        # rclpy keeps what -p / --params-file / parameter_overrides gave the node here (no public getter).
        given = getattr(node, "_parameter_overrides", {})
        if "defaults_file" not in given and "domain" in given and isinstance(given["domain"].value, str) \
                and given["domain"].value:
            own = domain_params_file(given["domain"].value)
            self.path: Optional[Path] = own
        else:
            self.path = resolve_path(value, "defaults_file") if value else None
        self.values: Dict[str, Any] = {}
        if self.path is not None:
            try:
                self.values = node_parameters(self.section, self.path)
            except SpecError as err:
                raise NodeSetupError(f"parameter defaults_file: {err}") from None

    def apply(self, params: Sequence[Param]) -> List[Param]:
        """``params`` with each default replaced by the file's value, where the file has one.

        Raises:
            NodeSetupError: a file value has another type than the parameter (the message
                names the file, the section and the parameter).
        """
        out = []
        for p in params:
            if p.name in self.values:
                try:
                    value = _fits(self.values[p.name], p.default)
                    # A non-empty list fixes the ROS type itself (an explicit type is for []).
                    p = replace(p, default=value, type=p.type if value == [] else None)
                except TypeError:
                    raise NodeSetupError(f"{self.path}: {self.section}.{p.name}: expected {_type_name(p.default)}, "
                                         f"got {self.values[p.name]!r}") from None
            out.append(p)
        return out

    def under(self, prefix: str) -> Mapping[str, Any]:
        """The file's values whose names start with ``prefix`` + ``.``, prefix removed."""
        start = prefix + "."
        return {k[len(start):]: v for k, v in self.values.items() if k.startswith(start)}
