"""The C kernels (the solvers' and the online planner's step) compile without a single warning (-Wall -Wextra -Werror).

The package build (setup.py) passes -Wall -Wextra, so a new warning shows in every build
log; this test makes one fail CI. It compiles each kernel the way setup.py does (the
interpreter's own C compiler and headers), at -O2 and -O3: gcc finds some
maybe-uninitialised reads only when optimising (issue 26: ``Pall`` in ``py_prune``).
"""
import shlex
import shutil
import subprocess
import sysconfig
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
KERNELS = ["pearl_pomdp/solvers/_prune.c", "pearl_pomdp/solvers/_pointbased_kernel.c",
           "pearl_pomdp/solvers/_search_kernel.c", "pearl_pomdp/online/_step_kernel.c"]
STRICT = ["-Wall", "-Wextra", "-Werror"]


def compiler():
    cc = shlex.split(sysconfig.get_config_var("CC") or "cc")
    if shutil.which(cc[0]) is None:
        pytest.fail(f"the C compiler Python was built with ({cc[0]}) is not on PATH; the kernels need it to build")
    return cc


@pytest.mark.parametrize("opt", ["-O2", "-O3"])
@pytest.mark.parametrize("source", KERNELS)
def test_kernel_compiles_warning_free(source, opt, tmp_path):
    cmd = [*compiler(), opt, "-std=c99", *STRICT, "-fPIC", f"-I{sysconfig.get_paths()['include']}",
           "-c", str(REPO / source), "-o", str(tmp_path / "kernel.o")]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, f"{source} does not build warning-free ({' '.join(cmd)}):\n{proc.stderr}"
    assert proc.stderr.strip() == "", proc.stderr

