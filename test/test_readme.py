"""The README's library example runs from a clone as written and gives the numbers it claims."""
from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
#: What a clone does not have beside it: the workplace's sibling folder, its benchmarks and its
#: design notes (joined from parts, so that this file does not contain the names it looks for).
OUTSIDE = ("/".join(("..", "shared")), "/".join(("shared", "benchmarks")), ".".join(("DESIGN", "md")))


def _library_example() -> str:
    text = (REPO / "README.md").read_text(encoding="utf-8")
    section = text.split("## Using it as a library", 1)[1]
    match = re.search(r"```python\n(.*?)```", section, re.S)
    assert match, "README.md: no python block under 'Using it as a library'"
    return match.group(1)


def test_library_example_runs_from_the_clone_and_prints_its_claims():
    code = _library_example()
    assert OUTSIDE[0] not in code
    probe = code + ("\nimport json\nprint(json.dumps({'vectors': result.policy.num_vectors, "
                    "'value': result.value_at_start, 'left': float(b[0]), 'action': tiger.actions[action]}))\n")
    out = subprocess.run([sys.executable, "-c", probe], cwd=REPO, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    import json

    got = json.loads(out.stdout.strip().splitlines()[-1])
    # The comments of the example: 47 vectors, V(b0) = 9.72842474467767, P(left) = 0.9698.
    assert got["vectors"] == 47
    assert abs(got["value"] - 9.72842474467767) < 1e-9
    assert round(got["left"], 4) == 0.9698
    assert got["action"] == "open-right"   # the tiger is most likely left: open the right door


def test_no_tracked_file_reaches_outside_the_clone():
    # A user's clone has nothing beside it: no code, test, doc or bench may name a folder next
    # to the repository (bench/peers.py once looked for its models in the sibling folder), this
    # file included: OUTSIDE spells the names in parts so that it does not name them itself.
    tracked = subprocess.run(["git", "ls-files"], cwd=REPO, capture_output=True, text=True, check=True).stdout.split()
    offenders = []
    for name in tracked:
        path = REPO / name
        if path.suffix not in {".py", ".md", ".yaml", ".yml", ".cfg", ".ini", ".toml", ".sh", ""}:
            continue
        if not path.is_file():
            continue
        text = path.read_text(encoding="utf-8", errors="replace")
        for pattern in OUTSIDE:
            if pattern in text:
                offenders.append(f"{name}: {pattern}")
    assert not offenders, offenders
