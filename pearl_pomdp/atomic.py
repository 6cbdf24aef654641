"""Atomic file replacement: a reader sees the old file or the new one, never half of one.

Every file the project writes for users to load again (policies, models, bag metadata)
goes through :func:`atomic_write`: write a temporary file in the same directory, flush
and fsync it, ``os.replace`` it over the target, then fsync the directory so the rename
itself survives a crash (best effort: not every file system allows it).

The new file gets the mode a plain ``open(path, "w")`` would give it: the mode of the file it
replaces, or ``0o666`` less the process umask for a new file (``mkstemp`` alone would leave
every policy, model and ``metadata.yaml`` at 0600, unreadable to the other users of a bag).
"""
from __future__ import annotations

import os
import stat
import tempfile
from pathlib import Path
from typing import Union


def _umask() -> int:
    """The process umask, read without changing it where Linux allows (``os.umask`` is a set-and-get
    that would briefly change the mask of every thread)."""
    try:
        with open("/proc/self/status", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError, IndexError):
        pass
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def file_mode_for(path: Path) -> int:
    """Permission bits a plain write of ``path`` would leave: the existing file's, else 0o666 & ~umask."""
    try:
        return stat.S_IMODE(os.stat(path).st_mode) & 0o777  # no set-id bits on a new inode
    except FileNotFoundError:
        return 0o666 & ~_umask()


def atomic_write(path: Union[str, Path], data: Union[bytes, str], encoding: str = "utf-8", sync: bool = True) -> Path:
    """Replace ``path`` with ``data`` (bytes, or text encoded with ``encoding``) atomically.

    Creates the parent directory if needed. On any error the temporary file is removed and
    ``path`` is left as it was. The file's mode is that of a plain write (see the module
    doc). Returns ``path``. ``sync`` False skips the two fsyncs: the replace is still atomic
    against the writer's own death (SIGKILL), not against a power loss — for a file rewritten
    many times a second whose loss a restart survives.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    payload = data.encode(encoding) if isinstance(data, str) else data
    mode = file_mode_for(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=str(path.parent))
    try:
        with os.fdopen(fd, "wb") as fh:
            os.fchmod(fh.fileno(), mode)
            fh.write(payload)
            fh.flush()
            if sync:
                os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        raise
    if not sync:
        return path
    try:
        dfd = os.open(path.parent, os.O_RDONLY)
        try:
            os.fsync(dfd)
        finally:
            os.close(dfd)
    except OSError:
        pass
    return path
