"""Type stub of the C kernel ``_step_kernel.c`` (:meth:`pearl_pomdp.online.generative.ExplicitModel.step`).

Arrays are C-contiguous numpy arrays, read in place: ``indptr``/``indices`` of ``T[action]`` as CSR
(int32 or int64), ``data`` and ``O[A, S, Z]`` float32 or float64, ``mass[S]`` float64 (T[action]'s row
masses, from ``row_masses``: each CSR row summed left to right, as ``step`` sums it), ``R[S, A]``,
``states[N]`` int64, ``uniforms[N, >= 2]`` float64 in [0, 1). The outputs ``next_out``/``obs_out`` (int64) and
``reward_out`` (float64), ``[N]`` each, are written. Bad input raises ``ValueError``.
"""
import numpy as np

def row_masses(indptr: np.ndarray, data: np.ndarray, out: np.ndarray) -> None: ...

def step(indptr: np.ndarray, indices: np.ndarray, data: np.ndarray, mass: np.ndarray, O: np.ndarray, R: np.ndarray,
         action: int, states: np.ndarray, uniforms: np.ndarray, next_out: np.ndarray, obs_out: np.ndarray,
         reward_out: np.ndarray) -> None: ...
