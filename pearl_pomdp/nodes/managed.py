"""Managed (lifecycle) Pearl nodes, the way Nav2 brings a robot's stack up.

A :class:`ManagedPearlNode` is a :class:`~pearl_pomdp.nodes.common.PearlNode` with the ROS 2
lifecycle (``rclpy.lifecycle``): ``unconfigured → configure → inactive → activate → active``,
and back with ``deactivate`` / ``cleanup``, ``shutdown`` from any state. Subclasses put their
work in four methods:

* :meth:`configure_node` — load the domain/policy, validate parameters, create publishers
  (:meth:`lifecycle_publisher`: they publish only while active), subscriptions and timers
  (:meth:`managed_subscription` / :meth:`managed_timer`: destroyed again on cleanup).
  Raising :class:`~pearl_pomdp.nodes.common.NodeSetupError` fails the transition with that
  one-line reason.
* :meth:`activate_node` / :meth:`deactivate_node` — start and stop acting (state is kept).
* :meth:`cleanup_node` — release what configure made (the defaults destroy the entities).

The ``autostart`` parameter (default true) configures and activates the node at once, so
``pearl demo``, ``pearl launch`` and the launch file work as before; with
``autostart:=false`` the node waits for ``ros2 lifecycle set /NODE configure`` (the
``~/change_state`` service). With autostart a configure failure is raised from the
constructor, so a bad parameter is still a one-line start-up error.
"""
from __future__ import annotations

from typing import Any, Callable, List, Optional

from rclpy.lifecycle import LifecycleNodeMixin, LifecycleState, TransitionCallbackReturn

from pearl_pomdp.nodes.common import NodeSetupError, Param, PearlNode, QosWarningPublisherEvents

__all__ = ["ManagedPearlNode", "AUTOSTART"]

#: The autostart parameter every managed Pearl node declares.
AUTOSTART = Param("autostart", True, "Configure and activate at start-up (false: wait for lifecycle transitions)")


class ManagedPearlNode(LifecycleNodeMixin, PearlNode):
    """A Pearl node with the ROS 2 lifecycle (see the module doc).

    Args:
        lifecycle_services: False leaves out the ``~/change_state`` … services (in-process
            graphs that nobody manages from outside); the transitions still work from Python.
        **kwargs: as :class:`~pearl_pomdp.nodes.common.PearlNode`.

    Attributes:
        active: True between activate and deactivate.
    """

    def __init__(self, *, lifecycle_services: bool = True, **kwargs: Any):
        PearlNode.__init__(self, **kwargs)
        LifecycleNodeMixin.__init__(self, enable_communication_interface=lifecycle_services)
        self.active = False
        self._managed_subscriptions: List[Any] = []
        self._managed_timers: List[Any] = []
        self._lifecycle_publishers: List[Any] = []
        self._transition_error: Optional[BaseException] = None
        self._autostarting = False

    # ------------------------------------------------------------ for subclasses
    def configure_node(self) -> None:
        """Load and validate; create publishers, subscriptions and timers (override)."""

    def activate_node(self) -> None:
        """Start acting (override; publishers are already active)."""

    def deactivate_node(self) -> None:
        """Stop acting; keep state (override; publishers are already inactive)."""

    def cleanup_node(self) -> None:
        """Release what :meth:`configure_node` made beyond its managed entities (override)."""

    def lifecycle_publisher(self, msg_type, topic: str, qos):
        """A publisher that publishes only while the node is active."""
        pub = self.create_lifecycle_publisher(msg_type, topic, qos, event_callbacks=QosWarningPublisherEvents())
        self._lifecycle_publishers.append(pub)
        return pub

    def managed_subscription(self, msg_type, topic: str, callback: Callable, qos, **kwargs: Any):
        """A subscription destroyed on cleanup."""
        sub = self.create_subscription(msg_type, topic, callback, qos, **kwargs)
        self._managed_subscriptions.append(sub)
        return sub

    def managed_timer(self, period: float, callback: Callable, **kwargs: Any):
        """A timer destroyed on cleanup."""
        timer = self.create_timer(period, callback, **kwargs)
        self._managed_timers.append(timer)
        return timer

    def start(self, autostart: bool) -> None:
        """Configure and activate now when ``autostart``; raise what made configure fail."""
        if not autostart:
            self.get_logger().info("autostart is false: waiting for lifecycle transitions (configure, activate)")
            return
        self._autostarting = True
        try:
            self.trigger_configure()
        finally:
            self._autostarting = False
        if self._transition_error is not None:
            error, self._transition_error = self._transition_error, None
            raise error
        self.trigger_activate()

    # ---------------------------------------------------------- the transitions
    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        try:
            self.configure_node()
        except (NodeSetupError, ValueError) as err:
            self._transition_error = err if isinstance(err, NodeSetupError) else NodeSetupError(str(err))
            if not self._autostarting:
                # Asked from outside (ros2 lifecycle set): the caller sees FAILURE, the log says why.
                # At autostart the constructor raises it instead (the node's one start-up line).
                self.get_logger().error(f"configure failed: {err}")
                self._transition_error = None
            self._release()
            return TransitionCallbackReturn.FAILURE
        return super().on_configure(state)

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        result = super().on_activate(state)       # activates the lifecycle publishers
        self.active = True
        self.activate_node()
        return result

    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        self.active = False
        self.deactivate_node()
        return super().on_deactivate(state)

    def on_cleanup(self, state: LifecycleState) -> TransitionCallbackReturn:
        self.cleanup_node()
        self._release()
        return super().on_cleanup(state)

    def on_shutdown(self, state: LifecycleState) -> TransitionCallbackReturn:
        self.active = False
        return super().on_shutdown(state)

    def _release(self) -> None:
        for timer in self._managed_timers:
            self.destroy_timer(timer)
        for sub in self._managed_subscriptions:
            self.destroy_subscription(sub)
        for pub in self._lifecycle_publishers:
            self.destroy_lifecycle_publisher(pub)
        self._managed_timers, self._managed_subscriptions, self._lifecycle_publishers = [], [], []
