"""A node's journal: what it needs to resume after a crash, in a small file and its update (ROS-free).

A node that dies (a segfault in a driver library, the out-of-memory killer, a power blip)
and is started again reads its journal and carries on where it was, instead of starting
the day again at ``b0``. The belief tracker journals its belief, step counter, open step and
its deadline; the policy node the step it last answered and the operator's autonomy level
(docs/reliability.md, "Crashes").

The file is JSON, replaced atomically after every change (a reader sees the old journal or the
new one, never half of one; how, and when it reaches the disk: :data:`SYNC_MODES`)::

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

**A write that leaves the arrays as they were goes to a small second file.** Most of the tracker's
writes change only small fields: a step opens (its action, opening time, drive limit) or an input is
queued, with the belief the last write had. Rewriting the whole journal for those cost the ward's
tracker ~3 ms a step (its belief is 2.5 MB of base64), on the path of the next input. So when every
:func:`encode_array` value of a state is the very object the last whole write had (the tracker keeps
its encoded belief until the belief changes), :meth:`Journal.write` replaces only the *update* file
(:func:`update_path`: ``<name>.update.json``) with the state's other fields. Each whole write carries
a fresh random ``base`` token, and an update names the token of the whole journal it completes;
:meth:`Journal.load` applies an update only to that journal, so a death between any two writes loads
either the last whole journal with its latest update, or the last whole journal alone when the update
was of an older one — never a belief with another write's step.

**Fields that only grow go to a log.** A simulator journals every call it made on its world; rewritten
whole after every tick, a day's list (tens of thousands of calls) made each tick's write slower than
the last. :meth:`Journal.write`'s ``growing`` fields are appended instead: each write adds one line
with the items new since the last (``<name>.<id>.log``, a fresh ``id`` for each :class:`Journal`), and
the journal names the log and how many of its lines it covers; :meth:`Journal.load` puts the whole
lists back into the state. A line is appended before the journal that counts it, so a death between
the two leaves a line the journal does not count (ignored), never a journal with a line missing.
"""
from __future__ import annotations

import base64
import hashlib
import json
import os
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Dict, List, Mapping, Optional, Sequence, Union

import numpy as np

from pearl_pomdp.atomic import atomic_write, file_mode_for

__all__ = ["FORMAT", "DEFAULT_MAX_AGE", "SYNC_MODES", "DEFAULT_SYNC", "Journal", "Resumed", "domain_hash",
           "default_path", "encode_array", "decode_array", "flush_journals", "update_path",
           "SYNC_INTERVAL"]

#: The journal format this code writes and reads.
FORMAT = "pearl-journal/1"
#: Seconds a journal stays good for resuming (a node restarted later starts afresh).
DEFAULT_MAX_AGE = 120.0

#: When a journal write reaches the disk (every mode replaces the file atomically, so a reader —
#: a restarted node — sees the old journal or the new one, and a node killed right after a write
#: always finds it: the file is in the kernel's page cache, which outlives the process):
#:
#: * ``fsync``: before :meth:`Journal.write` returns (:func:`~pearl_pomdp.atomic.atomic_write`:
#:   the new file, renamed over the old, and its directory), so even a power loss right after it
#:   keeps the write; costs the caller ~0.6 ms a write here (more on a busy disk);
#: * ``background``: the write is :func:`_replace_fast`'s (no rename over an existing file, which
#:   ext4 flushes at once), and a thread of the process fsyncs the file and its directory soon
#:   after it (at most one round of fsyncs every :data:`SYNC_INTERVAL` s: writes that come faster
#:   share one), so a power loss can lose the writes of the last quarter second — the node then
#:   starts afresh or a few writes back; the caller pays ~0.1 ms a write;
#: * ``none``: as ``background`` without the thread (the kernel writes the file back within ~30 s).
SYNC_MODES = ("fsync", "background", "none")
#: The nodes' mode: a power loss also restarts the other nodes and usually outlasts
#: ``journal_max_age``, so the milliseconds ``fsync`` would protect rarely matter, while its cost
#: lands on every step's latency (docs/reliability.md, "Crashes").
DEFAULT_SYNC = "background"


def _next_path(path: Path) -> Path:
    """The complete next journal :func:`_replace_fast` writes before it takes ``path``'s name."""
    return path.with_name(f".{path.name}.next")


def update_path(path: Union[str, Path]) -> Path:
    """The update file beside the journal ``path`` (see the module doc): ``name.json`` → ``name.update.json``."""
    path = Path(path)
    return path.with_name(f"{path.stem}.update{path.suffix or '.json'}")


def _replace_fast(path: Path, pieces: Sequence[bytes], mode: int) -> None:
    """Replace ``path`` with the concatenated ``pieces``, atomic against the writer's death, without a rename over
    an existing file: ext4 flushes a file renamed over another at once (``auto_da_alloc``), which
    cost ~0.2 ms of every ~0.25 ms journal write here. The next journal is written complete under
    :func:`_next_path`, then the old one is unlinked and the next renamed to ``path``. A death
    before the unlink leaves the old journal; between the unlink and the rename, the complete next
    one, which :meth:`Journal.load` reads when ``path`` is missing. On an error before the unlink
    the old journal is left as it was."""
    nxt = _next_path(path)
    fd = os.open(nxt, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, mode)
    try:
        written = os.writev(fd, pieces)
        total = sum(len(p) for p in pieces)
        if written < total:   # a short write (rare on a regular file): the rest piece by piece
            view = memoryview(b"".join(pieces))[written:]
            while view:
                view = view[os.write(fd, view):]
    finally:
        os.close(fd)
    try:
        os.unlink(path)
    except FileNotFoundError:
        pass
    os.rename(nxt, path)


def _fsync_file_and_directory(path: Path) -> None:
    """fsync ``path`` (whatever file it names now: a newer journal is as good) and its directory
    (so the rename survives too). Best effort: a file replaced or removed meanwhile is skipped."""
    for target, flags in ((path, os.O_RDONLY), (path.parent, os.O_RDONLY)):
        try:
            fd = os.open(target, flags)
        except OSError:
            continue
        try:
            os.fsync(fd)
        except OSError:
            pass
        finally:
            os.close(fd)


#: ``background`` mode: the fsync thread's least time (s) from the start of one round of fsyncs to
#: the start of the next. Writes that come faster share a round: a flood of inputs, or steps back to
#: back, would otherwise fsync after every write, and each fsync's kernel work (~0.7 ms of CPU here,
#: on a 2-core robot computer) competes with the very next step's tracker and policy
#: (``bench/latency.py``: p50 4.4 → 3.1 ms without the per-write fsync). A robot whose steps are a
#: second or more apart is synced after every write, as before; a power loss can lose the writes of
#: the last quarter second. A flush (a node that stops) does not wait for the interval.
SYNC_INTERVAL = 0.25


class _BackgroundSync:
    """The process's one fsync thread (``background`` mode): journals ask for a sync after each
    write; the thread fsyncs every file asked for since its last round, at most one round every
    :data:`SYNC_INTERVAL` s (sooner when :meth:`flush` waits), then waits again."""

    def __init__(self) -> None:
        self._cond = threading.Condition()
        self._pending: Dict[Path, None] = {}
        self._busy = False
        self._flushing = 0
        self._thread: Optional[threading.Thread] = None

    def request(self, path: Path) -> None:
        with self._cond:
            # Wake the thread only when it waits for work: a write while syncs are already pending
            # joins them, and waking the thread for it would cost the writer a switch and the GIL.
            idle = not self._pending
            self._pending[path] = None
            if self._thread is None or not self._thread.is_alive():
                self._thread = threading.Thread(target=self._run, name="pearl-journal-fsync", daemon=True)
                self._thread.start()
            elif idle:
                self._cond.notify_all()

    def _run(self) -> None:
        last_round = -SYNC_INTERVAL
        while True:
            with self._cond:
                while not self._pending:
                    self._cond.wait()
                # Let writes gather until the interval since the last round has passed (a flush cuts it).
                hold = last_round + SYNC_INTERVAL - time.monotonic()
                if hold > 0:
                    self._cond.wait_for(lambda: self._flushing > 0, hold)
                paths = list(self._pending)
                self._pending.clear()
                self._busy = True
            last_round = time.monotonic()
            try:
                for path in paths:
                    _fsync_file_and_directory(path)
            finally:
                with self._cond:
                    self._busy = False
                    self._cond.notify_all()

    def flush(self, timeout: Optional[float]) -> bool:
        """Wait until every sync asked for is done; False when ``timeout`` (s) ran out first."""
        with self._cond:
            self._flushing += 1
            self._cond.notify_all()
            try:
                return self._cond.wait_for(lambda: not self._pending and not self._busy, timeout)
            finally:
                self._flushing -= 1


_BACKGROUND = _BackgroundSync()


def flush_journals(timeout: Optional[float] = 1.0) -> bool:
    """Wait (at most ``timeout`` s) until every ``background`` journal write of this process is on
    disk: a node calls it before its process ends. True when nothing is left pending."""
    return _BACKGROUND.flush(timeout)


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


class _Base64Text(str):
    """Text :func:`encode_array` made: base64's alphabet only, so JSON holds it between two quotes as
    it is. :meth:`Journal.write` puts it in without ``json.dumps`` scanning it for characters to
    escape, which took 5 of the ~10 ms a write of the ward's 233,280-state belief cost."""


def encode_array(values: np.ndarray) -> str:
    """A float array as base64 of its little-endian float64 bytes (exact; see the module doc)."""
    return _Base64Text(base64.b64encode(np.ascontiguousarray(values, dtype="<f8").tobytes()).decode("ascii"))


def _journal_bytes(body: Mapping[str, Any]) -> List[bytes]:
    """The bytes of ``json.dumps(body, separators=(",", ":"))`` in pieces, with the state's top-level
    :class:`_Base64Text` values as pieces of their own: neither scanned by ``json.dumps`` nor copied
    into one string (each pass over the ward's 2.5 MB of base64 cost 2-5 ms; the pieces go to the
    file in one ``writev``)."""
    state = body["state"]
    texts = [(key, value) for key, value in state.items() if isinstance(value, _Base64Text)]
    if not texts:
        return [json.dumps(body, separators=(",", ":")).encode("utf-8")]
    # Each goes in as a placeholder no other value can dump to: it starts with a NUL, which JSON
    # escapes (so the quoted placeholder appears nowhere else), and carries a fresh random token.
    token = os.urandom(8).hex()
    holders = {key: f"\0{token}{i}" for i, (key, _value) in enumerate(texts)}
    rest = json.dumps(dict(body, state={k: holders.get(k, v) for k, v in state.items()}), separators=(",", ":"))
    pieces: List[bytes] = []
    for key, value in texts:   # in the state's order, which dumps keeps
        head, found, rest = rest.partition(json.dumps(holders[key]))
        assert found and json.dumps(holders[key]) not in rest, "a journal placeholder is not unique"
        pieces += [head.encode("utf-8"), b'"', value.encode("ascii"), b'"']
    pieces.append(rest.encode("utf-8"))
    return pieces


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
        sync: when a write reaches the disk, one of :data:`SYNC_MODES` (every mode is atomic
            against the writer's death).

    Raises:
        ValueError: ``max_age`` not positive, or ``sync`` not one of :data:`SYNC_MODES` (the
            message names the node parameter, ``journal_max_age`` or ``journal_sync``).
    """

    def __init__(self, path: Union[str, Path], kind: str, domain: str, domain_hash: str,
                 max_age: float = DEFAULT_MAX_AGE, sync: str = "fsync"):
        if not max_age > 0:
            raise ValueError(f"journal_max_age: must be > 0 s, got {max_age}")
        if sync not in SYNC_MODES:
            raise ValueError(f"journal_sync: {sync!r} is not one of {', '.join(SYNC_MODES)}")
        self.path = Path(path)
        self.kind, self.domain, self.domain_hash, self.max_age = kind, domain, domain_hash, float(max_age)
        self.sync = sync
        self.writes = 0
        #: Of the writes, those that went to the update file (see the module doc).
        self.updates = 0
        self._mode: Optional[int] = None   # the file's permission bits, read at the first write
        #: The last whole write's ``base`` token and its :func:`encode_array` values (held, so that an
        #: unchanged array is recognised by identity, without comparing megabytes).
        self._base: Optional[tuple] = None
        #: The ``growing`` fields' log: its id, lines written and items logged per field (None: none yet).
        self._log: Optional[Dict[str, Any]] = None

    def log_path(self, log_id: str) -> Path:
        """The log of ``growing`` fields with id ``log_id`` (see the module doc)."""
        return self.path.with_name(f"{self.path.stem}.{log_id}.log")

    def write(self, state: Mapping[str, Any], now: Optional[float] = None, *,
              growing: Optional[Mapping[str, Sequence[Any]]] = None) -> None:
        """Replace the journal with ``state`` (JSON-serialisable), stamped ``now`` (wall clock s).

        When every :func:`encode_array` value of ``state`` is the object the last whole write had,
        only the other fields are written, to :func:`update_path` (the module doc says why and why a
        death cannot mix two writes); :meth:`load` gives the same state either way.

        ``growing``: lists that only grow (the same keys at every write, none of them in ``state``);
        only the items added since this journal's last write are written, appended to its log, and
        :meth:`load` returns the whole lists as fields of the state.

        Raises:
            OSError: the file cannot be written (the old journal is left as it was).
            ValueError: a ``growing`` list is shorter than already logged, or its keys changed.
        """
        state = dict(state)
        written_at = time.time() if now is None else float(now)
        if growing is not None:
            state["growing_log"] = self._append(growing)
        arrays = {key: value for key, value in state.items() if isinstance(value, _Base64Text)}
        base = self._base
        if (arrays and base is not None and arrays.keys() == base[1].keys()
                and all(value is base[1][key] for key, value in arrays.items())):
            light = {key: value for key, value in state.items() if key not in arrays}
            self._replace(update_path(self.path), [json.dumps(
                {"format": FORMAT, "kind": self.kind, "domain_hash": self.domain_hash, "written_at": written_at,
                 "base": base[0], "state": light}, separators=(",", ":")).encode("utf-8")])
            self.updates += 1
        else:
            token = os.urandom(8).hex()
            body = {"format": FORMAT, "kind": self.kind, "domain": self.domain, "domain_hash": self.domain_hash,
                    "written_at": written_at, "base": token, "state": state}
            self._replace(self.path, _journal_bytes(body))
            self._base = (token, arrays) if arrays else None
        self.writes += 1
        if self._log is not None and not self._log["cleaned"]:
            # The journal now names this log: the logs of earlier runs (one this node resumed from) go.
            self._log["cleaned"] = True
            for old in self.path.parent.glob(f"{self.path.stem}.*.log"):
                if old != self.log_path(self._log["id"]):
                    old.unlink(missing_ok=True)

    def _append(self, growing: Mapping[str, Sequence[Any]]) -> Dict[str, Any]:
        """Append the ``growing`` lists' new items to the log as one line; what the journal records of it."""
        log = self._log
        if log is None:
            log = self._log = {"id": os.urandom(8).hex(), "lines": 0, "logged": {k: 0 for k in growing},
                               "cleaned": False}
        logged = log["logged"]
        if set(growing) != set(logged):
            raise ValueError(f"journal {self.path}: growing fields {sorted(growing)}, this journal logs {sorted(logged)}")
        short = [k for k, items in growing.items() if len(items) < logged[k]]
        if short:
            raise ValueError(f"journal {self.path}: growing field {short[0]!r} has {len(growing[short[0]])} items, "
                             f"{logged[short[0]]} were logged (it may only grow)")
        tails = {k: list(items[logged[k]:]) for k, items in growing.items()}
        if any(tails.values()) or log["lines"] == 0:
            line = json.dumps({"log": log["id"], "line": log["lines"], "items": tails}, separators=(",", ":")) + "\n"
            path = self.log_path(log["id"])
            if self._mode is None:
                path.parent.mkdir(parents=True, exist_ok=True)
                self._mode = file_mode_for(self.path)
            fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_APPEND, self._mode)
            try:
                data = line.encode("utf-8")
                while data:   # an append of one line; a death inside it leaves a line no journal counts
                    data = data[os.write(fd, data):]
                if self.sync == "fsync":
                    os.fsync(fd)
            finally:
                os.close(fd)
            if self.sync == "background":
                _BACKGROUND.request(path)
            log["lines"] += 1
            for k, items in growing.items():
                logged[k] = len(items)
        return {"id": log["id"], "lines": log["lines"], "fields": sorted(logged)}

    def _read_log(self, ref: Any) -> Dict[str, List[Any]]:
        """The whole ``growing`` lists a journal's ``growing_log`` names (``ValueError`` naming the log when
        it has fewer whole lines than the journal counts)."""
        if not (isinstance(ref, dict) and isinstance(ref.get("id"), str) and isinstance(ref.get("lines"), int)
                and isinstance(ref.get("fields"), list)):
            raise ValueError("its growing_log is malformed")
        path = self.log_path(ref["id"])
        lists: Dict[str, List[Any]] = {str(k): [] for k in ref["fields"]}
        found = 0
        try:
            with open(path, encoding="utf-8") as lines:
                for text in lines:
                    if found == ref["lines"]:
                        break   # lines appended after the journal was written: not counted
                    line = json.loads(text)
                    if line.get("log") != ref["id"] or line.get("line") != found or set(line["items"]) != set(lists):
                        break
                    for k, items in line["items"].items():
                        lists[k].extend(items)
                    found += 1
        except FileNotFoundError:
            pass
        except (OSError, UnicodeDecodeError, ValueError, AttributeError, KeyError, TypeError):
            pass   # a line cut short or damaged: counted below
        if found < ref["lines"]:
            raise ValueError(f"its log {path} has {found} of the {ref['lines']} whole lines it counts")
        return lists

    def _replace(self, path: Path, pieces: List[bytes]) -> None:
        """Replace ``path`` with ``pieces`` as :attr:`sync` says (:data:`SYNC_MODES`)."""
        if self.sync == "fsync":
            atomic_write(path, b"".join(pieces), sync=True)
            return
        if self._mode is None:
            path.parent.mkdir(parents=True, exist_ok=True)
            self._mode = file_mode_for(path)
        _replace_fast(path, pieces, self._mode)
        if self.sync == "background":
            _BACKGROUND.request(path)

    def remove(self) -> None:
        """Delete the journal and its update (and a next one a death left), so the next start begins afresh."""
        update = update_path(self.path)
        for target in (self.path, _next_path(self.path), update, _next_path(update),
                       *self.path.parent.glob(f"{self.path.stem}.*.log")):
            try:
                target.unlink()
            except FileNotFoundError:
                pass
        self._base = self._log = None

    def load(self, now: Optional[float] = None) -> Resumed:
        """The journal's state if it may be resumed from, else ``None`` and the one-line reason
        (which names the file). A missing file is no error: the node starts afresh."""
        now = time.time() if now is None else float(now)
        where = f"journal {self.path}"
        try:
            text = _read_or_next(self.path)
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
        update = self._update_of(body)
        if update is not None:
            body["state"].update(update["state"])
            written = update["written_at"]
        age = now - float(written)
        if age > self.max_age:
            return Resumed(None, f"refused {where}: written {age:.1f} s ago, more than journal_max_age "
                                 f"{self.max_age:g} s; starting afresh", age)
        if age < -self.max_age:
            return Resumed(None, f"refused {where}: written {-age:.1f} s in the future (the clock moved "
                                 f"back?); starting afresh", age)
        if "growing_log" in body["state"]:
            try:
                body["state"].update(self._read_log(body["state"].pop("growing_log")))
            except ValueError as err:
                return Resumed(None, f"refused {where}: {err}; starting afresh", age)
        return Resumed(body["state"], f"resuming from {where}, written {max(age, 0.0):.1f} s ago", age)

    def _update_of(self, body: Mapping[str, Any]) -> Optional[Dict[str, Any]]:
        """The update file's body when it completes the whole journal ``body`` (the same ``base``
        token, kind and domain), else ``None``: an update of an older whole write, one cut short
        or unreadable is left unused (it holds only what a step's opening adds, the whole journal
        before it is a state the node was in)."""
        token = body.get("base")
        if not isinstance(token, str):
            return None
        try:
            update = json.loads(_read_or_next(update_path(self.path)))
        except (OSError, UnicodeDecodeError, ValueError):
            return None
        if (isinstance(update, dict) and update.get("base") == token and update.get("format") == FORMAT
                and update.get("kind") == self.kind and update.get("domain_hash") == body.get("domain_hash")
                and isinstance(update.get("state"), dict) and isinstance(update.get("written_at"), (int, float))):
            return update
        return None


def _read_or_next(path: Path) -> str:
    """The text of ``path``, or of the next one :func:`_replace_fast` left when its writer died between
    unlinking the old file and renaming the next (``FileNotFoundError`` when neither is there)."""
    try:
        return path.read_text(encoding="utf-8")
    except FileNotFoundError:
        return _next_path(path).read_text(encoding="utf-8")
