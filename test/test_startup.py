"""Start-up cost: commands import the heavy libraries only when they need them (issue 15)."""
import subprocess
import sys


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
