"""`.ci/run` fails when the install fails (issue 16 item 10).

In a scratch copy: a tiny package is installed once (so a `.venv` with pytest exists), then its
setup.py is broken on purpose. The old script (`pip … | grep … || true`) went on and ran pytest
in that stale venv, printing "1 passed" and exiting 0; the script must now stop with pip's error.
"""
import shutil
import subprocess
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]

GOOD_SETUP = ('from setuptools import setup\n'
              'setup(name="ci_scratch_pkg", version="0.1", packages=["ci_scratch_pkg"],\n'
              '      extras_require={"ros": [], "test": ["pytest", "mypy"]})\n')


def _ci(repo: Path) -> subprocess.CompletedProcess:
    return subprocess.run(["bash", str(repo / ".ci" / "run")], cwd=repo, capture_output=True, text=True,
                          timeout=300)


@pytest.mark.skipif(shutil.which("bash") is None, reason="needs bash")
def test_ci_run_fails_on_a_broken_install_instead_of_testing_a_stale_venv(tmp_path):
    repo = tmp_path / "scratch"
    (repo / ".ci").mkdir(parents=True)
    shutil.copy(REPO / ".ci" / "run", repo / ".ci" / "run")
    (repo / "ci_scratch_pkg").mkdir()
    (repo / "ci_scratch_pkg" / "__init__.py").write_text("")
    (repo / "test").mkdir()
    (repo / "test" / "test_ok.py").write_text("def test_ok():\n    assert 1 + 1 == 2\n")
    (repo / "setup.py").write_text(GOOD_SETUP)
    (repo / "mypy.ini").write_text("[mypy]\nfiles = ci_scratch_pkg\n")   # .ci/run type-checks what mypy.ini names

    good = _ci(repo)
    assert good.returncode == 0, good.stdout + good.stderr
    assert "1 passed" in good.stdout
    assert "WARNING: Location" not in good.stdout + good.stderr

    (repo / "setup.py").write_text('raise SystemExit("deliberately broken setup.py")\n')
    broken = _ci(repo)
    output = broken.stdout + broken.stderr
    assert broken.returncode != 0, output
    assert "deliberately broken setup.py" in output   # pip's error reaches the log
    assert "passed" not in output                    # pytest never ran in the stale venv
