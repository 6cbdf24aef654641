"""Root beliefs for the online search, and why none of them starves.

DESPOT samples its scenarios from the belief at the root. A plain particle filter loses
particles when an observation is unlikely (particle deprivation, the online planners' users'
recurring complaint); the beliefs here do not:

* :func:`sample_belief` — the exact belief vector of an explicit model (what the project's
  tracker keeps for every domain up to ~10⁶ states): scenarios are drawn from it afresh at each
  decision, so they can never run out.
* :class:`~pearl_pomdp.online.rocksample.RockBelief` — RockSample's exact factored belief.
* :class:`ParticleBelief` — beyond that: importance weighting with the model's observation
  likelihood, resampling, and *reinvigoration*: when the effective sample size falls below a
  share of the particles (or every weight is zero), fresh particles from the model's
  ``reinvigorate(observation, count, rng)`` (states consistent with what was just seen) replace
  part of the set, and the number of such events is counted.
"""
from __future__ import annotations

from typing import Callable

import numpy as np

from pearl_pomdp.errors import BeliefError

__all__ = ["sample_belief", "ParticleBelief"]


def sample_belief(belief: np.ndarray, count: int, rng: np.random.Generator) -> np.ndarray:
    """``count`` state indices drawn from the probability vector ``belief`` ``[S]``.

    Raises:
        BeliefError: the belief has a negative or non-finite entry, or no mass.
    """
    b = np.asarray(belief, dtype=float).ravel()
    if not np.isfinite(b).all() or (b < 0).any() or b.sum() <= 0:
        raise BeliefError("belief: not a probability vector (negative, non-finite or zero mass)")
    cdf = np.cumsum(b)
    return np.minimum(np.searchsorted(cdf, rng.random(count) * cdf[-1], side="right"), b.shape[0] - 1).astype(np.int64)


class ParticleBelief:
    """A particle filter with reinvigoration over a generative model (module doc).

    Args:
        model: a generative model with ``observation_likelihood(next_states, action, observation)``.
        particles: the start particles ``[N]``.
        reinvigorate: ``(action, observation, count, rng) -> states`` consistent with the observation.
        min_effective_share: reinvigorate when the effective sample size is below this share of N.
        fresh_share: the share of the particles reinvigoration replaces.
    """

    def __init__(self, model, particles: np.ndarray,
                 reinvigorate: Callable[[int, int, int, np.random.Generator], np.ndarray],
                 min_effective_share: float = 0.1, fresh_share: float = 0.1):
        self.model = model
        self.particles = np.asarray(particles, dtype=np.int64)
        self.reinvigorate = reinvigorate
        self.min_effective_share = float(min_effective_share)
        self.fresh_share = float(fresh_share)
        self.reinvigorations = 0

    def sample(self, count: int, rng: np.random.Generator) -> np.ndarray:
        return self.particles[rng.integers(0, self.particles.shape[0], count)]

    def update(self, action: int, observation: int, rng: np.random.Generator) -> None:
        m = self.model
        n = self.particles.shape[0]
        nxt, _, _ = m.step(self.particles, action, rng.random((n, m.uniforms_per_step)))
        w = np.asarray(m.observation_likelihood(nxt, action, observation), dtype=float)
        total = w.sum()
        ess = (total * total / float((w * w).sum())) if total > 0 else 0.0
        if total > 0:
            nxt = nxt[np.minimum(np.searchsorted(np.cumsum(w), rng.random(n) * total, side="right"), n - 1)]
        if ess < self.min_effective_share * n:
            self.reinvigorations += 1
            fresh = n if total <= 0 else max(1, int(round(self.fresh_share * n)))
            new = np.asarray(self.reinvigorate(action, observation, fresh, rng), dtype=np.int64)
            if new.shape[0] != fresh:
                raise BeliefError(f"reinvigorate returned {new.shape[0]} particles, expected {fresh}")
            nxt = np.concatenate([nxt[: n - fresh], new]) if total > 0 else new
        self.particles = nxt
