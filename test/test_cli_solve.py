"""`pearl solve` and `pearl simulate` run in-process, checked against published numbers."""
import json

import pytest

from pearl_pomdp.cli import main

# pomdp-solve 5.5.2 on tiger.95 (run on this machine; AI-Toolbox's unit test expects the same).
TIGER_H15_VECTORS = [3, 5, 9, 7, 13, 15, 19, 25, 27, 27, 37, 35, 39, 47, 47]
TIGER_H15_VALUE = 9.72842474467767
TIGER_INF_VALUE = 19.3713683743952


def run_json(capsys, *argv):
    code = main(list(argv) + ["--json", "--quiet"])
    out, err = capsys.readouterr()
    assert code == 0, err
    lines = out.strip().splitlines()
    assert len(lines) == 1, out  # exactly one JSON object
    return json.loads(lines[0])


def run_error(capsys, *argv):
    code = main(list(argv))
    out, err = capsys.readouterr()
    assert code == 2
    assert "Traceback" not in err
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    return lines[0]


def test_incprune_tiger_horizon_15(capsys, benchmarks_dir):
    r = run_json(capsys, "solve", str(benchmarks_dir / "tiger.95.POMDP"), "--method", "incprune", "--horizon", "15")
    assert (r["states"], r["actions"], r["observations"]) == (2, 3, 2)
    assert r["method"] == "incprune" and r["iterations"] == 15
    assert r["vectors_per_epoch"] == TIGER_H15_VECTORS
    assert r["alpha_vectors"] == 47
    assert r["value_at_start"] == pytest.approx(TIGER_H15_VALUE, abs=1e-9)
    assert r["upper_bound"] is None
    assert r["seconds"] >= 0


def test_default_method_is_incprune_for_tiger(capsys, benchmarks_dir):
    r = run_json(capsys, "solve", str(benchmarks_dir / "tiger.95.POMDP"), "--horizon", "10")
    assert r["method"] == "incprune" and r["alpha_vectors"] == 27
    assert r["value_at_start"] == pytest.approx(6.69336843175073, abs=1e-9)


def test_qmdp_tiger_value(capsys, benchmarks_dir):
    r = run_json(capsys, "solve", str(benchmarks_dir / "tiger.95.POMDP"), "--method", "qmdp")
    # Fully observed, the best is to open the tiger-free door every step: V = 10 / (1 − .95) = 200.
    # Q(s, listen) = −1 + .95·200 = 189; Q(s, open) averages +10 and −100 at the uniform
    # belief: .5·(10 + 190) + .5·(−100 + 190) = 145. QMDP at b0 = max(189, 145) = 189.
    assert r["method"] == "qmdp" and r["alpha_vectors"] == 3
    assert r["value_at_start"] == pytest.approx(189.0, abs=1e-3)


def test_human_output(capsys, benchmarks_dir):
    assert main(["solve", str(benchmarks_dir / "tiger.95.POMDP"), "--horizon", "15", "--quiet"]) == 0
    out = capsys.readouterr().out
    assert "2 states, 3 actions, 2 observations (γ = 0.95)" in out
    assert "47 α-vectors after 15 epochs" in out
    assert "V(b0) = 9.728424745" in out
    assert "vectors per epoch: " + " ".join(map(str, TIGER_H15_VECTORS)) in out


def test_json_says_why_incprune_stopped_and_its_last_residual(capsys, benchmarks_dir):
    tiger = str(benchmarks_dir / "tiger.95.POMDP")
    r = run_json(capsys, "solve", tiger, "--method", "incprune")
    assert r["stop_reason"] == "converged" and r["converged"] and r["iterations"] == 477
    assert r["value_at_start"] == pytest.approx(TIGER_INF_VALUE, abs=1e-9)
    # pomdp-solve's threshold ε(1−γ)/(2γ) with ε = 1e-9: the residual got under it
    assert 0 < r["last_residual"] <= 1e-9 * 0.05 / 1.9 and r["cycle_period"] is None
    r = run_json(capsys, "solve", tiger, "--method", "incprune", "--horizon", "3")
    assert r["stop_reason"] == "horizon" and r["converged"]
    from pearl_pomdp.model import load_model
    from pearl_pomdp.solvers.incremental_pruning import solve_incremental_pruning

    api = solve_incremental_pruning(load_model(tiger), horizon=3)
    assert r["last_residual"] == api.extra["last_residual"] > 1.0  # max_b |V_3(b) − V_2(b)|
    r = run_json(capsys, "solve", tiger, "--method", "incprune", "--time-limit", "0.02")
    assert r["stop_reason"] == "time_limit" and not r["converged"] and r["last_residual"] > 1e-9
    assert run_json(capsys, "solve", tiger, "--method", "qmdp")["stop_reason"] == "converged"


def test_human_output_says_why_it_stopped(capsys, benchmarks_dir):
    assert main(["solve", str(benchmarks_dir / "tiger.95.POMDP"), "--method", "incprune", "--quiet"]) == 0
    out = capsys.readouterr().out
    assert "9 α-vectors after 477 epochs" in out and "(converged)" in out
    assert "last residual 2.61e-11" in out


def test_pointbased_save_then_simulate(capsys, tmp_path, benchmarks_dir):
    model = str(benchmarks_dir / "tiger.95.POMDP")
    policy = tmp_path / "tiger.npz"
    r = run_json(capsys, "solve", model, "--method", "pointbased", "--time-limit", "20", "--out", str(policy))
    # SARSOP's bounds [19.3711, 19.3721] bracket the exact 19.3713684 (pomdp-solve, converged).
    assert r["method"] == "pointbased"
    assert TIGER_INF_VALUE - 1e-2 <= r["value_at_start"] <= TIGER_INF_VALUE + 1e-6
    assert r["upper_bound"] >= TIGER_INF_VALUE - 1e-6
    assert r["upper_bound"] - r["value_at_start"] <= 1e-2
    header = json.loads((tmp_path / "tiger.json").read_text())
    assert header["method"] == "pointbased" and header["value_at_start"] == r["value_at_start"]
    assert header["upper_bound"] == r["upper_bound"] and header["num_vectors"] == r["alpha_vectors"]

    s = run_json(capsys, "simulate", model, str(policy), "--episodes", "3000", "--seed", "0")
    assert s["episodes"] == 3000 and s["steps"] == 135
    # The simulated mean of the (near-)optimal policy brackets its computed value.
    assert abs(s["mean"] - TIGER_INF_VALUE) < 2 * s["ci95"], s
    assert 0 < s["ci95"] < 2.5
    again = run_json(capsys, "simulate", model, str(policy), "--episodes", "3000", "--seed", "0")
    assert again["mean"] == s["mean"]


def test_simulate_rejects_policy_of_other_model(capsys, tmp_path, benchmarks_dir):
    policy = tmp_path / "tiger.npz"
    run_json(capsys, "solve", str(benchmarks_dir / "tiger.95.POMDP"), "--horizon", "3", "--out", str(policy))
    line = run_error(capsys, "simulate", str(benchmarks_dir / "tiger.aaai.POMDP"), str(policy))
    assert line.startswith(f"pearl simulate: error: {policy}: policy was solved for model ")
    assert "this model is" in line


def test_missing_model_file(capsys, tmp_path):
    missing = tmp_path / "nope.pomdp"
    line = run_error(capsys, "solve", str(missing), "--json")
    assert line.startswith("pearl solve: error:") and str(missing) in line


def test_bad_model_line(capsys, tmp_path):
    bad = tmp_path / "bad.pomdp"
    bad.write_text("discount: 0.95\nvalues: reward\nstates: a b\nactions: x\nobservations: o\n"
                   "T: x : a : c 1.0\n")
    line = run_error(capsys, "solve", str(bad))
    assert line.startswith(f"pearl solve: error: {bad}:6")


def test_horizon_only_for_incprune(capsys, benchmarks_dir):
    line = run_error(capsys, "solve", str(benchmarks_dir / "tiger.95.POMDP"), "--method", "qmdp", "--horizon", "5")
    assert line == "pearl solve: error: --horizon applies to incprune only, not to qmdp"


def test_trial_budget_pointbased(capsys, benchmarks_dir):
    first = run_json(capsys, "solve", str(benchmarks_dir / "tiger.95.POMDP"), "--method", "pointbased", "--trials", "3",
                     "--epsilon", "1e-12")
    again = run_json(capsys, "solve", str(benchmarks_dir / "tiger.95.POMDP"), "--method", "pointbased", "--trials", "3",
                     "--epsilon", "1e-12")
    assert first["iterations"] == 3 and not first["converged"] and first["stop_reason"] == "trials"
    assert (first["value_at_start"], first["upper_bound"]) == (again["value_at_start"], again["upper_bound"])


def test_trials_only_for_pointbased(capsys, benchmarks_dir):
    line = run_error(capsys, "solve", str(benchmarks_dir / "tiger.95.POMDP"), "--method", "incprune", "--trials", "5")
    assert line == "pearl solve: error: --trials applies to pointbased only, not to incprune"
