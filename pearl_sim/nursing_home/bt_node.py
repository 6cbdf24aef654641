"""The behaviour-tree baseline as a ROS 2 node, in place of the POMDP policy node.

``pearl_bt`` (console script) runs :class:`~pearl_sim.nursing_home.behaviour_tree.PearlBehaviourTree`
in the Pearl graph: it listens to the belief tracker's ``/pearl/belief`` (``pearl_interfaces/Belief``
with the ``step``, the ``action`` that opened the closed step and the ``observation`` that closed
it; :func:`pearl_pomdp.nodes.conversions.msg_to_marginals`) and
publishes the tree's action on ``/pearl/action`` (``pearl_interfaces/Action``, the policy node's
latched QoS, so the tracker opens the next step with it). The tracker, the executor and
the hardware are unchanged: start the graph with this node instead of
``hierarchical_policy``.

The tree ignores the marginals (it has no belief); it keeps its own memory on its
blackboard. A message for a step already answered (a latched re-delivery) is ignored; a
closed step without its action or observation is logged and counted (``rejected``) and never
stops the node. Step 0 (the tracker's ``b0``, no action yet) resets the tree.

It lives in ``pearl_sim`` because the core never imports the simulator, and the tree is
the simulator study's baseline.
"""
from __future__ import annotations

import sys
from typing import List, Optional

from pearl_pomdp.nodes import conversions as cv
from pearl_pomdp.nodes.common import LATCHED_QOS, Param, PearlNode, resolve_path, run_node

__all__ = ["BehaviourTreeNode", "main"]


class BehaviourTreeNode(PearlNode):
    """The py_trees Pearl tree as the action source of the graph.

    Parameters (read-only):
        * ``domain`` (str): the domain whose action names the tree may publish.
        * ``belief_topic`` (str): the tracker's belief with its step (default ``/pearl/belief``).
        * ``action_topic`` (str): where the action goes (default ``/pearl/action``).

    Subscribers:
        * ``/pearl/belief`` (pearl_interfaces/Belief, TRANSIENT_LOCAL depth 1).

    Publishers:
        * ``/pearl/action`` (pearl_interfaces/Action, TRANSIENT_LOCAL depth 1).
    """

    DEFAULT_NAME = "behaviour_tree"
    PARAMETERS = (
        Param("domain", "config/pearl.domain.yaml", "Factored domain (.yaml): the action names"),
        Param("belief_topic", "/pearl/belief", "Tracker's belief with its step (pearl_interfaces/Belief)"),
        Param("action_topic", "/pearl/action", "Primitive action output (pearl_interfaces/Action)"),
    )

    def __init__(self, *, actions: Optional[List[str]] = None, **kwargs):
        super().__init__(**kwargs)
        self.params = p = self.declare_table(self.PARAMETERS)
        if actions is None:
            from pearl_pomdp.model.domain_yaml import load_domain

            actions = list(load_domain(resolve_path(p["domain"], "domain")).actions)
        from pearl_sim.nursing_home.behaviour_tree import PearlBehaviourTree

        self.tree = PearlBehaviourTree("behaviour_tree", actions)
        self.last_step: Optional[int] = None
        self.decisions = 0
        self.rejected = 0
        self.action_pub = self.create_publisher(cv.ActionMsg, p["action_topic"], LATCHED_QOS)
        self.create_subscription(cv.BeliefMsg, p["belief_topic"], self._on_step, LATCHED_QOS)
        self.get_logger().info(f"behaviour tree ready; listening on {p['belief_topic']}")

    def _on_step(self, msg) -> None:
        try:
            body = cv.msg_to_marginals(msg)
            step = int(body["step"])
            action, observation = body.get("action"), body.get("observation")
            if step > 0 and not (isinstance(action, str) and isinstance(observation, str)):
                raise ValueError("a closed step needs string 'action' and 'observation'")
        except (ValueError, KeyError, TypeError) as err:
            self.rejected += 1
            self.get_logger().error(f"rejected message on {self.params['belief_topic']}: {err}")
            return
        restarted = step == 0 and bool(self.last_step)
        if self.last_step is not None and step <= self.last_step and not restarted:
            return          # already answered (a latched re-delivery)
        if step == 0:
            self.tree.reset()
        else:
            assert isinstance(action, str) and isinstance(observation, str)  # checked above
            self.tree.observe(action, observation)
        self.last_step = step
        decision = self.tree.execute(None)
        self.action_pub.publish(cv.action_to_msg(decision.action_name, self.now_s()))
        self.decisions += 1


def main(args: Optional[List[str]] = None) -> int:
    """Console script ``pearl_bt``."""
    return run_node(BehaviourTreeNode, args)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
