"""A node's journal, wired to the node: its parameters, its log and its /diagnostics.

The tracker and the policy node journal what they need to resume after a crash (the core:
:mod:`pearl_pomdp.journal`; docs/reliability.md, "Crashes"). :class:`NodeJournal` adds what
both nodes share: the ``journal`` and ``journal_max_age`` parameters (:data:`JOURNAL_PARAMETERS`),
the file's place (``auto``: :func:`pearl_pomdp.journal.default_path` of the node's name; ``''``:
off), the domain's hash, one line in the log for what was resumed or refused, and writes that
never stop the node (a full disk is logged once and counted).
"""
from __future__ import annotations

import json
from pathlib import Path
from typing import Any, Callable, Dict, Mapping, Optional

from pearl_pomdp.journal import DEFAULT_MAX_AGE, DEFAULT_SYNC, SYNC_MODES, Journal, default_path, domain_hash
from pearl_pomdp.nodes.common import NodeSetupError, Param

__all__ = ["JOURNAL_PARAMETERS", "NodeJournal", "model_hash"]

JOURNAL_PARAMETERS = (
    Param("journal", "auto", "File the node journals its state to after every change and resumes from when "
                             "restarted (docs/reliability.md, Crashes); auto: $ROS_HOME/pearl/journal/"
                             "domain<ROS_DOMAIN_ID>/<node name>.json; '': no journal"),
    Param("journal_max_age", DEFAULT_MAX_AGE, "Seconds a journal stays good to resume from; an older one is "
                                              "refused and the node starts afresh", range=(0.001, 1.0e7)),
    Param("journal_sync", DEFAULT_SYNC, f"When a journal write reaches the disk ({' | '.join(SYNC_MODES)}): "
                                        "fsync before the node goes on (survives a power loss at once); "
                                        "background: a thread fsyncs it right after (a killed node always "
                                        "finds it; a power loss may lose the last milliseconds); none: never"),
)


def model_hash(model, source: str) -> str:
    """The hash a journal is tied to: the domain file's bytes when ``source`` is a readable file,
    else the model's names and ``b0`` (a model built in memory)."""
    path = Path(source)
    if path.is_file():
        return domain_hash(path)
    ident = json.dumps([model.name, list(model.states), list(model.actions), list(model.observations),
                        [float(x) for x in model.b0]])
    return domain_hash(ident.encode())


class NodeJournal:
    """The journal of one node (see the module doc).

    Args:
        node: the node (its logger and fully qualified name).
        kind: the node kind written into the journal (another kind's journal is refused).
        params: the node's parameter values (``journal``, ``journal_max_age``, ``journal_sync``).
        model, source: the model and the domain file it came from (for the hash).

    Attributes:
        journal: the :class:`~pearl_pomdp.journal.Journal`, or ``None`` when journaling is off.
        status: one line for /diagnostics: what was resumed or refused at start, or ``off``.
        errors: writes that failed (the node goes on).

    Raises:
        NodeSetupError: ``journal_max_age`` is not positive, or ``journal_sync`` not a mode.
    """

    def __init__(self, node, kind: str, params: Mapping[str, Any], model, source: str):
        self._node = node
        self.errors = 0
        self._last: Any = None
        self.status = "off (parameter journal is '')"
        self.journal: Optional[Journal] = None
        value = str(params["journal"]).strip()
        if not value:
            return
        path = (default_path(node.get_fully_qualified_name(), node.context.get_domain_id()) if value == "auto"
                else Path(value).expanduser())
        try:
            self.journal = Journal(path, kind, source, model_hash(model, source), params["journal_max_age"],
                                   sync=str(params["journal_sync"]).strip())
        except ValueError as err:
            raise NodeSetupError(f"parameter {err}") from None

    def resume(self, apply: Callable[[Dict[str, Any]], str]) -> bool:
        """Load the journal and hand its state to ``apply`` (which returns what was resumed, for
        the log, or raises ``ValueError`` when the state does not fit). Logs one line; True when resumed."""
        if self.journal is None:
            return False
        found = self.journal.load()
        logger = self._node.get_logger()
        if found.state is None:
            self.status = found.reason
            if found.reason.startswith("no journal"):
                logger.info(found.reason)
            else:
                logger.warning(found.reason)
            return False
        try:
            what = apply(found.state)
        except ValueError as err:
            self.status = f"refused journal {self.journal.path}: {err}; starting afresh"
            logger.warning(self.status)
            return False
        self.status = f"{found.reason}: {what}"
        logger.warning(self.status)   # a restart after a crash is worth a warning line
        return True

    def write(self, key: Any, state: Callable[[], Mapping[str, Any]]) -> None:
        """Journal ``state()`` unless ``key`` (a cheap summary of it) is what was written last."""
        if self.journal is None or key == self._last:
            return
        try:
            self.journal.write(state())
            self._last = key
        except OSError as err:
            self.errors += 1
            self._node.get_logger().error(f"cannot write journal {self.journal.path}: {err} "
                                          f"({self.errors} failed writes; the node goes on without it)",
                                          throttle_duration_sec=10.0)

    def diagnostics(self) -> Dict[str, Any]:
        """``journal`` (the file or ``off``), ``journal_status``, ``journal_writes``, ``journal_errors``."""
        return {"journal": str(self.journal.path) if self.journal is not None else "off",
                "journal_status": self.status,
                "journal_writes": self.journal.writes if self.journal is not None else 0,
                "journal_errors": self.errors}
