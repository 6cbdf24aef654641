"""JSON output of reports and headers that hold numpy values."""
from __future__ import annotations

__all__ = ["numpy_to_json"]


def numpy_to_json(value):
    """``json.dump(..., default=numpy_to_json)``: numpy scalars → Python numbers, arrays → lists.

    Raises:
        TypeError: ``value`` is neither (as ``json`` expects from a ``default`` hook).
    """
    import numpy as np  # imported here so that `pearl --help` does not load numpy

    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    raise TypeError(f"not JSON serialisable: {type(value).__name__}")
