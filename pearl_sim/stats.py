"""Confidence intervals shared by every study (the nursing home's and the reception's)."""
from __future__ import annotations

import math
from typing import Dict, Optional, Sequence

import numpy as np

__all__ = ["mean_ci", "proportion_ci", "t_ci"]


def mean_ci(values: Sequence[float]) -> Dict[str, Optional[float]]:
    """Mean and 95% half-width (normal approximation; 0 for fewer than two values)."""
    x = np.asarray(list(values), dtype=float)
    if x.size == 0:
        return {"mean": None, "ci95": None, "n": 0}
    half = 1.96 * x.std(ddof=1) / math.sqrt(x.size) if x.size > 1 else 0.0
    return {"mean": float(x.mean()), "ci95": float(half), "n": int(x.size)}


def proportion_ci(successes: int, n: int) -> Dict[str, Optional[float]]:
    """Success rate with a 95% Wilson score interval."""
    if n == 0:
        return {"rate": None, "low": None, "high": None, "successes": 0, "n": 0}
    z = 1.96
    p = successes / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return {"rate": p, "low": max(0.0, centre - half), "high": min(1.0, centre + half), "successes": successes, "n": n}


def t_ci(values: Sequence[float]) -> dict:
    """Mean and 95 % half-width from Student's t (0 for fewer than two values)."""
    from scipy import stats

    x = np.asarray([v for v in values if v is not None], dtype=float)
    if x.size == 0:
        return {"mean": None, "ci95": None, "low": None, "high": None, "n": 0}
    half = float(stats.t.ppf(0.975, x.size - 1) * x.std(ddof=1) / math.sqrt(x.size)) if x.size > 1 else 0.0
    m = float(x.mean())
    return {"mean": m, "ci95": half, "low": m - half, "high": m + half, "n": int(x.size)}
