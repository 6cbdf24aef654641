"""bench/online.py's pooling of runs over disjoint episodes (``--first-episode``, ``--combine``):
the pooled mean and CI equal those of one run over all the episodes."""
import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest

BENCH = Path(__file__).resolve().parents[1] / "bench" / "online.py"


@pytest.fixture(scope="module")
def online_bench():
    spec = importlib.util.spec_from_file_location("bench_online", BENCH)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


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
