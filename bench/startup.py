"""Start-up cost of the ``pearl`` command: ``pearl --help`` and ``pearl solve`` on tiger.

Each measurement is a fresh process running ``pearl_pomdp.cli.main`` (what the
``pearl`` console script runs) from ``--repo`` (default: this checkout), so an
older checkout can be measured with the same interpreter for a before/after::

    OMP_NUM_THREADS=1 .venv/bin/python bench/startup.py [--repo DIR] [--runs 7]

Reported (medians over ``--runs``, with min–max):

* ``python_bare_s``: ``python -c pass`` — the interpreter alone, the floor;
* ``help_s``: ``pearl --help``;
* ``solve_s``: ``pearl solve tiger.95.POMDP --method incprune --horizon 15 --json --quiet``,
  its ``seconds`` (the solve alone, as the command reports it) and
  ``solve_fixed_s`` = wall − seconds: what the command costs beyond solving;
* ``imports_help`` / ``imports_solve``: whether numpy, scipy, scipy.optimize, highspy, tqdm,
  matplotlib or rclpy were imported by each command.

Prints ONE JSON object on stdout.
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
TIGER = REPO / "test" / "data" / "pomdp" / "tiger.95.POMDP"
HEAVY = ["numpy", "scipy", "scipy.optimize", "scipy.sparse", "highspy", "tqdm", "matplotlib", "rclpy"]

_RUN = "import sys\nfrom pearl_pomdp.cli import main\nsys.exit(main(sys.argv[1:]))\n"
_MODULES = """
import io, contextlib, json, sys
from pearl_pomdp.cli import main
buf = io.StringIO()
try:
    with contextlib.redirect_stdout(buf):
        main(sys.argv[1:])
except SystemExit:
    pass
print(json.dumps({m: m in sys.modules for m in %r}))
""" % (HEAVY,)


def timed(cmd, env, cwd):
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True, env=env, cwd=cwd, timeout=120)
    return time.perf_counter() - t0, proc


def summary(xs):
    return {"median": statistics.median(xs), "min": min(xs), "max": max(xs)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repo", type=Path, default=REPO, help="checkout whose pearl_pomdp to run (default: this one)")
    ap.add_argument("--runs", type=int, default=7)
    ap.add_argument("--model", type=Path, default=TIGER)
    args = ap.parse_args()
    if not (args.repo / "pearl_pomdp" / "cli" / "__init__.py").is_file():
        raise SystemExit(f"bench/startup.py: --repo {args.repo}: no pearl_pomdp/cli there")
    if not args.model.is_file():
        raise SystemExit(f"bench/startup.py: --model {args.model}: no such file")
    # `python -c` puts the working directory first on sys.path: run from the checkout itself.
    cwd = str(args.repo.resolve())
    env = dict(os.environ, PYTHONPATH=cwd)
    py = sys.executable
    solve_args = ["solve", str(args.model), "--method", "incprune", "--horizon", "15", "--json", "--quiet"]
    bare, helps, solves, seconds = [], [], [], []
    for _ in range(args.runs):  # interleaved, so machine load hits every command alike
        bare.append(timed([py, "-c", "pass"], env, cwd)[0])
        t, proc = timed([py, "-c", _RUN, "--help"], env, cwd)
        if proc.returncode != 0:
            raise SystemExit(f"bench/startup.py: pearl --help failed: {proc.stderr[-300:]}")
        helps.append(t)
        t, proc = timed([py, "-c", _RUN, *solve_args], env, cwd)
        if proc.returncode != 0:
            raise SystemExit(f"bench/startup.py: pearl solve failed: {proc.stderr[-300:]}")
        solves.append(t)
        seconds.append(float(json.loads(proc.stdout.strip().splitlines()[-1])["seconds"]))
    mods = {}
    for name, argv in (("imports_help", ["--help"]), ("imports_solve", solve_args)):
        proc = subprocess.run([py, "-c", _MODULES, *argv], capture_output=True, text=True, env=env, cwd=cwd,
                              timeout=120)
        mods[name] = json.loads(proc.stdout.strip().splitlines()[-1])
    mods["pearl_pomdp_from"] = subprocess.run([py, "-c", "import pearl_pomdp; print(pearl_pomdp.__file__)"],
                                              capture_output=True, text=True, env=env, cwd=cwd).stdout.strip()
    fixed = [w - s for w, s in zip(solves, seconds)]
    print(json.dumps({
        "bench": "startup", "repo": str(args.repo.resolve()), "runs": args.runs, "model": args.model.name,
        "python": sys.version.split()[0], "load_avg": os.getloadavg(),
        "python_bare_s": summary(bare), "help_s": summary(helps), "solve_s": summary(solves),
        "solve_seconds_reported": summary(seconds), "solve_fixed_s": summary(fixed), **mods,
    }, indent=1))


if __name__ == "__main__":
    main()
