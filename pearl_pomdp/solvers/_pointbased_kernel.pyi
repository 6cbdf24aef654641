"""Type stub of the C kernel ``_pointbased_kernel.c`` (the point-based solver's inner loops).

Every array argument is a C-contiguous numpy array of float64 or int64 as the C source's
comments name; outputs are written in place.
"""
from typing import Tuple

import numpy as np

def successors(idx: np.ndarray, val: np.ndarray, t_ptr: np.ndarray, t_ind: np.ndarray, t_dat: np.ndarray,
               O: np.ndarray, A: int, S: int, Z: int, bT: np.ndarray, pos: np.ndarray, U_out: np.ndarray,
               C_out: np.ndarray, p_out: np.ndarray, live_out: np.ndarray,
               allowed: bytes | bytearray | np.ndarray = ...) -> Tuple[int, int]: ...
def lower_rows(C: np.ndarray, nU: int, U: np.ndarray, rows: np.ndarray, GT: np.ndarray, cap: int, k0: int, K: int,
               lb: np.ndarray, best: np.ndarray, only_better: bool) -> None: ...
def sawtooth(C: np.ndarray, nU: int, U: np.ndarray, rows: np.ndarray, with_fib: bool, since: int, pos: np.ndarray,
             Vc: np.ndarray, Qfib: np.ndarray, pt_start: np.ndarray, pt_len: np.ndarray, pt_probe: np.ndarray,
             pt_pinv: np.ndarray, ent_idx: np.ndarray, ent_val: np.ndarray, pt_delta: np.ndarray,
             pt_stamp: np.ndarray, n: int, nprobe: int, A: int, out: np.ndarray) -> None: ...
def refresh_upper(Rb: np.ndarray, p: np.ndarray, ub_c: np.ndarray, seen: np.ndarray, C: np.ndarray, nU: int,
                  U: np.ndarray, live: np.ndarray, g: float, A: int, Z: int, ub_version: int, vc_version: int,
                  pos: np.ndarray, Vc: np.ndarray, Qfib: np.ndarray, pt_start: np.ndarray, pt_len: np.ndarray,
                  pt_probe: np.ndarray, pt_pinv: np.ndarray, ent_idx: np.ndarray, ent_val: np.ndarray,
                  pt_delta: np.ndarray, pt_stamp: np.ndarray, n: int, nprobe: int, Qu: np.ndarray) -> int: ...
def qvalue(Rb: np.ndarray, p: np.ndarray, X: np.ndarray, g: float, A: int, Z: int) -> Tuple[int, float]: ...
def excess_obs(p: np.ndarray, ub_c: np.ndarray, lb: np.ndarray, jitter: np.ndarray, a: int, thr: float,
               Z: int) -> int: ...
def alpha(a: int, best_a: np.ndarray, R: np.ndarray, O: np.ndarray, GT: np.ndarray, cap: int, tv_ptr: np.ndarray,
          tv_ind: np.ndarray, tv_dat: np.ndarray, S: int, A: int, Z: int, g: float, inner: np.ndarray,
          out: np.ndarray) -> None: ...
