"""Error classes of Pearl POMDP.

Every error a user can meet names *where* (file, line or field path, topic) and
*what* is wrong, and renders as one line, e.g.::

    config/pearl.yaml: actions.GuideToPhysio.effects.UserLocation[room]: row sums to 0.97, expected 1

The command line prints ``str(error)`` and exits non-zero; no traceback.
"""
from __future__ import annotations

from pathlib import Path
from typing import Optional, Union

PathLike = Union[str, Path]


class PearlError(Exception):
    """Base class of every error the project raises on purpose."""


class SpecError(PearlError):
    """A user-written file (model, domain, hierarchy, scenario, params) is invalid.

    Args:
        source: the file (or a description such as ``"<string>"``) that holds the problem.
        where: a dotted field path (``actions.Move.effects.UserLocation``) or a
            location such as ``"line 12"``; empty when the whole file is at fault.
        problem: what is wrong, and where possible what would be valid.
        line: optional 1-based line number; rendered after the file name.
    """

    def __init__(self, source: Optional[PathLike], where: str, problem: str, line: Optional[int] = None):
        self.source = str(source) if source is not None else "<input>"
        self.where = where
        self.problem = problem
        self.line = line
        parts = [self.source if line is None else f"{self.source}:{line}"]
        if where:
            parts.append(where)
        parts.append(problem)
        super().__init__(": ".join(parts))


class ModelFormatError(SpecError):
    """A ``.pomdp`` / PomdpX file cannot be read (syntax, unknown name, bad row...)."""


class PolicyError(PearlError):
    """A policy file is unreadable or does not belong to the model it is used with, or a policy
    cannot decide (every action it could choose is forbidden)."""


class BeliefError(PearlError):
    """A belief or observation given to the filter is malformed (wrong size, negative, unknown symbol)."""
