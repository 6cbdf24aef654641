"""Names a package exports but imports on first use (PEP 562), so importing it stays cheap."""
from __future__ import annotations

import importlib
from typing import Any, Dict, Mapping

__all__ = ["lazy_attribute"]


def lazy_attribute(namespace: Dict[str, Any], homes: Mapping[str, str], name: str) -> Any:
    """``name`` from its module ``homes[name]``, cached in the package's ``namespace`` (its ``globals()``).

    Raises:
        AttributeError: ``name`` is not one of ``homes`` (what a missing attribute raises).
    """
    home = homes.get(name)
    if home is None:
        raise AttributeError(f"module {namespace['__name__']!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(home), name)
    namespace[name] = value
    return value
