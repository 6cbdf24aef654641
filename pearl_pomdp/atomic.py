"""Atomic file replacement: a reader sees the old file or the new one, never half of one.

Every file the project writes for users to load again (policies, models, bag metadata)
goes through :func:`atomic_write`: write a temporary file in the same directory, flush
and fsync it, ``os.replace`` it over the target, then fsync the directory so the rename
itself survives a crash (best effort: not every file system allows it).
"""
from __future__ import annotations

import os
import tempfile
from pathlib import Path
from typing import Union


def atomic_write(path: Union[str, Path], data: Union[bytes, str], encoding: str = "utf-8") -> Path:
    """Replace ``path`` with ``data`` (bytes, or text encoded with ``encoding``) atomically.

    Creates the parent directory if needed. On any error the temporary file is removed and
    ``path`` is left as it was. Returns ``path``.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    payload = data.encode(encoding) if isinstance(data, str) else data
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=str(path.parent))
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(payload)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        raise
    try:
        dfd = os.open(path.parent, os.O_RDONLY)
        try:
            os.fsync(dfd)
        finally:
            os.close(dfd)
    except OSError:
        pass
    return path
