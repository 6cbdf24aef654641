"""Confidence intervals for every study of every world, from ``scipy.stats`` (one implementation).

A mean gets Student's t interval (``ttest_1samp(...).confidence_interval()``: what a few dozen
episodes or days call for; the normal approximation the nursing-home study once used is 1.96 where
t with 4 degrees of freedom is 2.78); a success rate gets Wilson's score interval
(``binomtest(...).proportion_ci(method="wilson")``).
"""
from __future__ import annotations

from typing import Dict, Optional, Sequence

import numpy as np

__all__ = ["proportion_ci", "t_ci"]


def proportion_ci(successes: int, n: int) -> Dict[str, Optional[float]]:
    """Success rate with a 95 % Wilson score interval (``rate``/``low``/``high`` ``None`` for ``n`` = 0)."""
    if n == 0:
        return {"rate": None, "low": None, "high": None, "successes": 0, "n": 0}
    from scipy import stats

    ci = stats.binomtest(int(successes), int(n)).proportion_ci(confidence_level=0.95, method="wilson")
    return {"rate": successes / n, "low": float(ci.low), "high": float(ci.high), "successes": int(successes), "n": int(n)}


def t_ci(values: Sequence[Optional[float]]) -> dict:
    """Mean and 95 % interval from Student's t (``None`` values left out; a half-width of 0 for one
    value or for values that are all equal; every field ``None`` but ``n`` = 0 for none)."""
    x = np.asarray([v for v in values if v is not None], dtype=float)
    if x.size == 0:
        return {"mean": None, "ci95": None, "low": None, "high": None, "n": 0}
    m = float(x.mean())
    if x.size == 1 or np.ptp(x) == 0.0:
        # scipy's interval is NaN here (no spread to estimate); the data say the mean exactly.
        return {"mean": m, "ci95": 0.0, "low": m, "high": m, "n": int(x.size)}
    from scipy import stats

    ci = stats.ttest_1samp(x, 0.0).confidence_interval(confidence_level=0.95)
    return {"mean": m, "ci95": float(ci.high) - m, "low": float(ci.low), "high": float(ci.high), "n": int(x.size)}
