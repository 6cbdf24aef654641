"""The lifecycle supervisor node: brings the managed nodes up in order and back after a crash.

A thin wrapper of :class:`pearl_pomdp.supervision.Supervisor` (the rules are there), in the
manner of Nav2's ``lifecycle_manager``: every ``heartbeat_period`` seconds of the steady clock
it asks each managed node for its state (``/<node>/get_state``), and it makes the transitions
the core asks for (``/<node>/change_state``: configure, activate). The managed nodes run with
``autostart:=false`` under it; the launcher respawns a node that died (``respawn="true"``),
and the supervisor configures and activates it again. Nothing here blocks: requests are sent
asynchronously and their answers read at the next tick.

Run it with ``lifecycle_supervisor --ros-args -p node_names:="[action_executor, hierarchical_policy,
belief_tracker]"`` (console script), ``pearl run lifecycle_supervisor …`` or from the launch files.
"""
from __future__ import annotations

import sys
import time
from typing import Any, Dict, List, Optional, Tuple

from rclpy.parameter import Parameter

from pearl_pomdp.nodes import conversions as cv
from pearl_pomdp.nodes.common import EVENT_QOS, NodeSetupError, Param, PearlNode, run_node
from pearl_pomdp.supervision import Supervisor, SupervisorEvent

__all__ = ["LifecycleSupervisorNode", "main", "MANAGED"]

#: Pearl's managed nodes in the order they come up: the executor and the policy wait for the
#: tracker's first belief, which starts the loop.
MANAGED = ["action_executor", "hierarchical_policy", "belief_tracker"]
_LEVELS = {"ok": cv.DIAG_OK, "warn": cv.DIAG_WARN, "error": cv.DIAG_ERROR}


class LifecycleSupervisorNode(PearlNode):
    """Configures and activates the managed nodes in order; watches them; brings a respawned one back.

    Parameters (read-only):
        * ``node_names`` (str[]): the managed nodes (names or ``/namespace/name``), in start order.
        * ``heartbeat_period`` (double, s): how often each node is asked for its state.
        * ``heartbeat_timeout`` (double, s): without an answer this long a node is down.
        * ``transition_timeout`` (double, s): how long a configure/activate may take (a policy planned
          at configure takes seconds); after it the node's state is asked again.
        * ``max_restarts`` (int), ``restart_window`` (double, s): comebacks and failed transitions
          allowed within the window; a node needing more is left down.
        * ``diagnostics_period`` (double, s).

    Publishers:
        * ``/diagnostics``: one status per managed node (``pearl: supervisor: <node>``): OK active,
          WARN coming up, ERROR down or left down; values ``state``, ``comebacks``.

    Clients:
        * ``/<node>/get_state`` and ``/<node>/change_state`` (lifecycle_msgs) of each managed node.
    """

    DEFAULT_NAME = "lifecycle_supervisor"
    PARAMETERS = (
        Param("node_names", MANAGED, "Managed nodes in the order they are brought up",
              type=Parameter.Type.STRING_ARRAY),
        Param("heartbeat_period", 0.5, "Seconds between state requests to each node", range=(0.01, 60.0)),
        Param("heartbeat_timeout", 4.0, "Seconds without an answer after which a node is down", range=(0.05, 600.0)),
        Param("transition_timeout", 120.0, "Seconds a configure/activate may take", range=(0.1, 3600.0)),
        Param("max_restarts", 3, "Comebacks and failed transitions allowed within restart_window; more: "
                                 "the node is left down", range=(0, 1000)),
        Param("restart_window", 300.0, "Seconds over which max_restarts counts", range=(1.0, 1.0e6)),
        Param("diagnostics_period", 1.0, "Seconds between /diagnostics summaries", range=(0.01, 3600.0)),
    )

    def __init__(self, **kwargs: Any):
        super().__init__(**kwargs)
        from lifecycle_msgs.srv import ChangeState, GetState
        from rclpy.clock import Clock, ClockType

        self.params = p = self.declare_table(self.PARAMETERS)
        try:
            self.core = Supervisor(list(p["node_names"]), p["heartbeat_timeout"], p["max_restarts"],
                                   p["restart_window"])
        except ValueError as err:
            raise NodeSetupError(f"parameter {err}") from None
        self._lifecycle_clients: Dict[str, Tuple[Any, Any]] = {}
        for name in self.core.order:
            base = name if name.startswith("/") else f"/{name}"
            self._lifecycle_clients[name] = (self.create_client(GetState, f"{base}/get_state"),
                                   self.create_client(ChangeState, f"{base}/change_state"))
        self._asking: Dict[str, Tuple[Any, float]] = {}                # name → (get_state future, sent at)
        self._changing: Dict[str, Tuple[Any, str, float]] = {}         # name → (future, transition, sent at)
        self._change_msg = ChangeState.Request
        self._get_msg = GetState.Request
        self.diag_pub = self.create_publisher(cv.DiagnosticsMsg, "/diagnostics", EVENT_QOS)
        steady = Clock(clock_type=ClockType.STEADY_TIME)
        self.create_timer(p["heartbeat_period"], self._tick, clock=steady)
        self.create_timer(p["diagnostics_period"], self.publish_diagnostics, clock=steady)
        self.get_logger().info(f"supervising {', '.join(self.core.order)} (in that order); heartbeat "
                               f"{p['heartbeat_period']:g} s, down after {p['heartbeat_timeout']:g} s, "
                               f"at most {p['max_restarts']} restarts in {p['restart_window']:g} s")

    def _tick(self) -> None:
        now = time.monotonic()
        events: List[SupervisorEvent] = []
        for name, (future, sent) in list(self._asking.items()):
            client = self._lifecycle_clients[name][0]
            if future.done():
                del self._asking[name]
                result = future.result()
                if result is not None:
                    events += self.core.answered(name, result.current_state.label, now)
            elif now - sent > self.params["heartbeat_timeout"] / 2:
                # Lost or unanswered (a dead process): ask again, so that a respawned one is heard soon.
                client.remove_pending_request(future)
                del self._asking[name]
        for name, (future, transition, sent) in list(self._changing.items()):
            if future.done():
                del self._changing[name]
                result = future.result()
                events += self.core.transition_done(name, transition, bool(result and result.success), now)
            elif now - sent > self.params["transition_timeout"]:
                self._lifecycle_clients[name][1].remove_pending_request(future)
                del self._changing[name]
                events += self.core.transition_done(name, transition, None, now)
        todo, judged = self.core.tick(now)
        events += judged
        for event in events:
            self._log(event)
        if events:
            self.publish_diagnostics()
        for name, transition in todo:
            self._change(name, transition, now)
        for name, (get_client, _) in self._lifecycle_clients.items():
            if name not in self._asking and name not in self._changing and get_client.service_is_ready():
                self._asking[name] = (get_client.call_async(self._get_msg()), now)

    def _change(self, name: str, transition: str, now: float) -> None:
        from lifecycle_msgs.msg import Transition

        client = self._lifecycle_clients[name][1]
        if not client.service_is_ready():
            self.core.not_sent(name)   # not there yet: next tick
            return
        request = self._change_msg()
        request.transition.id = {"configure": Transition.TRANSITION_CONFIGURE,
                                 "activate": Transition.TRANSITION_ACTIVATE}[transition]
        self.get_logger().info(f"{transition} {name}")
        future = client.call_async(request)
        future.add_done_callback(lambda _: self._tick())   # the next transition at once, not a period later
        self._changing[name] = (future, transition, now)

    def _log(self, event: SupervisorEvent) -> None:
        # One call site per severity: rclpy refuses a call site whose severity changes.
        if event.level == "error":
            self.get_logger().error(event.text)
        elif event.level == "warn":
            self.get_logger().warning(event.text)
        else:
            self.get_logger().info(event.text)

    def publish_diagnostics(self) -> None:
        """One status per managed node (see the class doc)."""
        now = self.now_s()
        for name in self.core.order:
            node = self.core.nodes[name]
            level = self.core.level(name)
            self.diag_pub.publish(cv.diagnostics_to_msg(f"pearl: supervisor: {name}", "pearl", _LEVELS[level],
                                                        self.core.summary(name),
                                                        {"state": node.state, "comebacks": node.comebacks,
                                                         "left_down": node.left_down}, now))


def main(args: Optional[List[str]] = None) -> int:
    """Console script ``lifecycle_supervisor``: exit 0 on SIGINT/SIGTERM, 2 on a start-up error."""
    return run_node(LifecycleSupervisorNode, args)


if __name__ == "__main__":
    sys.exit(main())
