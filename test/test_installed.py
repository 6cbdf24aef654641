"""The README's install gives everything the suite tests: a missing or broken dependency fails
here (and in the tests that import it), it never turns those tests into skips.

The requirements are read from setup.py (``install_requires`` and the ``ros`` and ``test``
extras the README installs), so a new dependency is checked as soon as it is declared.
"""
from __future__ import annotations

import ast
import importlib
import re
from importlib import metadata
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]

#: Distribution → a module it must make importable (the ones the package and the tests use).
MODULES = {"ros-jazzy-rclpy": "rclpy", "ros-jazzy-common-interfaces": "std_msgs.msg", "mcap": "mcap",
           "mcap-ros2-support": "mcap_ros2", "matplotlib": "matplotlib", "foxglove-sdk": "foxglove",
           "py_trees": "py_trees", "pocketsphinx": "pocketsphinx", "espeakng-loader": "espeakng_loader",
           "pytest": "pytest", "hypothesis": "hypothesis", "rosbags": "rosbags", "websockets": "websockets",
           "mypy": "mypy", "pearl_interfaces": "pearl_interfaces.msg", "numpy": "numpy", "scipy": "scipy", "PyYAML": "yaml", "tqdm": "tqdm"}


def _requirements() -> list:
    """Every requirement string of install_requires and the ros/test extras (SPEECH expanded)."""
    tree = ast.parse((REPO / "setup.py").read_text(encoding="utf-8"))
    names = {}
    for node in ast.walk(tree):
        if isinstance(node, ast.Assign) and len(node.targets) == 1 and isinstance(node.targets[0], ast.Name):
            try:
                names[node.targets[0].id] = ast.literal_eval(node.value)
            except ValueError:
                # A direct reference built from setup.py's folder (f"pearl_interfaces @ {…}"): its name.
                if isinstance(node.value, ast.JoinedStr) and isinstance(node.value.values[0], ast.Constant):
                    names[node.targets[0].id] = str(node.value.values[0].value).split("@")[0].strip()
    setup_call = next(n for n in ast.walk(tree) if isinstance(n, ast.Call) and getattr(n.func, "id", "") == "setup")
    kw = {k.arg: k.value for k in setup_call.keywords}
    reqs = list(ast.literal_eval(kw["install_requires"]))
    extras = kw["extras_require"]
    assert isinstance(extras, ast.Dict)
    for key, value in zip(extras.keys, extras.values):
        if ast.literal_eval(key) not in ("ros", "test"):
            continue
        reqs += _list(value, names)      # e.g. "ros": [...] + SPEECH
    return sorted(set(reqs))


def _list(node: ast.expr, names: dict) -> list:
    """A list literal, a module-level name bound to one, or a sum of those."""
    if isinstance(node, ast.BinOp) and isinstance(node.op, ast.Add):
        return _list(node.left, names) + _list(node.right, names)
    if isinstance(node, ast.Name):
        return list(names[node.id])
    if isinstance(node, ast.List):
        return [names[e.id] if isinstance(e, ast.Name) else ast.literal_eval(e) for e in node.elts]
    return list(ast.literal_eval(node))


REQUIREMENTS = _requirements()


def test_the_requirements_are_read():
    names = {re.split(r"[<>=!~ ]", r, 1)[0] for r in REQUIREMENTS}
    assert {"numpy", "ros-jazzy-rclpy", "pocketsphinx", "foxglove-sdk", "pytest", "mypy", "pearl_interfaces"} <= names


@pytest.mark.parametrize("requirement", REQUIREMENTS)
def test_every_declared_dependency_is_installed_and_importable(requirement):
    name = re.split(r"[<>=!~ ]", requirement, 1)[0]
    try:
        version = metadata.version(name)
    except metadata.PackageNotFoundError:
        pytest.fail(f"{requirement!r} (setup.py) is not installed: run the README's install command")
    assert version
    module = MODULES.get(name)
    if module is not None:
        importlib.import_module(module)   # installed but broken (a missing shared library) fails too
