"""PARAMETERIZE (eq. 11–17) on a 3-state domain checked entry by entry against hand-computed values.

Domain: a resident either wants her meds (``wantMeds``), wants to move (``wantMove``) or is
``done``. Hierarchy: ``Act → {ClarifyTask, Help}``, ``Help → {CheckMeds, Move}``.

Help's local policy at the corner beliefs is π_Help = (CheckMeds, Move, CheckMeds):
CheckMeds earns +10 in wantMeds, Move +10 in wantMove, and in ``done`` CheckMeds costs
-3 against Move's -5 (both keep ``done``), so every number below follows by hand.
"""
import numpy as np
import pytest

from pearl_pomdp.belief import BeliefFilter
from pearl_pomdp.hierarchy import parse_hierarchy, plan
from pearl_pomdp.hierarchy.abstraction import abstract_subtask
from pearl_pomdp.hierarchy.parameterize import StateFactors, local_reward_problems, parameterize
from pearl_pomdp.model.pomdp import Pomdp

STATES = ["wantMeds", "wantMove", "done"]
ACTIONS = ["ClarifyTask", "CheckMeds", "Move"]
OBS = ["o_meds", "o_move", "o_none"]

T_CLARIFY = np.eye(3)
T_CHECKMEDS = np.array([[0.1, 0.0, 0.9], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
T_MOVE = np.array([[1.0, 0.0, 0.0], [0.0, 0.2, 0.8], [0.0, 0.0, 1.0]])
O_CLARIFY = np.array([[0.8, 0.1, 0.1], [0.1, 0.8, 0.1], [0.1, 0.1, 0.8]])
O_CHECKMEDS = np.array([[0.6, 0.2, 0.2], [0.2, 0.6, 0.2], [0.1, 0.1, 0.8]])
O_MOVE = np.array([[1 / 3, 1 / 3, 1 / 3], [1 / 3, 1 / 3, 1 / 3], [0.2, 0.2, 0.6]])
R = np.array([[-1.0, 10.0, -5.0],
              [-1.0, -5.0, 10.0],
              [-1.0, -3.0, -5.0]])

HIERARCHY = """
root: Act
parameterize: corner
defaults: {solver: incprune, horizon: 4}
subtasks:
  Act: {actions: [ClarifyTask, Help]}
  Help: {actions: [CheckMeds, Move]}
"""


def meds_domain() -> Pomdp:
    return Pomdp.create(STATES, ACTIONS, OBS, [T_CLARIFY, T_CHECKMEDS, T_MOVE],
                        np.stack([O_CLARIFY, O_CHECKMEDS, O_MOVE]), R, b0=[0.4, 0.4, 0.2],
                        discount=0.95, name="meds")


@pytest.fixture(scope="module")
def setup():
    model = meds_domain()
    h = parse_hierarchy(HIERARCHY, ACTIONS, source="meds.hierarchy.yaml")
    return model, h


def test_primitive_children_keep_the_full_model(setup):
    """Eq. 11–14: T_h, O_h, R_h of a primitive child equal the full model's, b0_h = b0."""
    model, h = setup
    sub = parameterize(model, h.subtasks["Help"], {})
    assert sub.actions == ["CheckMeds", "Move"]
    np.testing.assert_array_equal(sub.transition(0), T_CHECKMEDS)
    np.testing.assert_array_equal(sub.transition(1), T_MOVE)
    for s in range(3):
        np.testing.assert_array_equal(sub.observation_pair(0)[s], O_CHECKMEDS)  # same for every previous s
        np.testing.assert_array_equal(sub.observation_pair(1)[s], O_MOVE)
    np.testing.assert_array_equal(sub.R, [[10, -5], [-5, 10], [-3, -5]])
    np.testing.assert_array_equal(sub.b0, [0.4, 0.4, 0.2])


def test_plan_finds_help_policy_at_corner_beliefs(setup):
    model, h = setup
    hp = plan(model, h)
    names = [model.actions[a] for a in hp.subtasks["Help"].effective]
    assert names == ["CheckMeds", "Move", "CheckMeds"]


def test_abstract_child_eq_15_to_17_by_hand(setup):
    """Act's model of abstract action Help, with π_Help = (CheckMeds, Move, CheckMeds)."""
    model, h = setup
    pi = np.array([1, 2, 1])  # CheckMeds, Move, CheckMeds
    sub = parameterize(model, h.subtasks["Act"], {"Help": pi})
    assert sub.actions == ["ClarifyTask", "Help"] and sub.abstract == [False, True]
    # Eq. 15: T_Act(s, Help, s') = T(s, π(s), s'), row by row.
    T_help = np.asarray(sub.transition(1))
    expected_T = [[0.1, 0.0, 0.9],   # wantMeds: CheckMeds
                  [0.0, 0.2, 0.8],   # wantMove: Move
                  [0.0, 0.0, 1.0]]   # done: CheckMeds
    np.testing.assert_array_equal(T_help, expected_T)
    np.testing.assert_array_equal(np.asarray(sub.transition(0)), np.eye(3))
    # Eq. 17: R_Act(s, Help) = R(s, π(s)).
    np.testing.assert_array_equal(sub.R[:, 1], [10.0, 10.0, -3.0])
    np.testing.assert_array_equal(sub.R[:, 0], [-1.0, -1.0, -1.0])
    # Eq. 16, state-pair form: P(o | s, Help, s') = O(s', π(s), o).
    P = sub.observation_pair(1)  # [s, s', o]
    np.testing.assert_allclose(P[0, 2], [0.1, 0.1, 0.8])        # from wantMeds via CheckMeds, arrive done
    np.testing.assert_allclose(P[1, 2], [0.2, 0.2, 0.6])        # from wantMove via Move, arrive done
    np.testing.assert_allclose(P[2, 2], [0.1, 0.1, 0.8])        # from done via CheckMeds
    np.testing.assert_allclose(P[1, 1], [1 / 3, 1 / 3, 1 / 3])  # wantMove stays, Move's observation
    np.testing.assert_allclose(P[0, 0], [0.6, 0.2, 0.2])        # wantMeds stays, CheckMeds' observation
    # ClarifyTask is primitive: its O row does not depend on the previous state.
    np.testing.assert_allclose(sub.observation_pair(0)[1, 0], [0.8, 0.1, 0.1])


def test_state_pair_observations_become_exact_standard_model(setup):
    """'done' is reached by Help through CheckMeds *or* Move with different observation rows:
    the standard-form model gets a second copy of 'done', and nothing else changes."""
    model, h = setup
    sub = parameterize(model, h.subtasks["Act"], {"Help": np.array([1, 2, 1])})
    ab = abstract_subtask(sub, StateFactors.from_domain(model))
    m = ab.model
    assert m.states == ["wantMeds", "wantMove", "done", "done#1"]
    assert list(ab.state_to_model) == [0, 1, 2]
    T_help = m.T[1]
    np.testing.assert_allclose(T_help, [[0.1, 0.0, 0.9, 0.0],
                                        [0.0, 0.2, 0.0, 0.8],   # Move's arrival in done → copy #1
                                        [0.0, 0.0, 1.0, 0.0],
                                        [0.0, 0.0, 1.0, 0.0]])  # the copy behaves like done
    obs = {name: i for i, name in enumerate(m.observations)}
    col = [obs["o_meds"], obs["o_move"], obs["o_none"]]
    np.testing.assert_allclose(m.O[1][2][col], [0.1, 0.1, 0.8])
    np.testing.assert_allclose(m.O[1][3][col], [0.2, 0.2, 0.6])
    np.testing.assert_allclose(m.O[1][1][col], [1 / 3, 1 / 3, 1 / 3])
    np.testing.assert_allclose(m.R[:, 1], [10, 10, -3, -3])
    # ClarifyTask is primitive: from either copy it lands on copy 0 (its row needs no copy).
    np.testing.assert_allclose(m.T[0], [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 1, 0]])
    np.testing.assert_allclose(m.O[0][3][col], [0.1, 0.1, 0.8])  # ClarifyTask in done (either copy)


def test_belief_update_through_abstract_action_by_hand(setup):
    """b = (0.3, 0.5, 0.2), Help, hear o_none:
    b'(wantMeds) ∝ 0.3·0.1·0.2 = 0.006
    b'(wantMove) ∝ 0.5·0.2·(1/3) = 0.0333…
    b'(done)     ∝ 0.3·0.9·0.8 + 0.5·0.8·0.6 + 0.2·1·0.8 = 0.616
    normalised by 0.655333… → (0.0091556, 0.0508647, 0.9399797)."""
    model, h = setup
    sub = parameterize(model, h.subtasks["Act"], {"Help": np.array([1, 2, 1])})
    ab = abstract_subtask(sub, StateFactors.from_domain(model))
    b = ab.project(np.array([0.3, 0.5, 0.2]))
    post = BeliefFilter(ab.model).update(b, "Help", ab.model.observations.index("o_none"))
    marginal = [post[0], post[1], post[2] + post[3]]
    total = 0.006 + 0.5 * 0.2 / 3 + 0.616
    np.testing.assert_allclose(marginal, [0.006 / total, (0.5 * 0.2 / 3) / total, 0.616 / total], atol=1e-12)
    np.testing.assert_allclose(marginal, [0.0091556, 0.0508647, 0.9399797], atol=1e-7)


def test_reward_shaping_is_added_where_it_matches():
    model = meds_domain()
    h = parse_hierarchy(HIERARCHY.replace("Help: {actions: [CheckMeds, Move]}",
                                          "Help: {actions: [CheckMeds, Move], shaping: "
                                          "[{action: Move, reward: 2.5, when: {state: done}}]}"),
                        ACTIONS, {"state": STATES})
    sub = parameterize(model, h.subtasks["Help"], {}, StateFactors.from_domain(model))
    np.testing.assert_array_equal(sub.R, [[10, -5], [-5, 10], [-3, -2.5]])
    np.testing.assert_array_equal(sub.R_unshaped, [[10, -5], [-5, 10], [-3, -5]])


@pytest.mark.parametrize("R, problem", [
    (np.full((3, 2), -1.0), "all actions give the same reward"),
    (np.array([[-1.0, -2.0]] * 3), "no action's reward depends on the state"),
    (np.array([[1.0], [2.0], [3.0]]), "single action"),
])
def test_local_reward_assumption_violations_are_reported(R, problem):
    found = local_reward_problems(R, ["a", "b"][: R.shape[1]], "Sub")
    assert len(found) == 1 and problem in found[0] and "'Sub'" in found[0]


def test_local_reward_assumption_holds_for_discriminative_reward():
    assert local_reward_problems(np.array([[10.0, -5], [-5, 10], [-3, -5]]), ["CheckMeds", "Move"]) == []


def test_plan_reports_violating_subtask(caplog):
    model = meds_domain()
    text = HIERARCHY.replace("Help: {actions: [CheckMeds, Move]}",
                             "Help: {actions: [CheckMeds, Move]}\n  Idle: {actions: [ClarifyTask, Help2]}\n"
                             "  Help2: {actions: [ClarifyTask]}").replace("[ClarifyTask, Help]", "[Idle, Help]")
    h = parse_hierarchy(text, ACTIONS)
    with caplog.at_level("WARNING", logger="pearl_pomdp.hierarchy"):
        hp = plan(model, h)
    by_name = {r["name"]: r for r in hp.report["subtasks"]}
    assert any("single action" in w for w in by_name["Help2"]["warnings"])
    assert any("same reward" in w for w in by_name["Idle"]["warnings"])
    assert by_name["Help"]["warnings"] == []
    assert "Help2" in caplog.text
