"""Type stub of the C kernel ``_pointbased_kernel.c`` (the point-based solver's inner loops).

Every array argument is a C-contiguous numpy array of float64 or int64 as the C source's
comments name; outputs are written in place.
"""
from typing import Tuple

import numpy as np

def successors(idx: np.ndarray, val: np.ndarray, t_ptr: np.ndarray, t_ind: np.ndarray, t_dat: np.ndarray,
               O: np.ndarray, A: int, S: int, Z: int, bT: np.ndarray, pos: np.ndarray, U_out: np.ndarray,
               C_out: np.ndarray, p_out: np.ndarray, live_out: np.ndarray) -> Tuple[int, int]: ...
def lower_rows(C: np.ndarray, nU: int, U: np.ndarray, rows: np.ndarray, GT: np.ndarray, cap: int, k0: int, K: int,
               lb: np.ndarray, best: np.ndarray, only_better: bool) -> None: ...
def sawtooth(C: np.ndarray, nU: int, U: np.ndarray, rows: np.ndarray, Vc: np.ndarray, Qfib: np.ndarray, A: int,
             with_fib: bool, pos: np.ndarray, pts: np.ndarray, pt_start: np.ndarray, pt_len: np.ndarray,
             pt_probe: np.ndarray, pt_pinv: np.ndarray, nprobe: int, ent_idx: np.ndarray, ent_val: np.ndarray,
             pt_delta: np.ndarray, out: np.ndarray) -> None: ...
def alpha(a: int, best_a: np.ndarray, R: np.ndarray, O: np.ndarray, GT: np.ndarray, cap: int, tv_ptr: np.ndarray,
          tv_ind: np.ndarray, tv_dat: np.ndarray, S: int, A: int, Z: int, g: float, inner: np.ndarray,
          out: np.ndarray) -> None: ...
