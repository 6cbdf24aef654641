"""Monte-Carlo policy evaluation in the flat model, with common random numbers and control variates.

:func:`~pearl_pomdp.simulate.simulate` estimates a policy's discounted value at ``b0`` by the
mean of the returns; on Pearl's flat model the returns spread far (std ≈ 12 for a mean
≈ 5: reminders and questions arrive at random times), so a ±1 % interval would need about
a quarter of a million episodes. :func:`evaluate_policies` runs the same episodes (the same
random draws as :func:`simulate` for the same seed, so its plain returns are identical, and
every policy sees the same draws: common random numbers) and subtracts **control variates**
that have mean exactly zero whatever the policy does:

``D = (V̂(s_0) − b0·V̂) + Σ_t γ^{t+1} (V̂(s_{t+1}) − Σ_{s'} T[a_t][s_t, s'] V̂(s'))``

for each column ``V̂`` of ``controls`` (functions of the true state; by default the MDP
value): each term is a martingale difference of the state process, so ``E[D] = 0`` for any
policy. The estimate is ``mean(G − D·β)``; ``β`` minimises the variance and is fitted by
least squares on the *other* half of the episodes (two-fold cross fitting), so it is
independent of the episodes it corrects and the estimate stays unbiased.

Measured on Pearl's flat model (hierarchical policy, 1000 episodes): the MDP value alone
cuts the return's std from 12.0 to 6.2 (3.7× less variance). Richer controls overfit: with
the 11 feature indicators (:func:`feature_controls`) added, a rare indicator got a
coefficient of −3079 in one half and the std rose to 8.9; the FIB or lower-bound corner
values instead of the MDP value gave the same 6.1–6.2.

The returns stop after ``steps`` steps; the part left out lies in
``γ^T·[R_min, R_max] / (1 − γ)``, reported as ``truncation`` and added to the interval, so
``lower`` is a 95 % lower confidence bound on the policy's infinite-horizon value (and so on
the optimal value ``V*(b0)``).
"""
from __future__ import annotations

import math
import time
from typing import Dict, Mapping, Optional

import numpy as np

from pearl_pomdp.belief import BeliefFilter
from pearl_pomdp.errors import PearlError
from pearl_pomdp.model.pomdp import Pomdp
from pearl_pomdp.simulate import EpisodeSampler, batched_actions

__all__ = ["evaluate_policies", "steps_for_truncation", "feature_controls"]


def steps_for_truncation(model: Pomdp, tolerance: float) -> int:
    """Steps ``T`` after which ``γ^T·max|R|/(1 − γ) ≤ tolerance`` (at most 10,000)."""
    g = float(model.discount)
    if g >= 1.0:
        raise PearlError("the model is undiscounted (γ = 1): give the number of steps explicitly")
    scale = float(np.abs(np.asarray(model.R)).max()) / (1.0 - g)
    if scale <= tolerance:
        return 1
    return int(min(10_000, math.ceil(math.log(tolerance / scale) / math.log(g))))


def feature_controls(model: Pomdp, values: Optional[np.ndarray] = None) -> np.ndarray:
    """Control functions ``[S, k]`` of the state: one indicator per feature value (the first
    value of each feature left out: the indicators of a feature sum to one) from the
    compiled domain's ``metadata["features"]`` (state names ``F=v,…``), plus ``values``
    (e.g. the MDP value) when given. A model without features gets one indicator per state."""
    S = model.num_states
    cols = []
    features = model.metadata.get("features") if isinstance(model.metadata, dict) else None
    if features:
        # The compiled state order is the product of the features in order, last fastest.
        sizes = [len(v) for v in features.values()]
        if int(np.prod(sizes)) != S:
            raise PearlError(f"model {model.name!r}: metadata features multiply to {int(np.prod(sizes))}, "
                             f"the model has {S} states")
        digits = np.stack(np.unravel_index(np.arange(S), sizes), axis=1)   # [S, F]
        for f, n in enumerate(sizes):
            for v in range(1, n):
                cols.append((digits[:, f] == v).astype(float))
    else:
        cols.extend(np.eye(S)[:, 1:].T)
    if values is not None:
        cols.append(np.asarray(values, dtype=float).reshape(S))
    return np.stack(cols, axis=1) if cols else np.zeros((S, 0))


def _run(model: Pomdp, policy, N: int, steps: int, seed: int, controls: np.ndarray, TV: np.ndarray):
    """One policy over ``N`` episodes: the returns ``[N]`` and control sums ``[N, k]``.
    The random draws are :func:`~pearl_pomdp.simulate.simulate`'s, in the same order."""
    rng = np.random.default_rng(seed)
    A = model.num_actions
    filt = BeliefFilter(model)
    sampler = EpisodeSampler(model)
    choose = batched_actions(policy)
    b0 = sampler.b0
    states = sampler.start(rng.random(N))
    beliefs = np.tile(b0, (N, 1))
    returns = np.zeros(N)
    D = controls[states] - (b0 / b0.sum()) @ controls
    weight = 1.0
    g = model.discount
    R = np.asarray(model.R)
    for _ in range(steps):
        actions = choose(beliefs)
        if actions.shape != (N,) or (actions.size and (actions.min() < 0 or actions.max() >= A)):
            raise PearlError(f"policy {type(policy).__name__} returned an action outside 0..{A - 1}")
        returns += weight * R[states, actions]
        u_state, u_obs = rng.random(N), rng.random(N)
        nxt, obs = sampler.step(states, actions, u_state, u_obs)
        D += (weight * g) * (controls[nxt] - TV[actions, states])
        beliefs = filt.update_batch(beliefs, actions, obs)
        states = nxt
        weight *= g
    return returns, D


def _cross_fitted(G: np.ndarray, D: np.ndarray) -> np.ndarray:
    """``G − D·β`` per episode, ``β`` fitted on the other fold (even / odd episodes)."""
    if D.shape[1] == 0 or G.shape[0] < 4:
        return G.copy()
    Y = G.copy()
    folds = [np.arange(0, G.shape[0], 2), np.arange(1, G.shape[0], 2)]
    for fit, apply in ((folds[0], folds[1]), (folds[1], folds[0])):
        Dc = D[fit] - D[fit].mean(axis=0)
        beta = np.linalg.lstsq(Dc, G[fit] - G[fit].mean(), rcond=None)[0]
        Y[apply] = G[apply] - D[apply] @ beta
    return Y


def _summary(x: np.ndarray) -> dict:
    n = x.shape[0]
    std = float(x.std(ddof=1)) if n > 1 else 0.0
    return {"mean": float(x.mean()), "ci95": 1.96 * std / math.sqrt(n), "std": std}


def evaluate_policies(model: Pomdp, policies: Mapping[str, object], episodes: int = 2000,
                      steps: Optional[int] = None, seed: int = 0, controls: Optional[np.ndarray] = None,
                      truncation_tolerance: float = 0.01, progress: bool = False) -> Dict[str, dict]:
    """Evaluate each policy at ``b0`` over the same seeded episodes (see the module docstring).

    Args:
        model: the flat POMDP (``γ < 1`` unless ``steps`` is given).
        policies: name → policy (``.action(b)``, or ``.actions_batch(B)`` for speed).
        episodes: episodes per policy (the same draws for every policy).
        steps: steps per episode; default: enough for the truncation to be at most
            ``truncation_tolerance`` (:func:`steps_for_truncation`).
        seed: the random stream (that of :func:`~pearl_pomdp.simulate.simulate`).
        controls: ``[S, k]`` control functions of the state (default: the MDP value,
            one column); ``k = 0`` for none.
        truncation_tolerance: see ``steps``.
        progress: a line per policy on stderr.

    Returns:
        name → ``{"mean", "ci95", "std"`` (control-variate estimate), ``"plain"`` (the mean of
        the returns ± CI, as :func:`simulate`), ``"truncation"`` ``[lo, hi]`` (what the
        steps left out lies in), ``"lower"`` / ``"upper"`` (the 95 % interval of the
        infinite-horizon value including the truncation), ``"episodes", "steps", "seconds",
        "variance_reduction"`` (plain variance / CV variance), ``"values"`` (``[N]`` CV
        per-episode values, for paired comparisons)}``.

    Raises:
        ValueError: ``episodes`` or ``steps`` < 1, or ``controls`` of the wrong shape.
    """
    if episodes < 1:
        raise ValueError(f"episodes must be ≥ 1, got {episodes}")
    if steps is None:
        steps = steps_for_truncation(model, truncation_tolerance)
    if steps < 1:
        raise ValueError(f"steps must be ≥ 1, got {steps}")
    S = model.num_states
    if controls is None:
        from pearl_pomdp.solvers.mdp import mdp_value_iteration

        controls = mdp_value_iteration(model)[0][:, None]
    controls = np.asarray(controls, dtype=float)
    if controls.ndim != 2 or controls.shape[0] != S:
        raise ValueError(f"controls must be [S={S}, k], got shape {controls.shape}")
    TV = np.stack([np.asarray(Ta @ controls) for Ta in model.T])              # [A, S, k]
    g = float(model.discount)
    R = np.asarray(model.R)
    if g < 1.0:
        tail = (g ** steps / (1.0 - g)) * np.array([min(R.min(), 0.0), max(R.max(), 0.0)])
    else:
        tail = np.array([-math.inf, math.inf])
    out: Dict[str, dict] = {}
    for name, policy in policies.items():
        t0 = time.perf_counter()
        G, D = _run(model, policy, int(episodes), int(steps), seed, controls, TV)
        Y = _cross_fitted(G, D)
        cv, plain = _summary(Y), _summary(G)
        out[name] = {
            **cv, "plain": plain, "truncation": tail.tolist(),
            "lower": cv["mean"] - cv["ci95"] + float(tail[0]), "upper": cv["mean"] + cv["ci95"] + float(tail[1]),
            "episodes": int(episodes), "steps": int(steps), "seed": seed,
            "seconds": time.perf_counter() - t0,
            "variance_reduction": (plain["std"] / cv["std"]) ** 2 if cv["std"] > 0 else math.inf,
            "values": Y, "returns": G,
        }
        if progress:
            import sys

            print(f"evaluate {name}: {cv['mean']:.4f} ± {cv['ci95']:.4f} (plain {plain['mean']:.4f} ± "
                  f"{plain['ci95']:.4f}) {out[name]['seconds']:.1f} s", file=sys.stderr, flush=True)
    return out
