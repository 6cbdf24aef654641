"""The hierarchical policy node: beliefs in, primitive actions out (docs/design.md §4, §6).

For every belief it runs EXECUTE top-down (root → … → primitive) and publishes the
primitive action and the trace. All planning happens at start-up, before spinning: a
callback only evaluates α-vectors (py_trees#420: a tick must be near-instant).
"""
from __future__ import annotations

import collections
import sys
import time
from typing import Deque, List, Optional

import numpy as np

from pearl_pomdp.errors import BeliefError
from pearl_pomdp.nodes import conversions as cv
from pearl_pomdp.nodes.common import (EVENT_QOS, LATCHED_QOS, NodeSetupError, Param,
                                      load_domain_and_model, resolve_path, run_node)
from pearl_pomdp.nodes.defaults import FileDefaults
from pearl_pomdp.nodes.managed import AUTOSTART, ManagedPearlNode

__all__ = ["HierarchicalPolicyNode", "load_decider", "main"]


def load_decider(model, domain, policy: str, hierarchy: str, logger=None):
    """The decider the node runs (an object with ``.execute(belief) -> Decision``).

    * ``policy`` a directory: a saved hierarchical policy (``pearl plan --out DIR``).
    * ``policy`` a file: a flat α-vector policy (``.npz`` + ``.json``), wrapped in
      :class:`pearl_pomdp.executive.FlatPolicyDecider`.
    * ``policy`` empty: PLAN now from ``domain`` and the ``hierarchy`` file.

    Raises:
        NodeSetupError: nothing to load, or a file is missing.
    """
    if policy:
        path = resolve_path(policy, "policy", kind="policy file or directory")
        if path.is_dir():
            from pearl_pomdp.hierarchy import load_hierarchical_policy

            # A flat .pomdp model can have a (flat-featured) hierarchy too: pass the model then.
            return load_hierarchical_policy(path, domain if domain is not None else model)
        from pearl_pomdp.executive import FlatPolicyDecider
        from pearl_pomdp.policy_io import load_policy

        return FlatPolicyDecider(load_policy(path, model), model)
    if not hierarchy:
        raise NodeSetupError("parameters policy and hierarchy are both empty: give a planned policy "
                             "(policy:=DIR from `pearl plan --out DIR`) or a hierarchy to plan at start-up")
    from pearl_pomdp.hierarchy import load_hierarchy, plan

    hpath = resolve_path(hierarchy, "hierarchy")
    if logger is not None:
        logger.info(f"planning {hpath} at start-up (pass policy:=DIR to skip)")
    start = time.perf_counter()
    target = domain if domain is not None else model
    decider = plan(target, load_hierarchy(hpath, target))
    if logger is not None:
        logger.info(f"planned in {time.perf_counter() - start:.2f} s")
    return decider


class HierarchicalPolicyNode(ManagedPearlNode):
    """Answers each belief with a primitive action (EXECUTE of the hierarchical policy).

    Parameters (read-only):
        * ``domain`` (str): factored domain ``.yaml`` (or flat ``.pomdp`` with a flat policy).
        * ``hierarchy`` (str): action hierarchy ``.yaml``; planned at start-up when ``policy`` is empty.
        * ``policy`` (str): a planned policy — a directory from ``pearl plan --out DIR``
          (hierarchical) or an ``.npz`` file (flat); empty: plan at start-up.
        * ``diagnostics_period`` (double, s): period of the /diagnostics summary.
        * ``belief_topic``, ``action_topic``, ``decision_topic`` (str): topic names.
        * ``defaults_file`` (str, ``config/pearl_nodes.yaml``): params file giving the defaults
          (:mod:`pearl_pomdp.nodes.defaults`; ``''``: none).
        * ``use_sim_time`` (bool): follow /clock.

    Subscribers:
        * ``/pearl/belief`` (std_msgs/Float64MultiArray, TRANSIENT_LOCAL): the tracker's belief.

    Publishers:
        * ``/pearl/action`` (std_msgs/String, TRANSIENT_LOCAL depth 1): the primitive action.
        * ``/pearl/decision`` (std_msgs/String JSON): ``{"step", "action", "trace": [{"subtask",
          "choice", "value"}], "latency_s", "expansions"}`` — the EXECUTE trace, the decision's step
          latency (belief message received → action published, wall clock) and the beliefs its
          forward search expanded (0: the one-step choice only).
        * ``/diagnostics`` (diagnostic_msgs/DiagnosticArray): decisions, rejected beliefs and
          latency p50/p99/max over the last 1000 decisions.

    In-process use: ``HierarchicalPolicyNode(context=ctx, parameter_overrides={...}, domain=dom,
    model=model, decider=d)`` — ``decider`` (anything with ``.execute(belief) -> Decision``)
    skips loading/planning; ``domain``/``model`` skip loading the domain file.

    Raises:
        NodeSetupError: missing file, nothing to plan from (one line).
    """

    DEFAULT_NAME = "hierarchical_policy"
    PARAMETERS = (
        Param("domain", "config/pearl.domain.yaml", "Factored domain (.yaml) or flat model (.pomdp) file"),
        Param("hierarchy", "config/pearl.hierarchy.yaml", "Action hierarchy (.yaml); planned at start-up "
                                                         "when policy is empty"),
        Param("policy", "", "Planned policy: directory from `pearl plan --out DIR`, or flat .npz; "
                            "empty: plan at start-up"),
        Param("diagnostics_period", 1.0, "Seconds between /diagnostics summaries", range=(0.01, 3600.0)),
        Param("belief_topic", "/pearl/belief", "Belief input (std_msgs/Float64MultiArray)"),
        Param("action_topic", "/pearl/action", "Primitive action output (std_msgs/String)"),
        Param("decision_topic", "/pearl/decision", "EXECUTE trace output (JSON std_msgs/String)"),
        AUTOSTART,
    )

    def __init__(self, *, domain=None, model=None, decider=None, **kwargs):
        super().__init__(**kwargs)
        # Defaults from the params file's /** and hierarchical_policy sections (``defaults_file``),
        # so a node started alone behaves as under the launch file.
        self.params = p = self.declare_table(FileDefaults(self).apply(self.PARAMETERS))
        self._preloaded = (domain, model, decider)
        self.decider = None
        self.decisions = 0
        self.rejected = 0
        self.inactive_beliefs = 0  # beliefs that arrived while not active (not answered)
        self.latencies: Deque[float] = collections.deque(maxlen=1000)
        self.last_decision = None
        self.diag_pub = self.create_publisher(cv.DiagnosticsMsg, "/diagnostics", EVENT_QOS)
        self.start(p["autostart"])

    def configure_node(self) -> None:
        """Load the domain and the policy (or PLAN it); create the topics."""
        p = self.params
        domain, model, decider = self._preloaded
        if model is None:
            domain, model = load_domain_and_model(resolve_path(p["domain"], "domain"))
        self.domain, self.model = domain, model
        self.decider = decider if decider is not None else load_decider(model, domain, p["policy"],
                                                                        p["hierarchy"], self.get_logger())
        self.action_pub = self.lifecycle_publisher(cv.TextMsg, p["action_topic"], LATCHED_QOS)
        self.decision_pub = self.lifecycle_publisher(cv.TextMsg, p["decision_topic"], EVENT_QOS)
        self.managed_subscription(cv.BeliefMsg, p["belief_topic"], self._on_belief, LATCHED_QOS)
        self.managed_timer(p["diagnostics_period"], self.publish_diagnostics)
        self.get_logger().info(f"policy ready for {model.name} ({type(self.decider).__name__})")

    def cleanup_node(self) -> None:
        self.decider = None

    def _on_belief(self, msg) -> None:
        if not self.active or self.decider is None:
            self.inactive_beliefs += 1   # a deactivated policy does not act
            return
        start = time.perf_counter()
        try:
            belief = cv.msg_to_belief(msg, self.model.num_states)
        except BeliefError as err:
            self.rejected += 1
            self.get_logger().error(f"rejected belief on {self.params['belief_topic']}: {err}")
            self.publish_diagnostics()
            return
        decision = self.decider.execute(belief)
        self.action_pub.publish(cv.action_to_msg(decision.action_name))
        latency = time.perf_counter() - start
        self.latencies.append(latency)
        self.decision_pub.publish(cv.decision_to_msg(self.decisions, decision.action_name,
                                                     decision.trace, latency, getattr(decision, "expansions", 0)))
        self.decisions += 1
        self.last_decision = decision

    def publish_diagnostics(self) -> None:
        """Publish decision count, rejected beliefs and latency percentiles on /diagnostics."""
        lat = np.array(self.latencies) if self.latencies else np.zeros(1)
        values = {"decisions": self.decisions, "rejected_beliefs": self.rejected,
                  "latency_p50_ms": f"{np.percentile(lat, 50) * 1e3:.3f}",
                  "latency_p99_ms": f"{np.percentile(lat, 99) * 1e3:.3f}",
                  "latency_max_ms": f"{lat.max() * 1e3:.3f}"}
        values["inactive_beliefs"] = self.inactive_beliefs
        level = cv.DIAG_WARN if self.rejected else cv.DIAG_OK
        self.diag_pub.publish(cv.diagnostics_to_msg(f"pearl: {self.get_name()}", self.model.name, level,
                                                    f"{self.decisions} decisions", values, self.now_s()))


def main(args: Optional[List[str]] = None) -> int:
    """Console script ``hierarchical_policy``: exit 0 on SIGINT/SIGTERM, 2 on a start-up error."""
    return run_node(HierarchicalPolicyNode, args)


if __name__ == "__main__":
    sys.exit(main())
