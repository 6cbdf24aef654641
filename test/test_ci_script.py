"""`.ci/run` tests a fresh clone that nothing beside it can reach, and fails when the install fails.

In a scratch git repository with a ``shared/`` folder beside it (as on the project's machine): a
tiny package whose one test asserts that that sibling ``shared`` folder is out of reach passes under `.ci/run`
(the script clones the checkout into an empty temporary folder and runs there). Then its setup.py
is broken on purpose and committed: the old script (`pip … | grep … || true`) went on and ran pytest in a
stale venv, printing "1 passed" and exiting 0; the script must stop with pip's error.
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


def _commit(repo: Path, message: str) -> None:
    git = ["git", "-C", str(repo), "-c", "user.name=ci", "-c", "user.email=ci@example.org"]
    subprocess.run(git + ["add", "-A"], check=True, capture_output=True)
    subprocess.run(git + ["commit", "-q", "-m", message], check=True, capture_output=True)


NO_SHARED_TEST = ("from pathlib import Path\n\n"
                  "def test_nothing_beside_the_clone():\n"
                  "    here = Path(__file__).resolve().parents[1]\n"
                  "    assert not (here.parent / 'shared').exists(), here\n"
                  "    assert 1 + 1 == 2\n")


def _scratch_repo(root: Path, setup_py: str) -> Path:
    """A git repository under ``root`` (a ``shared/`` folder beside it, as on the project's machine)
    with a tiny package, its one test, ``.ci/run`` and the given setup.py, committed."""
    repo = root / "scratch"
    (root / "shared").mkdir(parents=True)   # what the project's machine has beside a checkout
    (repo / ".ci").mkdir(parents=True)
    shutil.copy(REPO / ".ci" / "run", repo / ".ci" / "run")
    (repo / "ci_scratch_pkg").mkdir()
    (repo / "ci_scratch_pkg" / "__init__.py").write_text("")
    (repo / "test").mkdir()
    (repo / "test" / "test_ok.py").write_text(NO_SHARED_TEST)
    (repo / "setup.py").write_text(GOOD_SETUP)
    (repo / "mypy.ini").write_text("[mypy]\nfiles = ci_scratch_pkg\n")   # .ci/run type-checks what mypy.ini names
    subprocess.run(["git", "init", "-q", str(repo)], check=True)
    _commit(repo, "scratch")
    if setup_py != GOOD_SETUP:
        (repo / "setup.py").write_text(setup_py)
        _commit(repo, "broken")
    return repo


@pytest.mark.slow
@pytest.mark.skipif(shutil.which("bash") is None or shutil.which("git") is None, reason="needs bash and git")
def test_ci_run_tests_a_clone_out_of_reach_of_shared_and_fails_on_a_broken_install(tmp_path):
    from concurrent.futures import ThreadPoolExecutor

    # The good and the broken checkout side by side, their two CI runs at once (each ~12 s, mostly
    # creating a venv and waiting on pip): the broken one is the good one with setup.py broken on
    # purpose and committed.
    good_repo = _scratch_repo(tmp_path / "good", GOOD_SETUP)
    broken_repo = _scratch_repo(tmp_path / "broken", 'raise SystemExit("deliberately broken setup.py")\n')
    with ThreadPoolExecutor(2) as pool:
        good, broken = pool.map(_ci, (good_repo, broken_repo))

    assert good.returncode == 0, good.stdout + good.stderr
    assert "1 passed" in good.stdout
    assert "WARNING: Location" not in good.stdout + good.stderr
    assert not (good_repo / ".venv").exists()   # the run happened in the clone, not in the checkout

    output = broken.stdout + broken.stderr
    assert broken.returncode != 0, output
    assert "deliberately broken setup.py" in output   # pip's error reaches the log
    assert "passed" not in output                    # pytest never ran in the stale venv
