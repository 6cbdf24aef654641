"""Every example in every subcommand's --help runs as written.

The examples are the ``pearl …`` lines of the "Example(s)" section of each command's help
(its module docstring, which `pearl CMD --help` prints). Each runs through ``bash -c``, so
quoting, pipes, ``&&`` and redirections are checked as a newcomer would type them, in a fresh
directory that holds what the repository gives a newcomer (``config/``, ``bags/``,
``launch/``), the policy `pearl plan config/pearl.domain.yaml` saves (out/policies/pearl),
and the bags the examples name (``run1`` as `pearl record run1` leaves it, ``killed_run``
as a recorder killed mid-write leaves it). Commands that run until Ctrl-C (nodes, launch,
record without --duration) are started, must report that they are ready, and must exit 0
on SIGINT. The slowest example (a demo) takes ~20-30 s.
"""
from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path
from typing import List

import pytest

from pearl_pomdp.cli import _command_modules
from ros_helpers import Proc, allocate_domain_id, ros_env, wait_for

REPO = Path(__file__).resolve().parents[1]
pytestmark = pytest.mark.slow   # every command's help examples, run as written (~2 min together)

_HEADING = re.compile(r"^Examples?\b.*:$")


def examples_of(doc: str) -> List[str]:
    """The ``pearl …`` command lines of a help text's Example(s) section (continuations joined)."""
    lines = doc.splitlines()
    found: List[str] = []
    inside = False
    for line in lines:
        if _HEADING.match(line.strip()) and not line.startswith(" "):
            inside = True
            continue
        if inside and line.strip() and not line.startswith(" "):
            inside = False
        if not inside:
            continue
        text = line.strip()
        if found and found[-1].endswith("\\"):
            found[-1] += "\n" + text
        elif text.startswith("pearl "):
            found.append(text)
    return found


EXAMPLES = {m.COMMAND: examples_of(m.__doc__ or "") for m in _command_modules()}

#: Examples that run until Ctrl-C → what their output says once they are up.
UNTIL_CTRL_C = {
    "pearl record run1": "recording into",
    "pearl run belief_tracker": "tracking pearl",
    "pearl run hierarchical_policy": "policy ready",
    # Every node of the launch file up (the stop during start-up is test_shutdown's business).
    "pearl launch launch/pearl.launch.xml policy:=": ("tracking pearl", "policy ready", "executing", "landmarks",
                                                      "guide pace"),
}


def test_every_command_has_an_example():
    assert sorted(command for command, examples in EXAMPLES.items() if not examples) == []


def test_examples_are_found_as_help_prints_them():
    doc = "Plan it.\n\nExamples:\n  pearl plan a.yaml   # one\n  pearl explain a.yaml \\\n      --belief X=y\n\nProse after.\n  pearl not-an-example\n"
    assert examples_of(doc) == ["pearl plan a.yaml   # one", "pearl explain a.yaml \\\n--belief X=y"]


def _newcomer_dir(root: Path, pearl_policy: Path) -> Path:
    work = root / "work"
    work.mkdir()
    for name in ("config", "bags", "launch"):
        (work / name).symlink_to(REPO / name)
    shutil.copytree(pearl_policy, work / "out" / "policies" / "pearl")
    shutil.copytree(REPO / "bags" / "table4_clarification", work / "run1")
    killed = work / "killed_run"
    shutil.copytree(REPO / "bags" / "table4_clarification", killed)
    (killed / "metadata.yaml").unlink()
    mcap = next(killed.glob("*.mcap"))
    data = mcap.read_bytes()
    mcap.write_bytes(data[: len(data) * 2 // 3])   # cut mid-file: no footer, a partial record
    return work


def _run_until_ctrl_c(text: str, ready, env, work: Path, logs: Path, name: str) -> None:
    markers = ready if isinstance(ready, tuple) else (ready,)
    proc = Proc(["bash", "-c", "exec " + text], env, logs, name, cwd=work)

    def up_or_gone() -> bool:
        output = proc.stdout() + proc.stderr()
        return all(m in output for m in markers) or proc.returncode is not None

    try:
        up = wait_for(up_or_gone, timeout=60)
    finally:
        code = proc.stop(timeout=15)
    output = proc.stdout() + proc.stderr()
    assert up and all(m in output for m in markers), f"$ {text}\n{output[-3000:]}"
    assert code == 0, f"$ {text}\nexit {code} after SIGINT\n{output[-3000:]}"
    return output


@pytest.mark.parametrize("command", sorted(EXAMPLES))
def test_help_examples_run_as_written(command, tmp_path, pearl_policy):
    """The command's examples, in order, in one newcomer's directory (later ones may use earlier output)."""
    work = _newcomer_dir(tmp_path, pearl_policy)
    env = ros_env(allocate_domain_id(), tmp_path / "ros_log")
    env["PATH"] = f"{Path(sys.executable).parent}{os.pathsep}{env.get('PATH', '')}"   # `pearl` of this venv
    for index, text in enumerate(EXAMPLES[command]):
        if command == "record":
            shutil.rmtree(work / "run1", ignore_errors=True)   # each example records a new bag
        ready = next((mark for prefix, mark in UNTIL_CTRL_C.items() if text.startswith(prefix)), None)
        if ready is not None and "--duration" not in text:
            _run_until_ctrl_c(text, ready, env, work, tmp_path / "logs", f"{command}-{index}")
            continue
        done = subprocess.run(["bash", "-o", "pipefail", "-c", text], cwd=work, env=env, capture_output=True,
                              text=True, timeout=180)
        assert done.returncode == 0, f"$ {text}\n{done.stdout[-2000:]}\n{done.stderr[-3000:]}"
