"""Shared fixtures: where the benchmark models live."""
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared"
BENCHMARKS = SHARED / "benchmarks" / "pomdp"


@pytest.fixture(scope="session")
def benchmarks_dir() -> Path:
    """``../shared/benchmarks/pomdp`` (CI clones the repo with ``shared/`` beside it)."""
    if not BENCHMARKS.is_dir():
        pytest.fail(f"benchmark models not found at {BENCHMARKS}; clone with ../shared beside the repo")
    return BENCHMARKS


# ROS fixtures (ros_context, pearl_policy) live in test/ros_helpers.py; registered here once so
# the session-scoped planned Pearl policy is shared by every test module.
from ros_helpers import pearl_policy, ros_context  # noqa: E402,F401
