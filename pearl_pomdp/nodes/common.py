"""What the three nodes share: parameter declaration, model loading, QoS, ``main``.

* :class:`Param` / :class:`PearlNode` — each node lists its parameters once, as a table of
  :class:`Param` (name, default, description, read-only, range); :class:`PearlNode` declares
  them with ``ParameterDescriptor`` s, so ``ros2 param describe`` shows them, and rclpy
  checks types and ranges of ``--ros-args -p`` / ``--params-file`` overrides.
* :func:`run_node` — the body of every node's ``main``: init, build the node (a bad
  parameter or a missing file prints **one line** ``<node>: error: …`` and exits 2), spin,
  and exit 0 on SIGINT and SIGTERM within :data:`SHUTDOWN_DEADLINE` s, in every phase.
* :func:`resolve_path` — a relative file parameter is looked up in the working directory,
  then in the package's share directory (``config/pearl.domain.yaml`` works from the source
  tree, from a pip install and from a colcon install).

Nodes built in one process (tests, replay, ``pearl_pomdp.nodes.graph``) pass
``parameter_overrides={name: value}`` and optionally preloaded objects (``domain=``,
``model=``, ``decider=``) to the node constructors; see each node's docstring.
"""
from __future__ import annotations

import os
import signal
import sys
import threading
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Dict, List, Mapping, Optional, Sequence, Tuple, Type

import rclpy
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rclpy.event_handler import (PublisherEventCallbacks, QoSPublisherEventType, QoSSubscriptionEventType,
                                 SubscriptionEventCallbacks)
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.utilities import get_default_context
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from pearl_pomdp.errors import PearlError
from pearl_pomdp.journal import flush_journals
from pearl_pomdp.launch_xml import package_share_dir

__all__ = ["Param", "PearlNode", "NodeSetupError", "run_node", "resolve_path", "load_domain_and_model",
           "LATCHED_QOS", "EVENT_QOS", "INPUT_QOS", "SHUTDOWN_DEADLINE"]

#: Reliable, keep-last 1, TRANSIENT_LOCAL: the latest belief / action reaches a late joiner
#: (the policy started after the tracker published b0; a test probe started late).
LATCHED_QOS = QoSProfile(depth=1, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)
#: Reliable, volatile, keep-last 10: events that must not be replayed to late joiners
#: (the executor must not re-say an old action when it restarts).
EVENT_QOS = QoSProfile(depth=10, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE,
                       durability=DurabilityPolicy.VOLATILE)
#: What a replay of a recorded bag needs from a node (the tracker's step rules and places; the
#: policy's domain, policy and starting autonomy), published latched when the node is activated on
#: this topic, relative to the node (``/belief_tracker/settings``): a recorder started later gets it too
#: (:func:`pearl_pomdp.nodes.bag_replay.replay_config`).
SETTINGS_TOPIC = "~/settings"
#: Sensor inputs: reliable, volatile, keep-last 20 (a burst of inputs is queued, not lost).
INPUT_QOS = QoSProfile(depth=20, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE,
                       durability=DurabilityPolicy.VOLATILE)


class NodeSetupError(PearlError):
    """A node cannot start: a parameter is invalid or a file it names is missing."""


def _without_type_events(handlers, incompatible_type) -> list:
    """The event handlers rclpy made, less the incompatible-type one (destroyed at once)."""
    kept = []
    for handler in handlers:
        if handler.event_type == incompatible_type:
            handler.destroy()
        else:
            kept.append(handler)
    return kept


class QosWarningSubscriptionEvents(SubscriptionEventCallbacks):
    """rclpy's default subscription events less "incompatible type": the QoS warning stays.

    Every event handler is a waitable that the executor re-enters, re-counts and re-adds on
    *every* spin, whatever woke it; rclpy gives each publisher and subscription two
    (incompatible QoS, incompatible type). The Pearl nodes' topic types are fixed in
    :mod:`~pearl_pomdp.nodes.conversions`, and a peer of another type simply never matches
    (``ros2 topic info`` shows it), so that handler is dropped: a spin of the tracker costs
    a third less (measured, docs/ros-nodes.md *Step latency*).
    """

    def create_event_handlers(self, callback_group, subscription, topic_name):
        return _without_type_events(super().create_event_handlers(callback_group, subscription, topic_name),
                                    QoSSubscriptionEventType.RCL_SUBSCRIPTION_INCOMPATIBLE_TYPE)


class QosWarningPublisherEvents(PublisherEventCallbacks):
    """rclpy's default publisher events less "incompatible type" (see :class:`QosWarningSubscriptionEvents`)."""

    def create_event_handlers(self, callback_group, publisher, topic_name):
        return _without_type_events(super().create_event_handlers(callback_group, publisher, topic_name),
                                    QoSPublisherEventType.RCL_PUBLISHER_INCOMPATIBLE_TYPE)


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

    def create_publisher(self, *args, event_callbacks=None, **kwargs):
        """As rclpy's, with :class:`QosWarningPublisherEvents` unless ``event_callbacks`` is given."""
        return super().create_publisher(*args, event_callbacks=event_callbacks or QosWarningPublisherEvents(),
                                        **kwargs)

    def create_subscription(self, *args, event_callbacks=None, **kwargs):
        """As rclpy's, with :class:`QosWarningSubscriptionEvents` unless ``event_callbacks`` is given."""
        return super().create_subscription(*args, event_callbacks=event_callbacks or QosWarningSubscriptionEvents(),
                                           **kwargs)

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
    from pearl_pomdp.model import Pomdp, load_domain_or_model

    loaded = load_domain_or_model(path)
    return (None, loaded) if isinstance(loaded, Pomdp) else (loaded, loaded.compile())


def one_line_error(err: BaseException) -> str:
    """``err`` as one line; rclpy's type error for a whole number given to a double parameter (``-p
    step_timeout:=8``, a launch argument ``rate:=40``) says how to write it."""
    text = " ".join((str(err).strip() or type(err).__name__).split())
    if isinstance(err, rclpy.exceptions.InvalidParameterTypeException) and "'INTEGER', expecting type 'DOUBLE'" in text:
        text += " (a whole number where a decimal is declared: write it with a decimal point, e.g. 8.0)"
    return text


#: Seconds from the first SIGINT/SIGTERM to the end of the process, whatever it is doing then
#: (starting up, spinning, or stuck in rclpy/Fast DDS clean-up). See :func:`run_node`.
SHUTDOWN_DEADLINE = 1.5
#: Extra seconds before the kernel ends the process (SIGALRM) when the Python watchdog thread
#: cannot run because the main thread holds the interpreter in C code.
SHUTDOWN_BACKSTOP = 0.3
#: Exit code of a node whose clean-up did not finish within :data:`SHUTDOWN_DEADLINE`.
EXIT_FORCED = 1


class _StopSignals:
    """SIGINT/SIGTERM handling for :func:`run_node`: a stop request with a deadline.

    Installed *before* ``rclpy.init``: rclpy's own handlers (which shut the context down and
    wake the executor) chain to these Python handlers. The first signal

    * arms a watchdog: after :data:`SHUTDOWN_DEADLINE` s a thread writes one line and calls
      ``os._exit(EXIT_FORCED)``; :data:`SHUTDOWN_BACKSTOP` s later ``SIGALRM`` (default
      action: terminate) ends the process from the kernel, in case the main thread holds the
      GIL in C code and the thread never runs;
    * during start-up, raises ``KeyboardInterrupt`` in the main thread, so a long start-up
      (planning a policy) stops at once instead of finishing first. While the executor
      spins it raises nothing: rclpy's handler has shut the context down and woken the
      executor, and ``spin()`` returns by itself (an exception raised inside rclpy's
      executor machinery leaves half-built objects behind, e.g. a ``Task`` whose
      ``__del__`` then prints a traceback).

    Later signals are ignored: the clean-up that is running is not interrupted (the watchdog
    bounds it).
    """

    def __init__(self, prog: str):
        self.prog = prog
        self.signum: Optional[int] = None
        self.cleaning_up = False
        self.spinning = False
        self._timer: Optional[threading.Timer] = None
        self._previous = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
        for s in self._previous:
            signal.signal(s, self._on_signal)

    def _on_signal(self, signum, _frame) -> None:
        if self.signum is not None:
            return
        self.signum = signum
        self._arm()
        if not (self.cleaning_up or self.spinning):
            raise KeyboardInterrupt

    def _arm(self) -> None:
        if self._timer is not None:
            return
        self._timer = threading.Timer(SHUTDOWN_DEADLINE, self._force_exit)
        self._timer.daemon = True
        self._timer.start()
        signal.signal(signal.SIGALRM, signal.SIG_DFL)
        signal.setitimer(signal.ITIMER_REAL, SHUTDOWN_DEADLINE + SHUTDOWN_BACKSTOP)

    def _force_exit(self) -> None:  # pragma: no cover - runs only when clean-up hangs
        why = signal.Signals(self.signum).name if self.signum else "shutdown"
        line = (f"{self.prog}: error: clean-up did not finish within {SHUTDOWN_DEADLINE} s of {why}; "
                f"exiting without it (exit code {EXIT_FORCED})\n")
        try:
            os.write(2, line.encode())
        finally:
            os._exit(EXIT_FORCED)

    def begin_cleanup(self) -> None:
        """Clean-up starts: from now on it is bounded by the deadline, signal or not."""
        self.cleaning_up = True
        self._arm()

    def close(self) -> None:
        """Clean-up finished in time: stop the watchdog thread and restore the previous handlers.

        After a stop signal the SIGALRM backstop stays armed until :func:`run_node` ends the
        process. Without a signal (a start-up error, an in-process caller) it is disarmed.
        """
        if self.signum is None:
            signal.setitimer(signal.ITIMER_REAL, 0)
        if self._timer is not None:
            self._timer.cancel()
        for s, handler in self._previous.items():
            signal.signal(s, handler)


def run_node(node_class: Type[PearlNode], args: Optional[List[str]] = None) -> int:
    """``main`` of a node: ``rclpy.init(args)``, build, spin; returns the exit code.

    * 0 after SIGINT or SIGTERM, also during start-up (a policy being planned stops at once).
    * 2 when the node cannot start: one line ``<node>: error: <what and where>`` on stderr.
    * Shutdown is bounded: the executor is shut down first; after a stop signal the DDS
      entities are left to the process's end (their one-by-one deletion can stall in Fast
      DDS with the GIL held; peers see the node leave when its lease ends); and the whole
      clean-up must finish within
      :data:`SHUTDOWN_DEADLINE` s of the signal — otherwise one line on stderr and exit code
      :data:`EXIT_FORCED` (1), or SIGALRM :data:`SHUTDOWN_BACKSTOP` s later.
    * After a stop signal this function does not return: once the clean-up is done it ends
      the process (``os._exit`` with the exit code, stdout/stderr flushed), skipping the
      interpreter's finalisation. Without a signal (a start-up error) it returns the code.
    """
    args = list(sys.argv if args is None else args)
    prog = node_class.DEFAULT_NAME
    stop = _StopSignals(prog)
    try:
        code = _init_spin_and_clean_up(node_class, args, prog, stop)
    finally:
        stop.close()
    # A journal write the fsync thread has not put on disk yet is on disk before the process
    # ends (bounded: a stop stays prompt; a killed process's writes are in the page cache anyway).
    flush_journals(timeout=1.0)
    if stop.signum is not None:
        # Stopped by a signal and cleaned up (node, context and DDS participant destroyed):
        # end the process here. The interpreter's finalisation has nothing left that matters
        # and, on a loaded machine, can take longer than the rest of the shutdown.
        for stream in (sys.stdout, sys.stderr):
            try:
                stream.flush()
            except (OSError, ValueError):
                pass
        os._exit(code)
    return code


def _init_spin_and_clean_up(node_class: Type[PearlNode], args: List[str], prog: str, stop: _StopSignals) -> int:
    try:
        rclpy.init(args=args)
    except KeyboardInterrupt:
        return 0
    except Exception as err:  # bad --ros-args syntax: rcl explains it in one line
        print(f"{prog}: error: {one_line_error(err)}", file=sys.stderr)
        return 2
    node = None
    executor = None
    try:
        # The executor exists before the node, so a signal during a long start-up (planning)
        # meets a complete setup; the signal raises KeyboardInterrupt in the start-up code.
        executor = SingleThreadedExecutor()
        try:
            node = node_class()
        except (PearlError, rclpy.exceptions.ParameterException, ValueError, OSError) as err:
            if not rclpy.ok() or stop.signum is not None:
                return 0  # stopped while starting; the error is a consequence
            print(f"{prog}: error: {one_line_error(err)}", file=sys.stderr)
            return 2
        executor.add_node(node)
        if stop.signum is None:  # a signal between the node's last line and here: do not spin
            stop.spinning = True
            executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except Exception:
        if rclpy.ok() and stop.signum is None:
            raise
        # SIGINT/SIGTERM arrived between two start-up steps and invalidated the context:
        # a normal stop, not an error.
    finally:
        stop.begin_cleanup()
        try:
            if executor is not None:
                executor.shutdown(timeout_sec=0.5)  # releases the entities it was waiting on
            # After a stop signal the process ends right after this clean-up, so the node's
            # DDS entities are not destroyed one by one: with several participants leaving at
            # once, Fast DDS can block an entity's deletion for seconds *holding the GIL*
            # (measured: about 1 trial in 8 of five nodes stopped together under a flood), which
            # no watchdog thread can cut. Peers see the node leave when its lease ends
            # (10 s, config/fastdds_profile.xml). Without a signal (an in-process caller, a
            # start-up error) everything is destroyed as before.
            if node is not None and stop.signum is None:
                node.destroy_node()
            context = get_default_context()
            rclpy.try_shutdown()
            # After a signal rclpy's handler has shut the context down, so try_shutdown() did
            # not finalise logging: do it (flushes the log file), as Context.shutdown would.
            # (Not after a stop signal: finalising logging also deletes the /rosout writer, the
            # same Fast DDS stall; stderr is flushed by run_node, the log file may miss its tail.)
            logging_fini = getattr(context, "_logging_fini", None)
            if (logging_fini is not None and getattr(context, "_logging_initialized", False)
                    and stop.signum is None):
                with context._lock:
                    logging_fini()
            # Without a signal: delete the DDS participant now, inside the bounded clean-up
            # (peers see the node leave at once), not later in the interpreter's finalisation.
            if stop.signum is None:
                context.destroy()
        except KeyboardInterrupt:  # pragma: no cover - a signal from outside rclpy's handlers
            pass
    return 0
