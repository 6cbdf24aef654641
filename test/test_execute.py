"""EXECUTE (Table 1): top-down trace with values, batch/flat agreement, save/load with model checks."""
import json
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
from test_parameterize import ACTIONS, HIERARCHY, meds_domain  # noqa: E402

from pearl_pomdp.errors import PolicyError
from pearl_pomdp.hierarchy import load_hierarchical_policy, parse_hierarchy, plan
from pearl_pomdp.policies import Lookahead


def expectimax(model, b, horizon):
    """Finite-horizon optimal value of a standard-form model at b, by enumeration."""
    if horizon == 0:
        return 0.0
    best = -np.inf
    for a in range(model.num_actions):
        v = float(b @ model.R[:, a])
        pred = b @ np.asarray(model.T[a])
        for o in range(model.num_observations):
            joint = pred * model.O[a][:, o]
            p = joint.sum()
            if p > 1e-15:
                v += model.discount * p * expectimax(model, joint / p, horizon - 1)
        best = max(best, v)
    return best


@pytest.fixture(scope="module")
def planned():
    model = meds_domain()
    return model, plan(model, parse_hierarchy(HIERARCHY, ACTIONS))


@pytest.mark.parametrize("belief, expected", [
    ([1.0, 0.0, 0.0], ["Help", "CheckMeds"]),
    ([0.0, 1.0, 0.0], ["Help", "Move"]),
    ([0.0, 0.0, 1.0], ["ClarifyTask"]),   # done: ClarifyTask costs -1/step, Help (CheckMeds there) -3
])
def test_execute_walks_top_down(planned, belief, expected):
    model, hp = planned
    d = hp.execute(np.array(belief))
    assert [t.choice for t in d.trace] == expected
    assert [t.subtask for t in d.trace] == ["Act", "Help"][: len(expected)]
    assert d.action_name == expected[-1] and d.action == model.actions.index(expected[-1])


def test_trace_values_are_subtask_values(planned):
    """Each trace value is the subtask's horizon-4 optimal value at the projected belief."""
    model, hp = planned
    b = np.array([0.7, 0.2, 0.1])
    d = hp.execute(b)
    for step in d.trace:
        ab = hp.abstract_models[step.subtask]
        assert step.value == pytest.approx(expectimax(ab.model, ab.project(b), 4), abs=1e-6)
        assert step.value == pytest.approx(hp.subtasks[step.subtask].value(b), abs=1e-12)


def test_batch_agrees_with_execute(planned):
    model, hp = planned
    B = np.random.default_rng(1).dirichlet(np.ones(3), size=200)
    assert list(hp.actions_batch(B)) == [hp.execute(b).action for b in B]


LOOKAHEAD_HIERARCHY = """
root: Act
parameterize: corner
defaults: {solver: incprune, horizon: 4}
subtasks:
  Act: {actions: [ClarifyTask, Help], horizon: 2, lookahead: 2}
  Help: {actions: [CheckMeds, Move]}
"""


@pytest.fixture(scope="module")
def planned_lookahead():
    model = meds_domain()
    return model, plan(model, parse_hierarchy(LOOKAHEAD_HIERARCHY, ACTIONS))


def test_lookahead_is_the_deeper_exact_value(planned, planned_lookahead):
    """Horizon 2 + forward search 2 = exact horizon 4: same values as incremental pruning to
    4 epochs and as brute-force expectimax, and the same choices."""
    model, deep = planned
    _, searched = planned_lookahead
    assert searched.report["subtasks"][-1]["lookahead"] == 2
    assert searched.subtasks["Act"].alphas.shape[0] < deep.subtasks["Act"].alphas.shape[0]
    ab = searched.abstract_models["Act"]
    for b in np.random.default_rng(7).dirichlet(np.ones(3), size=40):
        v = searched.subtasks["Act"].value(b)
        assert v == pytest.approx(deep.subtasks["Act"].value(b), abs=1e-9)
        assert v == pytest.approx(expectimax(ab.model, ab.project(b), 4), abs=1e-9)
        assert searched.execute(b).action == deep.execute(b).action


def test_lookahead_batch_and_round_trip(planned_lookahead, tmp_path):
    model, hp = planned_lookahead
    B = np.random.default_rng(3).dirichlet(np.ones(3), size=100)
    assert list(hp.actions_batch(B)) == [hp.execute(b).action for b in B]
    hp.save(tmp_path / "pol")
    header = json.loads((tmp_path / "pol" / "hierarchy.json").read_text())
    assert [e.get("lookahead", {}).get("depth") for e in header["subtasks"]] == [None, 2]
    loaded = load_hierarchical_policy(tmp_path / "pol", model)
    for b in B[:30]:
        assert loaded.execute(b) == hp.execute(b)


def test_lookahead_fast_last_step_is_bit_identical_to_the_loop(planned_lookahead):
    """The vectorised last search step (what the policy node runs per belief) gives exactly the
    per-(action, observation) loop's Q-values, single beliefs and batches: ties break the same."""
    _, hp = planned_lookahead
    la = hp.subtasks["Act"].lookahead
    looped = Lookahead(la.T, la.O, la.R, la.discount, la.alphas, la.depth)
    looped.LAST_STEP_BLOCK = 0  # every call takes the loop
    B = np.vstack([np.random.default_rng(5).dirichlet(np.ones(la.O.shape[1]) * 0.3, size=60),
                   np.eye(la.O.shape[1]), np.full((1, la.O.shape[1]), 1.0 / la.O.shape[1])])
    for depth in (1, 2):
        assert np.array_equal(la.q_values(B, depth), looped.q_values(B, depth))
        for b in B:
            assert np.array_equal(la.q_values(b[None], depth), looped.q_values(b[None], depth))


def test_save_load_round_trip(planned, tmp_path):
    model, hp = planned
    hp.save(tmp_path / "pol")
    assert sorted(p.name for p in (tmp_path / "pol").iterdir()) == ["hierarchy.json", "policy.npz"]
    loaded = load_hierarchical_policy(tmp_path / "pol", model)
    B = np.random.default_rng(2).dirichlet(np.ones(3), size=50)
    for b in B:
        assert loaded.execute(b) == hp.execute(b)
    assert loaded.report["subtasks"][0]["name"] == "Help"
    np.load(tmp_path / "pol" / "policy.npz", allow_pickle=False)  # no object arrays inside


def test_load_rejects_other_model(planned, tmp_path):
    model, hp = planned
    hp.save(tmp_path / "pol")
    other = meds_domain()
    other.R[0, 1] = 11.0
    with pytest.raises(PolicyError, match="fingerprint"):
        load_hierarchical_policy(tmp_path / "pol", other)


def test_load_rejects_mismatched_pair(planned, tmp_path):
    model, hp = planned
    hp.save(tmp_path / "pol")
    header = json.loads((tmp_path / "pol" / "hierarchy.json").read_text())
    header["npz_sha256"] = "0" * 64
    (tmp_path / "pol" / "hierarchy.json").write_text(json.dumps(header))
    with pytest.raises(PolicyError, match="SHA-256"):
        load_hierarchical_policy(tmp_path / "pol", model)
    with pytest.raises(PolicyError, match="not a hierarchical policy directory"):
        load_hierarchical_policy(tmp_path / "nothing", model)


PROBE_DOMAIN = """
name: probe
discount: 0.9
features:
  Goal: [a, b]
start: {Goal: {a: 0.5, b: 0.5}}
modalities:
  Speech: [sa, sb]
actions:
  Ask: {}
  DoA: {}
  DoB: {}
observations:
  Ask:
    parents: [Goal]
    table:
      a: {sa: 0.85, sb: 0.15}
      b: {sa: 0.15, sb: 0.85}
  default:
    parents: [Goal]
    table:
      a: {sa: 0.5, sb: 0.5}
      b: {sa: 0.5, sb: 0.5}
rewards:
  - {action: DoA, when: {Goal: a}, reward: 10, why: right}
  - {action: DoA, when: {Goal: b}, reward: -100, why: wrong}
  - {action: DoB, when: {Goal: b}, reward: 10, why: right}
  - {action: DoB, when: {Goal: a}, reward: -100, why: wrong}
  - {action: Ask, reward: -1, why: asking costs}
"""
PROBE_HIERARCHY = """
root: Top
parameterize: corner
defaults: {solver: incprune, horizon: 5}
subtasks:
  Top: {actions: [Ask, Do]}
  Do: {actions: [DoA, DoB]}
"""


def test_cli_plan_json_save_and_explain(tmp_path, capsys):
    from pearl_pomdp.cli import main

    (tmp_path / "probe.domain.yaml").write_text(PROBE_DOMAIN)
    (tmp_path / "probe.hierarchy.yaml").write_text(PROBE_HIERARCHY)  # found beside the domain
    assert main(["plan", str(tmp_path / "probe.domain.yaml"), "--json", "--out", str(tmp_path / "pol")]) == 0
    report = json.loads(capsys.readouterr().out)
    assert [s["name"] for s in report["subtasks"]] == ["Do", "Top"]
    top = report["subtasks"][1]
    assert (top["states_full"], top["states_abstract"], top["observations_full"], top["actions"], top["solver"]) == \
        (2, 2, 2, ["Ask", "Do"], "incprune")
    assert top["exact"] and report["total_seconds"] > 0
    # Eq. 15-17 model Do as "DoA in a, DoB in b" (the child's choice at each corner), so in Top
    # Do earns +10 everywhere and Ask -1: Top's reward does not depend on the state, the local
    # reward assumption fails, plan says so, and Top's policy is one vector (always Do).
    assert any("no action's reward depends on the state" in w for w in top["warnings"])
    assert top["alpha_vectors"] == 1
    assert main(["explain", str(tmp_path / "probe.domain.yaml"), str(tmp_path / "pol"), "--belief", "Goal=b", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["action_name"] == "DoB" and [t["subtask"] for t in out["trace"]] == ["Top", "Do"]
    assert main(["hierarchy", str(tmp_path / "probe.domain.yaml"), "--policy", str(tmp_path / "pol")]) == 0
    dot = capsys.readouterr().out
    assert 't_Top -> t_Do;' in dot and "S 2→2" in dot
    assert main(["explain", str(tmp_path / "probe.domain.yaml"), str(tmp_path / "pol"), "--belief", "Goal=c"]) == 2
    assert "unknown value 'c' of Goal" in capsys.readouterr().err
