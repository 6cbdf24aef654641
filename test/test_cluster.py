"""`pearl experiment --cluster`: the cells on a Dask cluster give the episodes of --jobs, bit for bit.

The test starts its own local cluster (two worker processes on this machine, loopback only)."""
import json
import time

import pytest

from pearl_sim.nursing_home import study
from pearl_sim.cluster import ClusterError, run_on_cluster
from pearl_sim.nursing_home.experiment import build_agents
from pearl_sim.nursing_home.residents import paper_residents, resident_scenarios, study_template
from pearl_sim.nursing_home.scenario import default_domain

distributed = pytest.importorskip("distributed")  # installed by the test extra; absent only by hand

STUDY = "config/scenarios/study.yaml"
CHANNELS = {"white": "config/speech/pearl_channel.json", "babble": "config/speech/pearl_channel_babble.json"}


@pytest.fixture(scope="module")
def cluster():
    from distributed import LocalCluster

    # No dashboard, and the scheduler's HTTP server on a free port: by default it takes 8787, which a
    # parallel test process (or the user's own cluster) may hold.
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None,
                      host="127.0.0.1", scheduler_kwargs={"dashboard_address": "127.0.0.1:0"}) as local:
        yield local.scheduler_address


@pytest.mark.slow
def test_cluster_gives_the_episodes_of_jobs_2_on_the_kind_snr_axis(cluster):
    """A small (kind, SNR) grid: 2 cases x 2 kinds x 2 SNRs x 1 seed x 2 policies = 16 episodes."""
    domain = default_domain()
    agents = build_agents(domain, None, policies=["behaviour_tree", "qmdp"])
    cases = resident_scenarios(study_template(STUDY), paper_residents(STUDY)[4:6])[:2]
    grid = study.cells(len(cases), [30.0, 10.0], 1, kinds=("white", "babble"))
    local = study.run_cells(domain, agents, cases, grid, jobs=2, channels=CHANNELS)
    remote = study.run_cells(domain, agents, cases, grid, channels=CHANNELS, cluster=cluster)
    assert len(local) == len(remote) == 16
    # (repr: the SNR axis has no word error rate, NaN, which is never == itself)
    assert [repr(e.row()) for e in remote] == [repr(e.row()) for e in local]
    assert [e.result.actions for e in remote] == [e.result.actions for e in local]
    assert {e.level for e in local} == {"white:30", "white:10", "babble:30", "babble:10"}
    # The two kinds are heard through different channels: the same worlds, different speech.
    by = {(e.policy, e.resident, e.task, e.level): e.result.actions for e in local}
    assert any(by[(p, r, t, "white:10")] != by[(p, r, t, "babble:10")] for (p, r, t, lv) in by if lv == "white:10")


def test_an_address_that_does_not_answer_is_one_clear_error():
    t0 = time.perf_counter()
    with pytest.raises(ClusterError, match=r"--cluster tcp://127\.0\.0\.1:9: no Dask scheduler answered within 1 s"):
        run_on_cluster("tcp://127.0.0.1:9", {}, [], timeout=1.0)
    assert time.perf_counter() - t0 < 15


@pytest.mark.slow
def test_experiment_cli_on_the_cluster_and_its_error(cluster, tmp_path, capsys):
    from pearl_pomdp.cli import main

    argv = ["experiment", "--policies", "behaviour_tree", "--residents", "generated:1", "--episodes", "1",
            "--snr", "10", "--noise-kind", "white,babble", "--json"]
    assert main(argv + ["--cluster", cluster, "--out", str(tmp_path / "c")]) == 0
    on_cluster = json.loads(capsys.readouterr().out)
    assert main(argv + ["--jobs", "2", "--out", str(tmp_path / "j")]) == 0
    with_jobs = json.loads(capsys.readouterr().out)
    assert on_cluster["episodes"] == with_jobs["episodes"] and len(with_jobs["episodes"]) == 6
    assert set(with_jobs["per_policy"]["behaviour_tree"]) == {"white:10", "babble:10"}
    assert set(with_jobs["acceptance"]) == {"white", "babble"}
    assert (tmp_path / "j" / "study-white.png").exists() and (tmp_path / "j" / "study-babble.png").exists()
    assert main(["experiment", "--snr", "10", "--cluster", "tcp://127.0.0.1:9", "--cluster-timeout", "1",
                 "--out", str(tmp_path / "x")]) == 2
    assert "--cluster tcp://127.0.0.1:9: no Dask scheduler answered within 1 s" in capsys.readouterr().err
