"""Type stub of the C kernel ``_search_kernel.c`` (the point-based solver's whole search, engine="c").

Array arguments are C-contiguous numpy arrays (float64, or int64 for ``t_ptr``/``t_ind``):
``R[S, A]``, ``O[A, S, Z]``, T as the (A·S) × S CSR ``t_ptr/t_ind/t_dat`` (row a·S + s is
T[a][s, :]), ``b0[S]``. The result holds ``alphas`` (bytes: K × S float64), ``actions`` (bytes:
K int64), ``vectors``, ``lower``, ``upper``, ``trials``, ``backups``, ``ub_points``, ``stop``
("epsilon", "time" or "trials"), ``seconds``, ``init_seconds``, ``fib_iterations``,
``blind_iterations``, ``trial_backups``, ``ub_sweeps``, ``ub_sweep_backups``, ``lb_sweep_backups``,
``corner_updates``.
"""
from typing import Any, Dict

import numpy as np

def search(S: int, A: int, Z: int, discount: float, R: np.ndarray, O: np.ndarray, t_ptr: np.ndarray,
           t_ind: np.ndarray, t_dat: np.ndarray, b0: np.ndarray, epsilon: float, kappa: float, init_tol: float,
           time_limit: float, init_max_iterations: int, max_trials: int, ub_sweep_ratio: float, lb_share: float,
           backoff: int) -> Dict[str, Any]: ...
