"""The suite on every core: `pytest -q` starts pytest-xdist workers (test/conftest.py), and the ROS
domain ids of test processes running side by side never meet (test/ros_helpers.py's leases)."""
from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import pytest

import ros_helpers
from ros_helpers import REPO, allocate_domain_id, domain_leases

#: A process that leases ``N`` domain ids in folder ``DIR``, prints them, then holds them until its
#: stdin closes (argv: the test folder, DIR, N).
HOLDER = textwrap.dedent("""
    import sys
    from pathlib import Path
    sys.path.insert(0, sys.argv[1])
    import ros_helpers
    ros_helpers.LEASE_DIR = Path(sys.argv[2])
    print(" ".join(str(ros_helpers.allocate_domain_id()) for _ in range(int(sys.argv[3]))), flush=True)
    sys.stdin.read()
""")


@pytest.fixture
def lease_dir(tmp_path, monkeypatch):
    """The leases of this test and its holders in a folder of their own: the other test processes'
    leases (another worker's, another run's) do not change the counts."""
    monkeypatch.setattr(ros_helpers, "LEASE_DIR", tmp_path / "leases")
    return tmp_path / "leases"


def _holder(lease_dir, count: int) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-c", HOLDER, str(REPO / "test"), str(lease_dir), str(count)],
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
                            env={**os.environ, "PYTEST_XDIST_WORKER": "gw0", "PYTEST_XDIST_WORKER_COUNT": "2"})


def test_an_id_another_process_holds_is_never_handed_out_and_is_free_once_it_ends(lease_dir):
    holder = _holder(lease_dir, 90)          # most of the 101 ids: this process must find the other eleven
    try:
        held = {int(n) for n in holder.stdout.readline().split()}
        assert len(held) == 90 and held <= set(range(1, ros_helpers.DOMAIN_IDS + 1))
        with domain_leases():
            mine = [allocate_domain_id() for _ in range(ros_helpers.DOMAIN_IDS - 90)]
            assert not set(mine) & held and len(set(mine)) == len(mine)
    finally:
        holder.stdin.close()
        holder.wait(10)
    with domain_leases():   # the holder ended: the kernel dropped its locks, every id is free again
        assert len({allocate_domain_id() for _ in range(ros_helpers.DOMAIN_IDS)}) == ros_helpers.DOMAIN_IDS


def test_leaving_the_scope_gives_the_ids_back(lease_dir):
    with domain_leases():
        inner = allocate_domain_id()
        assert ros_helpers._leases[-1][0] == inner
        other = _holder(lease_dir, ros_helpers.DOMAIN_IDS - 1)      # every id it can get: all but ours
        try:
            assert inner not in {int(n) for n in other.stdout.readline().split()}
        finally:
            other.stdin.close()
            other.wait(10)
    assert inner not in [domain_id for domain_id, _ in ros_helpers._leases]
    taker = _holder(lease_dir, ros_helpers.DOMAIN_IDS)
    try:
        assert inner in {int(n) for n in taker.stdout.readline().split()}
    finally:
        taker.stdin.close()
        taker.wait(10)


def test_workers_start_their_search_in_their_own_share_of_the_range(lease_dir, monkeypatch):
    firsts = []
    for worker in ("gw0", "gw1"):
        monkeypatch.setenv("PYTEST_XDIST_WORKER", worker)
        monkeypatch.setenv("PYTEST_XDIST_WORKER_COUNT", "2")
        with domain_leases():
            firsts.append(allocate_domain_id())
    share = ros_helpers.DOMAIN_IDS // 2
    assert 1 <= firsts[0] <= share < firsts[1] <= ros_helpers.DOMAIN_IDS


@pytest.mark.skipif(len(os.sched_getaffinity(0)) < 2, reason="one core: the suite runs sequentially")
def test_the_readme_command_runs_on_every_core_and_p_no_xdist_runs_in_one_process():
    pytest.importorskip("xdist")
    target = "test/test_parallel_suite.py::test_workers_start_their_search_in_their_own_share_of_the_range"
    env = {k: v for k, v in os.environ.items() if not k.startswith("PYTEST_")}
    workers = min(len(os.sched_getaffinity(0)), 4)

    def run(*extra):
        done = subprocess.run([sys.executable, "-m", "pytest", "-v", "-p", "no:cacheprovider", *extra, target],
                              cwd=REPO, env=env, capture_output=True, text=True, timeout=120)
        assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]
        return done.stdout

    parallel = run()
    # xdist's report: "N workers [1 item]", and the test's line names the worker that ran it.
    assert f"{workers} workers [1 item]" in parallel and "] [100%] PASSED" in parallel, parallel
    sequential = run("-p", "no:xdist")
    assert "workers [" not in sequential and "[gw" not in sequential and "PASSED" in sequential, sequential


def test_the_help_examples_are_handed_out_one_by_one_and_every_other_file_whole():
    """conftest's scheduler: the tests of SPLIT_FILES are units of their own (both workers run the help
    examples), every other file stays one unit (its module fixtures are built once); only for
    --dist loadfile."""
    pytest.importorskip("xdist")
    from types import SimpleNamespace

    import conftest

    loadfile = SimpleNamespace(getvalue=lambda name: {"dist": "loadfile", "tx": ["2*popen"]}[name])
    scheduler = conftest.pytest_xdist_make_scheduler(config=loadfile, log=None)
    plan, demo = (f"test/test_cli_help_examples.py::test_help_examples_run_as_written[{c}]" for c in ("plan", "demo"))
    assert "test/test_cli_help_examples.py" in conftest.SPLIT_FILES
    assert scheduler._split_scope(plan) == plan and scheduler._split_scope(demo) == demo
    ward = ["test/test_ward_launch.py::test_the_launch_stops_cleanly[online:5]",
            "test/test_ward_launch.py::test_the_ward_plans_online_through_the_nodes_as_the_core_does[hierarchical]"]
    assert {scheduler._split_scope(nodeid) for nodeid in ward} == {"test/test_ward_launch.py"}
    load = SimpleNamespace(getvalue=lambda name: {"dist": "load", "tx": ["2*popen"]}[name])
    assert conftest.pytest_xdist_make_scheduler(config=load, log=None) is None
