"""Type stub of the C kernel ``_step_kernel.c``: :meth:`pearl_pomdp.online.generative.ExplicitModel.step`, and
DESPOT's expansion (``group_outcomes``; ``group_max_means``, :meth:`~pearl_pomdp.online.generative.AlphaBounds.grouped`;
``rock_tours``, :meth:`~pearl_pomdp.online.rocksample.RockSampleBounds.many`), and a factored domain's ``T[a]`` (``product_rows``).

Arrays are C-contiguous numpy arrays, read in place: ``indptr``/``indices`` of ``T[action]`` as CSR
(int32 or int64), ``data`` and ``O[A, S, Z]`` float32 or float64, and T[action]'s tables from
``row_tables`` (``mass[S]``: each CSR row summed left to right, as ``step`` sums it; ``ends``/``peaks``
``[len(data) // BLOCK + 1]``: the rows' running sums on a grid of BLOCK entries), all float64, ``R[S, A]``,
``states[N]`` int64, ``uniforms[N, >= 2]`` float64 in [0, 1). The outputs ``next_out``/``obs_out`` (int64) and
``reward_out`` (float64), ``[N]`` each, are written. Bad input raises ``ValueError``.
"""
import numpy as np

#: The grid (in entries of ``data``) of ``row_tables``' ``ends``/``peaks``.
BLOCK: int

def row_tables(indptr: np.ndarray, data: np.ndarray, mass: np.ndarray, ends: np.ndarray,
               peaks: np.ndarray) -> None: ...

def step(indptr: np.ndarray, indices: np.ndarray, data: np.ndarray, mass: np.ndarray, ends: np.ndarray,
         peaks: np.ndarray, O: np.ndarray, R: np.ndarray, action: int, states: np.ndarray, uniforms: np.ndarray,
         next_out: np.ndarray, obs_out: np.ndarray, reward_out: np.ndarray) -> None: ...

def group_outcomes(next_states: np.ndarray, observations: np.ndarray, scenarios: np.ndarray, states_out: np.ndarray,
                   scenarios_out: np.ndarray, group_action_out: np.ndarray, group_obs_out: np.ndarray,
                   group_start_out: np.ndarray) -> int:
    """An expansion's children: ``[A, N]`` outcomes grouped by (action, observation), stable; returns their count G
    (``group_start_out[:G + 1]`` bounds them in ``states_out``/``scenarios_out``). All int64."""
    ...

def group_max_means(states: np.ndarray, starts: np.ndarray, table: np.ndarray, out: np.ndarray) -> None:
    """``out[g]`` = the largest column mean of ``table[S, C]`` (float64) over ``states[starts[g]:starts[g + 1]]``."""
    ...

def rock_tours(states: np.ndarray, starts: np.ndarray, k: int, n: int, rocks: np.ndarray, visit: np.ndarray,
               blind: np.ndarray, powers: np.ndarray, out: np.ndarray) -> None:
    """``out[g]`` = the best of RockSample's candidate tours ``visit[g, c]`` / ``blind[g, c]`` (rock masks) valued on
    the particles ``states[starts[g]:starts[g + 1]]`` (all at one cell), ``powers[t]`` = γ^t; see the C source."""
    ...

def product_rows(ptrs: np.ndarray, values: np.ndarray, probs: np.ndarray, strides: np.ndarray, indptr: np.ndarray,
                 indices_out: np.ndarray, data_out: np.ndarray) -> None:
    """A factored domain's ``T[a]`` as CSR (:meth:`pearl_pomdp.model.factored.FactoredDomain.transition_matrix`):
    each state's row holds the products of its features' non-zero factors (``ptrs[F, S + 1]`` int64 into
    ``values``/``probs``), columns ``Σ_f v_f · strides[f]``; ``indptr[S + 1]`` int64 gives the rows' sizes; writes
    ``indices_out`` (int32 or int64) and ``data_out`` (float64); see the C source."""
    ...
