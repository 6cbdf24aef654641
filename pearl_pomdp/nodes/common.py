"""What the three nodes share: parameter declaration, model loading, QoS, ``main``.

* :class:`Param` / :class:`PearlNode` — each node lists its parameters once, as a table of
  :class:`Param` (name, default, description, read-only, range); :class:`PearlNode` declares
  them with ``ParameterDescriptor`` s, so ``ros2 param describe`` shows them, and rclpy
  checks types and ranges of ``--ros-args -p`` / ``--params-file`` overrides.
* :func:`run_node` — the body of every node's ``main``: init, build the node (a bad
  parameter or a missing file prints **one line** ``<node>: error: …`` and exits 2), spin,
  and exit 0 on SIGINT and SIGTERM.
* :func:`resolve_path` — a relative file parameter is looked up in the working directory,
  then in the package's share directory (``config/pearl.domain.yaml`` works from the source
  tree, from a pip install and from a colcon install).

Nodes built in one process (tests, replay, ``pearl_pomdp.nodes.graph``) pass
``parameter_overrides={name: value}`` and optionally preloaded objects (``domain=``,
``model=``, ``decider=``) to the node constructors; see each node's docstring.
"""
from __future__ import annotations

import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Dict, List, Mapping, Optional, Sequence, Tuple, Type

import rclpy
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from pearl_pomdp.errors import PearlError
from pearl_pomdp.launch_xml import package_share_dir

__all__ = ["Param", "PearlNode", "NodeSetupError", "run_node", "resolve_path", "load_domain_and_model",
           "LATCHED_QOS", "EVENT_QOS", "INPUT_QOS"]

#: Reliable, keep-last 1, TRANSIENT_LOCAL: the latest belief / action reaches a late joiner
#: (the policy started after the tracker published b0; a test probe started late).
LATCHED_QOS = QoSProfile(depth=1, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)
#: Reliable, volatile, keep-last 10: events that must not be replayed to late joiners
#: (the executor must not re-say an old action when it restarts).
EVENT_QOS = QoSProfile(depth=10, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE,
                       durability=DurabilityPolicy.VOLATILE)
#: Sensor inputs: reliable, volatile, keep-last 20 (a burst of inputs is queued, not lost).
INPUT_QOS = QoSProfile(depth=20, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE,
                       durability=DurabilityPolicy.VOLATILE)


class NodeSetupError(PearlError):
    """A node cannot start: a parameter is invalid or a file it names is missing."""


@dataclass(frozen=True)
class Param:
    """One ROS parameter of a node.

    Attributes:
        name: parameter name (dots allowed, ``actions.<action>.say``).
        default: default value; its Python type fixes the ROS type (``float`` → DOUBLE …).
        description: one line for ``ros2 param describe``.
        read_only: True for parameters read once at start-up (most are).
        range: ``(low, high)`` for numbers, enforced by rclpy at declaration.
        type: explicit ROS type for empty-list defaults (``Parameter.Type.STRING_ARRAY``).
    """

    name: str
    default: Any
    description: str
    read_only: bool = True
    range: Optional[Tuple[float, float]] = None
    type: Optional[Parameter.Type] = None

    def descriptor(self) -> ParameterDescriptor:
        d = ParameterDescriptor(name=self.name, description=self.description, read_only=self.read_only)
        if self.range is not None:
            lo, hi = self.range
            if isinstance(self.default, bool) or not isinstance(self.default, (int, float)):
                raise TypeError(f"range given for non-numeric parameter {self.name}")
            if isinstance(self.default, int):
                d.integer_range = [IntegerRange(from_value=int(lo), to_value=int(hi), step=0)]
            else:
                d.floating_point_range = [FloatingPointRange(from_value=float(lo), to_value=float(hi), step=0.0)]
        return d


def _coerce(value: Any, default: Any) -> Any:
    """Let ``10`` stand for ``10.0`` where a double is expected (in-process overrides only)."""
    if isinstance(default, float) and isinstance(value, int) and not isinstance(value, bool):
        return float(value)
    if isinstance(default, list) and default and isinstance(default[0], float) and isinstance(value, (list, tuple)):
        return [float(v) if isinstance(v, int) and not isinstance(v, bool) else v for v in value]
    return value


class PearlNode(Node):
    """Base of the Pearl nodes: declares the class's :attr:`PARAMETERS` table.

    Args:
        node_name: defaults to the class's :attr:`DEFAULT_NAME`.
        namespace: ROS namespace (``None``: from ``-r __ns:=`` or root).
        context: rclpy context (``None``: the default one).
        parameter_overrides: ``{name: value}`` applied as if given with ``-p`` (in-process use).
        cli_args: node-specific ``--ros-args`` list.
        start_parameter_services: False leaves out the six ``~/get_parameters`` … services
            (no ``ros2 param`` access; each executor iteration then has fewer entities to
            wait on — for in-process replay and benchmarks).
    """

    DEFAULT_NAME = "pearl_node"
    PARAMETERS: Sequence[Param] = ()

    def __init__(self, *, node_name: Optional[str] = None, namespace: Optional[str] = None,
                 context=None, parameter_overrides: Optional[Mapping[str, Any]] = None,
                 cli_args: Optional[List[str]] = None, start_parameter_services: bool = True):
        defaults = {p.name: p.default for p in self.PARAMETERS}
        overrides = [Parameter(k, value=_coerce(v, defaults.get(k))) for k, v in (parameter_overrides or {}).items()]
        super().__init__(node_name or self.DEFAULT_NAME, namespace=namespace, context=context,
                         cli_args=cli_args, parameter_overrides=overrides,
                         start_parameter_services=start_parameter_services)

    def declare_table(self, params: Sequence[Param]) -> Dict[str, Any]:
        """Declare every :class:`Param` and return ``{name: value}`` after overrides.

        Raises:
            rclpy.exceptions.ParameterException: an override has the wrong type or is out of range.
        """
        values = {}
        for p in params:
            if p.type is not None:
                param = self.declare_parameter(p.name, p.type, p.descriptor())
                value = param.value
                if value is None:
                    value = p.default
            else:
                value = self.declare_parameter(p.name, p.default, p.descriptor()).value
            values[p.name] = value
        return values

    def now_s(self) -> float:
        """The node clock (sim time when ``use_sim_time``) in seconds."""
        return self.get_clock().now().nanoseconds * 1e-9


def resolve_path(value: str, parameter: str, must_exist: bool = True, kind: str = "file") -> Path:
    """A file/dir parameter as a path: as given, else relative to the package share directory.

    Raises:
        NodeSetupError: ``must_exist`` and neither place has it (the message names the
            parameter and both places looked at).
    """
    path = Path(value).expanduser()
    if path.exists() or path.is_absolute():
        if must_exist and not path.exists():
            raise NodeSetupError(f"parameter {parameter}: no such {kind}: {path}")
        return path
    share = package_share_dir("pearl_pomdp")
    candidate = share / path if share is not None else None
    if candidate is not None and candidate.exists():
        return candidate
    if must_exist:
        where = f" (nor {candidate})" if candidate is not None and candidate != path.resolve() else ""
        raise NodeSetupError(f"parameter {parameter}: no such {kind}: {path.resolve()}{where}")
    return path


def load_domain_and_model(path: Path):
    """``(domain or None, Pomdp)`` from a factored ``.yaml`` domain or a flat ``.pomdp`` file."""
    if path.suffix.lower() in (".yaml", ".yml"):
        from pearl_pomdp.model.factored import load_domain

        domain = load_domain(path)
        return domain, domain.compile()
    from pearl_pomdp.model import load_model

    return None, load_model(path)


def _one_line(err: BaseException) -> str:
    text = str(err).strip() or type(err).__name__
    return " ".join(text.split())


def run_node(node_class: Type[PearlNode], args: Optional[List[str]] = None) -> int:
    """``main`` of a node: ``rclpy.init(args)``, build, spin; returns the exit code.

    * 0 after SIGINT or SIGTERM (rclpy's handlers shut the context down; spin returns).
    * 2 when the node cannot start: one line ``<node>: error: <what and where>`` on stderr.
    """
    args = list(sys.argv if args is None else args)
    prog = node_class.DEFAULT_NAME
    try:
        rclpy.init(args=args)
    except Exception as err:  # bad --ros-args syntax: rcl explains it in one line
        print(f"{prog}: error: {_one_line(err)}", file=sys.stderr)
        return 2
    node = None
    try:
        # The executor exists before the node, so a signal during a long start-up (planning)
        # meets a complete setup; rclpy's handlers shut the context down and spin() returns.
        executor = SingleThreadedExecutor()
        try:
            node = node_class()
        except (PearlError, rclpy.exceptions.ParameterException, ValueError, OSError) as err:
            if not rclpy.ok():
                return 0  # stopped while starting; the error is a consequence
            print(f"{prog}: error: {_one_line(err)}", file=sys.stderr)
            return 2
        executor.add_node(node)
        executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except Exception:
        if rclpy.ok():
            raise
        # SIGINT/SIGTERM arrived between two start-up steps and invalidated the context:
        # a normal stop, not an error.
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return 0
