"""The front door: ``import pearl_pomdp`` is cheap and ROS-free, its few words load, plan, decide
and track, and :func:`pearl_pomdp.load_decider` reads every kind of policy spec."""
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
from test_parameterize import HIERARCHY, meds_domain  # noqa: E402

import pearl_pomdp as pp  # noqa: E402
from pearl_pomdp.errors import PolicyError  # noqa: E402
from pearl_pomdp.hierarchy import HierarchicalPolicy  # noqa: E402
from pearl_pomdp.interfaces import BatchPolicy  # noqa: E402
from pearl_pomdp.online.decider import OnlineDecider  # noqa: E402
from pearl_pomdp.policies import FlatPolicyDecider  # noqa: E402
from pearl_pomdp.policy_io import save_policy  # noqa: E402
from pearl_pomdp.simulate import simulate  # noqa: E402

TIGER = Path(__file__).resolve().parent / "data" / "pomdp" / "tiger.95.POMDP"


def test_import_pearl_pomdp_imports_no_numpy_and_no_ros():
    code = ("import json, sys, pearl_pomdp; "
            "print(json.dumps(sorted(m for m in sys.modules if m.split('.')[0] in ('numpy', 'scipy', 'rclpy'))))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert json.loads(out) == []


def test_every_exported_word_resolves():
    assert {"load_model", "load_domain", "solve", "plan", "load_decider", "BeliefFilter"} <= set(pp.__all__)
    assert all(callable(getattr(pp, name)) for name in pp.__all__)
    with pytest.raises(AttributeError, match="has no attribute 'nothing'"):
        getattr(pp, "nothing")


def test_readme_use_load_solve_track_decide(tmp_path):
    model = pp.load_model(TIGER)
    result = pp.solve(model, "incprune", horizon=15)
    assert result.policy.num_vectors == 47 and result.value_at_start == pytest.approx(9.72842474467767, abs=1e-9)
    track = pp.BeliefFilter(model)
    b = track.update(track.update(track.initial(), "listen", "tiger-left"), "listen", "tiger-left")
    assert b[0] == pytest.approx(0.9698, abs=1e-4)
    save_policy(tmp_path / "tiger.npz", result.policy, model, {"method": "incprune"})
    decider = pp.load_decider(tmp_path / "tiger.npz", model)
    decision = decider.execute(b)
    assert isinstance(decider, FlatPolicyDecider) and isinstance(decision, pp.Decision)
    assert decision.action_name == "open-right" == model.actions[result.policy.action(b)]


def test_a_flat_policys_decider_simulates_exactly_as_the_policy():
    model = pp.load_model(TIGER)
    policy = pp.solve(model, "incprune", horizon=10).policy
    bare = simulate(model, policy, episodes=300, steps=20, seed=4)
    decider = FlatPolicyDecider(policy, model)
    assert isinstance(decider, BatchPolicy)   # simulate takes its batched path
    wrapped = simulate(model, decider, episodes=300, steps=20, seed=4)
    np.testing.assert_array_equal(wrapped["returns"], bare["returns"])


def test_load_decider_reads_each_kind_of_spec(tmp_path):
    model = meds_domain()
    (tmp_path / "meds.hierarchy.yaml").write_text(HIERARCHY)
    planned = pp.load_decider("", model, hierarchy=tmp_path / "meds.hierarchy.yaml")
    assert isinstance(planned, HierarchicalPolicy)
    saved = pp.load_decider(planned.save(tmp_path / "policy"), model)
    online = pp.load_decider("online:20", model, seed=3)
    assert isinstance(online, OnlineDecider) and online.settings.trials == 20
    for b in (model.b0, np.array([0.1, 0.1, 0.8]), np.array([0.0, 1.0, 0.0])):
        assert saved.execute(b).action_name == planned.execute(b).action_name


@pytest.mark.parametrize("spec, message", [
    ("online:0", r"POLICY: 'online:0': expected online or online:TRIALS"),
    ("missing.npz", r"POLICY: no such policy file or directory: missing\.npz"),
    ("", r"POLICY: no policy and no hierarchy"),
])
def test_load_decider_names_what_is_wrong(spec, message):
    with pytest.raises(PolicyError, match=message):
        pp.load_decider(spec, meds_domain(), where="POLICY")
