"""Policy-contingent PLAN and EXECUTE (``parameterize: policy``): options, offers, values by hand.

The probe domain has one hidden goal (a or b, equally likely) and three actions: Ask (−1,
observes the goal with 85 % accuracy), DoA and DoB (+10 on the right goal, −100 on the wrong
one; either ends the task: the goal becomes ``done``). The hierarchy is Top → {Ask, Do},
Do → {DoA, DoB}.

The paper's eq. 15–17 model Do as "DoA in a, DoB in b" — the child's choice where it knows the
goal — so the parent believes Do earns +10 whatever it knows, and never asks
(test_execute.py::test_cli_plan_json_save_and_explain shows that plan). Policy-contingent, the
parent values what Do would actually do at its belief: at 50/50 that is a gamble worth
(10 − 100)/2, so it asks first.
"""
import io
import json

import numpy as np
import pytest

from pearl_pomdp.hierarchy import load_hierarchical_policy, parse_hierarchy, plan
from pearl_pomdp.hierarchy.options import DONE, EXIT, with_exit
from pearl_pomdp.model.domain_yaml import parse_domain
from pearl_pomdp.model.pomdp import Pomdp

PROBE_DOMAIN = """
name: probe
discount: 0.95
features:
  Goal: [a, b, done]
start: {Goal: {a: 0.5, b: 0.5}}
modalities:
  Answer: [sayA, sayB, silent]
actions:
  Ask: {}
  DoA:
    effects: {Goal: {set: done}}
  DoB:
    effects: {Goal: {set: done}}
observations:
  Ask:
    parents: [Goal]
    table:
      a: {sayA: 0.85, sayB: 0.15}
      b: {sayA: 0.15, sayB: 0.85}
      done: silent
  default:
    parents: [Goal]
    table:
      "*": silent
rewards:
  - {action: DoA, when: {Goal: a}, reward: 10, why: right}
  - {action: DoA, when: {Goal: b}, reward: -100, why: wrong}
  - {action: DoB, when: {Goal: b}, reward: 10, why: right}
  - {action: DoB, when: {Goal: a}, reward: -100, why: wrong}
  - {action: Ask, reward: -1, why: asking costs}
"""
HIERARCHY = """
root: Top
defaults: {trials: 200}
subtasks:
  Top: {actions: [Ask, Do]}
  Do: {actions: [DoA, DoB]}
"""


@pytest.fixture(scope="module")
def probe():
    domain = parse_domain(PROBE_DOMAIN)
    return domain, domain.compile(), plan(domain, parse_hierarchy(HIERARCHY, domain.actions))


def one_step_value(sub, b, action):
    """Subtask ``sub``'s one-step value of a primitive at the full belief ``b``, by hand from its
    saved arrays: b·R_a + γ Σ_o max_k α_k·(b T_a diag O_ao)."""
    la, bh = sub.lookahead, sub.project(b)[0]
    a = sub.model_actions.index(action)
    pred = np.asarray(la._Tt[a] @ bh)
    total = float(bh @ la.R[:, a])
    for o in range(la.O.shape[2]):
        succ = pred * la.O[a, :, o]
        if succ.sum() > 0:
            total += la.discount * float((sub.alphas @ succ).max())
    return total


def belief(model, **p):
    b = np.zeros(model.num_states)
    for name, mass in p.items():
        b[model.states.index(f"Goal={name}")] = mass
    return b


def test_options_add_a_free_stop_and_an_absorbing_done_state():
    model = Pomdp.create(["x", "y"], ["go", "stay"], ["o1", "o2"],
                         [np.array([[0.0, 1.0], [0.0, 1.0]]), np.eye(2)],
                         np.array([[[0.7, 0.3], [0.2, 0.8]], [[0.5, 0.5], [0.5, 0.5]]]),
                         np.array([[1.0, 0.0], [-2.0, 3.0]]), b0=[1.0, 0.0], discount=0.9)
    opt = with_exit(model)
    assert opt.states == ["x", "y", DONE] and opt.actions == ["go", "stay", EXIT]
    T = [np.asarray(t) for t in opt.T]
    assert np.array_equal(T[0][:2, :2], model.T[0]) and np.array_equal(T[1][:2, :2], model.T[1])
    assert all(t[2, 2] == 1.0 for t in T[:2])                     # done stays done
    assert np.array_equal(T[2], np.array([[0, 0, 1.0]] * 3))      # Exit: every state → done
    assert np.array_equal(opt.R, np.array([[1.0, 0.0, 0.0], [-2.0, 3.0, 0.0], [0.0, 0.0, 0.0]]))
    assert np.array_equal(opt.O[:2, :2], model.O) and opt.O[2, 0, 0] == 1.0 and opt.O[0, 2, 0] == 1.0
    assert list(opt.b0) == [1.0, 0.0, 0.0]
    with pytest.raises(ValueError, match="already has"):
        with_exit(opt)


def test_without_a_stop_an_infinite_horizon_reminder_is_never_delivered():
    """Why subtasks are options: a reminder subtask with only 'deliver' (+50 once due, −200
    when nothing is due) and 'wrong' (−100 while due) prefers never delivering for ever
    (−100/step) to delivering once and then being forced to deliver for nothing (−200/step)."""
    from pearl_pomdp.solvers.point_based import solve_point_based

    model = Pomdp.create(["due", "none"], ["deliver", "wrong"], ["-"],
                         [np.array([[0.0, 1.0], [0.0, 1.0]]), np.eye(2)], np.ones((2, 2, 1)),
                         np.array([[50.0, -100.0], [-200.0, -200.0]]), b0=[1.0, 0.0], discount=0.95)
    forced = solve_point_based(model, time_limit=None, epsilon=1e-3, max_trials=500)
    assert model.actions[forced.policy.action(model.b0)] == "wrong"
    option = solve_point_based(with_exit(model), time_limit=None, epsilon=1e-3, max_trials=500)
    assert option.value_at_start == pytest.approx(50.0, abs=1e-3)  # deliver, then stop
    assert option.upper_bound == pytest.approx(50.0, abs=2e-3)


def test_the_parent_sees_the_child_as_it_acts(probe):
    _, model, hp = probe
    assert hp.contingent and hp.report["parameterize"] == "policy"
    top, do = hp.report["subtasks"][1], hp.report["subtasks"][0]
    assert (do["name"], do["option"], top["name"], top["option"]) == ("Do", True, "Top", False)
    # At 50/50 Do would gamble; Top asks. Sure of the goal, Top lets Do act and Do picks right.
    assert hp.execute(belief(model, a=0.5, b=0.5)).action_name == "Ask"
    for goal, act in (("a", "DoA"), ("b", "DoB")):
        d = hp.execute(belief(model, **{goal: 1.0}))
        assert (d.action_name, [t.subtask for t in d.trace], d.trace[0].choice) == (act, ["Top", "Do"], "Do")
    # One clear answer (0.85/0.15) is enough to act: the expected loss of the remaining doubt
    # (0.15·110 = 16.5) is above the cost of another question, so Top asks once more only below that.
    assert hp.execute(belief(model, a=0.85, b=0.15)).action_name == "Ask"
    assert hp.execute(belief(model, a=0.98, b=0.02)).action_name == "DoA"


def test_trace_values_are_one_step_values_of_the_offers(probe):
    """Top's value of each child is b·R_a + γ Σ_o max_k α_k·(b T_a diag O_ao) for the primitive
    the child offers, computed here by hand from the saved arrays."""
    _, model, hp = probe
    top = hp.subtasks["Top"]
    b = belief(model, a=0.7, b=0.3)

    def q(action):
        return one_step_value(top, b, action)

    offer = hp.execute(np.where(np.arange(model.num_states) >= 0, b, 0)).trace
    values = hp.values(b)
    child_offer = hp.subtasks["Do"].actions[hp.pick("Do", b, {})[1]]
    assert values["Top"] == pytest.approx(max(q("Ask"), q(child_offer)), abs=1e-12)
    assert offer[0].value == pytest.approx(values["Top"], abs=1e-12)


def test_batch_decides_as_the_robot_does(probe):
    _, model, hp = probe
    rng = np.random.default_rng(3)
    B = np.zeros((300, model.num_states))
    B[:, :3] = rng.dirichlet(np.ones(3), size=300)
    assert list(hp.actions_batch(B)) == [hp.execute(b).action for b in B]


def test_save_load_round_trip_keeps_every_decision(probe, tmp_path):
    domain, model, hp = probe
    hp.save(tmp_path / "pol")
    back = load_hierarchical_policy(tmp_path / "pol", domain)
    assert back.contingent
    rng = np.random.default_rng(4)
    for _ in range(50):
        b = np.zeros(model.num_states)
        b[:3] = rng.dirichlet(np.ones(3))
        assert back.execute(b).as_dict() == hp.execute(b).as_dict()


def test_plans_are_byte_identical_run_to_run(probe):
    domain, _, hp = probe
    again = plan(domain, parse_hierarchy(HIERARCHY, domain.actions))
    for name in hp.subtasks:
        assert np.array_equal(hp.subtasks[name].alphas, again.subtasks[name].alphas)
    first, second = io.BytesIO(), io.BytesIO()
    np.savez(first, *[s.alphas for s in hp.subtasks.values()])
    np.savez(second, *[s.alphas for s in again.subtasks.values()])
    assert first.getvalue() == second.getvalue()


def test_plans_are_byte_identical_beside_a_cpu_burner(probe):
    # The budget is a trial count, so a busy machine changes the plan's time, never its vectors.
    import subprocess
    import sys

    domain, _, hp = probe
    burners = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(2)]
    try:
        busy = plan(domain, parse_hierarchy(HIERARCHY, domain.actions))
    finally:
        for p in burners:
            p.kill()
            p.wait(timeout=10)
    for name in hp.subtasks:
        assert hp.subtasks[name].alphas.tobytes() == busy.subtasks[name].alphas.tobytes()
        assert np.array_equal(hp.subtasks[name].alpha_actions, busy.subtasks[name].alpha_actions)


def test_an_exact_solve_that_cannot_finish_falls_back_to_point_based_without_losing_value(caplog):
    """Table 4's dialogue (8 states, 14 actions, 12 observations): exact pruning at the infinite
    horizon does not converge in a second, so the plan falls back to point-based — and the
    fallback's plan is the point-based plan itself (same trials, same vectors), not a
    truncated exact one (before the fix the fallback inherited the spent clock: 0 trials,
    V(b0) = -20 against 84.39)."""
    from pathlib import Path

    from pearl_pomdp.hierarchy import flat_hierarchy
    from pearl_pomdp.model.domain_yaml import load_domain

    domain = load_domain(Path(__file__).resolve().parents[1] / "config/table4.domain.yaml")
    exact_first = plan(domain, flat_hierarchy(list(domain.actions), solver="incprune", time_limit=2.0, horizon=None))
    point_based = plan(domain, flat_hierarchy(list(domain.actions)))
    first, pb = exact_first.report["subtasks"][-1], point_based.report["subtasks"][-1]
    assert first["solver"] == "pointbased" and not first["exact"]
    assert any("incremental pruning stopped by time_limit" in w and "planned point-based instead" in w
               for w in first["warnings"])
    assert first["stop_reason"] == pb["stop_reason"] == "converged"
    assert first["value_at_start"] == pb["value_at_start"] and first["value_at_start"] > 84.0
    assert first["gap"] <= 0.01
    root = exact_first.root
    assert exact_first.subtasks[root].alphas.tobytes() == point_based.subtasks[root].alphas.tobytes()


def test_deeper_search_counts_its_expansions_within_the_budget(probe):
    """lookahead: 1 searches two steps over the children's offers; the budget caps the beliefs
    expanded, and with enough budget the value is the two-step expectimax over the offers."""
    domain, model, _ = probe
    deep = plan(domain, parse_hierarchy(HIERARCHY.replace("Top: {actions: [Ask, Do]}",
                                                          "Top: {actions: [Ask, Do], lookahead: 1, expansions: 100}"),
                                        domain.actions))
    b = belief(model, a=0.6, b=0.4)
    d = deep.execute(b)
    assert 0 < d.expansions <= 100 and d.as_dict()["expansions"] == d.expansions
    # By hand: two steps over the offers, the vectors after them.
    top = deep.subtasks["Top"]
    la = top.lookahead

    def value(bf, depth):
        bh = top.project(bf)[0]
        best = -np.inf
        for k, child in enumerate(top.actions):
            prim = deep.pick(child, bf, {})[0] if top.abstract[k] else deep._index[child]
            a = top.model_actions.index(deep.action_names[prim])
            pred = np.asarray(la._Tt[a] @ bh)
            total = float(bh @ la.R[:, a])
            for o in la._live_obs[a]:
                succ = pred * la.O[a, :, o]
                m = succ.sum()
                if m <= 1e-300:
                    continue
                if depth == 1:
                    total += la.discount * float((top.alphas @ succ).max())
                else:
                    total += la.discount * m * value(top.lift(succ / m), depth - 1)
            best = max(best, total)
        return best

    assert d.trace[0].value == pytest.approx(value(b, 2), abs=1e-9)
    starved = plan(domain, parse_hierarchy(HIERARCHY.replace("Top: {actions: [Ask, Do]}",
                                                             "Top: {actions: [Ask, Do], lookahead: 2, expansions: 3}"),
                                           domain.actions))
    assert starved.execute(b).expansions == 3


def test_plan_report_has_the_bounds_of_every_subtask(probe):
    _, _, hp = probe
    for info in hp.report["subtasks"]:
        assert info["solver"] == "pointbased" and info["upper_bound"] is not None
        assert info["gap"] == pytest.approx(info["upper_bound"] - info["value_at_start"])
        assert info["stop_reason"] in ("converged", "trials")
        assert info["starts"] >= 1
    json.dumps(hp.report)  # JSON-ready


#: A group: Act has a subtask (Do) among its children, so Top is offered Ask and Do's pick —
#: Act's children's offers — and chooses between them by its own value.
GROUP_HIERARCHY = """
root: Top
defaults: {trials: 200}
subtasks:
  Top: {actions: [Act]}
  Act: {actions: [Ask, Do]}
  Do: {actions: [DoA, DoB]}
"""


@pytest.fixture(scope="module")
def grouped():
    """The probe domain planned with the group hierarchy (Top → Act → {Ask, Do → {DoA, DoB}})."""
    domain = parse_domain(PROBE_DOMAIN)
    return domain.compile(), plan(domain, parse_hierarchy(GROUP_HIERARCHY, domain.actions))


def probe_beliefs(model, seed):
    """The corners of the probe's belief simplex that matter, then 20 drawn with ``seed``."""
    rng = np.random.default_rng(seed)
    for p in np.concatenate([[0.5, 0.85, 0.98, 0.02], rng.uniform(size=20)]):
        yield belief(model, a=float(p), b=float(1 - p))


def test_a_group_passes_its_childrens_offers_up_and_the_parent_chooses_by_its_own_value(grouped):
    model, hp = grouped
    top, act = hp.subtasks["Top"], hp.subtasks["Act"]

    for b in probe_beliefs(model, 5):
        do_pick = hp.action_names[hp.pick("Do", b, {})[0]]
        offers = [(hp.action_names[prim], path) for prim, path in hp.offers(top.actions, b, {})]
        assert offers == [("Ask", (0, 0)), (do_pick, (0, 1))]       # Act's children, not Act's pick
        d = hp.execute(b)
        want = max(["Ask", do_pick], key=lambda a: one_step_value(top, b, a))   # first on ties, as EXECUTE
        assert d.action_name == want
        assert d.trace[0].value == pytest.approx(max(one_step_value(top, b, "Ask"), one_step_value(top, b, do_pick)),
                                                 abs=1e-9)
        # The trace goes through the group with the group's own value of what the root chose.
        assert [t.subtask for t in d.trace][:2] == ["Top", "Act"]
        assert d.trace[1].value == pytest.approx(one_step_value(act, b, want), abs=1e-9)
        # Batched EXECUTE (simulation) decides the same.
        assert hp.actions_batch(b[None, :])[0] == d.action


def test_each_choosing_level_names_its_runner_up_and_the_runner_ups_value(grouped):
    """The trace shows, beside each choice, the best offer the level did not take and its value by
    the same one-step measure (computed here by hand); a group that only passed offers up has none."""
    model, hp = grouped
    top, do = hp.subtasks["Top"], hp.subtasks["Do"]
    for b in probe_beliefs(model, 8):
        do_pick = hp.action_names[hp.pick("Do", b, {})[0]]
        d = hp.execute(b)
        rival, label = ("Ask", "Act→Ask") if d.action_name != "Ask" else (do_pick, f"Act→Do→{do_pick}")
        assert d.trace[0].runner_up == label
        assert d.trace[0].runner_up_value == pytest.approx(one_step_value(top, b, rival), abs=1e-9)
        assert d.trace[0].runner_up_value <= d.trace[0].value
        assert d.trace[1].subtask == "Act" and d.trace[1].runner_up == ""      # passed the offer up
        if d.action_name != "Ask":
            other = "DoB" if d.action_name == "DoA" else "DoA"
            assert (d.trace[2].subtask, d.trace[2].runner_up) == ("Do", other)
            assert d.trace[2].runner_up_value == pytest.approx(one_step_value(do, b, other), abs=1e-9)
        plain = d.as_dict()["trace"][0]
        assert (plain["runner_up"], plain["runner_up_value"]) == (label, d.trace[0].runner_up_value)


def test_pearl_answers_a_question_it_is_sure_of_while_the_walk_is_still_uncertain(pearl_policy):
    """Issue 21's second protocol found the converged plan waiting for a dozen steps while she
    asked for the time over and over: after the reminder the walk was wanted with 0.64, and
    Assist, ranking its children by its own option value, offered ConfirmGuideToPhysio (44.0)
    over TellTime (37.1); the root, shown only the confirmation, valued it below waiting. With
    the group's offers passed up the root sees TellTime too and answers first."""
    from pathlib import Path

    from pearl_pomdp.model.domain_yaml import load_domain

    domain = load_domain(Path(__file__).resolve().parents[1] / "config/pearl.domain.yaml")
    hp = load_hierarchical_policy(pearl_policy, domain)
    marginals = {"RobotLocation": {"room": 1.0}, "UserLocation": {"room": 1.0}, "UserPresent": {"yes": 1.0},
                 "ReminderGoal": {"none": 1.0}, "UserMotionGoal": {"toPhysioWithRobot": 0.64, "none": 0.36},
                 "UserInfoGoal": {"wantTime": 1.0}, "Battery": {"ok": 1.0}}
    b = np.ones(domain.compile().num_states)
    for f, feature in enumerate(domain.features):
        b *= np.array([marginals[feature.name].get(v, 0.0) for v in feature.values])[domain.state_values[:, f]]
    d = hp.execute(b / b.sum())
    assert d.action_name == "TellTime"
    assert [t.subtask for t in d.trace] == ["Act", "Assist", "Inform"]
