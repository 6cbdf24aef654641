"""Start-up cost: commands import the heavy libraries only when they need them (issue 15)."""
import subprocess
import sys

import pytest


def _loaded_after(argv, modules):
    """Which of ``modules`` are imported after ``pearl ARGV`` ran in a fresh interpreter (sorted)."""
    code = ("import contextlib, io, sys\n"
            "from pearl_pomdp.cli import main\n"
            "with contextlib.redirect_stdout(io.StringIO()):\n"
            "    try:\n"
            f"        main({list(argv)!r})\n"
            "    except SystemExit as stop:\n"   # --help exits 0; any other exit is a failure
            "        if stop.code:\n"
            "            raise\n"
            f"print(sorted(m for m in {tuple(modules)!r} if m in sys.modules))\n")
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.strip()


def test_help_imports_no_numpy():
    """`pearl --help` imports every command module: none may import numpy/scipy/tqdm/matplotlib/rclpy at top."""
    assert _loaded_after(["--help"], ("numpy", "scipy", "tqdm", "matplotlib", "rclpy")) == "[]"


def test_solving_tiger_needs_no_lp_solver(benchmarks_dir):
    """The pruning LPs are the C kernel's own: neither HiGHS nor scipy.optimize loads."""
    argv = ["solve", str(benchmarks_dir / "tiger.95.POMDP"), "--method", "incprune", "--horizon", "15", "--json",
            "--quiet"]
    assert _loaded_after(argv, ("scipy.optimize", "highspy", "matplotlib", "rclpy")) == "[]"


def test_solving_a_small_pomdp_file_imports_no_scipy_and_reads_no_entry_points(benchmarks_dir):
    """`pearl solve` on a small .POMDP file: T is read dense (no scipy.sparse), and the command's
    parser is built from its own module alone (no importlib.metadata scan of installed packages)."""
    argv = ["solve", str(benchmarks_dir / "network.POMDP"), "--method", "incprune", "--horizon", "3", "--json",
            "--quiet"]
    assert _loaded_after(argv, ("scipy", "importlib.metadata", "pearl_pomdp.cli.launch")) == "[]"


@pytest.mark.parametrize("name", ["tiger.95.POMDP", "cheese.95.POMDP", "4x3.95.POMDP"])
def test_point_based_on_a_small_pomdp_file_imports_no_scipy(benchmarks_dir, name):
    """The point-based solver builds its CSR arrays of T, FIB, sweeps and Perseus without scipy on
    small dense models: importing scipy.sparse costs more than solving them (issue 15)."""
    argv = ["solve", str(benchmarks_dir / name), "--method", "pointbased", "--json", "--quiet"]
    assert _loaded_after(argv, ("scipy",)) == "[]"


def test_dense_and_sparse_storage_give_the_same_fingerprint(benchmarks_dir):
    """The fingerprint of a dense T is computed without scipy; it must equal the CSR one."""
    from pearl_pomdp.model import Pomdp, load_model

    m = load_model(benchmarks_dir / "cheese.95.POMDP")
    assert not m.is_sparse
    sparse = Pomdp.create(m.states, m.actions, m.observations, list(m.T_dense()), m.O, m.R,
                          b0=m.b0, discount=m.discount, name=m.name, sparse=True)
    assert sparse.is_sparse
    assert sparse.fingerprint() == m.fingerprint()
