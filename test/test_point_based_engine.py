"""The point-based solver's C engine (``solve_point_based(engine="c")``, ``_search_kernel.c``)
against the Python engine and the reference values of test_point_based.py.

Reference values: pomdp-solve's converged value for tiger.95 (test_point_based.TIGER_EXACT),
SARSOP's 1e-3 brackets run on this project's machine for RockSample[4,4] ([17.9245, 17.9251],
as test_point_based uses) and 4x3.95 ([1.88988, 1.89085] in 0.59 s, `pomdpsol --precision 0.001`, run for this
test). Each solve here takes well under a second.
"""
import dataclasses
from pathlib import Path

import numpy as np
import pytest

from pearl_pomdp.model import pomdp_format
from pearl_pomdp.solvers.point_based import (C_ENGINE_SETTINGS, ENGINES, EngineLacksSetting, PointBasedSettings,
                                             solve_point_based)
from test_point_based import TIGER_EXACT, check_result, tiger

DATA = Path(__file__).parent / "data" / "pomdp"

#: file -> (a lower and an upper bound on V*(b0) from a reference solver).
REFERENCE = {
    "tiger.95.POMDP": (TIGER_EXACT, TIGER_EXACT),
    "4x3.95.POMDP": (1.88988, 1.89085),
    "RockSample_4_4.pomdp": (17.9245, 17.9251),
}


@pytest.mark.parametrize("name", sorted(REFERENCE))
def test_c_engine_brackets_the_reference_and_agrees_with_python(name):
    m = pomdp_format.read_pomdp(DATA / name)
    c = solve_point_based(m, time_limit=60.0, epsilon=1e-3, engine="c")
    check_result(c, m)
    assert c.extra["engine"] == "c"
    assert c.converged and c.upper_bound - c.value_at_start <= 1e-3
    lo_ref, hi_ref = REFERENCE[name]
    # V* lies in both brackets: the C engine's lower bound is below the reference's upper one and
    # its upper bound above the reference's lower one (to the reference's rounding).
    assert c.value_at_start <= hi_ref + 1e-5 and c.upper_bound >= lo_ref - 1e-5
    # Within the gap of the Python engine's bracket (both contain V*).
    py = solve_point_based(m, time_limit=60.0, epsilon=1e-3, engine="python")
    assert py.extra["engine"] == "python" and py.converged
    assert c.value_at_start <= py.upper_bound + 1e-9 and py.value_at_start <= c.upper_bound + 1e-9
    assert abs(c.value_at_start - py.value_at_start) <= 1e-3


def test_c_engine_lower_bound_is_what_its_vectors_achieve():
    m = pomdp_format.read_pomdp(DATA / "RockSample_4_4.pomdp")
    res = solve_point_based(m, time_limit=60.0, epsilon=1e-3, engine="c")
    alphas, actions = res.policy.alphas, res.policy.actions
    assert alphas.shape == (res.extra["vectors"], m.num_states) and actions.shape == (alphas.shape[0],)
    assert float(np.max(alphas @ m.b0)) == res.value_at_start
    # ... and it is the bound the search itself tracked (the kernel's LB(b0), not recomputed).
    assert res.extra["kernel_lower"] == pytest.approx(res.value_at_start, abs=1e-9)
    assert res.upper_bound >= res.value_at_start
    # Each vector is a lower bound on the value of a policy, so none is above V*(b0), which
    # SARSOP's upper bound 17.9251 caps; the search improved on the A blind start vectors.
    assert np.all(alphas @ m.b0 <= REFERENCE["RockSample_4_4.pomdp"][1] + 1e-5)
    assert alphas.shape[0] > m.num_actions


def test_c_engine_is_deterministic():
    m = pomdp_format.read_pomdp(DATA / "4x3.95.POMDP")
    runs = [solve_point_based(m, time_limit=None, epsilon=1e-3, engine="c") for _ in range(2)]
    a, b = runs
    assert (a.value_at_start, a.upper_bound, a.iterations) == (b.value_at_start, b.upper_bound, b.iterations)
    assert a.policy.alphas.tobytes() == b.policy.alphas.tobytes()
    assert a.policy.actions.tolist() == b.policy.actions.tolist()
    # A trial budget stops it there, the same way each time.
    c = solve_point_based(m, time_limit=None, max_trials=5, engine="c")
    d = solve_point_based(m, time_limit=None, max_trials=5, engine="c")
    assert c.iterations == 5 and not c.converged
    assert c.policy.alphas.tobytes() == d.policy.alphas.tobytes() and c.upper_bound == d.upper_bound
    assert c.upper_bound - c.value_at_start > a.upper_bound - a.value_at_start


def test_auto_is_c_unless_settings_or_a_trial_budget_ask_for_python():
    m = tiger()
    assert solve_point_based(m, time_limit=10.0).extra["engine"] == "c"
    assert solve_point_based(m, time_limit=10.0, settings=PointBasedSettings()).extra["engine"] == "python"
    assert solve_point_based(m, time_limit=None, max_trials=3).extra["engine"] == "python"
    assert ENGINES == ("auto", "c", "python")


def test_bad_engine_name_is_refused_naming_the_parameter():
    with pytest.raises(ValueError, match=r"engine must be one of 'auto', 'c', 'python', got 'C\+\+'"):
        solve_point_based(tiger(), engine="C++")


def test_c_engine_rejects_an_undiscounted_model():
    m = tiger()
    m.discount = 1.0
    with pytest.raises(ValueError, match="discount"):
        solve_point_based(m, time_limit=1.0, engine="c")


def test_c_engine_refuses_the_python_engines_knobs_by_name_and_takes_its_own():
    """The C engine has no Perseus rounds, PBVI sweeps, κ bandit or pruning knobs: asked for one it
    says which (EngineLacksSetting), instead of solving as if it had not been asked; its own knobs
    (C_ENGINE_SETTINGS, one κ arm) it takes."""
    m = tiger()
    for knobs, named in [({"sweep_ratio": 0.0}, "settings.sweep_ratio"),
                         ({"max_gamma_entries": 10}, "settings.max_gamma_entries"),
                         ({"trial_kappa": (0.3, 0.1)}, "settings.trial_kappa")]:
        with pytest.raises(EngineLacksSetting, match=named):
            solve_point_based(m, time_limit=1.0, engine="c", settings=PointBasedSettings(**knobs))
    own = solve_point_based(m, time_limit=None, epsilon=1e-3, engine="c",
                            settings=PointBasedSettings(trial_kappa=(0.3,), ub_sweep_ratio=1.0, perseus_share=0.5))
    assert own.extra["engine"] == "c" and own.converged
    assert set(C_ENGINE_SETTINGS) < {f.name for f in dataclasses.fields(PointBasedSettings)}
