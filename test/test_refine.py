"""Bound updates along a policy's paths keep the bounds on the right side of the exact value."""
import numpy as np
import pytest

from pearl_pomdp.solvers.mdp import solve_qmdp
from pearl_pomdp.solvers.point_based import PointBasedSolver
from pearl_pomdp.solvers.refine import policy_paths, refine_along_paths
from test_point_based import TIGER_EXACT, read, tiger


def _refined(model, trials, episodes=8, depth=12, sweeps=3):
    solver = PointBasedSolver(model, seed=0, fib_time=None)
    solver.run(time_limit=1e9, epsilon=1e-9, max_trials=trials)
    before = solver.bounds_at_start()
    paths = policy_paths(model, solve_qmdp(model).policy, episodes=episodes, depth=depth, seed=1)
    info = refine_along_paths(solver, paths, sweeps=sweeps)
    return solver, before, info


def test_paths_are_possible_action_observation_sequences():
    m = tiger()
    paths = policy_paths(m, solve_qmdp(m).policy, episodes=20, depth=6, seed=2)
    assert paths.shape == (20, 6)
    a, o = np.divmod(paths, m.num_observations)
    assert a.min() >= 0 and a.max() < m.num_actions and o.max() < m.num_observations
    np.testing.assert_array_equal(paths, policy_paths(m, solve_qmdp(m).policy, episodes=20, depth=6, seed=2))


def test_tiger_refined_bounds_bracket_the_exact_value_and_move_inwards():
    solver, (lb0, ub0), info = _refined(tiger(), trials=2)
    assert info["backups"] > 0 and info["sweeps"] == 3
    assert lb0 - 1e-12 <= info["lb"] <= TIGER_EXACT + 1e-9 <= info["ub"] + 1e-9 <= ub0 + 2e-9
    assert info["ub"] - info["lb"] < ub0 - lb0  # the updates did something
    # Every α-vector is the value of a plan: none exceeds the optimum at b0.
    assert float((solver.GT[:, : solver.K].T @ solver.b0).max()) <= TIGER_EXACT + 1e-9


# cheese and parr95: pomdp-solve's converged values (good to ~1e-6); 1d: ours with ε = 1e-10
# (solve_incremental_pruning, 76 epochs; pomdp-solve's default ε gives 1.260343623, 1.2e-6 lower).
@pytest.mark.parametrize("name, exact, tol", [("cheese.95.POMDP", 3.486206824, 1e-6),
                                              ("parr95.95.POMDP", 7.201039921, 1e-6),
                                              ("1d.POMDP", 1.2603448275435407, 1e-8)])
def test_refined_bounds_bracket_exact_values_on_shared_files(benchmarks_dir, name, exact, tol):
    model = read(benchmarks_dir / name)
    solver, (lb0, ub0), info = _refined(model, trials=1)
    assert info["lb"] <= exact + tol
    assert exact <= info["ub"] + tol
    assert info["lb"] >= lb0 - 1e-12 and info["ub"] <= ub0 + 1e-12


def test_needs_a_stopping_rule():
    solver = PointBasedSolver(tiger(), fib_time=None)
    with pytest.raises(ValueError, match="seconds or sweeps"):
        refine_along_paths(solver, np.zeros((1, 1), dtype=np.int64))
