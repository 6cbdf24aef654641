"""What a running ROS graph's nodes use, read by graph introspection (``pearl security policy``).

:func:`read_node_endpoints` asks the ROS graph (rclpy's ``get_*_names_and_types_by_node``) which
topics one node publishes and subscribes and which services it serves and calls — what SROS2's
``ros2 security generate_policy`` reads too. :class:`GraphWatch` waits until a launched graph is
up: every named node present, every managed (lifecycle) node active, and nothing changing.
"""
from __future__ import annotations

import time
from typing import Dict, Iterable, List, Mapping, Optional, Sequence, Tuple

import rclpy
from rclpy.node import Node

from pearl_pomdp.errors import PearlError
from pearl_pomdp.sros2_policy import NodeEndpoints

__all__ = ["read_node_endpoints", "GraphWatch", "probe_context", "close_probe"]

#: lifecycle_msgs' id of the active state.
ACTIVE = 3


def read_node_endpoints(probe: Node, name: str, namespace: str = "/") -> NodeEndpoints:
    """The endpoints the graph shows for node ``namespace/name`` (fully qualified names).

    Raises:
        rclpy.node.NodeNameNonExistentError: no such node in the graph (now).
    """
    def names(method) -> frozenset:
        return frozenset(topic for topic, _ in method(name, namespace))

    return NodeEndpoints(name, namespace,
                         publishes=names(probe.get_publisher_names_and_types_by_node),
                         subscribes=names(probe.get_subscriber_names_and_types_by_node),
                         serves=names(probe.get_service_names_and_types_by_node),
                         calls=names(probe.get_client_names_and_types_by_node))


def _split(fully_qualified: str) -> Tuple[str, str]:
    namespace, _, name = fully_qualified.rpartition("/")
    return name, namespace or "/"


class GraphWatch:
    """Watches the nodes ``names`` (fully qualified) through ``probe`` (spun by ``executor``)."""

    def __init__(self, probe: Node, executor, names: Sequence[str]):
        self.probe, self.executor, self.names = probe, executor, list(names)
        self._state_clients: Dict[str, object] = {}

    def spin(self, seconds: float) -> None:
        """Let the probe's callbacks run for ``seconds``."""
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            self.executor.spin_once(timeout_sec=max(0.0, min(0.05, end - time.monotonic())))

    def own_endpoints(self, timeout: float) -> NodeEndpoints:
        """The probe's own endpoints as the graph shows them (a bare node of this install: what
        any ROS node declares by itself), once they stop changing.

        Raises:
            PearlError: the graph does not show the probe within ``timeout`` seconds.
        """
        name, namespace = self.probe.get_name(), self.probe.get_namespace()
        deadline, last = time.monotonic() + timeout, None
        while time.monotonic() < deadline:
            self.spin(0.3)
            try:
                now = read_node_endpoints(self.probe, name, namespace)
            except Exception:  # noqa: BLE001 - not discovered yet
                continue
            if now == last and now.publishes:
                return now
            last = now
        raise PearlError(f"the graph did not show this command's own node {name} within {timeout:g} s")

    def present(self) -> List[str]:
        """The watched nodes the graph shows now."""
        seen = {f"{ns.rstrip('/')}/{n}" for n, ns in self.probe.get_node_names_and_namespaces()}
        return [n for n in self.names if n in seen]

    def enclaves(self) -> Dict[str, str]:
        """Each present watched node's enclave (``--enclave``; ``/`` when started without one)."""
        found = {f"{ns.rstrip('/')}/{n}": enclave
                 for n, ns, enclave in self.probe.get_node_names_and_namespaces_with_enclaves()}
        return {n: found[n] for n in self.names if n in found}

    def duplicated(self) -> List[str]:
        """Watched names that more than one node in the graph has (another graph on the domain)."""
        seen = [f"{ns.rstrip('/')}/{n}" for n, ns in self.probe.get_node_names_and_namespaces()]
        return sorted({n for n in self.names if seen.count(n) > 1})

    def endpoints(self) -> Dict[str, NodeEndpoints]:
        """Each present watched node's endpoints (a node leaving meanwhile is left out)."""
        found = {}
        for fqn in self.present():
            try:
                found[fqn] = read_node_endpoints(self.probe, *_split(fqn))
            except Exception:  # noqa: BLE001 - the node left between the two calls: not there
                continue
        return found

    def inactive(self, endpoints: Mapping[str, NodeEndpoints]) -> List[str]:
        """The managed nodes (those serving ``~/get_state``) among ``endpoints`` not active now."""
        from lifecycle_msgs.srv import GetState

        waiting = []
        for fqn, node in endpoints.items():
            if f"{fqn}/get_state" not in node.serves:
                continue
            client = self._state_clients.get(fqn)
            if client is None:
                client = self._state_clients[fqn] = self.probe.create_client(GetState, f"{fqn}/get_state")
            state = self._call(client, GetState.Request(), 2.0)
            if state is None or state.current_state.id != ACTIVE:
                waiting.append(fqn)
        return waiting

    def _call(self, client, request, timeout: float):
        if not client.wait_for_service(timeout_sec=timeout):
            return None
        future = client.call_async(request)
        end = time.monotonic() + timeout
        while not future.done() and time.monotonic() < end:
            self.executor.spin_once(timeout_sec=0.05)
        return future.result() if future.done() else None

    def parameters(self, fqn: str, names: Iterable[str], timeout: float = 5.0) -> Dict[str, str]:
        """String parameters ``names`` of node ``fqn`` (its ``~/get_parameters`` service); a name
        the node does not declare is left out.

        Raises:
            PearlError: the node did not answer within ``timeout`` seconds.
        """
        from rcl_interfaces.msg import ParameterType
        from rcl_interfaces.srv import GetParameters

        names = list(names)
        client = self.probe.create_client(GetParameters, f"{fqn}/get_parameters")
        try:
            reply = self._call(client, GetParameters.Request(names=names), timeout)
        finally:
            self.probe.destroy_client(client)
        if reply is None:
            raise PearlError(f"{fqn}/get_parameters: no answer within {timeout:g} s")
        return {n: v.string_value for n, v in zip(names, reply.values) if v.type == ParameterType.PARAMETER_STRING}

    def wait_ready(self, timeout: float, settle: float = 2.0) -> Dict[str, NodeEndpoints]:
        """Every watched node's endpoints once all are present, the managed ones active and the
        endpoints unchanged for ``settle`` seconds.

        Raises:
            PearlError: not so within ``timeout`` seconds (naming the nodes missing or not active),
                or a watched name is taken twice.
        """
        deadline = time.monotonic() + timeout
        last: Optional[Dict[str, NodeEndpoints]] = None
        since = time.monotonic()
        missing: List[str] = list(self.names)
        waiting: List[str] = []
        while time.monotonic() < deadline:
            self.spin(0.5)
            twice = self.duplicated()
            if twice:
                raise PearlError(f"node(s) {', '.join(twice)} run twice on this ROS domain: another graph is "
                                 "there; pick a free domain (--ros-domain-id)")
            now = self.endpoints()
            missing = [n for n in self.names if n not in now]
            waiting = self.inactive(now) if not missing else []
            if missing or waiting or now != last:
                last, since = now, time.monotonic()
                continue
            if time.monotonic() - since >= settle:
                return now
        raise PearlError(f"the graph was not up within {timeout:g} s: "
                         + "; ".join(part for part in (
                             f"not in the graph: {', '.join(missing)}" if missing else "",
                             f"not active: {', '.join(waiting)}" if waiting else "",
                             "its endpoints kept changing" if not missing and not waiting else "") if part))


def probe_context(domain_id: int, name: str):
    """``(context, probe node, executor)`` on ``domain_id``, for :class:`GraphWatch`; the caller
    ends them with :func:`close_probe`."""
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.signals import SignalHandlerOptions

    context = Context()
    rclpy.init(context=context, domain_id=domain_id, signal_handler_options=SignalHandlerOptions.NO)
    probe = rclpy.create_node(name, context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(probe)
    return context, probe, executor


def close_probe(context, probe, executor) -> None:
    """End what :func:`probe_context` started."""
    executor.shutdown()
    probe.destroy_node()
    rclpy.try_shutdown(context=context)
