"""Checks of command-line inputs, run before a command starts any work.

A command first checks every file and option it was given, so a typo fails in a moment with
one line naming the option and the path, instead of after planning or a started graph.
"""
from __future__ import annotations

from pathlib import Path
from typing import Union

from pearl_pomdp.errors import PearlError


def require_file(path: Union[str, Path], what: str) -> Path:
    """``path`` as a Path if it is a readable file; else a PearlError naming ``what`` and why.

    Args:
        path: the path given on the command line.
        what: what it should be, for the message (``"--scenario file"``, ``"model file"``).
    """
    p = Path(path)
    if p.is_dir():
        raise PearlError(f"{p}: is a directory, expected a {what}")
    if not p.is_file():
        raise PearlError(f"{p}: no such {what}" if not p.exists() else f"{p}: not a regular file, expected a {what}")
    return p


def require_dir(path: Union[str, Path], what: str) -> Path:
    """``path`` as a Path if it is a directory; else a PearlError naming ``what`` and why."""
    p = Path(path)
    if not p.is_dir():
        raise PearlError(f"{p}: is a file, expected a {what}" if p.exists() else f"{p}: no such {what}")
    return p
