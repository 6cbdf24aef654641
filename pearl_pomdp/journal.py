"""A node's journal: what it needs to resume after a crash, in one small file (ROS-free).

A node that dies (a segfault in a driver library, the out-of-memory killer, a power blip)
and is started again reads its journal and carries on where it was, instead of starting
the day again at ``b0``. The belief tracker journals its belief, step counter, open step and
its deadline; the policy node the step it last answered and the operator's autonomy level
(docs/reliability.md, "Crashes").

The file is JSON, replaced atomically after every change (:func:`pearl_pomdp.atomic.atomic_write`:
a reader sees the old journal or the new one, never half of one)::

    {"format": "pearl-journal/1", "kind": "belief_tracker", "domain": "config/pearl.domain.yaml",
     "domain_hash": "sha256:…", "written_at": 1796000000.123, "state": {…}}

A journal is refused — the node says so in one line naming the file and the reason, and
starts afresh — when it is older than ``max_age`` seconds (wall clock), was written for
another domain (its domain file's hash differs: another robot, or an edited file), by
another kind of node, in another format, or cannot be read. :class:`Journal` writes and
loads; what goes into ``state`` is the node's business (the tracker's:
:meth:`pearl_pomdp.tracking.BeliefTracker.journal_state`).

Arrays (a belief) go in as :func:`encode_array`: base64 of the little-endian float64 bytes,
so a restored belief equals the written one bit for bit and a large domain's belief stays
a fast write.
"""
from __future__ import annotations

import base64
import hashlib
import json
import os
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Dict, Mapping, Optional, Union

import numpy as np

from pearl_pomdp.atomic import atomic_write

__all__ = ["FORMAT", "DEFAULT_MAX_AGE", "Journal", "Resumed", "domain_hash", "default_path",
           "encode_array", "decode_array"]

#: The journal format this code writes and reads.
FORMAT = "pearl-journal/1"
#: Seconds a journal stays good for resuming (a node restarted later starts afresh).
DEFAULT_MAX_AGE = 120.0


def domain_hash(source: Union[str, Path, bytes]) -> str:
    """``sha256:<hex>`` of a domain file's bytes (or of ``bytes`` given directly)."""
    data = source if isinstance(source, bytes) else Path(source).read_bytes()
    return "sha256:" + hashlib.sha256(data).hexdigest()


def default_path(node_name: str, domain_id: int, environ: Optional[Mapping[str, str]] = None) -> Path:
    """Where a node's journal lives unless told otherwise:
    ``$ROS_HOME/pearl/journal/domain<domain_id>/<node name>.json`` (``ROS_HOME`` defaults to
    ``~/.ros``, as for ROS's logs), so graphs on different DDS domains keep apart."""
    env = os.environ if environ is None else environ
    home = Path(env.get("ROS_HOME") or Path.home() / ".ros").expanduser()
    name = node_name.strip("/").replace("/", "__") or "node"
    return home / "pearl" / "journal" / f"domain{int(domain_id)}" / f"{name}.json"


def encode_array(values: np.ndarray) -> str:
    """A float array as base64 of its little-endian float64 bytes (exact; see the module doc)."""
    return base64.b64encode(np.ascontiguousarray(values, dtype="<f8").tobytes()).decode("ascii")


def decode_array(text: str) -> np.ndarray:
    """The array :func:`encode_array` wrote.

    Raises:
        ValueError: not base64 of whole float64 values.
    """
    raw = base64.b64decode(text.encode("ascii"), validate=True)
    if len(raw) % 8:
        raise ValueError(f"{len(raw)} bytes are not whole float64 values")
    return np.frombuffer(raw, dtype="<f8").astype(float)


@dataclass(frozen=True)
class Resumed:
    """What :meth:`Journal.load` found: ``state`` to resume from (``None``: start afresh) and
    ``reason``, one line for the log (why it was refused, or what is resumed and how old it is)."""

    state: Optional[Dict[str, Any]]
    reason: str
    age: Optional[float] = None


class Journal:
    """One node's journal file.

    Args:
        path: the file (its directory is created on the first write).
        kind: the node kind that writes it (``belief_tracker``, ``hierarchical_policy``); a
            journal of another kind is refused.
        domain: the domain file's name, for the record and the messages.
        domain_hash: :func:`domain_hash` of the domain file; a journal with another is refused.
        max_age: seconds after which a journal is too old to resume from (> 0).
        sync: each write reaches the disk (fsync) before it counts; False: atomic against the
            writer's death only (:func:`~pearl_pomdp.atomic.atomic_write`).
    """

    def __init__(self, path: Union[str, Path], kind: str, domain: str, domain_hash: str,
                 max_age: float = DEFAULT_MAX_AGE, sync: bool = True):
        if not max_age > 0:
            raise ValueError(f"journal_max_age: must be > 0 s, got {max_age}")
        self.path = Path(path)
        self.kind, self.domain, self.domain_hash, self.max_age = kind, domain, domain_hash, float(max_age)
        self.sync = sync
        self.writes = 0

    def write(self, state: Mapping[str, Any], now: Optional[float] = None) -> None:
        """Replace the journal with ``state`` (JSON-serialisable), stamped ``now`` (wall clock s).

        Raises:
            OSError: the file cannot be written (the old journal is left as it was).
        """
        body = {"format": FORMAT, "kind": self.kind, "domain": self.domain, "domain_hash": self.domain_hash,
                "written_at": time.time() if now is None else float(now), "state": dict(state)}
        atomic_write(self.path, json.dumps(body, separators=(",", ":")), sync=self.sync)
        self.writes += 1

    def load(self, now: Optional[float] = None) -> Resumed:
        """The journal's state if it may be resumed from, else ``None`` and the one-line reason
        (which names the file). A missing file is no error: the node starts afresh."""
        now = time.time() if now is None else float(now)
        where = f"journal {self.path}"
        try:
            text = self.path.read_text(encoding="utf-8")
        except FileNotFoundError:
            return Resumed(None, f"no {where}: starting afresh")
        except (OSError, UnicodeDecodeError) as err:
            return Resumed(None, f"refused {where}: cannot read it ({err}); starting afresh")
        try:
            body = json.loads(text)
        except ValueError as err:
            return Resumed(None, f"refused {where}: not JSON ({err}); starting afresh")
        if not isinstance(body, dict) or body.get("format") != FORMAT:
            found = body.get("format") if isinstance(body, dict) else type(body).__name__
            return Resumed(None, f"refused {where}: format {found!r}, expected {FORMAT!r}; starting afresh")
        if body.get("kind") != self.kind:
            return Resumed(None, f"refused {where}: written by a {body.get('kind')!r} node, this is a "
                                 f"{self.kind!r}; starting afresh")
        if body.get("domain_hash") != self.domain_hash:
            return Resumed(None, f"refused {where}: written for another domain ({body.get('domain')!r}, "
                                 f"{str(body.get('domain_hash'))[:19]}…), this node runs {self.domain!r} "
                                 f"({self.domain_hash[:19]}…); starting afresh")
        written = body.get("written_at")
        if not isinstance(written, (int, float)) or not isinstance(body.get("state"), dict):
            return Resumed(None, f"refused {where}: no written_at time or no state; starting afresh")
        age = now - float(written)
        if age > self.max_age:
            return Resumed(None, f"refused {where}: written {age:.1f} s ago, more than journal_max_age "
                                 f"{self.max_age:g} s; starting afresh", age)
        if age < -self.max_age:
            return Resumed(None, f"refused {where}: written {-age:.1f} s in the future (the clock moved "
                                 f"back?); starting afresh", age)
        return Resumed(body["state"], f"resuming from {where}, written {max(age, 0.0):.1f} s ago", age)
