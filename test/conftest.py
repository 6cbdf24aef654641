"""Shared fixtures: where the benchmark models live (``test/data/pomdp``, in the repository)."""
import lzma
import os
import shutil
import tempfile
from pathlib import Path

import pytest

# One BLAS/OpenMP thread per process, for this process and every process a test starts (they
# inherit the environment). The ROS tests run three or four processes on this machine's two
# cores; with a thread per core in each, OpenBLAS's spinning workers fight over the cores: the
# ward launch test's start-up (four processes compiling 233,280 states and solving bounds) took
# 25 s against 12 s single-threaded. Set before any test module imports numpy; a caller's
# setting is kept.
for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")
# Node journals (journal:=auto, under $ROS_HOME) go to a folder of this session, never ~/.ros:
# no test resumes from another run's journal (test/ros_helpers.py gives each ROS test its own).
_ROS_HOME = os.environ["ROS_HOME"] = tempfile.mkdtemp(prefix="pearl-test-ros-home-")

REPO = Path(__file__).resolve().parents[1]
#: The benchmark .pomdp files with their provenance (test/data/pomdp/README.md).
MODELS = REPO / "test" / "data" / "pomdp"


def unpacked_models(target: Path) -> Path:
    """``target`` holding every model of :data:`MODELS` as a plain file: the plain ones linked,
    the ``.xz`` ones (too large to keep as text) decompressed. Returns ``target``."""
    target.mkdir(parents=True, exist_ok=True)
    for path in sorted(MODELS.iterdir()):
        if path.suffix == ".xz":
            out = target / path.stem
            with lzma.open(path) as src, open(out, "wb") as dst:
                shutil.copyfileobj(src, dst)
        elif path.suffix.lower() == ".pomdp":
            (target / path.name).symlink_to(path)
    return target


@pytest.fixture(scope="session")
def benchmarks_dir(tmp_path_factory) -> Path:
    """A folder with the benchmark models of ``test/data/pomdp`` as plain ``.pomdp`` files."""
    return unpacked_models(tmp_path_factory.mktemp("pomdp"))


@pytest.fixture(scope="session")
def ward_domain():
    """``config/ward.domain.yaml`` loaded once for the session. Its ``compile()`` is cached on it, so the
    tests that need the flat ward (233,280 states: ~2 s CPU and ~0.5 GB to compile) share one compilation.
    Nothing may change it: the tests read the model and build their own objects from it."""
    from pearl_pomdp.model.domain_yaml import load_domain

    return load_domain(Path(__file__).resolve().parents[1] / "config" / "ward.domain.yaml")


@pytest.fixture(scope="session")
def load_bench():
    """``load_bench("online")``: the script ``bench/online.py`` as a module (``bench/`` is no package)."""
    import importlib.util

    def load(name: str):
        path = Path(__file__).resolve().parents[1] / "bench" / f"{name}.py"
        spec = importlib.util.spec_from_file_location(f"bench_{name}", path)
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        return module

    return load


# ROS fixtures (ros_context, pearl_policy) live in test/ros_helpers.py; registered here once so
# the session-scoped planned Pearl policy is shared by every test module.
from ros_helpers import day_policy, domain_leases, pearl_policy, ros_context  # noqa: E402,F401


@pytest.fixture(autouse=True, scope="module")
def _module_domain_leases():
    """The ROS domain ids a module's fixtures leased go back when the module ends (ros_helpers)."""
    with domain_leases():
        yield


@pytest.fixture(autouse=True)
def _test_domain_leases():
    """The ROS domain ids a test (and its function fixtures) leased go back when it ends."""
    with domain_leases():
        yield


# ------------------------------------------------------------------ both cores (pytest-xdist)
#: At most this many worker processes by default: each may compile the ward (~0.5 GB) and run a
#: ROS graph of four processes, so more than four buys little even on a bigger machine.
MAX_WORKERS = 4


def _is_worker(config) -> bool:
    return hasattr(config, "workerinput")


@pytest.hookimpl(tryfirst=True)
def pytest_cmdline_main(config):
    """`pytest -q` runs on every core (up to MAX_WORKERS) when pytest-xdist is installed (the test
    extra installs it), a test file per worker at a time (--dist loadfile). An explicit ``-n`` /
    ``--dist`` / ``-p no:xdist`` wins; without xdist the run is sequential, as before.

    Why by file: a module's fixtures (a ROS graph, a planned policy, the ward's two launches) are
    built once per worker that runs one of its tests; split over workers, a module builds them twice
    and the ward launch test would run two ward graphs at once (each compiles the
    233,280-state ward in three processes). (Finer groups, --dist
    loadgroup, are no option: pytest-xdist 3.8 cannot group under pytest >= 9.2, its
    issue #1386, and then silently hands out the tests one by one.)"""
    if not config.pluginmanager.hasplugin("xdist") or _is_worker(config):
        return
    option = config.option
    if option.numprocesses is None and not option.tx and option.dist == "no" and not option.usepdb:
        workers = min(len(os.sched_getaffinity(0)), MAX_WORKERS)
        option.numprocesses = workers if workers > 1 else 0
        if workers > 1:
            option.dist = "loadfile"
            # Hand out the files in collection order, which pytest_collection_modifyitems puts the
            # slow ones first in (xdist's default orders them by their number of tests, so a
            # one-test file that takes 90 s could start last and run alone at the end).
            option.loadscopereorder = False


#: Files whose tests share no module- or class-scoped fixture (each test builds what it needs; the
#: planned Pearl policy is the session's, planned once for all workers): under pytest-xdist their
#: tests are handed out one at a time, so both workers take part. As one unit, the help examples
#: (~140 s of independent commands on an idle machine) were the suite's largest indivisible piece of
#: work; split, a loaded run gave one worker 125 s of them and the other 113 s.
SPLIT_FILES = frozenset({"test/test_cli_help_examples.py"})


@pytest.hookimpl(optionalhook=True, tryfirst=True)
def pytest_xdist_make_scheduler(config, log):
    """--dist loadfile (what :func:`pytest_cmdline_main` chooses), with each test of
    :data:`SPLIT_FILES` a unit of its own."""
    if config.getvalue("dist") != "loadfile":
        return None
    from xdist.scheduler import LoadFileScheduling

    class FileOrTestScheduling(LoadFileScheduling):
        def _split_scope(self, nodeid: str) -> str:
            path = nodeid.split("::", 1)[0]
            return nodeid if path in SPLIT_FILES else path

    return FileOrTestScheduling(config, log)


def pytest_collection_modifyitems(session, config, items):
    """The files with a ``slow`` test first, the rest after, each group in its collection order: with
    a file per worker at a time, the longest work starts first and the short files fill in around
    it (longest-first packing). The same order on every worker, as xdist requires."""
    slow_files = {item.path for item in items if item.get_closest_marker("slow") is not None}
    items[:] = sorted(items, key=lambda item: item.path not in slow_files)


def pytest_sessionfinish(session, exitstatus):
    """Leave no Fast DDS shared memory behind: the tests stop node processes by signal, and each such
    stop leaves its participant's segment in /dev/shm (pearl_pomdp.shared_memory; ~150 MB a run).
    Under xdist only the controller cleans, once every worker has ended: a worker that finished
    early must not clean while another still runs a test that counts the segments."""
    if _is_worker(session.config):
        return
    from pearl_pomdp.shared_memory import remove_dead_files

    remove_dead_files()
    shutil.rmtree(_ROS_HOME, ignore_errors=True)
