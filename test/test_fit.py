"""`pearl fit` (issue 11): counting with the true state recovers known tables, EM raises the
likelihood monotonically, the fitted file keeps the designer's text and loads, bad input is named."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from pearl_pomdp.errors import PearlError
from pearl_pomdp.fit import FITTED_MARKER, Episode, fit_domain, load_episodes, simulate_episodes, write_fitted
from pearl_pomdp.model.domain_yaml import load_domain, parse_domain

REPO = Path(__file__).resolve().parents[1]
SHIPPED = REPO / "config" / "pearl.domain.yaml"


@pytest.fixture(scope="module", autouse=True)
def _designer(tmp_path_factory):
    """The designer's Pearl domain: the shipped file without its ``fitted:`` section (issue 21
    appended one fitted to the world), so these tests fit the designer's tables."""
    global PEARL
    PEARL = tmp_path_factory.mktemp("designer") / "pearl.domain.yaml"
    PEARL.write_text(SHIPPED.read_text().split(FITTED_MARKER)[0])
    yield


PEARL = SHIPPED
TABLE4 = REPO / "config" / "table4.domain.yaml"

#: The world as it "really" is: two Pearl rows unlike the designer's (a resident who asks to be
#: walked over 25 times as often as the designer's 0.2 %/step; questions half as often), written
#: in the fitted format.
TRUTH_ROWS = """
fitted:
  transitions:
    DoNothing:
      UserMotionGoal:
        "none,yes,room": {none: 0.95, toPhysioWithRobot: 0.05}
      UserInfoGoal:
        "none": {none: 0.99, wantTime: 0.005, wantWeather: 0.005}
"""


def row(domain, action, feature, key):
    a = domain.actions.index(action)
    f = domain.feature_names.index(feature)
    cpt = domain._transitions[a][f]
    combo = tuple(domain.features[p].values.index(v) for p, v in zip(cpt.parents, key.split(",")))
    return dict(zip(domain.features[f].values, cpt.table[combo]))


def test_counting_with_truth_recovers_the_true_tables():
    designer = load_domain(PEARL)
    truth = parse_domain(PEARL.read_text() + TRUTH_ROWS, source="truth")
    assert row(truth, "DoNothing", "UserMotionGoal", "none,yes,room")["toPhysioWithRobot"] == 0.05
    # Mostly waiting (as a robot does), with the actions that change who is present.
    episodes = simulate_episodes(truth, episodes=60, steps=60, seed=3,
                                 actions=["DoNothing"] * 6 + ["RingDoorBell", "GotoPatientRoom"])
    # This world gives DoNothing rows unlike the other actions that share the designer's default
    # table, which a tied fit would average with theirs: fit each action on its own data.
    result = fit_domain(designer, episodes, prior_strength=10, tied=False)
    assert result.with_truth
    fitted = result.domain
    motion = row(fitted, "DoNothing", "UserMotionGoal", "none,yes,room")
    info = row(fitted, "DoNothing", "UserInfoGoal", "none")
    # Tolerance: the motion row sees a few hundred steps (sd of the estimate ~0.013), the info row
    # thousands (sd ~0.0015); 10 pseudo-counts of the designer's rows move them by < 0.005.
    assert abs(motion["toPhysioWithRobot"] - 0.05) < 0.03
    assert row(designer, "DoNothing", "UserMotionGoal", "none,yes,room")["toPhysioWithRobot"] == pytest.approx(0.002)
    assert abs(info["wantTime"] - 0.005) < 0.004 and abs(info["none"] - 0.99) < 0.006
    # The designer's tables are untouched; the report names what moved and how much data stood behind it.
    assert row(designer, "DoNothing", "UserInfoGoal", "none")["none"] == pytest.approx(0.98)
    changed = {(r.table, r.row): r for r in result.rows}
    assert changed[("transition DoNothing/UserMotionGoal", "none,yes,room")].n > 200


def test_em_without_truth_raises_the_likelihood_monotonically():
    designer = load_domain(TABLE4)
    hidden = simulate_episodes(designer, episodes=40, steps=15, seed=5)
    for ep in hidden:
        ep.states = None
    result = fit_domain(designer, hidden, prior_strength=0, em_iterations=10, tolerance=0.0)
    assert not result.with_truth and len(result.history) >= 3
    steps = np.diff(result.history)
    assert np.all(steps >= -1e-9), f"EM lowered the likelihood: {result.history}"
    assert result.history[-1] > result.history[0]


def test_fitted_file_keeps_the_designer_text_loads_and_refits(tmp_path):
    designer = load_domain(PEARL)
    truth = parse_domain(PEARL.read_text() + TRUTH_ROWS, source="truth")
    episodes = simulate_episodes(truth, episodes=10, steps=40, seed=1, actions=["DoNothing"])
    result = fit_domain(designer, episodes, prior_strength=5)
    out = write_fitted(PEARL, result, tmp_path / "fitted.yaml", 5)
    text = out.read_text()
    assert text.startswith(PEARL.read_text()) and "# fitted: n=" in text
    reloaded = load_domain(out)
    got = row(reloaded, "DoNothing", "UserInfoGoal", "none")
    want = row(result.domain, "DoNothing", "UserInfoGoal", "none")
    assert all(abs(got[k] - want[k]) < 1e-5 for k in want)
    again = write_fitted(out, result, tmp_path / "again.yaml", 5)          # a second fit replaces the section
    assert again.read_text().count("fitted:\n") == 1


def test_rows_with_too_little_data_keep_the_prior():
    designer = load_domain(PEARL)
    episodes = simulate_episodes(designer, episodes=1, steps=3, seed=0, actions=["GoHome"])
    result = fit_domain(designer, episodes, min_count=5)
    assert not result.rows and result.kept
    assert row(result.domain, "GoHome", "Battery", "ok") == row(designer, "GoHome", "Battery", "ok")


def test_bad_input_is_named(tmp_path):
    designer = load_domain(PEARL)
    with pytest.raises(PearlError, match="no episodes"):
        fit_domain(designer, [])
    with pytest.raises(PearlError, match=r"step 1: action 'Dance' is not an action of domain 'pearl'"):
        fit_domain(designer, [Episode(["Dance"], ["yes"], None, "x.jsonl:1")])
    bad = tmp_path / "bad.jsonl"
    bad.write_text(json.dumps({"actions": ["DoNothing"], "observations": []}) + "\n")
    with pytest.raises(PearlError, match=r"bad.jsonl:1: 1 actions but 0 observations"):
        load_episodes([bad])
    empty_bag = tmp_path / "bag"
    from pearl_pomdp.bags.writer import BagWriter

    with BagWriter(empty_bag) as w:
        w.add_topic("/pearl/speech", "std_msgs/msg/String")
    with pytest.raises(PearlError, match=r"no /pearl/belief topic of type pearl_interfaces/msg/Belief"):
        load_episodes([empty_bag])
    with pytest.raises(PearlError, match="--prior-strength must be >= 0"):
        fit_domain(designer, simulate_episodes(designer, 1, 2), prior_strength=-1)


def test_cli_fit_writes_a_loadable_domain(tmp_path, capsys):
    from pearl_pomdp.cli import main

    truth = parse_domain(PEARL.read_text() + TRUTH_ROWS, source="truth")
    path = tmp_path / "episodes.jsonl"
    with path.open("w") as fh:
        for ep in simulate_episodes(truth, episodes=5, steps=30, seed=2, actions=["DoNothing"]):
            fh.write(json.dumps({"actions": ep.actions, "observations": ep.observations, "states": ep.states}) + "\n")
    out = tmp_path / "fitted.yaml"
    assert main(["fit", str(PEARL), str(path), "--out", str(out), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["with_truth"] and report["steps"] == 150 and report["out"] == str(out)
    assert report["tables"]["transition DoNothing/UserMotionGoal"]["rows_fitted"] >= 1
    load_domain(out)
    assert main(["fit", str(PEARL), str(path), "--out", str(PEARL)]) == 2
    assert "would overwrite the domain it fits" in capsys.readouterr().err


def test_world_episodes_round_trip_into_the_fit(tmp_path):
    """pearl_sim.nursing_home.episodes records the study loop's steps with the world's truth; the fit reads them."""
    from pearl_sim.nursing_home.agents import ScriptedAgent
    from pearl_sim.nursing_home.episodes import record_episodes
    from pearl_sim.nursing_home.scenario import load_scenarios

    designer = load_domain(PEARL)
    (figure4,) = load_scenarios(REPO / "config" / "scenarios" / "figure4.yaml")
    path = tmp_path / "world.jsonl"
    written = record_episodes([figure4], ScriptedAgent("scripted", designer.actions), designer, range(2), path)
    episodes = load_episodes([path])
    assert len(episodes) == 2 and all(ep.states is not None for ep in episodes)
    assert [ep.actions for ep in episodes] == [w["actions"] for w in written]
    assert episodes[0].actions[0] == "DoNothing" and "GotoPatientRoom" in episodes[0].actions
    result = fit_domain(designer, episodes, min_count=3)
    assert result.with_truth and result.rows


def test_fitted_rows_with_many_small_entries_still_sum_to_one(tmp_path):
    """The fitted section is written with 12 significant digits: with 6, a row of seven equal
    entries (1/7 each) summed to 0.999999 and the written file did not load."""
    from pearl_pomdp.fit import FitResult, RowChange, fitted_section

    designer = load_domain(PEARL)
    symbols = ["yes", "no", "time", "weather", "go", "unknown", "t_yes"]
    after = {k: 1 / 7 for k in symbols}
    before = {k: (1.0 if k == "unknown" else 0.0) for k in symbols}
    row = RowChange("observation DoNothing", "none,no,none,none", 10.0, before, after)
    result = FitResult(designer, [row], [], True, [], 1, 1)
    text = PEARL.read_text() + "\n" + fitted_section(result, 5.0)
    parse_domain(text, source="seven")  # loads: the row sums to 1 within the tolerance


#: Two actions; the designer declares that neither acts on the resident's wish (defaults.effects):
#: Drive only moves the robot.
TIED_DOMAIN = """
name: tied
discount: 0.9
features:
  Wish: [none, want]
  Robot: [home, room]
start: {Wish: none, Robot: home}
modalities:
  Heard: {symbols: [nothing, asked]}
defaults:
  effects:
    Wish:
      parents: [Wish]
      table:
        none: {none: 0.9, want: 0.1}
        want: want
actions:
  Wait: {}
  Drive:
    effects:
      Robot: {set: room}
observations:
  default:
    parents: [Wish]
    table:
      none: {nothing: 0.9, asked: 0.1}
      want: {nothing: 0.5, asked: 0.5}
rewards:
  - {action: Wait, reward: 0, why: "the fit reads no reward"}
"""


def _confounded_episodes(count: int):
    """Her wish always arises during the drive (as questions scheduled on the clock fell in
    the long drives of issue 21's training episodes): Wait, Wait, Drive (wish arises), Wait."""
    none_home = {"Wish": "none", "Robot": "home"}
    episodes = []
    for i in range(count):
        states = [none_home, none_home, none_home, {"Wish": "want", "Robot": "room"}, {"Wish": "want", "Robot": "room"}]
        episodes.append(Episode(["Wait", "Wait", "Drive", "Wait"], ["nothing", "nothing", "asked", "asked"],
                                states, f"hand:{i}"))
    return episodes


def test_a_table_written_once_is_fitted_once_from_the_pooled_data(tmp_path):
    domain = parse_domain(TIED_DOMAIN, source="tied.domain.yaml")
    from pearl_pomdp.fit import tied_groups

    wish = domain.feature_names.index("Wish")
    assert (wish, [domain.actions.index("Wait"), domain.actions.index("Drive")]) in tied_groups(domain)
    episodes = _confounded_episodes(10)
    # Untied, the drive is credited with every wish: from 'none' it always led to 'want' (10 of 10),
    # waiting never did (0 of 20).
    untied = fit_domain(domain, episodes, prior_strength=0, min_count=1, tied=False).domain
    assert row(untied, "Drive", "Wish", "none")["want"] == pytest.approx(1.0)
    assert row(untied, "Wait", "Wish", "none")["want"] == pytest.approx(0.0)
    # Tied (the default), one row for both: 10 wishes in 30 steps from 'none' = 1/3, by hand.
    result = fit_domain(domain, episodes, prior_strength=0, min_count=1)
    for action in ("Drive", "Wait"):
        assert row(result.domain, action, "Wish", "none")["want"] == pytest.approx(1 / 3)
    # With the designer's row as 10 pseudo-counts: (10 * 0.1 + 10) / (10 + 30) = 0.275.
    prior = fit_domain(domain, episodes, prior_strength=10, min_count=1).domain
    assert row(prior, "Drive", "Wish", "none")["want"] == pytest.approx(0.275)
    # The robot's place is Drive's own table: not tied, fitted from Drive's data alone.
    assert row(result.domain, "Drive", "Robot", "home")["room"] == pytest.approx(1.0)
    # The written file says which rows were pooled and loads back to the same numbers.
    source = tmp_path / "tied.domain.yaml"
    source.write_text(TIED_DOMAIN)
    out = write_fitted(source, result, tmp_path / "fitted.yaml", 0)
    assert "pooled over the 2 actions of defaults.effects.Wish" in out.read_text()
    reloaded = load_domain(out)
    assert row(reloaded, "Wait", "Wish", "none")["want"] == pytest.approx(1 / 3, abs=1e-9)


def test_em_pools_tied_tables_too():
    """Without the true state the M-step pools the expected counts the same way: after EM the
    tied rows are equal, where the untied fit gives the drive its own row."""
    domain = parse_domain(TIED_DOMAIN, source="tied.domain.yaml")
    hidden = _confounded_episodes(10)
    for ep in hidden:
        ep.states = None
    tied = fit_domain(domain, hidden, prior_strength=1, min_count=0.5, em_iterations=5).domain
    untied = fit_domain(domain, hidden, prior_strength=1, min_count=0.5, em_iterations=5, tied=False).domain
    assert row(tied, "Drive", "Wish", "none") == pytest.approx(row(tied, "Wait", "Wish", "none"))
    assert row(untied, "Drive", "Wish", "none")["want"] > row(untied, "Wait", "Wish", "none")["want"] + 0.1
