"""Hierarchy YAML: structure, defaults, and errors that name file, line and field."""
from pathlib import Path

import pytest

from pearl_pomdp.errors import SpecError
from pearl_pomdp.hierarchy import load_hierarchy, parse_hierarchy

PRIMS = ["ClarifyTask", "CheckMeds", "Move"]
GOOD = """\
root: Act
parameterize: corner
defaults: {solver: incprune, horizon: 5}
subtasks:
  Act:
    actions: [ClarifyTask, Help]
  Help:
    actions: [CheckMeds, Move]
    solver: pointbased
    time_limit: 2
"""


def test_good_hierarchy_structure_and_settings():
    h = parse_hierarchy(GOOD, PRIMS, source="h.yaml")
    assert h.root == "Act"
    assert h.postorder() == ["Help", "Act"]
    assert h.is_abstract("Help") and not h.is_abstract("Move")
    assert h.descendants("Act") == ["ClarifyTask", "CheckMeds", "Move"]
    assert h.parent_of("Help") == "Act" and h.parent_of("Act") is None
    assert (h.subtasks["Act"].solver, h.subtasks["Act"].horizon) == ("incprune", 5)
    assert (h.subtasks["Help"].solver, h.subtasks["Help"].horizon, h.subtasks["Help"].time_limit) == ("pointbased", 5, 2.0)


def test_root_is_inferred_when_unique():
    h = parse_hierarchy(GOOD.replace("root: Act\n", ""), PRIMS)
    assert h.root == "Act"


@pytest.mark.parametrize("text, where, line, problem", [
    (GOOD.replace("[CheckMeds, Move]", "[CheckMeds, Move, Fly]"), "subtasks.Help.actions[2]", 8, "unknown action 'Fly'"),
    (GOOD.replace("    actions: [CheckMeds, Move]\n", "    actions: []\n"), "subtasks.Help.actions", 8,
     "abstract action has no children"),
    (GOOD.replace("[CheckMeds, Move]", "[CheckMeds, Help]"), "subtasks.Help.actions[1]", 8, "cycle in the hierarchy"),
    (GOOD.replace("[CheckMeds, Move]", "[CheckMeds, Move, Move]"), "subtasks.Help.actions[2]", 8, "duplicate action 'Move'"),
    (GOOD.replace("[CheckMeds, Move]", "[CheckMeds]"), "subtasks", 4, "missing from the tree: Move"),
    (GOOD.replace("solver: pointbased", "solver: magic"), "subtasks.Help.solver", 9, "unknown solver 'magic'"),
    (GOOD.replace("horizon: 5", "horizon: -1"), "defaults.horizon", 3, "positive integer"),
    (GOOD.replace("horizon: 5", "horizon: 5, lookahead: 4"), "defaults.lookahead", 3, "from 0 to 3"),
    (GOOD.replace("horizon: 5", "horizon: 5, lookahead: yes"), "defaults.lookahead", 3, "got 'yes'"),
    (GOOD.replace("time_limit: 2", "timelimit: 2"), "subtasks.Help.timelimit", 10, "unknown key"),
    (GOOD.replace("root: Act", "root: Top"), "root", 1, "root 'Top' is not a subtask"),
    (GOOD + "  Spare:\n    actions: [Move]\n", "subtasks.Spare", 11, "not reachable from the root"),
    (GOOD.replace("  Help:\n", "  Move:\n"), "subtasks.Move", 7, "also a primitive"),
])
def test_errors_name_file_line_and_field(text, where, line, problem):
    with pytest.raises(SpecError) as info:
        parse_hierarchy(text, PRIMS, source="h.yaml")
    err = info.value
    assert (err.source, err.where, err.line) == ("h.yaml", where, line)
    assert problem in err.problem
    assert str(err).startswith(f"h.yaml:{line}: {where}: ")


def test_subtask_used_twice_is_rejected():
    text = """\
root: Act
subtasks:
  Act: {actions: [A, B]}
  A: {actions: [C]}
  B: {actions: [C]}
  C: {actions: [ClarifyTask, CheckMeds, Move]}
"""
    with pytest.raises(SpecError, match=r"subtasks\.B\.actions\[0\]: subtask 'C' is used twice"):
        parse_hierarchy(text, PRIMS, source="h.yaml")


def test_cycle_below_root_is_reported_with_path():
    text = """\
root: Act
subtasks:
  Act: {actions: [A, ClarifyTask, CheckMeds, Move]}
  A: {actions: [B]}
  B: {actions: [A]}
"""
    with pytest.raises(SpecError, match="cycle in the hierarchy: Act → A → B → A"):
        parse_hierarchy(text, PRIMS)


def test_shaping_checks_features_and_values():
    feats = {"state": ["wantMeds", "wantMove", "done"]}
    ok = GOOD.replace("    time_limit: 2\n", "    shaping:\n      - {action: Move, reward: 1, when: {state: done}}\n")
    h = parse_hierarchy(ok, PRIMS, feats)
    rule = h.subtasks["Help"].shaping[0]
    assert (rule.action, rule.reward, rule.when) == ("Move", 1.0, (("state", ("done",)),))
    with pytest.raises(SpecError, match=r"shaping\[0\]\.when\.state: unknown value 'gone'"):
        parse_hierarchy(ok.replace("state: done", "state: gone"), PRIMS, feats)
    with pytest.raises(SpecError, match=r"shaping\[0\]\.action: 'ClarifyTask' is not an action of this subtask"):
        parse_hierarchy(ok.replace("action: Move", "action: ClarifyTask"), PRIMS, feats)


def test_invalid_yaml_names_line():
    with pytest.raises(SpecError) as info:
        parse_hierarchy("root: Act\nsubtasks: [\n", PRIMS, source="bad.yaml")
    assert info.value.source == "bad.yaml" and info.value.line is not None


def test_pearl_hierarchy_file_is_valid():
    from pearl_pomdp.model.domain_yaml import load_domain

    config = Path(__file__).resolve().parents[1] / "config"
    domain = load_domain(config / "pearl.domain.yaml")
    h = load_hierarchy(config / "pearl.hierarchy.yaml", domain)
    assert h.root == "Act"
    assert set(h.descendants("Act")) == set(domain.actions)
    assert h.subtasks["Contact"].children == ["RingDoorBell", "GotoPatientRoom"]
    assert set(h.subtasks["Act"].children) == {"Remind", "Assist", "Rest", "DoNothing"}
    assert h.parameterize == "policy"
    assert all(spec.solver == "pointbased" and spec.shaping == [] for spec in h.subtasks.values())
    assert h.subtasks["Act"].trials == 60 and h.subtasks["Assist"].trials == 30


POLICY = """\
root: Act
defaults: {trials: 50}
subtasks:
  Act:
    actions: [ClarifyTask, Help]
    lookahead: 1
    expansions: 10
  Help:
    actions: [CheckMeds, Move]
    solver: incprune
"""


def test_policy_parameterization_defaults_and_settings():
    h = parse_hierarchy(POLICY, PRIMS, source="h.yaml")
    assert h.parameterize == "policy"
    act, helper = h.subtasks["Act"], h.subtasks["Help"]
    assert (act.solver, act.trials, act.epsilon, act.time_limit, act.horizon) == ("pointbased", 50, 0.01, None, None)
    assert (act.lookahead, act.expansions) == (1, 10)
    assert (helper.solver, helper.expansions) == ("incprune", 256)


@pytest.mark.parametrize("text, where, problem", [
    (POLICY.replace("parameterize", "x").replace("root: Act", "root: Act\nparameterize: magic"), "parameterize",
     "unknown parameterisation 'magic'"),
    (POLICY.replace("    lookahead: 1\n", "    solver: incprune\n"), "subtasks.Act.solver",
     "incprune cannot solve 'Act': it has abstract children (Help)"),
    (POLICY.replace("    solver: incprune\n", "    horizon: 3\n"), "subtasks.Help.horizon", "applies to incprune only"),
    (POLICY.replace("{trials: 50}", "{trials: 0}"), "defaults.trials", "a positive integer or null"),
    (POLICY.replace("expansions: 10", "expansions: -1"), "subtasks.Act.expansions", "a non-negative integer"),
    (POLICY.replace("    expansions: 10\n", "    shaping: [{action: Help, reward: 1}]\n"),
     "subtasks.Act.shaping[0].action", "'Help' is not a primitive below 'Act'"),
])
def test_policy_parameterization_errors(text, where, problem):
    with pytest.raises(SpecError) as info:
        parse_hierarchy(text, PRIMS, source="h.yaml")
    assert info.value.where == where and problem in info.value.problem, str(info.value)


def test_policy_shaping_names_a_primitive_below_the_subtask():
    text = POLICY.replace("    expansions: 10\n", "    shaping: [{action: Move, reward: 2}]\n")
    assert parse_hierarchy(text, PRIMS).subtasks["Act"].shaping[0].action == "Move"
