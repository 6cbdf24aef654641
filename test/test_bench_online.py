"""bench/online.py's pooling of runs over disjoint episodes (``--first-episode``, ``--combine``):
the pooled mean and CI equal those of one run over all the episodes."""
import json

import numpy as np
import pytest


@pytest.fixture(scope="module")
def online_bench(load_bench):
    return load_bench("online")


def _part(bench, returns, first):
    mean, half = bench._ci(returns)
    return {"episodes": len(returns), "mean": mean, "ci95": half, "first_episode": first,
            "decision_s_p99": 0.9 + first / 1000, "mean_trials": 10.0}


@pytest.mark.parametrize("cuts", [(65,), (10, 40), (3, 4, 50)])
def test_pooled_parts_equal_one_run_over_all_episodes(online_bench, cuts):
    returns = list(np.random.default_rng(len(cuts)).normal(20.0, 7.0, 100))
    edges = [0, *cuts, len(returns)]
    parts = [_part(online_bench, returns[a:b], a) for a, b in zip(edges[:-1], edges[1:])]
    mean, half = online_bench._ci(returns)
    got = online_bench.pooled(parts)
    assert got["episodes"] == 100
    assert got["mean"] == pytest.approx(mean, rel=1e-12)
    assert got["ci95"] == pytest.approx(half, rel=1e-9)
    assert got["decision_s_p99_max"] == max(p["decision_s_p99"] for p in parts)


def test_combine_reads_the_outputs_and_pools_per_problem_and_budget(online_bench, tmp_path):
    returns = list(np.random.default_rng(9).normal(15.0, 5.0, 40))
    paths = []
    for i, (a, b) in enumerate([(0, 25), (25, 40)]):
        path = tmp_path / f"part{i}.json"
        path.write_text(json.dumps({"results": {"rs11_11": {"1s": _part(online_bench, returns[a:b], a)}}}))
        paths.append(str(path))
    got = online_bench.combine(paths)["results"]["rs11_11"]["1s"]
    assert got["episodes"] == 40
    assert got["mean"] == pytest.approx(float(np.mean(returns)), rel=1e-12)
    assert [p["first_episode"] for p in got["parts"]] == [0, 25]


def _result(mean, episodes=100, p99=0.99):
    return {"mean": mean, "ci95": 1.3, "episodes": episodes, "decision_s_p99": p99, "budget_s": 1.0,
            "p99_within_budget_plus_10pct": p99 <= 1.1}


def test_verdict_against_the_published_despot_figures(online_bench):
    ar, ab = (online_bench.PUBLISHED["figures"]["rs15_15"][v] for v in ("AR-DESPOT", "AB-DESPOT"))
    assert ar[0] - ar[1] > ab[0] - ab[1]          # AR-DESPOT's interval is the one that binds
    inside = online_bench.versus_published("rs15_15", _result(ar[0] - ar[1] + 0.01))
    assert inside["within_or_above"] is True and inside["per_variant"] == {"AR-DESPOT": True, "AB-DESPOT": True}
    # Between the two intervals: AB-DESPOT's met, AR-DESPOT's not — the verdict needs both.
    between = online_bench.versus_published("rs15_15", _result(ar[0] - ar[1] - 0.01))
    assert between["per_variant"] == {"AR-DESPOT": False, "AB-DESPOT": True}
    assert between["within_or_above"] is False
    # No figure found: not judged, never a pass.
    none = online_bench.versus_published("rs11_11", _result(100.0))
    assert none["within_or_above"] is None and none["per_variant"] == {}


def test_combine_judges_the_pooled_result(online_bench, tmp_path):
    paths = []
    for i, (mean, first, n, p99) in enumerate([(20.0, 0, 50, 1.02), (17.0, 50, 50, 1.08)]):
        part = dict(_result(mean, n, p99), first_episode=first, mean_trials=10.0)
        path = tmp_path / f"part{i}.json"
        path.write_text(json.dumps({"results": {"rs15_15": {"1s": part}}}))
        paths.append(str(path))
    out = online_bench.combine(paths)
    verdict = out["acceptance"]["rs15_15 1s vs DESPOT"]
    assert verdict["ours"][0] == pytest.approx(18.5) and verdict["episodes"] == 100
    assert verdict["within_or_above"] is True            # 18.5 ≥ 18.57 − 0.30
    assert out["acceptance"]["p99_within_budget_plus_10pct"] == {"rs15_15 1s": True}   # 1.08 ≤ 1.1
    slow = dict(_result(18.5, 10, 1.2), first_episode=100, mean_trials=10.0)
    (tmp_path / "slow.json").write_text(json.dumps({"results": {"rs15_15": {"1s": slow}}}))
    out = online_bench.combine([*paths, str(tmp_path / "slow.json")])
    assert out["acceptance"]["p99_within_budget_plus_10pct"] == {"rs15_15 1s": False}


# A round of DESPOT's laser_tag printout as it ran here (`despot_laser_tag --runs 1 -r 1 -t 0.1`,
# AdaCompNUS/despot 37a3e21), its middle steps cut: the start, the first step and the end.
DESPOT_LASERTAG_ROUND = """\
####################################### Round 0 #######################################
Initial state: 
...#.......
.....##..O.
...R......#
#..........
......#....
..#........
..#........

-----------------------------------Round 0 Step 0-----------------------------------
- Action = West
- State:
...#.....O.
.....##....
..R.......#
#..........
......#....
..#........
..#........
- Observation = 1 6 0 0 2 5 4 2 
- ObsProb = 1.58808e-05
- Reward = -1
- Current rewards:
  discounted / undiscounted = -1 / -1
Simulation terminated in 22 steps
Total discounted reward = -9.78315
Total undiscounted reward = -11
"""


def test_despot_lasertag_printout_gives_its_map_start_and_return(online_bench):
    (got,) = online_bench.parse_despot_lasertag_rounds(DESPOT_LASERTAG_ROUND)
    # The printout's top row is y = 6 (BaseTag::PrintState), so the '#' in its first row is (3, 6).
    assert got["obstacles"] == sorted([(3, 6), (5, 5), (6, 5), (10, 4), (0, 3), (6, 2), (2, 1), (2, 0)])
    assert got["robot"] == (3, 4) and got["opponent"] == (9, 5)
    assert got["return"] == -9.78315
    # Two rounds, the second starting with both in one cell ('Q').
    second = DESPOT_LASERTAG_ROUND.replace("...R......#", "..........#").replace(".....##..O.", ".....##..Q.")
    first, both = online_bench.parse_despot_lasertag_rounds(DESPOT_LASERTAG_ROUND + second)
    assert first == got and both["robot"] == both["opponent"] == (9, 5)


@pytest.mark.parametrize("edit, message", [
    (lambda t: t.replace("...R......#", "...R.......#"), "7 rows of 11 cells"),
    (lambda t: t.replace("...R......#", "..........#"), "0 robot"),
    (lambda t: t.replace("Total discounted reward", "Total reward"), "no 'Total discounted reward'"),
])
def test_despot_lasertag_printout_that_is_not_one_is_refused_naming_the_round(online_bench, edit, message):
    with pytest.raises(ValueError, match="round 0") as err:
        online_bench.parse_despot_lasertag_rounds(edit(DESPOT_LASERTAG_ROUND))
    assert message in str(err.value)


def test_paired_lasertag_replays_each_peer_run_on_its_map_from_its_start(online_bench, tmp_path):
    """The peer here is a script that prints the round above whatever its seed (DESPOT's code is not
    built in the suite); ours plays that map from that start, and the difference pairs them."""
    peer = tmp_path / "laser_tag"
    (tmp_path / "round.txt").write_text(DESPOT_LASERTAG_ROUND)
    peer.write_text(f"#!/bin/sh\ncat {tmp_path / 'round.txt'}\n")
    peer.chmod(0o755)
    out = online_bench.run_lasertag_paired(str(peer), budget=0.01, runs=2, steps=3, seed=0, max_minutes=5)
    assert out["despot"]["returns"] == [-9.78315, -9.78315]
    assert out["despot"]["starts"][0]["robot"] == (3, 4)
    from pearl_pomdp.online.lasertag import LaserTag

    model = LaserTag(out["despot"]["starts"][0]["obstacles"])
    assert out["ours"]["start_states"] == [model.index[(3, 4)] * model.n + model.index[(9, 5)]] * 2
    ours = out["ours"]["returns"]
    assert len(ours) == 2 and all(-3.0 <= r <= 10.0 for r in ours)   # 3 steps: −1 a move, ±10 a tag
    assert out["paired_difference"]["n"] == 2
    assert out["paired_difference"]["mean"] == pytest.approx(float(np.mean(ours)) + 9.78315)


#: The start of a round of DESPOT's rock_sample for RockSample(7,8) (its standard layout, seed 4), as
#: `despot_rock_sample --size 7 --number 8 -t 0.01 -s 3 --runs 1 -r 4` printed it, and its end.
DESPOT_ROCKSAMPLE_ROUND = """\
####################################### Round 0 #######################################
Initial state: 

# # # # # # # # # 
# . 7X. . . . . #
# . . . . . 6X. #
# . . 4$5X. . . #
# R . . . . . 3$#
# . . . . . . . #
# 1$. . 2X. . . #
# . . 0X. . . . #
# # # # # # # # # 

-----------------------------------Round 0 Step 0-----------------------------------
- Action = Check 4
Simulation terminated in 3 steps
Total discounted reward = 0
Total undiscounted reward = 0
"""


def test_despot_rocksample_printout_gives_its_layout_start_and_return(online_bench):
    (got,) = online_bench.parse_despot_rocksample_rounds(DESPOT_ROCKSAMPLE_ROUND, 7, 8)
    from pearl_pomdp.online.rocksample import LAYOUTS

    # The printout's top row is y = 6 (BaseRockSample::PrintState): DESPOT's layout is the standard one.
    assert got["rocks"] == LAYOUTS["7_8"][2] and got["rover"] == LAYOUTS["7_8"][1] == (0, 3)
    assert got["good"] == [False, True, False, True, True, False, False, False]
    assert got["return"] == 0.0
    # Rock numbers of two digits take three characters: RockSample(11,11)'s rock 10 at (9, 9) (its
    # start as `despot_rock_sample --size 11 --number 11 ... -r 3` printed it).
    eleven = """\
# # # # # # # # # # # # # 
# . . . . . . . . . . . #
# . . . . . . . . . 10X. #
# . 2X. 5$. 7X. . . . . #
# 1X. . . . . . . . . . #
# . . . . . . . . . . . #
# R . . . . . . . . . . #
# . . 3$. . . . . . . . #
# 0$. . 4X6$. . . . 9$. #
# . . . . . . . . . . . #
# . . . . . . 8X. . . . #
# . . . . . . . . . . . #
# # # # # # # # # # # # # 
"""
    (big,) = online_bench.parse_despot_rocksample_rounds(f"Initial state:\n\n{eleven}\nTotal discounted reward = 8.14506\n",
                                                          11, 11)
    assert big["rocks"] == LAYOUTS["11_11"][2] and big["rocks"][10] == (9, 9) and big["rover"] == (0, 5)


@pytest.mark.parametrize("edit, message", [
    (lambda t: t.replace("# R . . . . . 3$#", "# R . . . . 3$#"), "7 rows of 7 cells"),
    (lambda t: t.replace("# R . . . . . 3$#", "# . . . . . . 3$#"), "0 rover"),
    (lambda t: t.replace("# 1$. . 2X. . . #", "# . . . 2X. . . #"), "rocks [0, 2, 3, 4, 5, 6, 7]"),
    (lambda t: t.replace("Total discounted reward", "Total reward"), "no 'Total discounted reward'"),
])
def test_despot_rocksample_printout_that_is_not_one_is_refused_naming_the_round(online_bench, edit, message):
    with pytest.raises(ValueError, match="round 0") as err:
        online_bench.parse_despot_rocksample_rounds(edit(DESPOT_ROCKSAMPLE_ROUND), 7, 8)
    assert message in str(err.value)


def test_a_peer_run_with_a_rock_under_the_rover_is_left_out_and_the_next_seed_taken(online_bench, tmp_path):
    """DESPOT's random layouts (RockSample(15,15)) can put a rock under the rover's start, which its
    printout hides: the parser says which rock and where, and the pairing leaves that run out of both
    sides, names it, and runs the next seed in its place."""
    hidden = DESPOT_ROCKSAMPLE_ROUND.replace("# R . . . . . 3$#", "# R . . . . . . #")
    with pytest.raises(online_bench.UnreplayableRound, match="round 0") as err:
        online_bench.parse_despot_rocksample_rounds(hidden, 7, 8)
    assert "rock 3 is under the rover at (0, 3)" in str(err.value)
    peer = tmp_path / "rock_sample"
    (tmp_path / "hidden.txt").write_text(hidden)
    (tmp_path / "round.txt").write_text(DESPOT_ROCKSAMPLE_ROUND)
    # Seed 1 draws the hidden start, every other seed the whole one.
    peer.write_text(f"#!/bin/sh\necho \"$@\" >> {tmp_path / 'args.txt'}\n"
                    f"case \"$*\" in *'-r 1') cat {tmp_path / 'hidden.txt'};; *) cat {tmp_path / 'round.txt'};; esac\n")
    peer.chmod(0o755)
    out = online_bench.run_rocksample_paired(str(peer), "rs7_8", budget=0.01, runs=2, steps=2, seed=0, max_minutes=5)
    assert [line.rsplit(" ", 1)[1] for line in (tmp_path / "args.txt").read_text().splitlines()] == ["1", "2", "3"]
    assert out["despot"]["runs"] == 2 and out["paired_difference"]["n"] == 2
    (skip,) = out["despot"]["skipped"]
    assert skip["command"].endswith("-r 1") and "rock 3 is under the rover" in skip["why"]
    assert [c.rsplit(" ", 1)[1] for c in out["despot"]["commands"]] == ["2", "3"]


def test_paired_rocksample_replays_each_peer_run_from_its_start(online_bench, tmp_path):
    """As the LaserTag pairing: a script prints the round above whatever its arguments; ours plays
    RockSample(7,8) from that start (rover at (0, 3), rocks 1, 3 and 4 good)."""
    peer = tmp_path / "rock_sample"
    (tmp_path / "round.txt").write_text(DESPOT_ROCKSAMPLE_ROUND)
    peer.write_text(f"#!/bin/sh\necho \"$@\" >> {tmp_path / 'args.txt'}\ncat {tmp_path / 'round.txt'}\n")
    peer.chmod(0o755)
    out = online_bench.run_rocksample_paired(str(peer), "rs7_8", budget=0.01, runs=2, steps=3, seed=0, max_minutes=5)
    assert (tmp_path / "args.txt").read_text().splitlines() == [
        "--size 7 --number 8 -t 0.01 -s 3 --runs 1 -r 1", "--size 7 --number 8 -t 0.01 -s 3 --runs 1 -r 2"]
    assert out["despot"]["returns"] == [0.0, 0.0]
    from pearl_pomdp.online.rocksample import rocksample

    model = rocksample("7_8")
    good = 0b00011010   # rocks 1, 3 and 4
    assert out["ours"]["start_states"] == [model.encode(0, 3, good)] * 2
    ours = out["ours"]["returns"]
    assert len(ours) == 2 and all(-30.0 <= r <= 10.0 for r in ours)   # 3 steps: ±10 a sample, +10 the exit
    assert out["paired_difference"]["n"] == 2
    assert out["paired_difference"]["mean"] == pytest.approx(float(np.mean(ours)))


def test_regularization_reaches_the_search_and_the_report(online_bench, monkeypatch, capsys):
    seen = []
    real = online_bench.Despot

    def recording(model, bounds, settings):
        seen.append(settings.regularization)
        return real(model, bounds, settings)

    monkeypatch.setattr(online_bench, "Despot", recording)
    online_bench.main(["--problems", "lasertag", "--budgets", "0.01", "--episodes", "1", "--steps", "2",
                       "--clock", "process", "--regularization", "0.01"])
    out = json.loads(capsys.readouterr().out)
    assert seen and set(seen) == {0.01}
    assert out["settings"]["regularization"] == 0.01
