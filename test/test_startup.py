"""Start-up cost: commands import the heavy libraries only when they need them (issue 15)."""
import subprocess
import sys

import pytest


def test_help_imports_no_numpy():
    """`pearl --help` imports every command module: none may import numpy/scipy/tqdm/matplotlib/rclpy at top."""
    code = ("import contextlib, io, sys\n"
            "from pearl_pomdp.cli import main\n"
            "with contextlib.redirect_stdout(io.StringIO()):\n"
            "    try:\n"
            "        main(['--help'])\n"
            "    except SystemExit:\n"
            "        pass\n"
            "print(sorted(m for m in ('numpy', 'scipy', 'tqdm', 'matplotlib', 'rclpy') if m in sys.modules))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"


def test_solving_tiger_needs_no_lp_solver(benchmarks_dir):
    """Two states: the pruning LPs are solved in closed form, so neither HiGHS nor scipy.optimize loads."""
    code = ("import contextlib, io, sys\n"
            "from pearl_pomdp.cli import main\n"
            "with contextlib.redirect_stdout(io.StringIO()):\n"
            f"    main(['solve', {str(benchmarks_dir / 'tiger.95.POMDP')!r}, '--method', 'incprune',"
            " '--horizon', '15', '--json', '--quiet'])\n"
            "print(sorted(m for m in ('scipy.optimize', 'highspy', 'matplotlib', 'rclpy') if m in sys.modules))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"


def test_solving_a_small_pomdp_file_imports_no_scipy_and_reads_no_entry_points(benchmarks_dir):
    """`pearl solve` on a small .POMDP file: T is read dense (no scipy.sparse), and the command's
    parser is built from its own module alone (no importlib.metadata scan of installed packages)."""
    code = ("import contextlib, io, sys\n"
            "from pearl_pomdp.cli import main\n"
            "with contextlib.redirect_stdout(io.StringIO()):\n"
            f"    main(['solve', {str(benchmarks_dir / 'network.POMDP')!r}, '--method', 'incprune',"
            " '--horizon', '3', '--json', '--quiet'])\n"
            "print(sorted(m for m in ('scipy', 'importlib.metadata', 'pearl_pomdp.cli.launch') if m in sys.modules))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"


@pytest.mark.parametrize("name", ["tiger.95.POMDP", "cheese.95.POMDP", "4x3.95.POMDP"])
def test_point_based_on_a_small_pomdp_file_imports_no_scipy(benchmarks_dir, name):
    """The point-based solver builds its CSR arrays of T, FIB, sweeps and Perseus without scipy on
    small dense models: importing scipy.sparse costs more than solving them (issue 15)."""
    code = ("import contextlib, io, sys\n"
            "from pearl_pomdp.cli import main\n"
            "with contextlib.redirect_stdout(io.StringIO()):\n"
            f"    main(['solve', {str(benchmarks_dir / name)!r}, '--method', 'pointbased', '--json', '--quiet'])\n"
            "print(sorted(m for m in ('scipy',) if m in sys.modules))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"


def test_dense_and_sparse_storage_give_the_same_fingerprint(benchmarks_dir):
    """The fingerprint of a dense T is computed without scipy; it must equal the CSR one."""
    from pearl_pomdp.model import Pomdp, load_model

    m = load_model(benchmarks_dir / "cheese.95.POMDP")
    assert not m.is_sparse
    sparse = Pomdp.create(m.states, m.actions, m.observations, list(m.T_dense()), m.O, m.R,
                          b0=m.b0, discount=m.discount, name=m.name, sparse=True)
    assert sparse.is_sparse
    assert sparse.fingerprint() == m.fingerprint()
