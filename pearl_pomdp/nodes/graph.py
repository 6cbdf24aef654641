"""All three Pearl nodes in one process, on one executor, under simulated time.

For tests, replay and demos that must be deterministic (docs/design.md §6 "One loop, and in one process"):
the same node classes as the separate processes, on one ``SingleThreadedExecutor``, with
``use_sim_time`` on, so time only moves when someone publishes ``/clock``.

Example (what ``test/test_nodes_inprocess.py`` and replay do)::

    with PearlGraph(domain_id=42, overrides={"hierarchical_policy": {"policy": "plans/pearl"}}) as g:
        probe = g.add_node(rclpy.create_node("probe", context=g.context))
        clock = probe.create_publisher(ClockMsg, "/clock", 10)
        ...
        g.spin_until(lambda: got_action, timeout_sec=5.0)

The domain file is loaded once and shared by the nodes (``domain``/``model`` keywords of the
node classes); a ``decider`` may be passed to skip loading or planning the policy.
"""
from __future__ import annotations

import time
from typing import Any, Callable, Dict, List, Mapping, Optional

import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions

from pearl_pomdp.nodes.action_executor import ActionExecutorNode
from pearl_pomdp.nodes.belief_tracker import BeliefTrackerNode
from pearl_pomdp.nodes.common import load_domain_and_model, resolve_path
from pearl_pomdp.nodes.hierarchical_policy import HierarchicalPolicyNode

__all__ = ["PearlGraph"]


class PearlGraph:
    """belief_tracker + hierarchical_policy + action_executor in one process.

    Args:
        context: an initialised rclpy ``Context``; ``None`` creates (and later shuts down) one.
        domain_id: ROS domain of the created context (ignored when ``context`` is given).
        args: global ``--ros-args`` of the created context (e.g. ``["--ros-args",
            "--params-file", "config/pearl_nodes.yaml"]``); they apply to every node.
        use_sim_time: sets ``use_sim_time`` on every node (default True).
        shared: parameter overrides for every node (e.g. ``{"domain": path}``).
        overrides: per node name, parameter overrides (``{"belief_tracker": {"step_timeout": 0.0}}``).
        domain, model: preloaded domain/model (default: loaded once from the ``domain``
            parameter in ``shared``, or from the package's ``config/pearl.domain.yaml``).
        decider: preloaded policy for the policy node (skips loading/planning).
        channels: the tracker's inputs (:class:`~pearl_pomdp.channels.InputChannel`; default: the
            domain's, or a flat model's one ``observation`` input).
        executor: False to leave out the action executor.
        params_file: the ROS 2 params file whose ``/**`` and node sections give every node its
            defaults (each node's ``defaults_file`` parameter; default: the shipped
            ``config/pearl_nodes.yaml``, as for a node started alone; ``None``: the code's
            defaults only). ``shared`` and ``overrides`` win over it.
        parameter_services: False builds the nodes without parameter services (faster
            executor iterations; no remote ``ros2 param`` access).

    Attributes:
        tracker, policy, executor_node: the nodes; ``executor`` is the rclpy executor.
    """

    def __init__(self, *, context: Optional[Context] = None, domain_id: Optional[int] = None,
                 args: Optional[List[str]] = None, use_sim_time: bool = True,
                 shared: Optional[Mapping[str, Any]] = None,
                 overrides: Optional[Mapping[str, Mapping[str, Any]]] = None,
                 domain=None, model=None, decider=None, channels=None, executor: bool = True,
                 parameter_services: bool = True,
                 params_file: Any = "default"):
        self._own_context = context is None
        if context is None:
            context = Context()
            rclpy.init(args=args, context=context, domain_id=domain_id,
                       signal_handler_options=SignalHandlerOptions.NO)
        self.context = context
        self.nodes: List[Node] = []
        try:
            shared = dict(shared or {})
            shared.setdefault("use_sim_time", use_sim_time)
            overrides = overrides or {}
            if model is None:
                path = shared.get("domain", BeliefTrackerNode.PARAMETERS[0].default)
                domain, model = load_domain_and_model(resolve_path(path, "domain"))
            self.domain, self.model = domain, model

            # Every node reads its defaults from a params file itself (``defaults_file``,
            # pearl_pomdp.nodes.defaults): the shipped one unless told otherwise, as under
            # ``ros2 run`` and the launch file.
            base: Dict[str, Any] = {}
            if params_file is None:
                base["defaults_file"] = ""
            elif params_file != "default":
                base["defaults_file"] = str(params_file)

            def params(name: str) -> Dict[str, Any]:
                # No journal (docs/reliability.md, "Crashes"): a graph in one process that dies
                # dies whole, and a replay or a test starts from b0; overrides may ask for one.
                journal = {"journal": ""} if name in ("belief_tracker", "hierarchical_policy") else {}
                return {**base, **journal, **shared, **dict(overrides.get(name, {}))}

            common = {"context": context, "start_parameter_services": parameter_services}
            managed = {**common, "lifecycle_services": parameter_services}
            self.tracker = BeliefTrackerNode(parameter_overrides=params("belief_tracker"), domain=domain, model=model,
                                             channels=channels, **managed)
            self.nodes.append(self.tracker)
            self.policy = HierarchicalPolicyNode(parameter_overrides=params("hierarchical_policy"), domain=domain,
                                                 model=model, decider=decider, **managed)
            self.nodes.append(self.policy)
            self.executor_node = None
            if executor:
                exec_params = {k: v for k, v in params("action_executor").items() if k != "domain"}
                exec_params.setdefault("action_names", list(model.actions))
                self.executor_node = ActionExecutorNode(parameter_overrides=exec_params, **managed)
                self.nodes.append(self.executor_node)
            self.executor = SingleThreadedExecutor(context=context)
            for node in self.nodes:
                self.executor.add_node(node)
        except BaseException:
            self.shutdown()
            raise

    def add_node(self, node: Node) -> Node:
        """Add a helper node (a probe, a /clock driver) to the same executor; returns it."""
        self.nodes.append(node)
        self.executor.add_node(node)
        return node

    def spin_once(self, timeout_sec: float = 0.0) -> None:
        """Run at most one ready callback (waiting up to ``timeout_sec`` wall seconds)."""
        self.executor.spin_once(timeout_sec=timeout_sec)

    def spin_until(self, predicate: Callable[[], bool], timeout_sec: float = 10.0) -> bool:
        """Spin until ``predicate()`` is true or ``timeout_sec`` wall seconds passed; returns it."""
        deadline = time.monotonic() + timeout_sec
        while not predicate():
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                return bool(predicate())
            self.executor.spin_once(timeout_sec=min(remaining, 0.05))
        return True

    def shutdown(self) -> None:
        """Destroy the nodes (and the context when this graph created it)."""
        executor = getattr(self, "executor", None)
        if executor is not None:
            executor.shutdown()
        for node in reversed(self.nodes):
            node.destroy_node()
        self.nodes = []
        if self._own_context:
            rclpy.try_shutdown(context=self.context)

    def __enter__(self) -> "PearlGraph":
        return self

    def __exit__(self, *exc) -> None:
        self.shutdown()
